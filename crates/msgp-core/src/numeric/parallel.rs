//! Deterministic fan-out of independent work items over scoped threads.

use std::num::NonZeroUsize;

use crate::error::{MsgpError, Result};

/// `f(k, item)` for every item, on up to `threads` scoped threads (item `k` on thread
/// `k mod threads`); the results come back in item order, so a caller that reduces them in
/// that order gets the same answer for any thread count. A panic in `f` is resumed on the
/// calling thread.
pub(crate) fn map_indexed<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(usize, &T) -> Result<R> + Sync,
) -> Vec<Result<R>> {
    let threads = threads.min(items.len()).max(1);
    if threads == 1 {
        return items.iter().enumerate().map(|(k, x)| f(k, x)).collect();
    }
    let f = &f;
    let mut slots: Vec<Option<Result<R>>> = items.iter().map(|_| None).collect();
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|w| {
                scope.spawn(move || {
                    items
                        .iter()
                        .enumerate()
                        .skip(w)
                        .step_by(threads)
                        .map(|(k, x)| (k, f(k, x)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        for h in handles {
            match h.join() {
                Ok(done) => {
                    for (k, r) in done {
                        slots[k] = Some(r);
                    }
                }
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
    });
    slots
        .into_iter()
        .enumerate()
        .map(|(k, r)| {
            r.unwrap_or_else(|| Err(MsgpError::Data(format!("item {k} was not evaluated"))))
        })
        .collect()
}

/// The environment variable the front ends (`msgp`, the Python module) read the thread count
/// from ([`Threads::from_env`]); the library itself reads no environment.
pub const THREADS_VAR: &str = "MSGP_THREADS";

/// How many threads the independent work items of one computation may run on: a loss
/// gradient's episodes, the one-step fits' outputs, the policy search's candidates and starts.
/// Results never depend on it (work items are reduced in their order). Default: every available
/// core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Threads(NonZeroUsize);

impl Threads {
    /// One thread: the calling thread only.
    pub const ONE: Threads = Threads(NonZeroUsize::MIN);

    /// `n` threads; 0 is refused.
    pub fn new(n: usize) -> Result<Self> {
        NonZeroUsize::new(n)
            .map(Threads)
            .ok_or_else(|| MsgpError::InvalidSetting {
                name: "threads",
                reason: "need at least one thread".into(),
            })
    }

    /// Every core the process may use.
    pub fn available() -> Self {
        Threads(std::thread::available_parallelism().unwrap_or(NonZeroUsize::MIN))
    }

    /// [`THREADS_VAR`] when it is set (a positive integer), else [`Threads::available`]; any
    /// other value is refused with the variable's name.
    pub fn from_env() -> Result<Self> {
        match std::env::var(THREADS_VAR) {
            Err(std::env::VarError::NotPresent) => Ok(Self::available()),
            Ok(v) if v.trim().is_empty() => Ok(Self::available()),
            Ok(v) => v
                .trim()
                .parse::<usize>()
                .ok()
                .and_then(NonZeroUsize::new)
                .map(Threads)
                .ok_or_else(|| MsgpError::InvalidSetting {
                    name: THREADS_VAR,
                    reason: format!("must be a positive integer, got `{v}`"),
                }),
            Err(e) => Err(MsgpError::InvalidSetting {
                name: THREADS_VAR,
                reason: e.to_string(),
            }),
        }
    }

    /// The count.
    pub fn get(self) -> usize {
        self.0.get()
    }
}

impl Default for Threads {
    fn default() -> Self {
        Self::available()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_keep_item_order_for_any_thread_count() {
        let items: Vec<u64> = (0..11).collect();
        let square = |k: usize, x: &u64| -> Result<(usize, u64)> {
            if *x == 7 {
                Err(MsgpError::Data("seven".into()))
            } else {
                Ok((k, x * x))
            }
        };
        let one: Vec<String> = map_indexed(&items, 1, square)
            .into_iter()
            .map(|r| format!("{r:?}"))
            .collect();
        for threads in [2, 3, 16] {
            let many: Vec<String> = map_indexed(&items, threads, square)
                .into_iter()
                .map(|r| format!("{r:?}"))
                .collect();
            assert_eq!(one, many, "threads {threads}");
        }
        assert!(one[3].contains("(3, 9)"), "{}", one[3]);
        assert!(one[7].contains("seven"), "{}", one[7]);
        assert!(map_indexed(&Vec::<u64>::new(), 2, square).is_empty());
    }

    #[test]
    fn a_thread_count_is_positive() {
        assert!(Threads::new(0).is_err());
        assert_eq!(Threads::new(3).map(Threads::get).ok(), Some(3));
        assert_eq!(Threads::ONE.get(), 1);
        assert!(Threads::available().get() >= 1);
    }
}
