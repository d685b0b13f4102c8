//! How the pendulum loop's MSGP fit spends its time and how far its loss has come: fits the
//! loop's model (`LearnSettings::default().fit`: 300 one-step Adam iterations, then 300 on the
//! MSGP loss) on fixed data, the four random rollouts of seeds 0–3 as 30-sample segments plus
//! `k` 3 s episodes of the hand-tuned gains (seeds 500, 501, …), for each `k` given, and prints
//! the one-step start's seconds, the seconds per solver iteration, the training loss per step at
//! iterations 0, 50, …, 300 relative to the last one, the lowest loss and its iteration (the
//! iterate the fit returns), and the jumps of the loss by more than 0.3 nats per step from one
//! iteration to the next. A diagnostic for BENCHMARKS.md (issue 7's policy-iteration target).
//!
//! `cargo run --release -p msgp-diagnostics --bin loop_fit_convergence -- [k ...] [threads=N]`
//! (`k` default: 0 4 8; `threads` the fit's threads, default every core: the timings depend on
//! it, the losses do not)
use std::time::Instant;

use msgp_core::fit::{FitSettings, TrainingEpisode, fit_episodes};
use msgp_core::numeric::parallel::Threads;
use msgp_core::policy::PolicySpec;
use msgp_diagnostics::{Switches, usage_error};
use msgp_sim::learn::{LearnSettings, episode_trajectory, modelled_policy, segments};
use msgp_sim::{
    EpisodeConfig, PendulumParams, PidPdGains, PidPdPolicy, RandomExcitation, Saturation,
    run_episode,
};

const USAGE: &str = "loop_fit_convergence [k ...] [threads=N]";

/// The numbers of feedback episodes and the threads.
fn options() -> Result<(Vec<usize>, Threads), String> {
    let sw = Switches::from_args(usize::MAX, &["threads"])?;
    let mut ks = sw
        .positional()
        .iter()
        .map(|a| {
            a.parse::<usize>()
                .map_err(|_| format!("each argument is a number of feedback episodes, got {a:?}"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    if ks.is_empty() {
        ks = vec![0, 4, 8];
    }
    Ok((ks, sw.threads()?))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (ks, threads) = options().unwrap_or_else(|e| usage_error(USAGE, &e));
    let params = PendulumParams::default();
    let settings = LearnSettings::default();
    let mut random = Vec::new();
    for seed in 0..4u64 {
        let mut excitation = RandomExcitation::new(seed, &settings.excitation)?;
        let config = EpisodeConfig {
            seconds: settings.episode_seconds,
            seed,
            initial_theta: None,
        };
        let traj = episode_trajectory(&run_episode(&params, &mut excitation, &config)?)?;
        let warm = settings.fit.ly.max(settings.fit.lu) + 5;
        for traj in segments(&traj, 30, warm)? {
            random.push(TrainingEpisode { traj, policy: None });
        }
    }
    let mut gains = PidPdGains::hand_tuned();
    gains.saturation = Saturation::Sine;
    let policy = PolicySpec::Direct(msgp_core::policy::Policy::Pid(modelled_policy(
        &gains, &params,
    )?));
    let fit = FitSettings {
        seed: settings.seed,
        threads,
        ..settings.fit.clone()
    };
    println!(
        "k | one-step start s | ms per iteration | loss − last at 0, 50, …, 300 | lowest (iteration) | jumps > 0.3"
    );
    for k in ks {
        let mut episodes = random.clone();
        for s in 0..k as u64 {
            let mut controller = PidPdPolicy::new(gains, &params)?;
            let config = EpisodeConfig {
                seconds: settings.episode_seconds,
                seed: 500 + s,
                initial_theta: None,
            };
            episodes.push(TrainingEpisode {
                traj: episode_trajectory(&run_episode(&params, &mut controller, &config)?)?,
                policy: Some(policy.clone()),
            });
        }
        let clock = Instant::now();
        let mut losses: Vec<(f64, f64)> = Vec::new();
        fit_episodes(&episodes, &fit, &mut |p| {
            losses.push((p.loss, p.elapsed));
        })?;
        let total = clock.elapsed().as_secs_f64();
        let (Some(&(_, start)), Some(&(last, _))) = (losses.first(), losses.last()) else {
            continue;
        };
        let per_iteration = (total - start) / (losses.len() - 1).max(1) as f64;
        let (lowest_at, lowest) = losses.iter().enumerate().fold(
            (0, f64::INFINITY),
            |b, (i, &(l, _))| if l < b.1 { (i, l) } else { b },
        );
        let marks: Vec<String> = losses
            .iter()
            .step_by(50)
            .map(|(l, _)| format!("{:+.3}", l - last))
            .collect();
        let jumps: Vec<String> = losses
            .windows(2)
            .enumerate()
            .filter(|(_, w)| w[1].0 - w[0].0 > 0.3)
            .map(|(i, w)| format!("{}: {:+.2}", i + 1, w[1].0 - w[0].0))
            .collect();
        println!(
            "{k} | {start:.1} | {:.0} | {} | {:+.3} ({lowest_at}) | {}",
            per_iteration * 1e3,
            marks.join(", "),
            lowest - last,
            if jumps.is_empty() {
                "none".to_string()
            } else {
                jumps.join(", ")
            }
        );
    }
    Ok(())
}
