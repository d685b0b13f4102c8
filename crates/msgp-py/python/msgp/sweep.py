"""Sweeps of the paper's reproductions over many processes or machines.

``msgp reproduce table1`` fits its units (benchmark × seed × method) one after another, ``msgp
reproduce figure4`` its learning runs (model × seed). The units are independent, so this module
spreads them over local processes or over a Ray cluster and writes the same markdown section,
rows and files: every unit is computed by the library function the command line calls
(``msgp._msgp.table1_unit``, ``msgp._msgp.figure4_unit``), whose numbers do not depend on the
machine or the thread count. Only the provenance lines (command, wall time, machine, date) and
the measured seconds differ::

    python -m msgp.sweep table1 --seeds 0,1,2                      # local processes
    python -m msgp.sweep table1 --seeds 0,1,2 --ray auto           # the Ray cluster of this node
    python -m msgp.sweep table1 --seeds 0,1,2 --ray ray://head:10001
    python -m msgp.sweep table1 --seeds 0 --ray local              # start a Ray instance here
    python -m msgp.sweep figure4 --seeds 0-4 --models msgp-filter,linear-kf --ray auto

From Python: ``msgp.sweep.table1(seeds=[0, 1, 2], ray="auto")``, ``msgp.sweep.figure4(seeds=range(5),
models=["msgp-filter", "linear-kf"])``. Ray is an optional extra (``pip install "msgp[ray]"``);
the workers need msgp installed (the same version) and, for the real series, the data folder at
the same path (or ``data_dir=`` pointing at a shared one). A Figure 4 run's folder (policy,
episodes, plots, summary) is made in a scratch folder on its worker and sent back to the driver,
which writes it into the plan's folder: the workers need no shared file system.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import multiprocessing
import os
import shlex
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from . import _msgp

__all__ = ["table1", "figure4", "main"]


def _single_threaded() -> None:
    """Each worker fits one unit on one thread; the workers fill the cores."""
    os.environ["MSGP_THREADS"] = "1"


def _table1_unit(plan: Dict[str, Any], unit: Dict[str, Any]) -> Dict[str, Any]:
    _single_threaded()
    return _msgp.table1_unit(plan, unit)


def _table1_line(unit: Dict[str, Any], cell: Dict[str, Any]) -> str:
    mm, mean = cell["metrics"]
    return (
        f"{unit['column']} on {unit['benchmark']} (seed {unit['seed']}): RMSE {mm['rmse']:.4f}, "
        f"mean feedback {mean['rmse']:.4f}, NLL {mm['nll']:.3f}, {cell['train_seconds']:.1f} s"
    )


def _figure4_unit(plan: Dict[str, Any], unit: Dict[str, Any]) -> Dict[str, Any]:
    """One learning run in a scratch folder; its files (relative path → bytes) and summary."""
    _single_threaded()
    with tempfile.TemporaryDirectory(prefix="msgp-figure4-") as scratch:
        summary = _msgp.figure4_unit(plan, unit, scratch)
        root = Path(scratch)
        files = {
            path.relative_to(root).as_posix(): path.read_bytes()
            for path in sorted(root.rglob("*"))
            if path.is_file()
        }
    return {"summary": summary, "files": files}


def _figure4_line(unit: Dict[str, Any], result: Dict[str, Any]) -> str:
    s = result["summary"]
    first = s["first_stable_iteration"]
    found = "no stable policy" if first is None else f"first stable at iteration {first}"
    return f"{unit['model']} seed {unit['seed']}: {found}, {s['wall_seconds']:.0f} s"


Work = Callable[[Dict[str, Any], Dict[str, Any]], Dict[str, Any]]


def _progress(quiet: bool, done: int, total: int, line: str) -> None:
    if not quiet:
        print(f"[{done}/{total}] {line}", file=sys.stderr, flush=True)


def _run_local(
    plan, units, work: Work, describe, workers: int, quiet: bool, done=None
) -> List[Tuple[dict, dict]]:
    """``work(plan, unit)`` for every unit on ``workers`` processes; ``done(unit, result)`` is
    called in the driver as each finishes."""
    total = len(units)
    results = []

    def finished(unit, result):
        if done is not None:
            done(unit, result)
        results.append((unit, result))
        _progress(quiet, len(results), total, describe(unit, result))

    if workers == 1:
        # the units run here, each single-threaded; the caller's MSGP_THREADS is theirs again after
        before = os.environ.get("MSGP_THREADS")
        try:
            for unit in units:
                finished(unit, work(plan, unit))
        finally:
            if before is None:
                os.environ.pop("MSGP_THREADS", None)
            else:
                os.environ["MSGP_THREADS"] = before
        return results
    # spawn: a fresh interpreter per worker (no fork of a process that runs Rust threads)
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_single_threaded
    ) as pool:
        futures = {pool.submit(work, plan, unit): k for k, unit in enumerate(units)}
        for future in concurrent.futures.as_completed(futures):
            finished(units[futures[future]], future.result())
    return results


def _ray_module():
    try:
        import ray  # noqa: PLC0415 (optional dependency)
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            'msgp.sweep with ray= needs Ray: pip install "msgp[ray]" (or pip install ray)'
        ) from e
    return ray


def _run_ray(
    plan, units, work: Work, describe, address: str, quiet: bool, done=None
) -> Tuple[List[Tuple[dict, dict]], str]:
    ray = _ray_module()
    if not ray.is_initialized():
        if address == "local":
            ray.init(include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
    remote = ray.remote(num_cpus=1)(work)
    plan_ref = ray.put(plan)
    pending = {remote.remote(plan_ref, unit): unit for unit in units}
    results = []
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        for ref in ready:
            unit = pending.pop(ref)
            result = ray.get(ref)
            if done is not None:
                done(unit, result)
            results.append((unit, result))
            _progress(quiet, len(results), len(units), describe(unit, result))
    cpus = int(ray.cluster_resources().get("CPU", 0))
    nodes = len([n for n in ray.nodes() if n.get("Alive")])
    return results, f"a Ray cluster ({address}) of {nodes} node(s), {cpus} CPUs"


def _run(plan, units, work: Work, describe, ray, workers, quiet, done=None):
    """The units on Ray (``ray``: an address) or on local processes; results and the machine
    line of the report (``None``: this machine)."""
    if ray is not None:
        return _run_ray(plan, units, work, describe, ray, quiet, done)
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    count = workers or os.cpu_count() or 1
    used = min(count, max(1, len(units)))
    return _run_local(plan, units, work, describe, used, quiet, done), None


def table1(
    seeds: Sequence[int] = (0,),
    *,
    only: Optional[Sequence[str]] = None,
    methods: Optional[Sequence[str]] = None,
    likelihoods: Optional[Sequence[str]] = None,
    inducing: int = 100,
    iters: Optional[int] = None,
    optimizer: str = "adam",
    history: str = "paper",
    data_dir: Optional[str] = None,
    out: Optional[str] = "RESULTS.md",
    ray: Optional[str] = None,
    workers: Optional[int] = None,
    quiet: bool = False,
    command: Optional[str] = None,
) -> Dict[str, Any]:
    """The paper's Table 1 as ``msgp reproduce table1`` computes it, its units spread over
    ``workers`` local processes (default: one per core; 1 runs them here) or, with ``ray`` (an
    address: ``"auto"``, ``"ray://host:10001"``, or ``"local"`` to start one here; an already
    initialised Ray is used as it is), over a Ray cluster. ``history="auto"`` chooses each
    fit's history on its training part (``msgp fit --history auto``) instead of taking the
    paper's. Writes the plan's section of ``out`` (``None``: nothing written) and returns ``{"section", "markdown", "rows",
    "seconds"}``; the rows are those of ``msgp reproduce table1 --json``."""
    started = time.monotonic()
    made = _msgp.table1_plan(
        list(seeds),
        data_dir=data_dir,
        only=list(only) if only else None,
        methods=list(methods) if methods else None,
        likelihoods=list(likelihoods) if likelihoods else None,
        inducing=inducing,
        iters=iters,
        optimizer=optimizer,
        history=history,
    )
    plan, units = made["plan"], made["units"]
    results, machine = _run(plan, units, _table1_unit, _table1_line, ray, workers, quiet)
    seconds = time.monotonic() - started
    if command is None:
        command = f"`msgp.sweep.table1(seeds={list(seeds)!r}, ...)`"
    report = _msgp.table1_report(plan, results, command, seconds, machine)
    if out is not None:
        _msgp.update_results_section(out, report["section"], report["markdown"])
    report["seconds"] = seconds
    return report


def _write_run(run_dir: Path, files: Dict[str, bytes]) -> None:
    """A run's files into its folder, each through a temporary sibling and a rename, the
    summary last (a folder with a summary is a finished run)."""
    order = sorted(files, key=lambda name: (name == "summary.json", name))
    for name in order:
        target = run_dir / name
        target.parent.mkdir(parents=True, exist_ok=True)
        temporary = target.with_name(f".{target.name}.part")
        temporary.write_bytes(files[name])
        os.replace(temporary, target)


def figure4(
    seeds: Sequence[int] = (0, 1, 2, 3, 4),
    *,
    models: Optional[Sequence[str]] = None,
    tier: str = "apollo",
    params: Optional[Dict[str, Any]] = None,
    iterations: int = 8,
    budget: Optional[Dict[str, Any]] = None,
    dir: Optional[str] = None,
    out: Optional[str] = "RESULTS.md",
    ray: Optional[str] = None,
    workers: Optional[int] = None,
    quiet: bool = False,
    command: Optional[str] = None,
) -> Dict[str, Any]:
    """The paper's Figure 4 as ``msgp reproduce figure4`` computes it: PILCO on the simulated
    pendulum for every model ("msgp" (free-run likelihood), "msgp-filter", "gp-narx",
    "linear-kf"; default all) and seed, on the plant ``tier`` ("apollo" or "noisy"; ``params``
    overrides its parameters) with ``budget`` (overrides of ``msgp._msgp.figure4_budget()``, the
    command line's budget options). Runs whose finished folder is already in ``dir`` (default
    ``results/figure4-<tier>``) are reused, as the command line does; the others run on
    ``workers`` local processes (default: one per core) or, with ``ray``, on a Ray cluster, and
    their folders are written into ``dir``. Writes the ``figure4-<tier>`` section of ``out``
    (``None``: nothing written) and ``dir/figure4.png``; returns ``{"section", "markdown",
    "plot", "seconds", "ran", "reused"}``."""
    started = time.monotonic()
    made = _msgp.figure4_plan(
        list(seeds),
        tier=tier,
        params=params,
        models=list(models) if models else None,
        iterations=iterations,
        budget=budget,
        dir=dir,
    )
    plan, pending = made["plan"], made["pending"]
    root = Path(made["dir"])

    def keep(unit, result):
        _write_run(root / f"{unit['model']}-seed{unit['seed']}", result["files"])

    if not quiet:
        for unit in made["units"]:
            if unit not in pending:
                print(f"reusing {unit['model']}-seed{unit['seed']} in {root}", file=sys.stderr)
    machine = None
    if pending:
        _, machine = _run(plan, pending, _figure4_unit, _figure4_line, ray, workers, quiet, keep)
    seconds = time.monotonic() - started
    if command is None:
        command = f"`msgp.sweep.figure4(seeds={list(seeds)!r}, ...)`"
    report = _msgp.figure4_report(plan, command, seconds, machine)
    if out is not None:
        _msgp.update_results_section(out, report["section"], report["markdown"])
    report["seconds"] = seconds
    report["ran"] = len(pending)
    report["reused"] = len(made["units"]) - len(pending)
    return report


def _csv(text: str) -> List[str]:
    return [part.strip() for part in text.split(",") if part.strip()]


def _seeds(text: str) -> List[int]:
    """``0,1,2`` or ``0-4`` (inclusive) or a mix."""
    out: List[int] = []
    for part in _csv(text):
        if "-" in part:
            lo, hi = part.split("-", 1)
            out.extend(range(int(lo), int(hi) + 1))
        else:
            out.append(int(part))
    if not out:
        raise argparse.ArgumentTypeError("give at least one seed")
    return out


def _common(p: argparse.ArgumentParser, seeds: List[int]) -> None:
    p.add_argument("--seeds", type=_seeds, default=seeds, help="e.g. 0,1,2 or 0-4")
    p.add_argument("--out", default="RESULTS.md", help="markdown file whose section is written")
    p.add_argument("--ray", metavar="ADDRESS", default=None,
                   help='Ray address ("auto", "ray://host:10001") or "local"')
    p.add_argument("--workers", type=int, default=None,
                   help="local processes without --ray (default: one per core)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


# the budget options of `msgp reproduce figure4` this entry point takes as flags (the rest:
# --budget JSON); `None` leaves the command line's default
_BUDGET_FLAGS = [
    ("--random-rollouts", int, "random episodes before the first policy"),
    ("--episode-seconds", float, "length of every interaction episode [s]"),
    ("--fit-iters", int, "solver iterations of each model fit"),
    ("--warm-start", int, "continue the previous model for N iterations (0: from scratch)"),
    ("--inducing", int, "pseudo-inputs of the model"),
    ("--search-iters", int, "Adam steps of each policy optimisation start"),
    ("--candidates", int, "random gain candidates screened per search"),
    ("--policy-horizon", float, "horizon of the predicted rollouts [s]"),
]


def _budget(args: argparse.Namespace) -> Dict[str, Any]:
    budget: Dict[str, Any] = json.loads(args.budget) if args.budget else {}
    if not isinstance(budget, dict):
        raise ValueError(f"--budget must be a JSON object, got {args.budget}")
    for flag, _, _ in _BUDGET_FLAGS:
        key = flag[2:].replace("-", "_")
        value = getattr(args, key)
        if value is not None:
            budget[key] = value
    if args.mean is not None:
        budget["mean"] = args.mean
    return budget


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m msgp.sweep",
        description="Run a reproduction of the paper on local processes or a Ray cluster.",
    )
    sub = parser.add_subparsers(dest="what", required=True)
    t1 = sub.add_parser("table1", help="the paper's Table 1 (as msgp reproduce table1)")
    _common(t1, [0])
    t1.add_argument("--only", type=_csv, default=None, help="benchmarks, comma-separated")
    t1.add_argument("--methods", type=_csv, default=None, help="msgp,gp-narx,pilco-narx")
    t1.add_argument("--likelihoods", type=_csv, default=None, help="free-run,filter")
    t1.add_argument("--inducing", type=int, default=100)
    t1.add_argument("--iters", type=int, default=None)
    t1.add_argument("--optimizer", choices=["adam", "lbfgs"], default="adam")
    t1.add_argument("--history", choices=["paper", "auto"], default="paper",
                    help="each fit's history: the paper's Table 3, or chosen on its training part")
    t1.add_argument("--data-dir", default=None)
    t1.add_argument("--json", action="store_true", help="print the rows as JSON")
    f4 = sub.add_parser("figure4", help="the paper's Figure 4 (as msgp reproduce figure4)")
    _common(f4, [0, 1, 2, 3, 4])
    f4.add_argument("--models", type=_csv, default=None,
                    help="msgp,msgp-filter,gp-narx,linear-kf (default: all)")
    f4.add_argument("--plant", choices=["apollo", "noisy"], default="apollo",
                    help="plant tier")
    f4.add_argument("--params", default=None, metavar="PARAMS.json",
                    help="plant parameters overriding the tier's (a JSON file)")
    f4.add_argument("--iterations", type=int, default=8, help="policy iterations per run")
    f4.add_argument("--dir", default=None,
                    help="folder of the runs and the plot (default: results/figure4-<plant>)")
    for flag, kind, text in _BUDGET_FLAGS:
        f4.add_argument(flag, type=kind, default=None, help=text)
    f4.add_argument("--mean", choices=["zero", "linear"], default=None,
                    help="prior mean of the GP models")
    f4.add_argument("--budget", default=None, metavar="JSON",
                    help="further budget options as a JSON object (msgp._msgp.figure4_budget())")
    args = parser.parse_args(argv)
    words = list(sys.argv[1:] if argv is None else argv)
    command = f"`python -m msgp.sweep {shlex.join(words)}`"
    try:
        if args.what == "table1":
            report = table1(
                args.seeds,
                only=args.only,
                methods=args.methods,
                likelihoods=args.likelihoods,
                inducing=args.inducing,
                iters=args.iters,
                optimizer=args.optimizer,
                history=args.history,
                data_dir=args.data_dir,
                out=args.out,
                ray=args.ray,
                workers=args.workers,
                quiet=args.quiet,
                command=command,
            )
        else:
            params = None
            if args.params is not None:
                with open(args.params, encoding="utf-8") as f:
                    params = json.load(f)
            report = figure4(
                args.seeds,
                models=args.models,
                tier=args.plant,
                params=params,
                iterations=args.iterations,
                budget=_budget(args),
                dir=args.dir,
                out=args.out,
                ray=args.ray,
                workers=args.workers,
                quiet=args.quiet,
                command=command,
            )
    except (_msgp.MsgpError, ValueError, ImportError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    if args.what == "table1" and args.json:
        print(json.dumps({"command": "sweep table1", "out": args.out, "seconds": report["seconds"],
                          "rows": report["rows"]}))
    else:
        print(f"wrote the {report['section']} section of {args.out} in {report['seconds']:.0f} s",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
