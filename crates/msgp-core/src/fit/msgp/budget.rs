//! How long the final training is ([`crate::fit::MsgpSettings::choose_final_budget`]): its whole length
//! unless a shorter one's proxy simulates the validation tail clearly better.

use super::outcomes::FinalTraining;
use crate::error::{MsgpError, Result};
use crate::fit::CLEARLY_BETTER;
use crate::gp::{GpConfig, GpParams, PreparedGp};
use crate::narx::NarxSpec;
use crate::numeric::linalg::JitterLog;
use crate::rollout::{Control, Episode, simulate};

/// A length of the final training and its proxy's RMSE on the validation tail (`None` where
/// its simulation failed): [`crate::fit::FitReport::final_budgets`].
pub(super) type LengthScore = (usize, Option<f64>);

/// The chosen length, every length's tail RMSE (longest first), and the proxy's iterate at
/// the chosen length.
type BudgetChoice = (usize, Vec<LengthScore>, (GpParams<f64>, usize));

/// The length of the final training among those both it (its `snapshots`) and its `proxy`
/// reached, by [`shorter_if_clearly_better`] on the proxy's iterates' tail RMSEs (`rmse`).
/// `None` where the longest length's simulation failed.
pub(super) fn choose_budget(
    snapshots: &[(usize, GpParams<f64>, usize)],
    proxy: &FinalTraining,
    rmse: &dyn Fn(&GpParams<f64>) -> Result<f64>,
) -> Result<Option<BudgetChoice>> {
    let mut scored = Vec::new();
    for (budget, params, iteration) in proxy.snapshots.iter().rev() {
        if !snapshots.iter().any(|s| s.0 == *budget) {
            continue;
        }
        let score = match rmse(params) {
            Ok(r) => Some(r),
            Err(MsgpError::NotPositiveDefinite { .. } | MsgpError::NonFinite(_)) => None,
            Err(e) => return Err(e),
        };
        scored.push((*budget, score, params, *iteration));
    }
    let rmses: Vec<Option<f64>> = scored.iter().map(|s| s.1).collect();
    let Some(k) = shorter_if_clearly_better(&rmses) else {
        return Ok(None);
    };
    let (budget, _, params, iteration) = &scored[k];
    let budgets = scored.iter().map(|s| (s.0, s.1)).collect();
    Ok(Some((*budget, budgets, ((*params).clone(), *iteration))))
}

/// Which of the candidates' tail RMSEs — the longest training first, `None` where its
/// simulation failed — is chosen: the lowest among the first and those at least
/// [`CLEARLY_BETTER`] below the first; the first where none is. The longest training is the
/// protocol's default, chosen on the training data of every row; a short tail that chooses
/// among several close candidates chooses its own noise, so a shorter one replaces it only by a
/// clear margin (`docs/experiments/2026-12-05-how-long-the-final-training-is.md`). `None`
/// where the first failed.
pub(super) fn shorter_if_clearly_better(rmses: &[Option<f64>]) -> Option<usize> {
    let first = (*rmses.first()?)?;
    let bar = (1.0 - CLEARLY_BETTER) * first;
    let mut chosen = (0, first);
    for (k, r) in rmses.iter().enumerate().skip(1) {
        if let Some(r) = *r
            && r <= bar
            && r < chosen.1
        {
            chosen = (k, r);
        }
    }
    Some(chosen.0)
}

/// The RMSE of the moment-matching free simulation of the feed-forward `tails` (normalised
/// units, pooled over their steps and outputs) under the model of `params`: its means only,
/// which the correlated variances of a reported simulation do not move.
pub(super) fn tail_rmse(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    tails: &[Episode],
) -> Result<f64> {
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(params, config, &mut log)?;
    let (mut sum, mut count) = (0.0, 0usize);
    for tail in tails {
        let traj = &tail.traj;
        let steps = simulate(&gp, spec, traj, &Control::FeedForward, traj.len(), &mut log)?;
        for (i, s) in steps.iter().enumerate() {
            for j in 0..spec.dy {
                let r = traj.y[(spec.warmup() + i, j)] - s.mean[j];
                sum += r * r;
                count += 1;
            }
        }
    }
    if count == 0 || !sum.is_finite() {
        return Err(MsgpError::NonFinite(
            "the validation tail's simulation".into(),
        ));
    }
    Ok((sum / count as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::{CLEARLY_BETTER, shorter_if_clearly_better};

    #[test]
    fn a_shorter_training_replaces_the_longest_only_where_clearly_better() {
        let longest = 1.0;
        let margin = 1.0 - CLEARLY_BETTER;
        let clearly = margin - 1e-9;
        let barely = margin + 1e-9;
        assert_eq!(
            shorter_if_clearly_better(&[Some(longest), Some(clearly)]),
            Some(1)
        );
        assert_eq!(
            shorter_if_clearly_better(&[Some(longest), Some(barely)]),
            Some(0)
        );
        // among the clearly better ones, the lowest; failed and worse ones are passed over
        let best = 0.5;
        let worse = 1.5;
        assert_eq!(
            shorter_if_clearly_better(&[Some(longest), Some(clearly), None, Some(best)]),
            Some(3)
        );
        assert_eq!(
            shorter_if_clearly_better(&[Some(longest), Some(best), Some(clearly)]),
            Some(1)
        );
        assert_eq!(
            shorter_if_clearly_better(&[Some(longest), Some(worse), Some(barely)]),
            Some(0)
        );
        // the longest failed: no choice
        assert_eq!(shorter_if_clearly_better(&[None, Some(clearly)]), None);
        assert_eq!(shorter_if_clearly_better(&[]), None);
    }
}
