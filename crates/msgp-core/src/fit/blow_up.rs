//! The blow-up test of a training without a validation tail (the final training on all the
//! data, the calibration's proxy): a training loss that rises far above its lowest since Adam's
//! first steps has left the model behind ([`super::MsgpSettings::full_data_blow_up`]).

/// Adam's first steps are not judged by [`super::MsgpSettings::full_data_blow_up`]: before its moment estimates
/// settle they move every coordinate by about the full step size at once, and the loss jumps and
/// recovers (by up to 100 nats per step on a small linear plant, 9 on actuator's linear start).
const BLOW_UP_AFTER: usize = 10;

/// Watches a training loss for a blow-up: a rise by more than `limit` nats per step above its
/// lowest since iteration [`BLOW_UP_AFTER`].
pub(super) struct BlowUp {
    limit: f64,
    /// The lowest loss since [`BLOW_UP_AFTER`] and its iteration.
    lowest: (f64, usize),
}

impl BlowUp {
    pub(super) fn new(limit: f64) -> Self {
        Self {
            limit,
            lowest: (f64::INFINITY, 0),
        }
    }

    /// The loss of iteration `it`; why it is a blow-up, if it is one.
    pub(super) fn observe(&mut self, it: usize, loss: f64) -> Option<String> {
        if it < BLOW_UP_AFTER {
            return None;
        }
        if loss > self.lowest.0 + self.limit {
            return Some(format!(
                "the training loss on all the data blew up at iteration {it}: {loss:.3} nats per \
                 step after {:.3} at iteration {}",
                self.lowest.0, self.lowest.1
            ));
        }
        if loss < self.lowest.0 {
            self.lowest = (loss, it);
        }
        None
    }
}

#[cfg(test)]
mod blow_up_tests {
    use super::BlowUp;

    fn first_blow_up(losses: &[f64]) -> Option<(usize, String)> {
        let mut watch = BlowUp::new(crate::fit::DEFAULT_FULL_DATA_BLOW_UP);
        losses
            .iter()
            .enumerate()
            .find_map(|(it, &l)| watch.observe(it, l).map(|w| (it, w)))
    }

    /// Ballbeam's final training (seed 0: 1.32 → 0.38 in ten steps, 56 at the 11th) is a
    /// blow-up; Adam's first-step jumps that the loss recovers from, and setbacks of a nat or
    /// two later on, are not.
    #[test]
    fn a_blow_up_is_a_large_rise_after_adams_first_steps() {
        let ballbeam = [
            1.32, 1.16, 1.14, 1.09, 1.03, 0.97, 0.89, 0.78, 0.72, 0.66, 0.38, 56.0, 39.0, 25.6,
        ];
        let (it, why) = first_blow_up(&ballbeam).expect("a blow-up");
        assert_eq!(it, 11);
        assert!(
            why.contains("at iteration 11") && why.contains("0.380"),
            "{why}"
        );
        let first_steps = [
            -1.47, 99.2, 4.5, 3.6, 4.0, 5.8, 5.5, 5.3, 5.4, 5.5, 5.6, 5.6, 5.1,
        ];
        assert_eq!(first_blow_up(&first_steps), None);
        let mut setbacks: Vec<f64> = (0..60).map(|k| 2.0 - 0.05 * k as f64).collect();
        setbacks[40] += 1.6;
        setbacks[50] += 4.9;
        assert_eq!(first_blow_up(&setbacks), None);
        setbacks[55] += 5.1 + 0.3;
        assert_eq!(first_blow_up(&setbacks).map(|b| b.0), Some(55));
    }
}
