//! A feedback controller with a known excitation added to its command (a *dither*).
//!
//! In closed loop the command is a function of the measurements the model's window already
//! holds, so a feedback episode alone cannot tell how the plant answers the command from how
//! it evolves on its own (closed-loop identifiability). A small independent excitation added to
//! the command makes every feedback episode informative about the input response too.

use super::{Controller, RandomExcitation};
use crate::plant::Measurement;

/// `inner`'s command plus `dither.value(t)`; the plant clips the sum.
#[derive(Debug, Clone)]
pub struct Dithered<C> {
    inner: C,
    dither: RandomExcitation,
}

impl<C: Controller> Dithered<C> {
    /// `inner` with `dither` added to every command.
    pub fn new(inner: C, dither: RandomExcitation) -> Self {
        Self { inner, dither }
    }
}

impl<C: Controller> Controller for Dithered<C> {
    fn reset(&mut self) {
        self.inner.reset();
    }

    fn command(&mut self, t: f64, measurement: &Measurement) -> f64 {
        self.inner.command(t, measurement) + self.dither.value(t)
    }

    fn describe(&self) -> String {
        format!(
            "{} + dither ({})",
            self.inner.describe(),
            self.dither.describe()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controller::ExcitationConfig;

    struct Constant(f64, usize);

    impl Controller for Constant {
        fn reset(&mut self) {
            self.1 += 1;
        }
        fn command(&mut self, _t: f64, _m: &Measurement) -> f64 {
            self.0
        }
        fn describe(&self) -> String {
            "constant".into()
        }
    }

    #[test]
    fn adds_the_excitation_to_the_inner_command() {
        let config = ExcitationConfig {
            components: 5,
            min_hz: 0.5,
            max_hz: 5.0,
            rms: 0.3,
        };
        let dither = RandomExcitation::new(7, &config).expect("excitation");
        let mut c = Dithered::new(Constant(1.5, 0), dither.clone());
        c.reset();
        assert_eq!(c.inner.1, 1, "reset reaches the inner controller");
        let m = Measurement { theta: 0.0, x: 0.0 };
        for k in 0..50 {
            let t = 0.02 * f64::from(k);
            assert_eq!(c.command(t, &m), 1.5 + dither.value(t));
        }
        assert!(
            c.describe()
                .starts_with("constant + dither (random_excitation seed=7")
        );
    }
}
