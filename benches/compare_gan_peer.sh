#!/usr/bin/env bash
# Runs the PyTorch peer's generator and critic steps (../shared/peer/torch_gan_step.py) and
# patch-gan's (crates/patch-gan/examples/gan_step.rs) back to back for every row of the table in
# docs/performance-patch-gan.md, then prints the table: seconds per step on both sides, volgen's
# speed relative to PyTorch (PyTorch seconds / volgen seconds: above 1 is faster), and the
# effective GFLOP/s of both against the `gemm` crate's rate measured in the same run.
# The rows run ROUNDS times, the two sides alternating, and each side's time is the median of
# its rounds' medians: on a shared machine a slow minute then hits both sides, where a single
# round could land it on one side only (the ratio of one row moved 1.4x-2.5x between runs).
# The per-round ratios are printed too.
# Needs the peer's venv: bash ../shared/peer/setup.sh
#   bash benches/compare_gan_peer.sh            (THREADS=2 REPEAT=5 ROUNDS=3 by default)
set -euo pipefail
cd "$(dirname "$0")/.."
P=${PEER_PYTHON:-/tmp/peer/venv/bin/python}
PEER_DIR=${PEER_DIR:-../shared/peer}
THREADS=${THREADS:-2}
REPEAT=${REPEAT:-5}
ROUNDS=${ROUNDS:-3}
cargo build --release -p patch-gan --example gan_step
G=$PWD/target/release/examples/gan_step
OUT=$(mktemp)
trap 'rm -f "$OUT"' EXIT
ROWS=(
  "generator --size 28 --channels 32 --layers 5"
  "generator --size 40 --channels 32 --layers 5"
  "generator --size 53 --channels 32 --layers 5"
  "generator --size 71 --channels 32 --layers 5"
  "critic --size 54 --batch 2 --channels 32 --layers 5"
  "critic --size 108 --batch 2 --channels 32 --layers 5"
)
uptime
# A pause before each run: a process that just exited can still be returning its memory.
sleep 3; "$G" gemm --size 2048 --threads "$THREADS" --repeat "$REPEAT" | sed 's/^/gemm /' >> "$OUT"
for round in $(seq "$ROUNDS"); do
  for row in "${ROWS[@]}"; do
    # shellcheck disable=SC2086
    sleep 3; (cd "$PEER_DIR" && "$P" torch_gan_step.py $row --threads "$THREADS" --repeat "$REPEAT") | sed "s/^/torch $round /" >> "$OUT"
    # shellcheck disable=SC2086
    sleep 3; "$G" $row --threads "$THREADS" --repeat "$REPEAT" | sed "s/^/volgen $round /" >> "$OUT"
  done
done
uptime
python3 - "$OUT" <<'PY'
import json, statistics, sys
gemm, rows = None, {}
for line in open(sys.argv[1]):
    side, _, payload = line.partition(" ")
    if side == "gemm":
        gemm = json.loads(payload)["gflops"]
        continue
    _, _, payload = payload.partition(" ")
    row = json.loads(payload)
    key = (row["what"], row["size"], row["batch"])
    rows.setdefault(key, {"torch": [], "volgen": []})[side].append(row)
print(f"gemm crate, 2048^3 f32: {gemm:.0f} GFLOP/s")
print()
print("| step | shape | PyTorch s | volgen s | volgen speed vs PyTorch | per round | PyTorch GFLOP/s | volgen GFLOP/s | volgen / gemm |")
print("|---|---|---|---|---|---|---|---|---|")
for (what, size, batch), sides in rows.items():
    shape = f"{size}^3" if what == "generator" else f"batch {batch}, {size}^2"
    flop = sides["volgen"][0]["gflop"]
    t = statistics.median(r["seconds"] for r in sides["torch"])
    o = statistics.median(r["seconds"] for r in sides["volgen"])
    rounds = " / ".join(f"{a['seconds'] / b['seconds']:.2f}" for a, b in zip(sides["torch"], sides["volgen"]))
    print(f"| {what} | {shape} | {t:.4f} | {o:.4f} | **{t / o:.2f}x** | {rounds} | "
          f"{flop / t:.0f} | {flop / o:.0f} | {flop / o / gemm:.0%} |")
PY
