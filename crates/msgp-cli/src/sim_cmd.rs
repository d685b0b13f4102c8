//! `msgp sim`: the inverted-pendulum-on-end-effector simulator (crate `msgp-sim`).
//!
//! * `msgp sim pendulum (--policy P.json | --gains KP,KI,KD,KPθ,KDθ | --preset NAME | --random)
//!   [--seconds S] [--seed N] --out RUN.csv|RUN.mcap` — one episode, written atomically.
//! * `msgp sim stability (--policy P.json | --gains … | --preset NAME) [--seed N] [--json]` —
//!   the stability test (five starts × three noise draws); exits non-zero when any episode fails.
//! * Both take `--saturation clip|sine` for the gains' command limit (default: clip for
//!   `--gains` and `--preset`, the file's for `--policy`).
//!
//! Plant parameters default to `msgp_sim::PendulumParams::default()`; `--params FILE.json`
//! and the per-field flags override them (flags win).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, Subcommand, ValueEnum};
use msgp_sim::{
    Controller, EpisodeConfig, ExcitationConfig, LogFormat, PendulumParams, PidPdGains,
    PidPdPolicy, RandomExcitation, Saturation, StabilityCriteria, run_episode, stability_test,
    write_run,
};

/// Subcommands of `msgp sim`.
#[derive(Debug, Subcommand)]
pub enum SimCommand {
    /// Simulate one episode of the pole on the robot end effector and write a CSV or MCAP log.
    Pendulum(PendulumArgs),
    /// Stability test of PID + PD gains: 5 starts (±0.03, ±0.015, 0 rad), 3 noise draws each,
    /// 10 s each; pass iff every episode keeps |θ| < 0.1 rad and |x| < 0.3 m throughout and RMS θ
    /// over the last 5 s < 0.03 rad.
    Stability(StabilityArgs),
}

/// Options of `msgp sim pendulum`.
#[derive(Debug, Args)]
pub struct PendulumArgs {
    #[command(flatten)]
    controller: ControllerArgs,
    /// Episode length in seconds (the episode stops early if |θ| > stop-theta or |x| > stop-x).
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    seconds: f64,
    /// Seed of the initial angle, the measurement noise and the random excitation.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Fixed initial pole angle [rad] instead of a draw from N(0, theta0-std²).
    #[arg(long, allow_negative_numbers = true)]
    theta0: Option<f64>,
    /// RMS of the random excitation [m/s²] (with --random).
    #[arg(long, default_value_t = 1.0)]
    excitation_rms: f64,
    #[command(flatten)]
    saturation: SaturationArgs,
    /// Output run log; the extension selects the format: .csv or .mcap.
    #[arg(long)]
    out: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    plant: PlantArgs,
}

/// Options of `msgp sim stability`.
#[derive(Debug, Args)]
pub struct StabilityArgs {
    #[command(flatten)]
    gains: GainArgs,
    #[command(flatten)]
    saturation: SaturationArgs,
    /// Seed of the measurement noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    plant: PlantArgs,
}

/// Exactly one controller for an episode.
#[derive(Debug, Args)]
#[group(required = true, multiple = false)]
struct ControllerArgs {
    /// PID + PD policy file (JSON: kp_x, ki_x, kd_x, kp_theta, kd_theta).
    #[arg(long, value_name = "POLICY.json")]
    policy: Option<PathBuf>,
    /// PID + PD gains "kp_x,ki_x,kd_x,kp_theta,kd_theta" (use --gains=-1,... for a leading minus).
    #[arg(long, value_name = "KP,KI,KD,KPθ,KDθ", value_parser = parse_gains, allow_hyphen_values = true)]
    gains: Option<[f64; 5]>,
    /// Built-in gains.
    #[arg(long, value_enum)]
    preset: Option<Preset>,
    /// Smooth random excitation (seeded sum of sines, 0.1–2 Hz) instead of a policy.
    #[arg(long)]
    random: bool,
}

/// Exactly one set of gains for the stability test.
#[derive(Debug, Args)]
#[group(required = true, multiple = false)]
struct GainArgs {
    /// PID + PD policy file (JSON: kp_x, ki_x, kd_x, kp_theta, kd_theta).
    #[arg(long, value_name = "POLICY.json")]
    policy: Option<PathBuf>,
    /// PID + PD gains "kp_x,ki_x,kd_x,kp_theta,kd_theta" (use --gains=-1,... for a leading minus).
    #[arg(long, value_name = "KP,KI,KD,KPθ,KDθ", value_parser = parse_gains, allow_hyphen_values = true)]
    gains: Option<[f64; 5]>,
    /// Built-in gains.
    #[arg(long, value_enum)]
    preset: Option<Preset>,
}

/// How the gains' command is limited to `±action-limit`.
#[derive(Debug, Args)]
struct SaturationArgs {
    /// Command saturation: `clip` (the default of --gains and --preset) or `sine` (PILCO's
    /// smooth saturation, which `msgp learn-policy` uses). With --policy it overrides the file's.
    #[arg(long, value_enum)]
    saturation: Option<SaturationKind>,
}

impl SaturationArgs {
    /// `gains` with the chosen saturation, if one was chosen.
    fn apply(&self, gains: PidPdGains) -> PidPdGains {
        match self.saturation {
            Some(kind) => PidPdGains {
                saturation: kind.into(),
                ..gains
            },
            None => gains,
        }
    }
}

/// [`Saturation`] as a command-line value.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum SaturationKind {
    /// Hard clipping.
    Clip,
    /// PILCO's sine saturation.
    Sine,
}

impl From<SaturationKind> for Saturation {
    fn from(kind: SaturationKind) -> Self {
        match kind {
            SaturationKind::Clip => Saturation::Clip,
            SaturationKind::Sine => Saturation::Sine,
        }
    }
}

/// Built-in gain sets.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum Preset {
    /// Apollo LQR gains [−34.55, −7.03, −1.98, −3.73, −0.3] on [θ, θ̇, x, ẋ, ∫x], mapped.
    ApolloLqr,
    /// Apollo LQR with the position loop halved; balances the default noisy plant.
    HandTuned,
    /// All gains zero (the pole falls).
    Zero,
}

/// Plant parameter overrides (defaults: `msgp_sim::PendulumParams::default()`).
#[derive(Debug, Args)]
#[command(next_help_heading = "Plant")]
pub(crate) struct PlantArgs {
    /// JSON file with plant parameters (missing fields keep their defaults).
    #[arg(long, value_name = "PARAMS.json")]
    params: Option<PathBuf>,
    /// Pole length [m] (default 1.067).
    #[arg(long)]
    pole_length: Option<f64>,
    /// Pole mass [kg] (default 0.2903).
    #[arg(long)]
    pole_mass: Option<f64>,
    /// Distance pivot → centre of mass [m] (default 0.637).
    #[arg(long)]
    pole_com: Option<f64>,
    /// Pole inertia about its centre of mass [kg·m²] (default m·L²/12).
    #[arg(long)]
    pole_inertia: Option<f64>,
    /// Viscous hinge damping [N·m·s] (default 0.0116).
    #[arg(long)]
    hinge_damping: Option<f64>,
    /// Gravity [m/s²] (default 9.81; negative hangs the pole).
    #[arg(long, allow_negative_numbers = true)]
    gravity: Option<f64>,
    /// Command limit [m/s²] (default 3).
    #[arg(long)]
    action_limit: Option<f64>,
    /// Control rate [Hz] (default 50).
    #[arg(long)]
    control_hz: Option<f64>,
    /// Physics rate [Hz], an integer multiple of the control rate (default 1000).
    #[arg(long)]
    physics_hz: Option<f64>,
    /// Command delay in control steps (default 1).
    #[arg(long)]
    delay_steps: Option<u32>,
    /// First-order lag time constant [s] (default 0.03; 0 = none).
    #[arg(long)]
    lag: Option<f64>,
    /// Angle measurement noise σ [rad] (default 5e-3).
    #[arg(long)]
    sigma_theta: Option<f64>,
    /// Position measurement noise σ [m] (default 2e-3).
    #[arg(long)]
    sigma_x: Option<f64>,
    /// Switch off measurement noise (overrides --sigma-theta/--sigma-x).
    #[arg(long)]
    noiseless: bool,
    /// σ of the random initial angle [rad] (default 0.02).
    #[arg(long)]
    theta0_std: Option<f64>,
    /// Early stop when |θ| exceeds this [rad] (default 0.5).
    #[arg(long)]
    stop_theta: Option<f64>,
    /// Early stop when |x| exceeds this [m] (default 0.5).
    #[arg(long)]
    stop_x: Option<f64>,
}

impl PlantArgs {
    /// Defaults ← `--params` file ← individual flags, then validated.
    pub(crate) fn resolve(&self) -> anyhow::Result<PendulumParams> {
        let mut p = match &self.params {
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read plant parameters {}", path.display()))?;
                serde_json::from_str::<PendulumParams>(&text)
                    .with_context(|| format!("bad plant parameters in {}", path.display()))?
            }
            None => PendulumParams::default(),
        };
        let set = |field: &mut f64, value: Option<f64>| {
            if let Some(v) = value {
                *field = v;
            }
        };
        set(&mut p.pole_length, self.pole_length);
        set(&mut p.pole_mass, self.pole_mass);
        set(&mut p.pole_com, self.pole_com);
        set(&mut p.pole_inertia_com, self.pole_inertia);
        set(&mut p.hinge_damping, self.hinge_damping);
        set(&mut p.gravity, self.gravity);
        set(&mut p.action_limit, self.action_limit);
        set(&mut p.control_rate_hz, self.control_hz);
        set(&mut p.physics_rate_hz, self.physics_hz);
        set(&mut p.lag_time_constant, self.lag);
        set(&mut p.sigma_theta, self.sigma_theta);
        set(&mut p.sigma_x, self.sigma_x);
        set(&mut p.initial_theta_std, self.theta0_std);
        set(&mut p.stop_theta, self.stop_theta);
        set(&mut p.stop_x, self.stop_x);
        if let Some(d) = self.delay_steps {
            p.command_delay_steps = d;
        }
        if self.noiseless {
            p = p.noiseless();
        }
        p.validate().context("invalid plant parameters")?;
        Ok(p)
    }
}

/// Parses "kp_x,ki_x,kd_x,kp_theta,kd_theta".
fn parse_gains(s: &str) -> Result<[f64; 5], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 5 {
        return Err(format!(
            "expected 5 comma-separated gains kp_x,ki_x,kd_x,kp_theta,kd_theta, got {}",
            parts.len()
        ));
    }
    let mut gains = [0.0; 5];
    for (g, part) in gains.iter_mut().zip(&parts) {
        *g = part
            .parse::<f64>()
            .map_err(|e| format!("bad gain `{part}`: {e}"))?;
        if !g.is_finite() {
            return Err(format!("gain `{part}` is not finite"));
        }
    }
    Ok(gains)
}

/// Gains from exactly one of policy file / list / preset.
fn resolve_gains(
    policy: Option<&Path>,
    gains: Option<[f64; 5]>,
    preset: Option<Preset>,
) -> anyhow::Result<Option<PidPdGains>> {
    Ok(match (policy, gains, preset) {
        (Some(path), _, _) => Some(PidPdGains::read_json_file(path)?),
        (_, Some(g), _) => Some(PidPdGains::from_array(g)),
        (_, _, Some(Preset::ApolloLqr)) => Some(PidPdGains::apollo_lqr()),
        (_, _, Some(Preset::HandTuned)) => Some(PidPdGains::hand_tuned()),
        (_, _, Some(Preset::Zero)) => Some(PidPdGains::default()),
        (None, None, None) => None,
    })
}

/// Runs `msgp sim …`.
pub fn run(cmd: &SimCommand) -> anyhow::Result<()> {
    match cmd {
        SimCommand::Pendulum(args) => run_pendulum(args),
        SimCommand::Stability(args) => run_stability(args),
    }
}

fn run_pendulum(args: &PendulumArgs) -> anyhow::Result<()> {
    // Check the output format before spending time on the simulation.
    LogFormat::from_path(&args.out)?;
    let params = args.plant.resolve()?;
    let c = &args.controller;
    let mut controller: Box<dyn Controller> =
        match resolve_gains(c.policy.as_deref(), c.gains, c.preset)? {
            Some(gains) => Box::new(PidPdPolicy::new(args.saturation.apply(gains), &params)?),
            None if c.random && args.saturation.saturation.is_some() => {
                bail!(
                    "--saturation applies to gains (--policy, --gains, --preset), not to --random"
                )
            }
            None if c.random => Box::new(RandomExcitation::new(
                args.seed,
                &ExcitationConfig {
                    rms: args.excitation_rms,
                    ..ExcitationConfig::default()
                },
            )?),
            None => bail!("choose a controller: --policy, --gains, --preset or --random"),
        };
    let episode = run_episode(
        &params,
        controller.as_mut(),
        &EpisodeConfig {
            seconds: args.seconds,
            seed: args.seed,
            initial_theta: args.theta0,
        },
    )?;
    write_run(&args.out, &episode)?;
    let duration = episode.samples.last().map_or(0.0, |s| s.t);
    if args.json {
        let summary = serde_json::json!({
            "out": args.out.display().to_string(),
            "samples": episode.samples.len(),
            "duration": duration,
            "termination": episode.info.termination,
            "initial_theta": episode.info.initial_theta,
            "seed": episode.info.seed,
            "controller": episode.info.controller,
        });
        crate::output::out(&summary.to_string())?;
    } else {
        crate::output::out(&format!(
            "wrote {}: {} steps, {duration:.2} s simulated, initial θ {:+.4} rad, termination {:?}, controller: {}",
            args.out.display(),
            episode.samples.len(),
            episode.info.initial_theta,
            episode.info.termination,
            episode.info.controller
        ))?;
    }
    Ok(())
}

fn run_stability(args: &StabilityArgs) -> anyhow::Result<()> {
    let params = args.plant.resolve()?;
    let g = &args.gains;
    let Some(gains) = resolve_gains(g.policy.as_deref(), g.gains, g.preset)? else {
        bail!("choose gains: --policy, --gains or --preset");
    };
    let gains = args.saturation.apply(gains);
    let report = stability_test(&params, &gains, args.seed, &StabilityCriteria::default())?;
    if args.json {
        crate::output::out(&serde_json::to_string_pretty(&report)?)?;
    } else {
        crate::output::out(&format!(
            "gains kp_x={} ki_x={} kd_x={} kp_theta={} kd_theta={}, {} saturation, seed {}",
            gains.kp_x,
            gains.ki_x,
            gains.kd_x,
            gains.kp_theta,
            gains.kd_theta,
            match gains.saturation {
                Saturation::Clip => "clip",
                Saturation::Sine => "sine",
            },
            args.seed
        ))?;
        crate::output::out(
            "  θ0 [rad]  draw  result  max|θ| [rad]  max|x| [m]  RMS θ last 5 s  failure",
        )?;
        for s in &report.starts {
            crate::output::out(&format!(
                "  {:+8.3}  {:4}  {:6}  {:12.4}  {:10.4}  {:14.4}  {}",
                s.initial_theta,
                s.repeat,
                if s.passed { "PASS" } else { "FAIL" },
                s.max_abs_theta,
                s.max_abs_x,
                s.rms_theta_final,
                s.failure.as_deref().unwrap_or("")
            ))?;
        }
    }
    let failed = report.starts.iter().filter(|s| !s.passed).count();
    if failed > 0 {
        bail!(
            "stability test failed: {failed} of {} episodes (starts × noise draws) failed",
            report.starts.len()
        );
    }
    if !args.json {
        crate::output::out("stability test passed")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gains_parse() {
        assert_eq!(
            parse_gains("1,2, 3,-4,5e-1").expect("valid"),
            [1.0, 2.0, 3.0, -4.0, 0.5]
        );
        assert!(parse_gains("1,2,3,4").is_err());
        assert!(parse_gains("1,2,3,4,x").is_err());
        assert!(parse_gains("1,2,3,4,inf").is_err());
    }
}
