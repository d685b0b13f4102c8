//! # msgp-sim — an inverted pendulum on a robot arm's end effector
//!
//! A deterministic simulator of the paper's robot experiment (section 4.2): a pole balanced
//! on a robot end effector that moves along one horizontal axis. The input is the
//! end-effector acceleration; the outputs are the pole angle and the end-effector position,
//! both noisy. The command is clipped, held over the control period, delayed by one control
//! step and passed through a first-order lag before it moves the end effector — the real
//! robot's troubles that made standard PILCO fail.
//!
//! * [`PendulumParams`] — the plant (defaults: the Apollo pole; 50 Hz control, 1 kHz physics).
//! * [`Plant`] — rapier physics ([`physics`]) driven by the [`actuator`] model; returns
//!   [`Measurement`]s, records [`LatentState`]s separately.
//! * [`controller`] — the paper's PID + PD policy ([`PidPdGains`], JSON policy files) and
//!   seeded [`RandomExcitation`].
//! * [`run_episode`] — seeded episodes; same seed, same bytes.
//! * [`stability_test`] — five fixed starts, pass/fail per start.
//! * [`plant_tasks`] — the loop's named plant tasks (Pendulum-v1, the arm swing-up): plant,
//!   target, preset settings per model, score.
//! * [`plot`] — the PNG cost curve of a learning run, and the style every msgp plot shares.
//! * [`log`] — CSV and MCAP (JSON messages, Foxglove-ready) run logs, written atomically
//!   ([`atomic`], as the policy files are).
//!
//! Sign conventions: x along the end effector's axis; `theta` from the upward vertical,
//! positive when the pole leans toward +x; a positive command accelerates toward +x.
//!
//! ```
//! use msgp_sim::{EpisodeConfig, PendulumParams, PidPdGains, PidPdPolicy, run_episode};
//! let params = PendulumParams::default();
//! let mut policy = PidPdPolicy::new(PidPdGains::apollo_lqr(), &params)?;
//! let config = EpisodeConfig { seconds: 1.0, seed: 42, initial_theta: None };
//! let episode = run_episode(&params, &mut policy, &config)?;
//! assert_eq!(episode.samples.len(), 51);
//! # Ok::<(), msgp_sim::SimError>(())
//! ```

pub mod actuator;
pub mod atomic;
pub mod controller;
pub mod episode;
pub mod error;
pub mod gym_pendulum;
pub mod learn;
pub mod log;
pub mod params;
pub mod physics;
pub mod plant;
pub mod plant_tasks;
pub mod plot;
pub mod seed;
pub mod stability;
pub mod swing_up;

pub use controller::{
    APOLLO_LQR_GAINS, Controller, ExcitationConfig, PidPdGains, PidPdPolicy, RandomExcitation,
    Saturation,
};
pub use episode::{Episode, EpisodeConfig, EpisodeInfo, Sample, Termination, run_episode};
pub use error::SimError;
pub use log::{LogFormat, RunLog, encode_run, read_run, write_run};
pub use params::{PendulumParams, PlantTier};
pub use plant::{LatentState, Measurement, Plant};
pub use stability::{StabilityCriteria, StabilityReport, StartReport, stability_test};
