#!/usr/bin/env bash
# Runs the PyTorch peer's generator and critic steps (../shared/peer/torch_gan_step.py) and
# patch-gan's (crates/patch-gan/examples/gan_step.rs) back to back for every row of the table in
# docs/performance-patch-gan.md, then prints the table: seconds per step on both sides, volgen's
# speed relative to PyTorch (PyTorch seconds / volgen seconds: above 1 is faster), and the
# effective GFLOP/s of both against the `gemm` crate's rate measured in the same run.
# Needs the peer's venv: bash ../shared/peer/setup.sh
#   bash benches/compare_gan_peer.sh            (THREADS=2 REPEAT=5 by default)
set -euo pipefail
cd "$(dirname "$0")/.."
P=${PEER_PYTHON:-/tmp/peer/venv/bin/python}
PEER_DIR=${PEER_DIR:-../shared/peer}
THREADS=${THREADS:-2}
REPEAT=${REPEAT:-5}
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
for row in "${ROWS[@]}"; do
  # shellcheck disable=SC2086
  sleep 3; (cd "$PEER_DIR" && "$P" torch_gan_step.py $row --threads "$THREADS" --repeat "$REPEAT") | sed 's/^/torch /' >> "$OUT"
  # shellcheck disable=SC2086
  sleep 3; "$G" $row --threads "$THREADS" --repeat "$REPEAT" | sed 's/^/volgen /' >> "$OUT"
done
uptime
python3 - "$OUT" <<'PY'
import json, sys
gemm, torch, ours = None, [], []
for line in open(sys.argv[1]):
    side, _, payload = line.partition(" ")
    row = json.loads(payload)
    if side == "gemm":
        gemm = row["gflops"]
    elif side == "torch":
        torch.append(row)
    else:
        ours.append(row)
print(f"gemm crate, 2048^3 f32: {gemm:.0f} GFLOP/s")
print()
print("| step | shape | PyTorch s | volgen s | volgen speed vs PyTorch | PyTorch GFLOP/s | volgen GFLOP/s | volgen / gemm |")
print("|---|---|---|---|---|---|---|---|")
for t, o in zip(torch, ours):
    shape = f"{o['size']}^3" if o["what"] == "generator" else f"batch {o['batch']}, {o['size']}^2"
    flop = o["gflop"]
    print(f"| {o['what']} | {shape} | {t['seconds']:.4f} | {o['seconds']:.4f} | "
          f"**{t['seconds'] / o['seconds']:.2f}x** | {flop / t['seconds']:.0f} | "
          f"{flop / o['seconds']:.0f} | {flop / o['seconds'] / gemm:.0%} |")
PY
