//! Model probe for the policy-search loop: fits the loop's model to its four random rollouts plus
//! `F` episodes of perturbed hand-tuned gains, then compares the model's predicted cost over 5 s
//! for three gain sets with the plant's (mean of 5 episodes each). A model that policy search can
//! use ranks them as the plant does: hand-tuned ≪ no position loop ≈ `kd_x = −1`.
//!
//! `cargo run --release -p msgp-sim --example probe -- [start_samples] [F] [seed]`
//! (`start_samples` 0, the default: the measured start window, else [`StartWindow::Smoothed`]
//! over that many samples; `F` default 4). `PROBE_FB="kp_x,ki_x,kd_x,kp_θ,kd_θ;…"` replaces the
//! perturbed hand-tuned episodes by episodes of the given gains (what a loop iteration has
//! seen). Prints the fitted linear mean, noise levels and length-scales, the training loss and
//! the predictions.
use msgp_core::fit::{TrainingEpisode, fit_episodes};
use msgp_core::narx::start_window::StartWindow;
use msgp_core::policy::PolicySpec;
use msgp_core::policy_search::cost::SaturatingCost;
use msgp_sim::learn::{
    LearnSettings, episode_cost, episode_trajectory, modelled_policy, pendulum_problem, segments,
};
use msgp_sim::{
    EpisodeConfig, PendulumParams, PidPdGains, PidPdPolicy, RandomExcitation, Saturation,
    run_episode,
};
use nalgebra::DVector;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let start_samples: usize = args.get(1).map_or(Ok(0), |s| s.parse())?;
    let feedback: usize = args.get(2).map_or(Ok(4), |s| s.parse())?;
    let seed: u64 = args.get(3).map_or(Ok(0), |s| s.parse())?;
    let params = PendulumParams::default();
    let settings = LearnSettings::default();
    let mut fit = settings.fit.clone();
    fit.seed = seed + 1;
    fit.start_window = match start_samples {
        0 => StartWindow::Measured,
        samples => StartWindow::Smoothed { samples, degree: 2 },
    };
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
    // feedback episodes: `PROBE_FB="kp_x,ki_x,kd_x,kp_θ,kd_θ;…"` (gains as the loop found
    // them), else `F` perturbations of the hand-tuned gains
    let mut fb_gains: Vec<PidPdGains> = Vec::new();
    if let Ok(list) = std::env::var("PROBE_FB") {
        for item in list.split(';').filter(|s| !s.trim().is_empty()) {
            let v: Vec<f64> = item
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<Result<_, _>>()?;
            if v.len() != 5 {
                return Err(format!("PROBE_FB entry {item:?}: five gains").into());
            }
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
        let parts = match std::env::var("PROBE_FB_SEG") {
            Ok(len) => segments(&traj, len.parse()?, 8)?,
            Err(_) => vec![traj],
        };
        for traj in parts {
            training.push(TrainingEpisode {
                traj,
                policy: Some(PolicySpec::Pid(modelled_policy(g, &params)?)),
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
            fit.complexity,
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
            // the 5 s cost's minimiser on the plant itself (examples/true_cost.rs, seed 1)
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
