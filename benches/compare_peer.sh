#!/usr/bin/env bash
# Runs the PyTorch peer renderer and volrender back to back on the same machine, so their
# throughputs can be compared as ratios (docs/performance-volrender.md).
# Needs the peer's venv: bash ../shared/peer/setup.sh
# Both sides tune glibc's malloc by default (the peer's `tune_malloc`); NO_MALLOPT=1 runs both
# with glibc's defaults instead.
set -euo pipefail
cd "$(dirname "$0")/.."
P=${PEER_PYTHON:-/tmp/peer/venv/bin/python}
PEER_DIR=${PEER_DIR:-../shared/peer}
cargo build --release --example render_throughput
R=./target/release/examples/render_throughput
ARGS=(--grid 64 --rays 65536 --samples 128 --threads 2 --backward --repeats 5 --warmup 3)
if [ "${NO_MALLOPT:-0}" = 1 ]; then ARGS+=(--no-mallopt); fi
# Three warm-up runs on both sides: the sparse forward's first two or three runs take up to
# twice the steady time while its buffers are made (2026-11-28: 40 ms, then 20.3 ms), and with
# one warm-up the median of five could land on one of them.
# A pause before each run: a process that just exited can still be returning its memory to
# the system, which slowed the first runs of the next one by up to 40%.
for scene in dense sparse; do
  echo "== $scene"; uptime
  sleep 3; (cd "$PEER_DIR" && "$P" torch_render.py "${ARGS[@]}" --scene "$scene")
  sleep 3; "$R" "${ARGS[@]}" --scene "$scene"
  sleep 3; "$R" "${ARGS[@]}" --scene "$scene" --skip-empty
done
