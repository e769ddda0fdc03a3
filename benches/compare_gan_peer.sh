#!/usr/bin/env bash
# Runs the PyTorch peer's generator and critic steps (../shared/peer/torch_gan_step.py) and
# patch-gan's (crates/patch-gan/examples/gan_step.rs) back to back for every row of the table in
# docs/performance-patch-gan.md, then prints the table: seconds per step on both sides, volgen's
# speed relative to PyTorch (PyTorch seconds / volgen seconds: above 1 is faster), and the
# effective GFLOP/s of both against the `gemm` crate's rate measured in the same run
# (crates/conv-kernels/examples/gemm_rate.rs).
# gan_step makes no process-wide setting beyond the thread count: it runs as a program that
# depends on patch-gan does. With STANDALONE=1 it is built as such a program, outside the
# workspace (benches/standalone_gan_step.sh), instead of as the workspace's example.
# The `active` rows run the generator on the active sites of a 7% (95^3) / 6% (126^3) shell
# as the `hd` preset's finer scales do; their peer is PyTorch's dense generator of the same
# size (it has no submanifold convolution), and their GFLOP/s count the dense step's work.
# The rows run ROUNDS times, the two sides alternating, and each side's time is the median of
# its rounds' medians: on a shared machine a slow minute then hits both sides, where a single
# round could land it on one side only (the ratio of one row moved 1.4x-2.5x between runs).
# The per-round ratios are printed too.
# Needs the peer's venv: bash ../shared/peer/setup.sh
#   bash benches/compare_gan_peer.sh            (THREADS=2 REPEAT=5 ROUNDS=3 by default)
#   ROWS=hd bash benches/compare_gan_peer.sh    (the hd rows only; ROWS=base the six first)
set -euo pipefail
cd "$(dirname "$0")/.."
P=${PEER_PYTHON:-/tmp/peer/venv/bin/python}
PEER_DIR=${PEER_DIR:-../shared/peer}
THREADS=${THREADS:-2}
REPEAT=${REPEAT:-5}
ROUNDS=${ROUNDS:-3}
cargo build --release -p conv-kernels --example gemm_rate
GEMM=$PWD/target/release/examples/gemm_rate
if [ "${STANDALONE:-0}" = "1" ]; then
  G=$(bash benches/standalone_gan_step.sh)
else
  cargo build --release -p patch-gan --example gan_step
  G=$PWD/target/release/examples/gan_step
fi
OUT=$(mktemp)
trap 'rm -f "$OUT"' EXIT
# shellcheck source=benches/gan_rows.sh
source benches/gan_rows.sh
echo "$(date -u +%FT%TZ), commit $(git rev-parse --short HEAD)$(git diff --quiet || echo ' (modified)'), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), avx512f: $(grep -qw avx512f /proc/cpuinfo && echo yes || echo no)"
uptime
# A pause before each run: a process that just exited can still be returning its memory.
sleep 3; "$GEMM" 2048 "$THREADS" "$REPEAT" | sed 's/^/gemm /' >> "$OUT"
for round in $(seq "$ROUNDS"); do
  for i in "${!ROWS[@]}"; do
    row=${ROWS[$i]}
    # The peer of an active-set step is the dense generator.
    peer_row=${row/#active/generator}
    # shellcheck disable=SC2086
    sleep 3; (cd "$PEER_DIR" && "$P" torch_gan_step.py $peer_row --threads "$THREADS" --repeat "$REPEAT") | sed "s/^/torch $i /" >> "$OUT"
    # shellcheck disable=SC2086
    sleep 3; "$G" $row --threads "$THREADS" --repeat "$REPEAT" | sed "s/^/volgen $i /" >> "$OUT"
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
    index, _, payload = payload.partition(" ")
    rows.setdefault(int(index), {"torch": [], "volgen": []})[side].append(json.loads(payload))
print(f"gemm crate, 2048^3 f32: {gemm:.0f} GFLOP/s")
print()
print("| step | shape | PyTorch s | volgen s | volgen speed vs PyTorch | per round | PyTorch GFLOP/s | volgen GFLOP/s | volgen / gemm |")
print("|---|---|---|---|---|---|---|---|---|")
for _, sides in sorted(rows.items()):
    ours = sides["volgen"][0]
    what, size = ours["what"], ours["size"]
    shape = f"{size}^3" if what != "critic" else f"batch {ours['batch']}, {size}^2"
    shape += f", {ours['channels']} ch" + (f", {ours['in_channels']} in" if ours["in_channels"] != 4 else "")
    if what == "active":
        shape += f", {ours['active']:.0%} active"
    flop = ours["gflop"]
    t = statistics.median(r["seconds"] for r in sides["torch"])
    o = statistics.median(r["seconds"] for r in sides["volgen"])
    rounds = " / ".join(f"{a['seconds'] / b['seconds']:.2f}" for a, b in zip(sides["torch"], sides["volgen"]))
    print(f"| {what} | {shape} | {t:.4f} | {o:.4f} | **{t / o:.2f}x** | {rounds} | "
          f"{flop / t:.0f} | {flop / o:.0f} | {flop / o / gemm:.0%} |")
PY
