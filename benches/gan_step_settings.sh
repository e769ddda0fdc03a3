#!/usr/bin/env bash
# Which of the process-wide settings of `singrav::runtime::init` a patch-gan user still needs:
# runs the standalone gan_step (a program outside the workspace that depends on patch-gan alone,
# benches/standalone_gan_step.sh) on each row of benches/compare_gan_peer.sh as it is, and
# with each setting that `init` makes, alternating, and prints each setting's speed-up
# (seconds as it is / seconds with the setting: above 1 means the library still gains from it).
# The settings, as a user would make them from the shell or main:
#   malloc: GLIBC_TUNABLES=glibc.malloc.mmap_max=0:glibc.malloc.trim_threshold=1073741824
#           (what `volrender::tune_malloc` sets through mallopt)
#   spin:   CANDLE_BARRIER_POOL_SPIN_LIMIT=1
#   candle1: CANDLE_NUM_THREADS=1
#   join:   gan_step --join-pool (rayon's global pool with the calling thread in it)
#   all:    the four together
#   bash benches/gan_step_settings.sh           (THREADS=2 REPEAT=5 ROUNDS=2; ROWS=base|hd|all)
set -euo pipefail
cd "$(dirname "$0")/.."
THREADS=${THREADS:-2}
REPEAT=${REPEAT:-5}
ROUNDS=${ROUNDS:-2}
G=$(bash benches/standalone_gan_step.sh)
# shellcheck source=benches/gan_rows.sh
source benches/gan_rows.sh
SETTINGS=(${SETTINGS:-none malloc spin candle1 join all})
MALLOC="glibc.malloc.mmap_max=0:glibc.malloc.trim_threshold=1073741824"
OUT=$(mktemp)
trap 'rm -f "$OUT"' EXIT
echo "$(date -u +%FT%TZ), commit $(git rev-parse --short HEAD)$(git diff --quiet || echo ' (modified)'), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), avx512f: $(grep -qw avx512f /proc/cpuinfo && echo yes || echo no)"
run() { # setting row...
  local setting=$1
  shift
  local env=() flags=()
  case "$setting" in
    malloc) env=(GLIBC_TUNABLES=$MALLOC) ;;
    spin) env=(CANDLE_BARRIER_POOL_SPIN_LIMIT=1) ;;
    candle1) env=(CANDLE_NUM_THREADS=1) ;;
    join) flags=(--join-pool) ;;
    all) env=(GLIBC_TUNABLES=$MALLOC CANDLE_BARRIER_POOL_SPIN_LIMIT=1 CANDLE_NUM_THREADS=1)
         flags=(--join-pool) ;;
  esac
  env "${env[@]}" "$G" "$@" "${flags[@]}" --threads "$THREADS" --repeat "$REPEAT"
}
for round in $(seq "$ROUNDS"); do
  for i in "${!ROWS[@]}"; do
    for s in "${SETTINGS[@]}"; do
      # shellcheck disable=SC2086
      sleep 2; run "$s" ${ROWS[$i]} | sed "s/^/$s $i /" >> "$OUT"
    done
  done
done
python3 - "$OUT" "${SETTINGS[@]}" <<'PY'
import json, statistics, sys
settings = sys.argv[2:]
rows = {}
for line in open(sys.argv[1]):
    setting, index, payload = line.split(" ", 2)
    rows.setdefault(int(index), {}).setdefault(setting, []).append(json.loads(payload))
others = [s for s in settings if s != "none"]
print("| step | shape | s as it is | " + " | ".join(f"{s} speed-up" for s in others) + " |")
print("|---|---|---|" + "---|" * len(others))
for _, by in sorted(rows.items()):
    ours = by["none"][0]
    what, size = ours["what"], ours["size"]
    shape = f"{size}^3" if what != "critic" else f"batch {ours['batch']}, {size}^2"
    shape += f", {ours['channels']} ch"
    base = statistics.median(r["seconds"] for r in by["none"])
    cells = [f"{base / statistics.median(r['seconds'] for r in by[s]):.2f}x" for s in others]
    print(f"| {what} | {shape} | {base:.4f} | " + " | ".join(cells) + " |")
PY
