#!/usr/bin/env bash
# Rust vs JAX comparison of the open-loop MSGP loss and gradient (dev-only tool, not shipped).
#
#   benches/reference/run.sh compare [--rounds 5] [--reps 5] [--configs d4,d20]
#   benches/reference/run.sh scaling [--reps 3]
#   benches/reference/run.sh minimax [--degree 9]   (the f64 exp's polynomial, exp_minimax.py)
#
# Creates benches/reference/.venv (gitignored) with the pinned CPU JAX, builds the Rust timing
# tool (msgp_perf), and runs compare.py single-threaded on one CPU (MSGP_PERF_CPU, default 1)
# at nice 19. Results go to benches/reference/out/ (gitignored).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
venv="$here/.venv"
if [ ! -x "$venv/bin/python" ]; then
  nice -n 19 python3 -m venv "$venv"
fi
if ! "$venv/bin/python" -c 'import jax, mpmath' 2>/dev/null; then
  nice -n 19 "$venv/bin/pip" install -q -r "$here/requirements.txt"
fi
if [ "${1:-}" = minimax ]; then
  shift
  exec nice -n 19 "$venv/bin/python" "$here/exp_minimax.py" "$@"
fi
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$root/target}"
(cd "$root" && nice -n 19 cargo build --release --locked -p msgp-benches --bin msgp_perf)
# one thread for XLA; taskset pins both the Python process and the Rust processes it starts
export XLA_FLAGS="--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
cmd="${1:-compare}"
shift || true
cd "$here"
exec nice -n 19 taskset -c "${MSGP_PERF_CPU:-1}" "$venv/bin/python" "$here/compare.py" "$cmd" \
  --bin "$CARGO_TARGET_DIR/release/msgp_perf" "$@"
