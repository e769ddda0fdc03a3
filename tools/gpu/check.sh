#!/usr/bin/env bash
# The GPU check: runs `volgen device-check --device cuda` with the binary tools/gpu/build.sh
# built (so the GPU machine builds nothing) and prints one JSON line per check, then one line
# with the GPU's peak memory while the checks ran (nvidia-smi, sampled every 200 ms).
#
#   tools/gpu/check.sh                          # the binary in target/cuda/release
#   VOLGEN=/path/to/volgen tools/gpu/check.sh   # another one (its lib/ beside it)
#   tools/gpu/check.sh --checks render,conv3d   # extra arguments go to device-check
#
# The checks (see docs/training.md, "GPU"): render, conv3d, generator, active-set, critic
# (each the device's form against the CPU kernels, values and gradients), micro-training
# (the same seed on both devices), paper-iterations (seconds per iteration at each scale of
# the `paper` preset), tiny-training (a `tiny` run, stopped with what the budget leaves).
# device-check looks at its --budget-seconds (420 by default) between checks and training
# iterations; check.sh kills it at 480 s whatever the budget, within the 8 minutes the issue
# allows. Exit status: 0 when every check ran and passed.
set -uo pipefail
cd "$(dirname "$0")/../.."

if [ -z "${VOLGEN:-}" ]; then
  VOLGEN=target/cuda/release/volgen
  # The compressed copy build.sh leaves (what a GPU machine is handed), unpacked once.
  if [ ! -x "$VOLGEN" ]; then
    if [ ! -x target/cuda/dist/volgen ] && [ -f target/cuda/volgen-cuda.tar.gz ]; then
      mkdir -p target/cuda/dist
      tar -xzf target/cuda/volgen-cuda.tar.gz -C target/cuda/dist
    fi
    VOLGEN=target/cuda/dist/volgen
  fi
fi
[ -x "$VOLGEN" ] || { echo "check.sh: no volgen binary at $VOLGEN (run tools/gpu/build.sh first)" >&2; exit 2; }
# The CUDA runtime the binary links, copied beside it by build.sh (cuBLAS, cuRAND and the
# driver come from the machine; copies put in that lib/ folder are found too).
export LD_LIBRARY_PATH="$(dirname "$VOLGEN")/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
MISSING=$(ldd "$VOLGEN" | awk '/not found/ {print $1}' | tr '\n' ' ')
# Machines with PyTorch for CUDA 13 (as the project's GPU machine, 2026-12-04) hold cuBLAS and
# cuRAND in its `nvidia` wheels rather than in the system's library path.
if [ -n "$MISSING" ] && command -v python3 > /dev/null; then
  WHEELS=$(python3 -c 'import nvidia, os; print(os.path.join(list(nvidia.__path__)[0], "cu13", "lib"))' 2> /dev/null || true)
  if [ -n "$WHEELS" ] && [ -d "$WHEELS" ]; then
    export LD_LIBRARY_PATH="$LD_LIBRARY_PATH:$WHEELS"
    MISSING=$(ldd "$VOLGEN" | awk '/not found/ {print $1}' | tr '\n' ' ')
  fi
fi
if [ -n "$MISSING" ]; then
  echo "{\"check\": \"libraries\", \"ok\": false, \"missing\": \"${MISSING% }\", \"note\": \"install CUDA 13 (driver R580+, cuBLAS, cuRAND) or put the libraries in $(dirname "$VOLGEN")/lib\"}"
  exit 1
fi

if command -v nvidia-smi > /dev/null; then
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader \
    | sed 's/^/{"gpu": "/; s/$/"}/'
  MEMLOG=$(mktemp)
  nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits -lms 200 > "$MEMLOG" &
  SAMPLER=$!
else
  echo '{"gpu": null, "note": "no nvidia-smi on this machine"}'
  SAMPLER=""
fi

timeout -k 10 480 "$VOLGEN" device-check --device cuda "$@"
STATUS=$?

if [ -n "$SAMPLER" ]; then
  kill "$SAMPLER" 2> /dev/null
  wait "$SAMPLER" 2> /dev/null
  PEAK=$(sort -n "$MEMLOG" | tail -1)
  echo "{\"check\": \"gpu-memory\", \"peak_mib\": ${PEAK:-null}}"
  rm -f "$MEMLOG"
fi
[ "$STATUS" -eq 124 ] && echo '{"check": "timeout", "ok": false, "note": "killed after 480 s"}'
exit "$STATUS"
