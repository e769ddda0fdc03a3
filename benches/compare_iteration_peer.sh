#!/usr/bin/env bash
# Whole training iterations, volgen against the PyTorch peer (../shared/peer/
# torch_singrav_iteration.py), at every 3D scale of the `tiny` and `small` presets: seconds per
# adversarial iteration (3 critic steps, then 3 generator steps) on both sides and volgen's speed
# relative to PyTorch (PyTorch seconds / volgen seconds: above 1 is faster).
#
# volgen's side is a real `volgen train` on the stones scene with a short schedule
# (--iterations, the first quarter reconstruction-only); its seconds are the median step of
# log.jsonl's cumulative `seconds` over the adversarial iterations of each scale. It does what
# training does, which is more than the peer's iteration: 8 reconstruction views per generator
# step where the peer renders 2, and the colour-distribution and opacity terms; and what the
# preset skips (the finer scales' active set, early ray termination) it skips here too.
# The peer renders as many views as volgen's generated views per step (2).
# Needs the peer's venv: bash ../shared/peer/setup.sh
#   bash benches/compare_iteration_peer.sh         (THREADS=2 by default)
set -euo pipefail
cd "$(dirname "$0")/.."
P=${PEER_PYTHON:-/tmp/peer/venv/bin/python}
PEER_DIR=$(cd "${PEER_DIR:-../shared/peer}" && pwd)
THREADS=${THREADS:-2}
cargo build --release --bin volgen
V=$PWD/target/release/volgen
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
"$V" scene stones --out "$WORK/stones" > /dev/null
"$V" scene stones --out "$WORK/stones216" --views 100 --resolution 216 > /dev/null
uptime
export RAYON_NUM_THREADS=$THREADS
sleep 3; "$V" train "$WORK/stones" --out "$WORK/tiny" --preset tiny --iterations 40 > /dev/null 2>&1
sleep 3; "$V" train "$WORK/stones216" --out "$WORK/small" --preset small --iterations 24 > /dev/null 2>&1
# preset, scale, then the peer's flags for that scale (the preset's volume, image and samples).
ROWS=(
  "tiny 1 --volume 16 --image 24 --samples 48"
  "tiny 2 --volume 21 --image 36 --samples 72"
  "tiny 3 --volume 28 --image 54 --samples 96"
  "small 1 --volume 24 --image 32 --samples 48"
  "small 2 --volume 32 --image 48 --samples 64"
  "small 3 --volume 43 --image 72 --samples 80"
  "small 4 --volume 57 --image 108 --samples 96"
)
for row in "${ROWS[@]}"; do
  read -r preset scale flags <<< "$row"
  # shellcheck disable=SC2086
  sleep 3; (cd "$PEER_DIR" && "$P" torch_singrav_iteration.py $flags --scale "$scale" --views 2 \
    --channels 16 --layers 5 --threads "$THREADS" --iterations 5) \
    | sed "s/^/$preset $scale /" >> "$WORK/peer.txt"
done
uptime
python3 - "$WORK" <<'PY'
import json, statistics, sys
work = sys.argv[1]

def adversarial_steps(run, scale):
    rows = [json.loads(l) for l in open(f"{work}/{run}/log.jsonl")]
    rows = [r for r in rows if r["scale"] == scale]
    return [b["seconds"] - a["seconds"] for a, b in zip(rows, rows[1:]) if b["critic"] is not None]

print("| preset, scale | volume / image / samples | PyTorch s/it | volgen s/it | volgen speed vs PyTorch |")
print("|---|---|---|---|---|")
for line in open(f"{work}/peer.txt"):
    preset, scale, payload = line.split(" ", 2)
    peer = json.loads(payload)
    ours = statistics.median(adversarial_steps(preset, int(scale)))
    shape = f"{peer['volume']} / {peer['image']} / {peer['samples']}"
    print(f"| {preset} {scale} | {shape} | {peer['seconds_per_iteration']:.3f} | {ours:.3f} | "
          f"**{peer['seconds_per_iteration'] / ours:.2f}x** |")
PY
