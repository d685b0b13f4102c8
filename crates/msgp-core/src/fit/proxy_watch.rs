//! The calibration's proxy read off a recipe's own training on the head.
//!
//! The proxy of a final training ([`super::calibration`]) is the same recipe trained from its
//! start on the head, without a tail, for the final training's length. The recipe's early-stopped
//! training on the head starts from the same parameters, on the same episodes, with the same
//! solver: its first iterates *are* the proxy's, bit for bit (with segments a proxy draws its
//! batches by its head's seed, whether read off the head or trained on its own). A [`ProxyWatch`]
//! rides along that training and keeps what the proxy's own run would return (its iterate of
//! lowest training loss, or with batches the mean of its second half; its blow-up test), and the head's training goes on past its early stop, without
//! further validation checks, until the proxy's length is reached. The separate proxy run of
//! up to 400 iterations is then not needed: on a short log it was the longer of the two
//! threads' last stages.

use super::blow_up::BlowUp;

/// Flat parameters and their iteration.
type Iterate = (Vec<f64>, usize);

/// What a [`ProxyWatch`] found: what the proxy's own training would have returned.
pub(super) struct ProxyOutcome {
    /// The proxy's model and its iteration; `None` where it blew up or failed at its start.
    pub outcome: Option<Iterate>,
    /// Why the proxy's training counts as failed (a blow-up, a failure at its start).
    pub failed: Option<String>,
    /// A numerical stop inside the proxy's length that still left a model.
    pub numerical_stop: Option<String>,
}

/// Watches a training's iterates as the proxy of `iterations` steps would.
pub(super) struct ProxyWatch {
    iterations: usize,
    batched: bool,
    blow_up: Option<BlowUp>,
    best: (f64, Vec<f64>, usize),
    average: Option<(Vec<f64>, usize)>,
    good: Option<Iterate>,
    blown: Option<String>,
    failure: Option<String>,
    done: bool,
}

impl ProxyWatch {
    /// A proxy of `iterations` steps, batched or not, with the blow-up limit `blow_up`.
    pub fn new(iterations: usize, batched: bool, blow_up: Option<f64>) -> Self {
        Self {
            iterations,
            batched,
            blow_up: blow_up.map(BlowUp::new),
            best: (f64::INFINITY, Vec::new(), 0),
            average: None,
            good: None,
            blown: None,
            failure: None,
            done: false,
        }
    }

    /// Whether the proxy's training has ended (its length reached, a blow-up, a failure).
    pub fn done(&self) -> bool {
        self.done
    }

    /// Iteration `it` of the watched training, with its loss and parameters.
    pub fn observe(&mut self, it: usize, loss: f64, x: &[f64]) {
        if self.done {
            return;
        }
        self.good = Some((x.to_vec(), it));
        if self.batched && 2 * it >= self.iterations {
            let (sum, count) = self.average.get_or_insert_with(|| (vec![0.0; x.len()], 0));
            sum.iter_mut().zip(x).for_each(|(s, x)| *s += x);
            *count += 1;
        }
        if !self.batched && loss < self.best.0 {
            self.best = (loss, x.to_vec(), it);
        }
        if let Some(why) = self.blow_up.as_mut().and_then(|w| w.observe(it, loss)) {
            self.blown = Some(why);
            self.done = true;
        }
        if it >= self.iterations {
            self.done = true;
        }
    }

    /// The watched training failed numerically at its next step (`why`): inside the proxy's
    /// length, the proxy failed there too.
    pub fn failed(&mut self, why: String) {
        if !self.done {
            self.failure = Some(why);
            self.done = true;
        }
    }

    /// What the proxy's own training would have returned.
    pub fn finish(self) -> ProxyOutcome {
        let mut out = ProxyOutcome {
            outcome: None,
            failed: self.blown,
            numerical_stop: None,
        };
        if out.failed.is_some() {
            return out;
        }
        let best = self
            .best
            .0
            .is_finite()
            .then_some((self.best.1, self.best.2));
        out.outcome = match (self.failure, self.good) {
            (Some(e), None) => {
                out.failed = Some(e);
                return out;
            }
            (Some(e), Some((x, it))) => {
                out.numerical_stop = Some(format!(
                    "the calibration's proxy: stopped at iteration {} of {}: {e}; kept \
                     iteration {it}",
                    it + 1,
                    self.iterations
                ));
                Some(best.unwrap_or((x, it)))
            }
            (None, Some((x, it))) => match (best, self.average) {
                (Some(b), _) => Some(b),
                (None, Some((sum, count))) if count > 0 => {
                    Some((sum.iter().map(|s| s / count as f64).collect(), it))
                }
                (None, _) => Some((x, it)),
            },
            (None, None) => None,
        };
        out
    }
}

#[cfg(test)]
mod tests {
    use super::ProxyWatch;

    #[test]
    fn the_watch_keeps_what_the_proxys_own_run_keeps() {
        // unbatched: the iterate of lowest loss within the length
        let mut w = ProxyWatch::new(4, false, None);
        for (it, loss) in [3.0, 2.0, 2.5, 1.0, 1.5, 0.1].into_iter().enumerate() {
            w.observe(it, loss, &[it as f64]);
        }
        assert!(w.done());
        let out = w.finish();
        assert_eq!(out.outcome, Some((vec![3.0], 3)));
        // batched: the mean of the second half (iterations 2..=4)
        let mut w = ProxyWatch::new(4, true, None);
        for it in 0..6 {
            w.observe(it, 1.0, &[it as f64]);
        }
        assert_eq!(w.finish().outcome, Some((vec![3.0], 4)));
        // a blow-up after Adam's first steps: no model, and why
        let mut w = ProxyWatch::new(40, false, Some(5.0));
        for it in 0..20 {
            w.observe(it, if it == 15 { 10.0 } else { 1.0 }, &[0.0]);
        }
        assert!(w.done());
        let out = w.finish();
        assert!(out.outcome.is_none());
        assert!(out.failed.expect("blown").contains("iteration 15"));
        // a numerical failure inside the length keeps the best so far; after it, nothing
        let mut w = ProxyWatch::new(10, false, None);
        w.observe(0, 2.0, &[0.0]);
        w.observe(1, 1.0, &[1.0]);
        w.failed("not positive definite".into());
        let out = w.finish();
        assert_eq!(out.outcome, Some((vec![1.0], 1)));
        assert!(out.numerical_stop.is_some());
        let mut w = ProxyWatch::new(1, false, None);
        w.observe(0, 2.0, &[0.0]);
        w.observe(1, 1.0, &[1.0]);
        w.failed("later".into());
        let out = w.finish();
        assert_eq!(out.outcome, Some((vec![1.0], 1)));
        assert!(out.numerical_stop.is_none());
    }
}
