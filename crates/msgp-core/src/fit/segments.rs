//! Long logs by segments: the trajectory likelihood over consecutive pieces of each training
//! trajectory, each rollout started from the data, and each solver step on a seeded random
//! batch of them.
//!
//! A free run of the whole log costs one moment-matching step per sample at every solver
//! iteration, in sequence: an hour of a 100 Hz log (360,000 samples) would take minutes per
//! iteration on one core. Cut into segments of `length` predicted steps — segment `k` covers
//! samples `[k·length, k·length + length + w)` of its trajectory, its first `w = max(l_y, l_u)`
//! samples the window it starts from, so every sample after the trajectory's first `w` is
//! predicted by exactly one segment — the likelihood is a sum of independent rollouts that run
//! on every core. With Adam, each step then evaluates `batch` segments drawn without
//! replacement (seeded by the fit's seed and the step), weighted so that the loss per predicted
//! step is an unbiased estimate of the whole sum's: the cost of a step no longer grows with the
//! log. L-BFGS, whose line search needs one deterministic function, sums every segment.
//!
//! What changes for the model: each training rollout forgets the data after `length` steps, so
//! the likelihood judges predictions up to that horizon (long against the time constants of
//! most logs long enough to need segments). The validation tails that stop the training and
//! choose the recipe stay whole (the last 20 % of each trajectory, one free run each): cut
//! into segments too, they judged 40-step predictions, stopped later and chose models whose
//! long free runs were worse (`docs/experiments/2026-12-06-long-logs-by-segments.md`, "Long logs by segments"). A trajectory of at
//! most `length + w` samples is one segment: the fit is then bit for bit the unsegmented one.

use rand::seq::index::sample;
use rand::{SeedableRng, rngs::StdRng};
use serde::{Deserialize, Serialize};

use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::rollout::{Episode, Excitation};

/// Training windows above which the default fit trains by segments ([`Segments::DEFAULT`]):
/// at about 45 µs per predicted step and its gradient (dryer history, 100 pseudo-inputs, this
/// machine), a whole-log iteration on 4,000 windows takes 0.18 s, and the default protocol's
/// ~1,600 iterations about 5 minutes.
pub const LONG_LOG_WINDOWS: usize = 4000;

/// How a fit cuts its training trajectories ([`super::MsgpSettings::segments`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Segments {
    /// Predicted steps per segment (after the window it starts from).
    pub length: usize,
    /// Segments per Adam step (all of them when there are fewer, and for L-BFGS).
    pub batch: usize,
}

impl Segments {
    /// The default for long logs: segments of 1,000 steps, 2 per Adam step (2,000 predicted
    /// steps per step, five times the dryer's whole training part). Against 200 × 8 (the same
    /// work per step) on a synthetic log, fewer restarts from the data simulated the held-out
    /// part better (`docs/experiments/2026-12-06-long-logs-by-segments.md`, "Long logs by segments").
    pub const DEFAULT: Segments = Segments {
        length: 1000,
        batch: 2,
    };

    /// Checks the settings (both at least 1).
    pub fn validate(&self) -> Result<()> {
        if self.length == 0 || self.batch == 0 {
            return Err(MsgpError::InvalidSetting {
                name: "segments",
                reason: format!(
                    "segment length and batch must be at least 1 (got {} and {})",
                    self.length, self.batch
                ),
            });
        }
        Ok(())
    }

    /// `episodes` (normalised) cut into segments of `self.length` predicted steps after a
    /// window of `warmup` samples (see the module docs); feedback episodes stay whole (their
    /// rollout runs under their policy from the start). A last piece with nothing to predict
    /// is dropped; one shorter than `length` is kept.
    pub(super) fn split(&self, episodes: &[Episode], warmup: usize) -> Result<Vec<Episode>> {
        let mut out = Vec::new();
        for ep in episodes {
            match ep.excitation {
                Excitation::FeedForward => out.extend(
                    cut(&ep.traj, self.length, warmup)?
                        .into_iter()
                        .map(Episode::feed_forward),
                ),
                Excitation::Feedback(_) => out.push(ep.clone()),
            }
        }
        Ok(out)
    }
}

/// `traj` as consecutive segments of `length` predicted steps after `warmup` samples each.
fn cut(traj: &Trajectory, length: usize, warmup: usize) -> Result<Vec<Trajectory>> {
    let n = traj.len();
    if n <= length + warmup {
        return Ok(vec![traj.clone()]);
    }
    let mut out = Vec::new();
    let mut start = 0;
    while start + warmup < n {
        let end = (start + length + warmup).min(n);
        out.push(Trajectory::new(
            traj.u.rows(start, end - start).into_owned(),
            traj.y.rows(start, end - start).into_owned(),
        )?);
        start += length;
    }
    Ok(out)
}

/// The batches of one training run: `batch` of `count` segments per solver step, drawn
/// without replacement from a generator seeded once per run.
#[derive(Debug)]
pub(super) struct Batches {
    rng: StdRng,
    count: usize,
    batch: usize,
}

impl Batches {
    /// Batches of `batch` out of `count`, or `None` when every step takes all of them.
    pub(super) fn new(count: usize, batch: usize, seed: u64) -> Option<Self> {
        (batch < count).then(|| Self {
            rng: StdRng::seed_from_u64(seed ^ 0x5e67_3e17_ba7c_4e55),
            count,
            batch,
        })
    }

    /// The next step's segments, in increasing order.
    pub(super) fn draw(&mut self) -> Vec<usize> {
        let mut picked = sample(&mut self.rng, self.count, self.batch).into_vec();
        picked.sort_unstable();
        picked
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(n: usize) -> Trajectory {
        let u: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let y: Vec<f64> = (0..n).map(|i| -(i as f64)).collect();
        Trajectory::siso(&u, &y).expect("finite")
    }

    /// Every sample after the first window is predicted by exactly one segment, each segment
    /// starts from the `warmup` samples before its first prediction, and a short trajectory is
    /// one segment, itself.
    #[test]
    fn segments_predict_every_sample_once() {
        let (length, warmup) = (7, 3);
        for n in [4, 10, 11, 12, 30, 31, 33] {
            let pieces = cut(&ramp(n), length, warmup).expect("cut");
            let mut predicted = Vec::new();
            for p in &pieces {
                assert!(
                    p.len() > warmup && p.len() <= length + warmup,
                    "{n}: {}",
                    p.len()
                );
                predicted.extend((warmup..p.len()).map(|t| p.u[(t, 0)] as usize));
            }
            assert_eq!(predicted, (warmup..n).collect::<Vec<_>>(), "n = {n}");
            if n <= length + warmup {
                assert_eq!(pieces, vec![ramp(n)]);
            }
        }
    }

    /// Feedback episodes stay whole; batches are seeded, sorted, distinct and cover every
    /// segment about equally often.
    #[test]
    fn batches_are_seeded_and_fair() {
        let policy = crate::policy::PolicySpec::Linear(
            crate::policy::LinearPolicy::new(
                nalgebra::DMatrix::zeros(1, 1),
                nalgebra::DVector::zeros(1),
            )
            .expect("policy"),
        );
        let episodes = vec![
            Episode::feed_forward(ramp(25)),
            Episode {
                traj: ramp(25),
                excitation: Excitation::Feedback(Box::new(policy)),
            },
        ];
        let split = Segments {
            length: 10,
            batch: 2,
        }
        .split(&episodes, 2)
        .expect("split");
        assert_eq!(split.len(), 4);
        assert_eq!(split[3].traj, episodes[1].traj);
        assert!(matches!(split[3].excitation, Excitation::Feedback(_)));
        assert!(Batches::new(4, 4, 0).is_none());
        let mut a = Batches::new(10, 3, 7).expect("batches");
        let mut b = Batches::new(10, 3, 7).expect("batches");
        let mut counts = [0usize; 10];
        for _ in 0..2000 {
            let d = a.draw();
            assert_eq!(d, b.draw());
            assert!(d.windows(2).all(|w| w[0] < w[1]), "{d:?}");
            d.iter().for_each(|&k| counts[k] += 1);
        }
        // 600 expected per segment; a binomial's sd is about 20
        assert!(
            counts.iter().all(|&c| (500..700).contains(&c)),
            "{counts:?}"
        );
    }
}
