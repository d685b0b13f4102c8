"""Sweeps of the paper's reproductions over many processes or machines.

``msgp reproduce table1`` fits its units (benchmark × seed × method) one after another. The same
units are independent, so this module spreads them over local processes or over a Ray cluster
and writes the same markdown section and rows: every unit is computed by the library function
the command line calls (``msgp._msgp.table1_unit``), whose numbers do not depend on the machine
or the thread count. Only the provenance lines (command, wall time, machine, date) differ::

    python -m msgp.sweep table1 --seeds 0,1,2                      # local processes
    python -m msgp.sweep table1 --seeds 0,1,2 --ray auto           # the Ray cluster of this node
    python -m msgp.sweep table1 --seeds 0,1,2 --ray ray://head:10001
    python -m msgp.sweep table1 --seeds 0 --ray local              # start a Ray instance here

From Python: ``msgp.sweep.table1(seeds=[0, 1, 2], ray="auto")``. Ray is an optional extra
(``pip install "msgp[ray]"``); the workers need msgp installed (the same version) and, for the
real series, the data folder at the same path (or ``data_dir=`` pointing at a shared one).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import multiprocessing
import os
import shlex
import sys
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

from . import _msgp

__all__ = ["table1", "main"]


def _single_threaded() -> None:
    """Each worker fits one unit on one thread; the workers fill the cores."""
    os.environ["MSGP_THREADS"] = "1"


def _unit(plan: Dict[str, Any], unit: Dict[str, Any]) -> Dict[str, Any]:
    _single_threaded()
    return _msgp.table1_unit(plan, unit)


def _describe(unit: Dict[str, Any]) -> str:
    return f"{unit['column']} on {unit['benchmark']} (seed {unit['seed']})"


def _progress(quiet: bool, done: int, total: int, unit: Dict[str, Any], cell: Dict[str, Any]):
    if quiet:
        return
    mm, mean = cell["metrics"]
    print(
        f"[{done}/{total}] {_describe(unit)}: RMSE {mm['rmse']:.4f}, mean feedback "
        f"{mean['rmse']:.4f}, NLL {mm['nll']:.3f}, {cell['train_seconds']:.1f} s",
        file=sys.stderr,
        flush=True,
    )


def _run_local(plan, units, workers: int, quiet: bool) -> List[Tuple[dict, dict]]:
    total = len(units)
    results = []
    if workers == 1:
        for unit in units:
            cell = _msgp.table1_unit(plan, unit)
            results.append((unit, cell))
            _progress(quiet, len(results), total, unit, cell)
        return results
    # spawn: a fresh interpreter per worker (no fork of a process that runs Rust threads)
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_single_threaded
    ) as pool:
        futures = {pool.submit(_unit, plan, unit): k for k, unit in enumerate(units)}
        for future in concurrent.futures.as_completed(futures):
            unit = units[futures[future]]
            cell = future.result()
            results.append((unit, cell))
            _progress(quiet, len(results), total, unit, cell)
    return results


def _ray_module():
    try:
        import ray  # noqa: PLC0415 (optional dependency)
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            'msgp.sweep with ray= needs Ray: pip install "msgp[ray]" (or pip install ray)'
        ) from e
    return ray


def _run_ray(plan, units, address: str, quiet: bool) -> Tuple[List[Tuple[dict, dict]], str]:
    ray = _ray_module()
    if not ray.is_initialized():
        if address == "local":
            ray.init(include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
    remote = ray.remote(num_cpus=1)(_unit)
    plan_ref = ray.put(plan)
    pending = {remote.remote(plan_ref, unit): unit for unit in units}
    results = []
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        for ref in ready:
            unit = pending.pop(ref)
            cell = ray.get(ref)
            results.append((unit, cell))
            _progress(quiet, len(results), len(units), unit, cell)
    cpus = int(ray.cluster_resources().get("CPU", 0))
    nodes = len([n for n in ray.nodes() if n.get("Alive")])
    return results, f"a Ray cluster ({address}) of {nodes} node(s), {cpus} CPUs"


def table1(
    seeds: Sequence[int] = (0,),
    *,
    only: Optional[Sequence[str]] = None,
    methods: Optional[Sequence[str]] = None,
    likelihoods: Optional[Sequence[str]] = None,
    inducing: int = 100,
    iters: Optional[int] = None,
    optimizer: str = "adam",
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
    initialised Ray is used as it is), over a Ray cluster. Writes the ``table1`` section of
    ``out`` (``None``: nothing written) and returns ``{"section", "markdown", "rows",
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
    )
    plan, units = made["plan"], made["units"]
    machine = None
    if ray is not None:
        results, machine = _run_ray(plan, units, ray, quiet)
    else:
        if workers is not None and workers < 1:
            raise ValueError(f"workers must be at least 1, got {workers}")
        count = workers or os.cpu_count() or 1
        results = _run_local(plan, units, min(count, max(1, len(units))), quiet)
    seconds = time.monotonic() - started
    if command is None:
        command = f"`msgp.sweep.table1(seeds={list(seeds)!r}, ...)`"
    report = _msgp.table1_report(plan, results, command, seconds, machine)
    if out is not None:
        _msgp.update_results_section(out, report["section"], report["markdown"])
    report["seconds"] = seconds
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


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m msgp.sweep",
        description="Run a reproduction of the paper on local processes or a Ray cluster.",
    )
    sub = parser.add_subparsers(dest="what", required=True)
    t1 = sub.add_parser("table1", help="the paper's Table 1 (as msgp reproduce table1)")
    t1.add_argument("--seeds", type=_seeds, default=[0], help="e.g. 0,1,2 or 0-4")
    t1.add_argument("--only", type=_csv, default=None, help="benchmarks, comma-separated")
    t1.add_argument("--methods", type=_csv, default=None, help="msgp,gp-narx,pilco-narx")
    t1.add_argument("--likelihoods", type=_csv, default=None, help="free-run,filter")
    t1.add_argument("--inducing", type=int, default=100)
    t1.add_argument("--iters", type=int, default=None)
    t1.add_argument("--optimizer", choices=["adam", "lbfgs"], default="adam")
    t1.add_argument("--data-dir", default=None)
    t1.add_argument("--out", default="RESULTS.md")
    t1.add_argument("--ray", metavar="ADDRESS", default=None,
                    help='Ray address ("auto", "ray://host:10001") or "local"')
    t1.add_argument("--workers", type=int, default=None,
                    help="local processes without --ray (default: one per core)")
    t1.add_argument("--json", action="store_true", help="print the rows as JSON")
    t1.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    args = parser.parse_args(argv)
    words = list(sys.argv[1:] if argv is None else argv)
    try:
        report = table1(
            args.seeds,
            only=args.only,
            methods=args.methods,
            likelihoods=args.likelihoods,
            inducing=args.inducing,
            iters=args.iters,
            optimizer=args.optimizer,
            data_dir=args.data_dir,
            out=args.out,
            ray=args.ray,
            workers=args.workers,
            quiet=args.quiet,
            command=f"`python -m msgp.sweep {shlex.join(words)}`",
        )
    except (_msgp.MsgpError, ValueError, ImportError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps({"command": "sweep table1", "out": args.out, "seconds": report["seconds"],
                          "rows": report["rows"]}))
    else:
        print(f"wrote the {report['section']} section of {args.out} in {report['seconds']:.0f} s",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
