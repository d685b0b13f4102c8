//! Independent units of work (Table 1's fits, Figure 4's runs) on a few workers at a time: on
//! two cores two single-threaded fits finish sooner than one fit on two threads, whose second
//! thread idles wherever the work has a single trajectory or output.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::anyhow;
use msgp_core::numeric::parallel::Threads;

/// The units whose results are already on disk, and the rest to run: `finished` reads a
/// unit's result (`None`: not there), `record` names where it was read from, printed as
/// `== <record>` unless `quiet`. The results come back in the units' order, `None` where the
/// unit is still to run; the units to run with their places.
#[allow(clippy::type_complexity)]
pub fn reuse<U, R>(
    units: Vec<U>,
    quiet: bool,
    finished: impl Fn(&U) -> anyhow::Result<Option<R>>,
    record: impl Fn(&U) -> String,
) -> anyhow::Result<(Vec<Option<R>>, Vec<(usize, U)>)> {
    let mut done = Vec::new();
    let mut todo = Vec::new();
    for (k, unit) in units.into_iter().enumerate() {
        match finished(&unit)? {
            Some(result) => {
                if !quiet {
                    eprintln!("== {}", record(&unit));
                }
                done.push(Some(result));
            }
            None => {
                done.push(None);
                todo.push((k, unit));
            }
        }
    }
    Ok((done, todo))
}

/// How many units run at a time and on how many threads each: `jobs` (default: the threads)
/// at most the units' number, each on `threads / jobs` threads; one job keeps the caller's own
/// threads (`None`).
pub fn share(
    jobs: Option<u16>,
    threads: usize,
    units: usize,
) -> anyhow::Result<(usize, Option<Threads>)> {
    let jobs = jobs.map_or(threads, usize::from).clamp(1, units.max(1));
    let per_unit = (jobs > 1)
        .then(|| Threads::new((threads / jobs).max(1)))
        .transpose()?;
    Ok((jobs, per_unit))
}

/// `work` on every item of `items` by `jobs` workers, each taking the next item when its last
/// is done; the results in the items' order. The first failure stops the workers from starting
/// further items and is returned once the running ones end.
pub fn run<T: Send, R: Send>(
    items: Vec<T>,
    jobs: usize,
    work: impl Fn(T) -> anyhow::Result<R> + Sync,
) -> anyhow::Result<Vec<R>> {
    let n = items.len();
    let queue = Mutex::new(items.into_iter().enumerate());
    let failed = AtomicBool::new(false);
    let worker = || -> anyhow::Result<Vec<(usize, R)>> {
        let mut done = Vec::new();
        loop {
            if failed.load(Ordering::Relaxed) {
                return Ok(done);
            }
            let next = queue
                .lock()
                .map_err(|_| anyhow!("a worker panicked"))?
                .next();
            let Some((k, item)) = next else {
                return Ok(done);
            };
            match work(item) {
                Ok(r) => done.push((k, r)),
                Err(e) => {
                    failed.store(true, Ordering::Relaxed);
                    return Err(e);
                }
            }
        }
    };
    let results: Vec<anyhow::Result<Vec<(usize, R)>>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..jobs.max(1)).map(|_| scope.spawn(worker)).collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(anyhow!("a worker panicked")))
            })
            .collect()
    });
    let mut slots: Vec<Option<R>> = (0..n).map(|_| None).collect();
    for r in results {
        for (k, v) in r? {
            slots[k] = Some(v);
        }
    }
    slots
        .into_iter()
        .map(|s| s.ok_or_else(|| anyhow!("a unit of work did not run")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_keep_the_items_order_and_the_first_failure_is_returned() {
        for jobs in 1..4 {
            let squares = run((0..20u64).collect(), jobs, |x| {
                // uneven work, so the workers finish out of order
                std::thread::sleep(std::time::Duration::from_millis((x * 7) % 5));
                Ok(x * x)
            })
            .expect("runs");
            assert_eq!(squares, (0..20u64).map(|x| x * x).collect::<Vec<_>>());
        }
        let failed = run((0..10u64).collect(), 2, |x| {
            if x == 3 {
                anyhow::bail!("unit {x} failed")
            }
            Ok(x)
        })
        .expect_err("a failure");
        assert_eq!(failed.to_string(), "unit 3 failed");
    }

    #[test]
    fn jobs_share_the_threads() {
        let (jobs, per) = share(None, 2, 30).expect("share");
        assert_eq!((jobs, per.map(|t| t.get())), (2, Some(1)));
        let (jobs, per) = share(Some(1), 2, 30).expect("share");
        assert_eq!((jobs, per), (1, None));
        let (jobs, per) = share(Some(8), 2, 3).expect("share");
        assert_eq!((jobs, per.map(|t| t.get())), (3, Some(1)));
    }
}
