//! The robot arm as seen by the pole: command delay, first-order lag and the exact
//! integration of the resulting end-effector motion.

use std::collections::VecDeque;

/// End-effector motion driven by delayed, lagged acceleration commands.
///
/// Commands enter a FIFO of `delay_steps` control periods; the command leaving the FIFO is
/// held constant over one control period and drives the lag state `a` through
/// `da/dt = (u - a) / tau`; the end-effector acceleration is `a`. Within a physics step the
/// lag, velocity and position are advanced with the exact solution of these linear ODEs,
/// so the motion does not depend on the physics rate.
#[derive(Debug, Clone)]
pub struct Actuator {
    /// Commands issued but not yet applied, oldest first (`delay_steps` entries).
    queue: VecDeque<f64>,
    /// Command driving the lag during the current control period.
    applied: f64,
    /// Lag time constant \[s\] (0: no lag).
    tau: f64,
    /// End-effector position \[m\].
    x: f64,
    /// End-effector velocity \[m/s\].
    v: f64,
    /// Lag state = end-effector acceleration \[m/s²\].
    a: f64,
}

impl Actuator {
    /// At rest at `x = 0` with `delay_steps` zero commands in the pipeline.
    pub fn new(delay_steps: u32, tau: f64) -> Self {
        Self {
            queue: std::iter::repeat_n(0.0, delay_steps as usize).collect(),
            applied: 0.0,
            tau,
            x: 0.0,
            v: 0.0,
            a: 0.0,
        }
    }

    /// Issues a (clipped) command at the start of a control period: it enters the delay
    /// line and the oldest command leaves it to drive the lag during this period.
    pub fn issue(&mut self, command: f64) {
        self.queue.push_back(command);
        self.applied = self.queue.pop_front().unwrap_or(command);
    }

    /// The command that will drive the lag during the next control period if no command
    /// is issued before; for zero delay this is `None` (it will be the next command itself).
    pub fn next_applied(&self) -> Option<f64> {
        self.queue.front().copied()
    }

    /// Command driving the lag during the current period.
    pub fn applied(&self) -> f64 {
        self.applied
    }

    /// Advances position, velocity and lag state by `h` seconds (exact solution).
    pub fn advance(&mut self, h: f64) {
        let u = self.applied;
        let (x0, v0, a0) = (self.x, self.v, self.a);
        if self.tau > 0.0 {
            let d = a0 - u;
            let decay = (-h / self.tau).exp();
            // 1 - e^{-h/tau}, accurate also for h << tau.
            let one_minus = -(-h / self.tau).exp_m1();
            self.a = u + d * decay;
            self.v = v0 + u * h + d * self.tau * one_minus;
            self.x = x0 + v0 * h + 0.5 * u * h * h + d * self.tau * (h - self.tau * one_minus);
        } else {
            self.a = u;
            self.v = v0 + u * h;
            self.x = x0 + v0 * h + 0.5 * u * h * h;
        }
    }

    /// End-effector position \[m\].
    pub fn position(&self) -> f64 {
        self.x
    }

    /// End-effector velocity \[m/s\].
    pub fn velocity(&self) -> f64 {
        self.v
    }

    /// End-effector acceleration = lag state \[m/s²\].
    pub fn acceleration(&self) -> f64 {
        self.a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delay_shifts_commands_by_whole_periods() {
        let mut act = Actuator::new(2, 0.0);
        let mut applied = Vec::new();
        for u in [1.0, 2.0, 3.0, 4.0] {
            act.issue(u);
            applied.push(act.applied());
        }
        assert_eq!(applied, vec![0.0, 0.0, 1.0, 2.0]);
        let mut direct = Actuator::new(0, 0.0);
        direct.issue(5.0);
        assert_eq!(direct.applied(), 5.0);
    }

    #[test]
    fn exact_lag_matches_fine_euler() {
        let (tau, u, total) = (0.03, 2.0, 0.1);
        let mut act = Actuator::new(0, tau);
        act.issue(u);
        for _ in 0..10 {
            act.advance(total / 10.0);
        }
        let (mut x, mut v, mut a) = (0.0, 0.0, 0.0);
        let n = 1_000_000;
        let h = total / f64::from(n);
        for _ in 0..n {
            x += v * h + 0.5 * a * h * h;
            v += a * h;
            a += (u - a) * (1.0 - (-h / tau).exp());
        }
        assert!((act.acceleration() - u * (1.0 - (-total / tau).exp())).abs() < 1e-12);
        assert!(
            (act.velocity() - v).abs() < 1e-5,
            "{} vs {v}",
            act.velocity()
        );
        assert!(
            (act.position() - x).abs() < 1e-6,
            "{} vs {x}",
            act.position()
        );
    }
}
