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

use std::path::Path;

use crate::args::{
    PendulumArgs, PlantArgs, PlantChoiceArgs, Preset, SaturationArgs, SimCommand, StabilityArgs,
};
use anyhow::{Context, bail};
use msgp_sim::{
    Controller, EpisodeConfig, ExcitationConfig, LogFormat, PendulumParams, PidPdGains,
    PidPdPolicy, RandomExcitation, Saturation, StabilityCriteria, run_episode, stability_test,
    write_run,
};

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

impl PlantChoiceArgs {
    /// The tier ← `--params` file (its fields over the tier's), validated.
    pub(crate) fn resolve(&self) -> anyhow::Result<PendulumParams> {
        let p = self.unchecked()?;
        p.validate().context("invalid plant parameters")?;
        Ok(p)
    }

    /// The tier ← `--params` file, not yet validated.
    fn unchecked(&self) -> anyhow::Result<PendulumParams> {
        let tier = PendulumParams::tier(self.plant.into());
        Ok(match &self.params {
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read plant parameters {}", path.display()))?;
                let bad = || format!("bad plant parameters in {}", path.display());
                let file: serde_json::Value = serde_json::from_str(&text).with_context(bad)?;
                let serde_json::Value::Object(fields) = file else {
                    anyhow::bail!("{}: expected a JSON object of plant parameters", bad());
                };
                let mut merged = serde_json::to_value(tier)?;
                if let Some(base) = merged.as_object_mut() {
                    base.extend(fields);
                }
                serde_json::from_value::<PendulumParams>(merged).with_context(bad)?
            }
            None => tier,
        })
    }
}

impl PlantArgs {
    /// The tier ← `--params` file ← individual flags, then validated.
    pub(crate) fn resolve(&self) -> anyhow::Result<PendulumParams> {
        let mut p = self.choice.unchecked()?;
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
        crate::render::output::out(&summary.to_string())?;
    } else {
        crate::render::output::out(&format!(
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
        // the report and the plant it ran on
        let mut json = serde_json::to_value(&report)?;
        if let Some(o) = json.as_object_mut() {
            o.insert("params".into(), serde_json::to_value(params)?);
        }
        crate::render::output::out(&serde_json::to_string_pretty(&json)?)?;
    } else {
        crate::render::output::out(&format!(
            "plant: σθ {} rad, σx {} m, delay {} steps, lag {} s, control {} Hz",
            params.sigma_theta,
            params.sigma_x,
            params.command_delay_steps,
            params.lag_time_constant,
            params.control_rate_hz
        ))?;
        crate::render::output::out(&format!(
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
        crate::render::output::out(
            "  θ0 [rad]  draw  result  max|θ| [rad]  max|x| [m]  RMS θ last 5 s  failure",
        )?;
        for s in &report.starts {
            crate::render::output::out(&format!(
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
        crate::render::output::out("stability test passed")?;
    }
    Ok(())
}
