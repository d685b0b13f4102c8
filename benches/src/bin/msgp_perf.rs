//! Dev-only timing and problem-dump tool for the performance comparison (`BENCHMARKS.md`).
//!
//! ```text
//! msgp_perf dump --d 4 --m 100 --t 500 [--seed 0] --out problem.json
//! msgp_perf time --d 4 --m 100 --t 500 [--seed 0] [--reps 10] [--what loss,grad,filter_grad,rollout,mm,kernel,exp]
//! ```
//!
//! `dump` writes the seeded problem of [`msgp_benches::problem`] (data, every parameter, the
//! settings) as JSON together with our loss value and adjoint gradient, and prints the loss; the
//! JAX reference (`benches/reference/`) loads the file and recomputes both.
//!
//! `time` prints one JSON line per measured operation with per-repetition wall and process-CPU
//! times (ms; one warm-up repetition first, not reported), then a line with the peak resident
//! set (`VmHWM`). `mm` and `kernel` repeat the operation `inner` times per repetition and report
//! the time of one call; `exp` times 10⁴ scalar `f64::exp` calls. Everything runs on the calling
//! thread.

use std::collections::BTreeMap;
use std::hint::black_box;
use std::time::Instant;

use msgp_benches::{problem, window_state};
use msgp_core::gp::kernel::kernel_matrix;
use msgp_core::gp::{GpConfig, GpParams, PreparedGp};
use msgp_core::loss::{self, Complexity, msgp_loss};
use msgp_core::moments::moment_match;
use msgp_core::narx::NarxSpec;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::numeric::parallel::Threads;
use msgp_core::rollout::Episode;
use msgp_core::rollout::{Control, simulate};
use nalgebra::DMatrix;
use serde_json::{Value, json};

type AnyResult<T> = std::result::Result<T, Box<dyn std::error::Error>>;

const USAGE: &str = "usage: msgp_perf dump --d D --m M --t T [--seed S] --out FILE\n       \
                     msgp_perf time --d D --m M --t T [--seed S] [--reps N] \
                     [--what loss,grad,filter_grad,rollout,mm,kernel,exp]";

struct Args {
    cmd: String,
    opts: BTreeMap<String, String>,
}

impl Args {
    fn parse() -> AnyResult<Self> {
        let mut it = std::env::args().skip(1);
        let cmd = it.next().ok_or(USAGE)?;
        let mut opts = BTreeMap::new();
        while let Some(k) = it.next() {
            let key = k
                .strip_prefix("--")
                .ok_or_else(|| format!("unexpected argument {k:?}\n{USAGE}"))?;
            let v = it
                .next()
                .ok_or_else(|| format!("--{key} needs a value\n{USAGE}"))?;
            opts.insert(key.to_string(), v);
        }
        Ok(Self { cmd, opts })
    }

    fn usize_or(&self, key: &str, default: Option<usize>) -> AnyResult<usize> {
        match (self.opts.get(key), default) {
            (Some(v), _) => v.parse().map_err(|e| format!("--{key} {v:?}: {e}").into()),
            (None, Some(d)) => Ok(d),
            (None, None) => Err(format!("--{key} is required\n{USAGE}").into()),
        }
    }
}

struct Problem {
    params: GpParams<f64>,
    spec: NarxSpec,
    episodes: Vec<Episode>,
    config: GpConfig,
    complexity: Complexity,
}

fn build(args: &Args) -> AnyResult<Problem> {
    let d = args.usize_or("d", None)?;
    let m = args.usize_or("m", None)?;
    let t = args.usize_or("t", None)?;
    let seed = args.usize_or("seed", Some(0))? as u64;
    if d < 2 || m == 0 || t == 0 {
        return Err("need d ≥ 2, m ≥ 1, t ≥ 1".into());
    }
    let (params, spec, episodes) = problem(m, d, t, seed)?;
    Ok(Problem {
        params,
        spec,
        episodes,
        config: GpConfig::default(),
        complexity: Complexity::default(),
    })
}

fn rows(m: &DMatrix<f64>) -> Value {
    json!(
        (0..m.nrows())
            .map(|i| m.row(i).iter().copied().collect::<Vec<f64>>())
            .collect::<Vec<_>>()
    )
}

fn dump(args: &Args) -> AnyResult<()> {
    let out = args.opts.get("out").ok_or("--out is required")?;
    let p = build(args)?;
    let mut log = JitterLog::default();
    let loss = msgp_loss(
        &p.params,
        &p.config,
        &p.spec,
        &p.episodes,
        p.complexity,
        &mut log,
    )?;
    let mut glog = JitterLog::default();
    let (gl, grad) = loss::loss_and_gradient(
        &p.params,
        &p.config,
        &p.spec,
        &p.episodes,
        p.complexity,
        Threads::from_env()?,
        &mut glog,
    )?;
    let traj = &p.episodes[0].traj;
    let shape = p.params.shape()?;
    let doc = json!({
        "spec": {"ly": p.spec.ly, "lu": p.spec.lu, "dy": p.spec.dy, "du": p.spec.du},
        "shape": {"m": shape.m, "d": shape.d, "e": shape.e},
        "noise_floor": p.config.noise_floor,
        "complexity": format!("{:?}", p.complexity),
        "params": {
            "pseudo_inputs": rows(&p.params.pseudo_inputs),
            "pseudo_targets": rows(&p.params.pseudo_targets),
            "log_lengthscales": rows(&p.params.log_lengthscales),
            "log_signal_var": p.params.log_signal_var.as_slice(),
            "log_process_noise": p.params.log_process_noise.as_slice(),
            "log_obs_noise": p.params.log_obs_noise.as_slice(),
        },
        "flat": p.params.to_flat(),
        "y": rows(&traj.y),
        "u": rows(&traj.u),
        "loss": {"total": loss.total(), "nll": loss.nll, "complexity": loss.complexity,
                 "steps": loss.steps},
        "adjoint_loss": gl.total(),
        "gradient": grad,
        "jitter_events": log.events + glog.events,
    });
    std::fs::write(out, serde_json::to_string(&doc)?)?;
    emit(
        &json!({"loss": loss.total(), "nll": loss.nll, "complexity": loss.complexity,
               "steps": loss.steps, "params": grad.len(), "jitter_events": log.events + glog.events,
               "out": out}),
    );
    Ok(())
}

/// Process CPU time in seconds (NaN where unsupported).
fn cpu_seconds() -> f64 {
    #[cfg(unix)]
    {
        let ts = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
        ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
    }
    #[cfg(not(unix))]
    {
        f64::NAN
    }
}

fn stats(v: &[f64]) -> (f64, f64) {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let min = s.first().copied().unwrap_or(f64::NAN);
    let med = if s.is_empty() {
        f64::NAN
    } else if s.len() % 2 == 1 {
        s[s.len() / 2]
    } else {
        0.5 * (s[s.len() / 2 - 1] + s[s.len() / 2])
    };
    (min, med)
}

/// Runs `f` once to warm up, then `reps` times; prints a JSON line of per-call times in ms.
fn measure(
    what: &str,
    p: &Problem,
    reps: usize,
    inner: usize,
    mut f: impl FnMut() -> AnyResult<()>,
) -> AnyResult<()> {
    f()?;
    let mut wall = Vec::with_capacity(reps);
    let mut cpu = Vec::with_capacity(reps);
    for _ in 0..reps {
        let c0 = cpu_seconds();
        let w0 = Instant::now();
        for _ in 0..inner {
            f()?;
        }
        let w = w0.elapsed().as_secs_f64();
        let c = cpu_seconds() - c0;
        wall.push(w * 1e3 / inner as f64);
        cpu.push(c * 1e3 / inner as f64);
    }
    let (wmin, wmed) = stats(&wall);
    let (cmin, cmed) = stats(&cpu);
    let shape = p.params.shape()?;
    emit(
        &json!({"what": what, "d": shape.d, "m": shape.m, "t": p.episodes[0].traj.len() - p.spec.warmup(),
               "reps": reps, "inner": inner, "wall_ms": wall, "cpu_ms": cpu,
               "min_wall_ms": wmin, "median_wall_ms": wmed,
               "min_cpu_ms": cmin, "median_cpu_ms": cmed}),
    );
    Ok(())
}

fn time(args: &Args) -> AnyResult<()> {
    let reps = args.usize_or("reps", Some(10))?;
    let p = build(args)?;
    let threads = Threads::from_env()?;
    let what = args
        .opts
        .get("what")
        .cloned()
        .unwrap_or_else(|| "loss,grad".to_string());
    for w in what.split(',') {
        match w {
            "loss" => measure("loss", &p, reps, 1, || {
                let mut log = JitterLog::default();
                black_box(msgp_loss(
                    &p.params,
                    &p.config,
                    &p.spec,
                    &p.episodes,
                    p.complexity,
                    &mut log,
                )?);
                Ok(())
            })?,
            "grad" => measure("grad", &p, reps, 1, || {
                let mut log = JitterLog::default();
                black_box(loss::loss_and_gradient(
                    &p.params,
                    &p.config,
                    &p.spec,
                    &p.episodes,
                    p.complexity,
                    threads,
                    &mut log,
                )?);
                Ok(())
            })?,
            "filter_grad" => measure("filter_grad", &p, reps, 1, || {
                let mut log = JitterLog::default();
                black_box(loss::filter_loss_and_gradient(
                    &p.params,
                    &p.config,
                    &p.spec,
                    &p.episodes,
                    p.complexity,
                    threads,
                    &mut log,
                )?);
                Ok(())
            })?,
            "rollout" => {
                let mut log = JitterLog::default();
                let gp = PreparedGp::new(&p.params, &p.config, &mut log)?;
                let traj = &p.episodes[0].traj;
                measure("rollout", &p, reps, 1, || {
                    let mut log = JitterLog::default();
                    black_box(simulate(
                        &gp,
                        &p.spec,
                        traj,
                        &Control::FeedForward,
                        traj.len(),
                        &mut log,
                    )?);
                    Ok(())
                })?
            }
            "mm" => {
                let mut log = JitterLog::default();
                let gp = PreparedGp::new(&p.params, &p.config, &mut log)?;
                let (mu, sigma) = window_state(&p.spec, &p.episodes[0]);
                measure("mm", &p, reps, 100, || {
                    let mut log = JitterLog::default();
                    black_box(moment_match(&gp, &mu, &sigma, &mut log)?);
                    Ok(())
                })?
            }
            "kernel" => {
                let inv_l2: Vec<f64> = p
                    .params
                    .log_lengthscales
                    .row(0)
                    .iter()
                    .map(|l| (-2.0 * l).exp())
                    .collect();
                let x = &p.params.pseudo_inputs;
                measure("kernel", &p, reps, 100, || {
                    black_box(kernel_matrix(x, x, &inv_l2, 1.0));
                    Ok(())
                })?
            }
            "exp" => {
                // scalar `f64::exp` (libm) over a 100 × 100 block of moment-matching-like
                // exponents in [−30, 0]; reported per call of the block (10⁴ exponentials)
                let xs: Vec<f64> = (0..10_000).map(|i| -30.0 * (i as f64 / 10_000.0)).collect();
                let mut out = vec![0.0; xs.len()];
                measure("exp_block_10k", &p, reps, 100, || {
                    for (o, x) in out.iter_mut().zip(black_box(&xs)) {
                        *o = x.exp();
                    }
                    black_box(&out);
                    Ok(())
                })?
            }
            other => return Err(format!("unknown --what entry {other:?}\n{USAGE}").into()),
        }
    }
    emit(&json!({"peak_rss_kib": peak_rss_kib()}));
    Ok(())
}

/// `VmHWM` of this process in KiB (None where /proc is unavailable).
fn peak_rss_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Prints one JSON line; a closed pipe (e.g. `| head`) is not an error worth a panic.
fn emit(v: &Value) {
    use std::io::Write;
    let _ = writeln!(std::io::stdout(), "{v}");
}

fn main() {
    let res = Args::parse().and_then(|a| match a.cmd.as_str() {
        "dump" => dump(&a),
        "time" => time(&a),
        other => Err(format!("unknown command {other:?}\n{USAGE}").into()),
    });
    if let Err(e) = res {
        eprintln!("msgp_perf: {e}");
        std::process::exit(2);
    }
}
