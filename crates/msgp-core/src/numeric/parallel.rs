//! Deterministic fan-out of independent work items over scoped threads.

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

/// Environment variable with the number of threads the loss gradient runs its episodes on
/// (default: every available core).
pub const THREADS_VAR: &str = "MSGP_THREADS";

/// Threads for the episodes of one loss gradient: [`THREADS_VAR`] if set to a positive integer,
/// else the available parallelism.
pub fn thread_count() -> usize {
    std::env::var(THREADS_VAR)
        .ok()
        .and_then(|v| v.trim().parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
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
}
