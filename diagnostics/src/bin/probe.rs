//! Model probe for the policy-search loop: fits the loop's model to its four random rollouts plus
//! `F` episodes of perturbed hand-tuned gains, then compares the model's predicted cost over 5 s
//! for seven gain sets with the plant's (mean of 5 episodes each). A model that policy search can
//! use ranks them as the plant does: hand-tuned ≪ no position loop ≈ `kd_x = −1`.
//!
//! `cargo run --release -p msgp-diagnostics --bin probe -- [start_samples] [F] [seed]
//! [fb="kp_x,ki_x,kd_x,kp_θ,kd_θ;…"] [fb_seg=N] [threads=N]`
//!
//! `start_samples` 0, the default: the measured start window, else [`StartWindow::Smoothed`]
//! over that many samples; `F` default 4; `seed` default 0. `fb` replaces the perturbed
//! hand-tuned episodes by episodes of the given gains (what a loop iteration has seen; `F` is
//! then unused). `fb_seg=N` enters the feedback episodes as `N`-sample segments instead of
//! whole. `threads` the fit's threads (default every core; results do not depend on it).
//! Prints the fitted linear mean, noise levels and length-scales, the training loss and the
//! predictions.
use msgp_core::fit::{TrainingEpisode, fit_episodes};
use msgp_core::narx::start_window::StartWindow;
use msgp_core::numeric::parallel::Threads;
use msgp_core::policy::PolicySpec;
use msgp_core::policy_search::SaturatingCost;
use msgp_diagnostics::{Switches, numbers, usage_error};
use msgp_sim::learn::{
    LearnSettings, episode_cost, episode_trajectory, modelled_policy, pendulum_problem, segments,
};
use msgp_sim::{
    EpisodeConfig, PendulumParams, PidPdGains, PidPdPolicy, RandomExcitation, Saturation,
    run_episode,
};
use nalgebra::DVector;

const USAGE: &str = "probe [start_samples] [F] [seed] [fb=\"kp_x,ki_x,kd_x,kp_θ,kd_θ;…\"] \
    [fb_seg=N] [threads=N]";

struct Options {
    start_samples: usize,
    feedback: usize,
    seed: u64,
    /// The `fb` switch: the feedback episodes' gains, five each.
    fb: Option<Vec<[f64; 5]>>,
    fb_seg: Option<usize>,
    threads: Threads,
}

fn options() -> Result<Options, String> {
    let sw = Switches::from_args(3, &["fb", "fb_seg", "threads"])?;
    let fb = match sw.get::<String>("fb")? {
        None => None,
        Some(list) => Some(
            list.split(';')
                .filter(|s| !s.trim().is_empty())
                .map(|item| {
                    <[f64; 5]>::try_from(numbers(item)?)
                        .map_err(|_| format!("fb entry {item:?}: five gains"))
                })
                .collect::<Result<_, _>>()?,
        ),
    };
    Ok(Options {
        start_samples: sw.arg(0, "start_samples")?.unwrap_or(0),
        feedback: sw.arg(1, "F")?.unwrap_or(4),
        seed: sw.arg(2, "seed")?.unwrap_or(0),
        fb,
        fb_seg: sw.get("fb_seg")?,
        threads: sw.threads()?,
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Options {
        start_samples,
        feedback,
        seed,
        fb,
        fb_seg,
        threads,
    } = options().unwrap_or_else(|e| usage_error(USAGE, &e));
    let params = PendulumParams::default();
    let settings = LearnSettings::default();
    let mut fit = settings.fit.clone();
    fit.seed = seed + 1;
    fit.threads = threads;
    let msgp = fit
        .msgp_mut()
        .ok_or("probe fits the loop's default model, MSGP")?;
    msgp.start_window = match start_samples {
        0 => StartWindow::Measured,
        samples => StartWindow::Smoothed { samples, degree: 2 },
    };
    let complexity = msgp.complexity;
    let mut training = Vec::new();
    for k in 0..settings.random_rollouts {
        let s = seed * 1000 + k as u64;
        let mut exc = RandomExcitation::new(s, &settings.excitation)?;
        let ep = run_episode(
            &params,
            &mut exc,
            &EpisodeConfig {
                seconds: settings.episode_seconds,
                seed: s,
                initial_theta: None,
            },
        )?;
        for traj in segments(&episode_trajectory(&ep)?, 30, 8)? {
            training.push(TrainingEpisode { traj, policy: None });
        }
    }
    let hand = PidPdGains {
        saturation: Saturation::Sine,
        ..PidPdGains::hand_tuned()
    };
    // feedback episodes: `fb="kp_x,ki_x,kd_x,kp_θ,kd_θ;…"` (gains as the loop found them), else
    // `F` perturbations of the hand-tuned gains
    let mut fb_gains: Vec<PidPdGains> = Vec::new();
    if let Some(list) = fb {
        for v in list {
            fb_gains.push(PidPdGains {
                kp_x: v[0],
                ki_x: v[1],
                kd_x: v[2],
                kp_theta: v[3],
                kd_theta: v[4],
                ..hand
            });
        }
    } else {
        for k in 0..feedback {
            let f = 0.6 + 0.8 * (k as f64 + 0.5) / feedback.max(1) as f64;
            fb_gains.push(PidPdGains {
                kp_theta: hand.kp_theta * f,
                kd_theta: hand.kd_theta * (1.6 - f + 0.4),
                ..hand
            });
        }
    }
    for (k, g) in fb_gains.iter().enumerate() {
        let ep = run_episode(
            &params,
            &mut PidPdPolicy::new(*g, &params)?,
            &EpisodeConfig {
                seconds: settings.episode_seconds,
                seed: seed * 1000 + 700 + k as u64,
                initial_theta: None,
            },
        )?;
        let traj = episode_trajectory(&ep)?;
        let parts = match fb_seg {
            Some(len) => segments(&traj, len, 8)?,
            None => vec![traj],
        };
        for traj in parts {
            training.push(TrainingEpisode {
                traj,
                policy: Some(PolicySpec::Direct(msgp_core::policy::Policy::Pid(
                    modelled_policy(g, &params)?,
                ))),
            });
        }
    }
    let clock = std::time::Instant::now();
    let (model, report) = fit_episodes(&training, &fit, &mut |_| {})?;
    let p = &model.params;
    println!(
        "fit {:.1} s, {} iterations; A (θ row) {:.4?}; A (x row) {:.4?}",
        clock.elapsed().as_secs_f64(),
        report.iterations_run,
        p.linear_mean.row(0).iter().collect::<Vec<_>>(),
        p.linear_mean.row(1).iter().collect::<Vec<_>>(),
    );
    {
        let mut eps = Vec::new();
        for t in &training {
            let traj = model.normalizer.apply(&t.traj);
            eps.push(match &t.policy {
                None => msgp_core::rollout::Episode::feed_forward(traj),
                Some(p) => msgp_core::rollout::Episode {
                    traj,
                    excitation: msgp_core::rollout::Excitation::Feedback(Box::new(
                        p.normalized(&model.normalizer)?,
                    )),
                },
            });
        }
        let mut log = msgp_core::numeric::linalg::JitterLog::default();
        let v = msgp_core::loss::msgp_loss(
            &model.params,
            &model.config,
            &model.spec,
            &eps,
            complexity,
            &mut log,
        )?;
        println!(
            "final loss: NLL {:.2} over {} steps, complexity {:.2}, total/step {:.4}",
            v.nll,
            v.steps,
            v.complexity,
            v.total() / v.steps as f64
        );
    }
    let n = &model.normalizer;
    for j in 0..2 {
        let sy = ((p.log_obs_noise[j].exp() + model.config.noise_floor).sqrt()) * n.y_std[j];
        let sx = ((p.log_process_noise[j].exp() + model.config.noise_floor).sqrt()) * n.y_std[j];
        println!(
            "output {j}: σ_y {sy:.2e}, σ_x {sx:.2e}, log ℓ {:.2?}",
            p.log_lengthscales.row(j).iter().collect::<Vec<_>>()
        );
    }
    let cost = SaturatingCost::with_widths(DVector::from_element(2, 0.0), &settings.cost_widths)?;
    let horizon = 250;
    let problem = pendulum_problem(&model, &params, cost.clone(), horizon);
    let probes = [
        ("hand-tuned", hand),
        (
            "no position loop",
            PidPdGains {
                kp_x: 0.0,
                ki_x: 0.0,
                kd_x: 0.0,
                ..hand
            },
        ),
        ("kd_x = -1", PidPdGains { kd_x: -1.0, ..hand }),
        (
            "loop's weak damping",
            PidPdGains {
                kp_x: 2.0,
                ki_x: 0.448,
                kd_x: 0.514,
                kp_theta: 33.63,
                kd_theta: 0.227,
                ..hand
            },
        ),
        (
            "weak angle damping",
            PidPdGains {
                kd_theta: 3.0,
                kp_theta: 18.0,
                ..hand
            },
        ),
        (
            // the 5 s cost's minimiser on the plant itself (the true_cost diagnostic, seed 1)
            "plant's 5 s optimum",
            PidPdGains {
                kp_x: 1.47,
                ki_x: -0.10,
                kd_x: 0.57,
                kp_theta: 41.7,
                kd_theta: 4.35,
                ..hand
            },
        ),
        (
            "a typical loop choice",
            PidPdGains {
                kp_x: 2.25,
                ki_x: 0.22,
                kd_x: 0.84,
                kp_theta: 14.7,
                kd_theta: 0.58,
                ..hand
            },
        ),
    ];
    for (name, g) in probes {
        let predicted = match problem.evaluate(&modelled_policy(&g, &params)?) {
            Ok((c, _)) => format!("{c:7.2}"),
            Err(e) => format!("failed ({e})"),
        };
        let mut measured = 0.0;
        for r in 0..5u64 {
            let ep = run_episode(
                &params,
                &mut PidPdPolicy::new(g, &params)?,
                &EpisodeConfig {
                    seconds: 5.0,
                    seed: 9000 + r,
                    initial_theta: None,
                },
            )?;
            measured += episode_cost(&ep, &cost, 3, horizon);
        }
        println!(
            "{name:>20}: predicted {predicted}, plant {:7.2}",
            measured / 5.0
        );
    }
    Ok(())
}
