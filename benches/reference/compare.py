"""Rust vs JAX comparison of the open-loop MSGP loss and its gradient (dev-only; see run.sh).

Subcommands (run through run.sh, which builds the Rust tool, sets XLA_FLAGS and pins the CPU):

  compare [--rounds R] [--reps N] [--configs d4,d20] [--baseline BIN]
      For each configuration: `msgp_perf dump` writes the problem and our loss/gradient; JAX
      recomputes both (loss must agree to 1e-8 relative); then R rounds, each running the Rust
      timing process (N reps of loss, N of value+gradient) followed by N JAX reps of each, so both
      sides see the same machine load. Ratios are taken per round and summarised. With
      --baseline, each round first times a second `msgp_perf` build (e.g. of an older commit)
      the same way, for before/after ratios from the same rounds.
  scaling [--reps N] [--rounds R]
      Loss and gradient time, Rust and JAX, as T, m and D vary; each measurement is a separate
      process under `/usr/bin/time -v` so its peak RSS is its own. R rounds over all sizes,
      Rust and JAX alternating; the table keeps the fastest (CPU time) of all rounds.
  calibrate
      XLA's single-thread f64 GEMM rate and exp throughput on this CPU (for the flop analysis).
  jax-time FILE [--what loss|grad] [--reps N]
      One JAX timing process (used by `scaling`), printing a JSON line like `msgp_perf time`.
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "out")

CONFIGS = {
    # name: (D, m, T); D = l_y + l_u with l_y = l_u = D/2, one output
    "d4": (4, 100, 500),
    "d20": (20, 100, 512),
}


def load_avg():
    return [round(x, 2) for x in os.getloadavg()]


def rust_dump(bin_, d, m, t, path):
    out = subprocess.run(
        [bin_, "dump", "--d", str(d), "--m", str(m), "--t", str(t), "--out", path],
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads(out.stdout)


def rust_time(bin_, d, m, t, what, reps, wrap_time=False):
    cmd = [bin_, "time", "--d", str(d), "--m", str(m), "--t", str(t)]
    cmd += ["--reps", str(reps), "--what", what]
    if wrap_time:
        cmd = ["/usr/bin/time", "-v"] + cmd
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    lines = [json.loads(x) for x in out.stdout.splitlines() if x.strip()]
    res = {x["what"]: x for x in lines if "what" in x}
    rss = next(x["peak_rss_kib"] for x in lines if "peak_rss_kib" in x)
    if wrap_time:
        rss = max_rss(out.stderr)
    return res, rss


def max_rss(time_v_stderr):
    mt = re.search(r"Maximum resident set size \(kbytes\): (\d+)", time_v_stderr)
    if not mt:
        raise RuntimeError("no max RSS in /usr/bin/time -v output:\n" + time_v_stderr)
    return int(mt.group(1))


class Jax:
    """Jitted loss and value_and_grad of one dumped problem."""

    def __init__(self, path):
        import jax

        from msgp_jax import make_loss

        self.jax = jax
        with open(path) as f:
            self.problem = json.load(f)
        loss, self.flat, self.y, self.u = make_loss(self.problem)
        self.loss = jax.jit(loss)
        self.vg = jax.jit(jax.value_and_grad(loss))

    def compile(self, which=("loss", "grad")):
        """Compile times (s) of the requested functions (None for the others)."""
        out = []
        for what, f in (("loss", self.loss), ("grad", self.vg)):
            if what in which:
                t = time.perf_counter()
                f.lower(self.flat, self.y, self.u).compile()
                out.append(time.perf_counter() - t)
            else:
                out.append(None)
        return tuple(out)

    def run(self, what):
        if what == "loss":
            return self.loss(self.flat, self.y, self.u).block_until_ready()
        return self.jax.block_until_ready(self.vg(self.flat, self.y, self.u))

    def time(self, what, reps):
        self.run(what)  # warm-up
        wall, cpu = [], []
        for _ in range(reps):
            c0, w0 = time.process_time(), time.perf_counter()
            self.run(what)
            wall.append((time.perf_counter() - w0) * 1e3)
            cpu.append((time.process_time() - c0) * 1e3)
        return {"wall_ms": wall, "cpu_ms": cpu}

    def agreement(self):
        import numpy as np

        p = self.problem
        v = float(self.run("loss"))
        v2, g = self.run("grad")
        g = np.asarray(g)
        gr = np.array(p["gradient"])
        ref = p["loss"]["total"]
        big = np.abs(gr) > 1e-6 * np.max(np.abs(gr))
        return {
            "loss_rust": ref,
            "loss_jax": v,
            "loss_rel_err": abs(v - ref) / abs(ref),
            "vg_value_rel_err": abs(float(v2) - ref) / abs(ref),
            "grad_max_abs_err_over_max_abs": float(
                np.max(np.abs(g - gr)) / np.max(np.abs(gr))
            ),
            "grad_norm_rel_err": float(np.linalg.norm(g - gr) / np.linalg.norm(gr)),
            "grad_max_entrywise_rel_err": float(
                np.max(np.abs(g[big] - gr[big]) / np.abs(gr[big]))
            ),
            "params": int(gr.size),
            "jitter_events_rust": p["jitter_events"],
        }


def summary(v):
    return {"min": min(v), "median": statistics.median(v)}


def cmd_compare(a):
    os.makedirs(OUT, exist_ok=True)
    import jax

    report = {
        "jax": jax.__version__,
        "xla_flags": os.environ.get("XLA_FLAGS"),
        "affinity": sorted(os.sched_getaffinity(0)),
        "configs": {},
    }
    for name in a.configs.split(","):
        d, m, t = CONFIGS[name]
        path = os.path.join(OUT, f"{name}.json")
        dumped = rust_dump(a.bin, d, m, t, path)
        jx = Jax(path)
        compile_s = jx.compile()
        agree = jx.agreement()
        if agree["loss_rel_err"] > 1e-8 or agree["jitter_events_rust"] != 0:
            raise SystemExit(f"{name}: Rust and JAX disagree: {agree}")
        rounds = []
        for r in range(a.rounds):
            load0 = load_avg()
            base = None
            if a.baseline:
                base, _ = rust_time(a.baseline, d, m, t, "loss,grad", a.reps)
            rust, _ = rust_time(a.bin, d, m, t, "loss,grad", a.reps)
            jl = jx.time("loss", a.reps)
            jg = jx.time("grad", a.reps)
            rounds.append(
                {
                    "load_before": load0,
                    "load_after": load_avg(),
                    "rust_loss": {k: rust["loss"][k] for k in ("wall_ms", "cpu_ms")},
                    "rust_grad": {k: rust["grad"][k] for k in ("wall_ms", "cpu_ms")},
                    "jax_loss": jl,
                    "jax_grad": jg,
                }
            )
            if base is not None:
                rounds[-1]["base_loss"] = {k: base["loss"][k] for k in ("wall_ms", "cpu_ms")}
                rounds[-1]["base_grad"] = {k: base["grad"][k] for k in ("wall_ms", "cpu_ms")}
            print(
                f"{name} round {r}: load {load0} rust loss {min(rust['loss']['wall_ms']):.1f} "
                f"grad {min(rust['grad']['wall_ms']):.1f} | jax loss {min(jl['wall_ms']):.1f} "
                f"grad {min(jg['wall_ms']):.1f} ms (min wall)",
                file=sys.stderr,
            )
        cfg = {
            "d": d,
            "m": m,
            "t": t,
            "rust_dump": dumped,
            "jax_compile_s": {"loss": compile_s[0], "value_and_grad": compile_s[1]},
            "agreement": agree,
            "rounds": rounds,
        }
        stats = {}
        sides = ["rust", "jax"] + (["base"] if a.baseline else [])
        for k in [f"{x}_{op}" for x in sides for op in ("loss", "grad")]:
            for clock in ("wall_ms", "cpu_ms"):
                allv = [x for r in rounds for x in r[k][clock]]
                stats[f"{k}_{clock}"] = summary(allv)
        ratios = {}
        for op in ("loss", "grad"):
            for clock in ("wall_ms", "cpu_ms"):
                per_round = [
                    min(r[f"rust_{op}"][clock]) / min(r[f"jax_{op}"][clock]) for r in rounds
                ]
                ratios[f"rust_over_jax_{op}_{clock}"] = {
                    "per_round_min_ratio": per_round,
                    "median": statistics.median(per_round),
                }
        if a.baseline:
            for op in ("loss", "grad"):
                for num, den in (("rust", "base"), ("base", "jax")):
                    per_round = [
                        min(r[f"{num}_{op}"]["cpu_ms"]) / min(r[f"{den}_{op}"]["cpu_ms"])
                        for r in rounds
                    ]
                    ratios[f"{num}_over_{den}_{op}_cpu_ms"] = {
                        "per_round_min_ratio": per_round,
                        "median": statistics.median(per_round),
                    }
        for side in sides:
            per_round = [
                min(r[f"{side}_grad"]["cpu_ms"]) / min(r[f"{side}_loss"]["cpu_ms"]) for r in rounds
            ]
            ratios[f"{side}_grad_over_loss_cpu"] = statistics.median(per_round)
        cfg["stats"] = stats
        cfg["ratios"] = ratios
        report["configs"][name] = cfg
    path = os.path.join(OUT, f"compare-{time.strftime('%Y%m%d-%H%M%S')}.json")
    with open(path, "w") as f:
        json.dump(report, f, indent=1)
    print_compare(report)
    print(f"\nfull results: {path}")


def print_compare(report):
    print(f"jax {report['jax']}, XLA_FLAGS={report['xla_flags']!r}, CPUs {report['affinity']}")
    for name, c in report["configs"].items():
        s, r, ag = c["stats"], c["ratios"], c["agreement"]
        t = c["t"]
        print(f"\n### {name}: D = {c['d']}, m = {c['m']}, T = {t}, P = {ag['params']}")
        print(
            f"agreement: loss {ag['loss_rust']:.12g} (Rust) vs {ag['loss_jax']:.12g} (JAX), "
            f"rel. err {ag['loss_rel_err']:.1e}; gradient: max|Δ|/max|g| "
            f"{ag['grad_max_abs_err_over_max_abs']:.1e}, ‖Δ‖/‖g‖ {ag['grad_norm_rel_err']:.1e}, "
            f"worst entry {ag['grad_max_entrywise_rel_err']:.1e}"
        )
        loads = [x["load_before"][0] for x in c["rounds"]] + [
            x["load_after"][0] for x in c["rounds"]
        ]
        print(f"load average (1 min) during the rounds: {min(loads)}–{max(loads)}")
        print(
            f"JAX compile: loss {c['jax_compile_s']['loss']:.1f} s, "
            f"value_and_grad {c['jax_compile_s']['value_and_grad']:.1f} s\n"
        )
        print("| what | Rust wall min / median | Rust CPU min | JAX wall min / median | JAX CPU min "
              "| Rust/JAX (CPU, median of rounds) | Rust/JAX (wall) |")
        print("|---|---|---|---|---|---|---|")
        for op, label in (("loss", "loss"), ("grad", "value + gradient")):
            rw, rc = s[f"rust_{op}_wall_ms"], s[f"rust_{op}_cpu_ms"]
            jw, jc = s[f"jax_{op}_wall_ms"], s[f"jax_{op}_cpu_ms"]
            print(
                f"| {label} | {rw['min']:.1f} / {rw['median']:.1f} ms | {rc['min']:.1f} ms "
                f"| {jw['min']:.1f} / {jw['median']:.1f} ms | {jc['min']:.1f} ms "
                f"| {r[f'rust_over_jax_{op}_cpu_ms']['median']:.2f} "
                f"| {r[f'rust_over_jax_{op}_wall_ms']['median']:.2f} |"
            )
        print(
            f"\nper step (CPU min): Rust loss {s['rust_loss_cpu_ms']['min'] / t * 1e6:.0f} ns, "
            f"JAX loss {s['jax_loss_cpu_ms']['min'] / t * 1e6:.0f} ns; "
            f"gradient/loss: Rust {r['rust_grad_over_loss_cpu']:.2f}, "
            f"JAX {r['jax_grad_over_loss_cpu']:.2f}"
        )
        if "base_loss_cpu_ms" in s:
            for op in ("loss", "grad"):
                nb = r[f"rust_over_base_{op}_cpu_ms"]
                bj = r[f"base_over_jax_{op}_cpu_ms"]
                print(
                    f"baseline {op}: CPU min {s[f'base_{op}_cpu_ms']['min']:.1f} ms; new/baseline "
                    f"{nb['median']:.2f} ({min(nb['per_round_min_ratio']):.2f}–"
                    f"{max(nb['per_round_min_ratio']):.2f}); baseline/JAX {bj['median']:.2f}"
                )


SCALING = (
    # vary T at D = 4, m = 100
    [(4, 100, t) for t in (125, 250, 500)]
    # vary m at D = 4, T = 500
    + [(4, m, 500) for m in (25, 50, 200)]
    # vary D at m = 100, T = 500
    + [(d, 100, 500) for d in (10, 20)]
)


def cmd_scaling(a):
    os.makedirs(OUT, exist_ok=True)
    rows = {}
    for rnd in range(a.rounds):
        for d, m, t in SCALING:
            path = os.path.join(OUT, f"scale-d{d}-m{m}-t{t}.json")
            if rnd == 0:
                rust_dump(a.bin, d, m, t, path)
            row = rows.setdefault((d, m, t), {"d": d, "m": m, "t": t, "load": []})
            row["load"].append(load_avg()[0])
            for what in ("loss", "grad"):
                res, rss = rust_time(a.bin, d, m, t, what, a.reps, wrap_time=True)
                cmd = ["/usr/bin/time", "-v", sys.executable, os.path.abspath(__file__)]
                cmd += ["jax-time", path, "--what", what, "--reps", str(a.reps)]
                out = subprocess.run(cmd, check=True, capture_output=True, text=True)
                jres = json.loads(out.stdout.strip().splitlines()[-1])
                for key, val in (
                    (f"rust_{what}_cpu_ms", res[what]["min_cpu_ms"]),
                    (f"rust_{what}_wall_ms", res[what]["min_wall_ms"]),
                    (f"rust_{what}_rss_kib", rss),
                    (f"jax_{what}_cpu_ms", min(jres["cpu_ms"])),
                    (f"jax_{what}_wall_ms", min(jres["wall_ms"])),
                    (f"jax_{what}_rss_kib", max_rss(out.stderr)),
                ):
                    row.setdefault(key + "_rounds", []).append(val)
                    pick = max if key.endswith("rss_kib") else min
                    row[key] = pick(row[key + "_rounds"])
            print(json.dumps(row), file=sys.stderr)
    rows = list(rows.values())
    # JAX's fixed cost: import, jit and run a trivial function
    cmd = ["/usr/bin/time", "-v", sys.executable, "-c",
           "import jax, jax.numpy as jnp; jax.jit(lambda x: x + 1)(jnp.ones(3)).block_until_ready()"]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    base = max_rss(out.stderr)
    path = os.path.join(OUT, f"scaling-{time.strftime('%Y%m%d-%H%M%S')}.json")
    with open(path, "w") as f:
        json.dump({"rows": rows, "jax_baseline_rss_kib": base}, f, indent=1)
    print("| D | m | T | Rust loss | Rust grad | grad/loss | JAX loss | JAX grad | Rust/JAX loss "
          "| Rust/JAX grad | Rust peak RSS loss / grad | JAX peak RSS loss / grad | load |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['d']} | {r['m']} | {r['t']} | {r['rust_loss_cpu_ms']:.1f} ms "
            f"| {r['rust_grad_cpu_ms']:.1f} ms | {r['rust_grad_cpu_ms'] / r['rust_loss_cpu_ms']:.2f} "
            f"| {r['jax_loss_cpu_ms']:.1f} ms | {r['jax_grad_cpu_ms']:.1f} ms "
            f"| {r['rust_loss_cpu_ms'] / r['jax_loss_cpu_ms']:.2f} "
            f"| {r['rust_grad_cpu_ms'] / r['jax_grad_cpu_ms']:.2f} "
            f"| {r['rust_loss_rss_kib'] / 1024:.0f} / {r['rust_grad_rss_kib'] / 1024:.0f} MiB "
            f"| {r['jax_loss_rss_kib'] / 1024:.0f} / {r['jax_grad_rss_kib'] / 1024:.0f} MiB "
            f"| {min(r['load'])}–{max(r['load'])} |"
        )
    print(f"\nJAX baseline (import + trivial jit) peak RSS: {base / 1024:.0f} MiB; full results: {path}")


def cmd_calibrate(a):
    """Single-thread reference rates on this CPU through XLA: f64 GEMM and f64 exp."""
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)

    def best(f, *args, reps=5):
        f(*args).block_until_ready()
        ts = []
        for _ in range(reps):
            t = time.perf_counter()
            f(*args).block_until_ready()
            ts.append(time.perf_counter() - t)
        return min(ts)

    key = jax.random.PRNGKey(0)
    n = 1024
    x = jax.random.normal(key, (n, n), dtype=jnp.float64)
    mm = jax.jit(lambda x: x @ x)
    gemm = 2 * n**3 / best(mm, x) / 1e9
    v = jax.random.normal(key, (4_000_000,), dtype=jnp.float64)
    ex = jax.jit(jnp.exp)
    exp_ns = best(ex, v) / v.size * 1e9
    q = jax.random.normal(key, (100, 100), dtype=jnp.float64)
    small = jax.jit(lambda q: jax.lax.fori_loop(0, 1000, lambda i, z: jnp.exp(z * 0.5), q))
    exp_small_ns = best(small, q) / (1000 * q.size) * 1e9
    print(json.dumps({"jax_dgemm_1024_gflops": gemm, "jax_exp_ns_per_element_4e6": exp_ns,
                      "jax_exp_ns_per_element_100x100_block": exp_small_ns,
                      "load": load_avg()}))


def cmd_jax_time(a):
    jx = Jax(a.file)
    jx.compile((a.what,))
    res = jx.time(a.what, a.reps)
    res["what"] = a.what
    print(json.dumps(res))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("compare")
    c.add_argument("--bin", required=True)
    c.add_argument("--rounds", type=int, default=5)
    c.add_argument("--reps", type=int, default=5)
    c.add_argument("--configs", default="d4,d20")
    c.add_argument("--baseline", default=None, help="a second msgp_perf binary to time per round")
    s = sub.add_parser("scaling")
    s.add_argument("--bin", required=True)
    s.add_argument("--reps", type=int, default=5)
    s.add_argument("--rounds", type=int, default=2)
    cal = sub.add_parser("calibrate")
    cal.add_argument("--bin", required=False)
    j = sub.add_parser("jax-time")
    j.add_argument("file")
    j.add_argument("--what", choices=["loss", "grad"], default="loss")
    j.add_argument("--reps", type=int, default=3)
    a = ap.parse_args()
    sys.path.insert(0, HERE)
    cmds = {"compare": cmd_compare, "scaling": cmd_scaling, "calibrate": cmd_calibrate,
            "jax-time": cmd_jax_time}
    cmds[a.cmd](a)


if __name__ == "__main__":
    main()
