#!/usr/bin/env bash
# Runs PyTorch's trilinear resampling (benches/resample_peer.py, `F.interpolate`) and
# radiance-volume's `resample_tensor` (crates/radiance-volume/examples/resample_step.rs) back to
# back at the `hd` preset's pyramid steps (4 channels, as the generators' raw volumes), then
# prints the table of docs/performance.md ("Resampling between scales"): seconds of a
# forward and of a forward + backward on both sides, and volgen's speed relative to PyTorch
# (PyTorch seconds / volgen seconds: above 1 is faster).
# resample_step makes no process-wide setting beyond the thread count: it runs as a program that
# depends on radiance-volume does. The rows run ROUNDS times, the two sides alternating, and each
# side's time is the median of its rounds.
# Needs the peer's venv: bash ../shared/peer/setup.sh
#   bash benches/compare_resample_peer.sh       (THREADS=2 REPEAT=10 ROUNDS=3 by default)
set -euo pipefail
cd "$(dirname "$0")/.."
P=${PEER_PYTHON:-/tmp/peer/venv/bin/python}
THREADS=${THREADS:-2}
REPEAT=${REPEAT:-10}
ROUNDS=${ROUNDS:-3}
cargo build --release -p radiance-volume --example resample_step
R=$PWD/target/release/examples/resample_step
OUT=$(mktemp)
trap 'rm -f "$OUT"' EXIT
ROWS=("45 63" "63 89" "89 126")
echo "$(date -u +%FT%TZ), commit $(git rev-parse --short HEAD)$(git diff --quiet || echo ' (modified)'), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), avx512f: $(grep -qw avx512f /proc/cpuinfo && echo yes || echo no)"
uptime
for round in $(seq "$ROUNDS"); do
  for row in "${ROWS[@]}"; do
    read -r from to <<< "$row"
    args=(--from "$from" --to "$to" --channels 4 --threads "$THREADS" --repeat "$REPEAT")
    sleep 1; "$P" benches/resample_peer.py "${args[@]}" | sed "s/^/torch /" >> "$OUT"
    sleep 1; "$R" "${args[@]}" | sed "s/^/volgen /" >> "$OUT"
  done
done
uptime
python3 - "$OUT" <<'PY'
import json, statistics, sys
rows = {}
for line in open(sys.argv[1]):
    side, _, payload = line.partition(" ")
    r = json.loads(payload)
    rows.setdefault((r["from"], r["to"]), {"torch": [], "volgen": []})[side].append(r)
print("| step (4 channels) | pass | PyTorch s | volgen s | volgen speed vs PyTorch | per round |")
print("|---|---|---|---|---|---|")
for (a, b), sides in sorted(rows.items()):
    for key, name in [("forward_seconds", "forward"), ("backward_seconds", "forward + backward")]:
        t = statistics.median(r[key] for r in sides["torch"])
        o = statistics.median(r[key] for r in sides["volgen"])
        rounds = " / ".join(f"{x[key] / y[key]:.2f}" for x, y in zip(sides["torch"], sides["volgen"]))
        print(f"| {a}^3 to {b}^3 | {name} | {t:.4f} | {o:.4f} | **{t / o:.2f}x** | {rounds} |")
PY
