#!/usr/bin/env bash
# Builds volgen's `cuda` binary (and the GPU check program) on a machine without a GPU or a
# CUDA toolkit: NVIDIA's compiler, headers and runtime come from PyPI into a venv, the compute
# capability from the environment (no nvidia-smi needed).
#
#   tools/gpu/build.sh                    # H100/H200 (compute capability 90)
#   CUDA_COMPUTE_CAP=80 tools/gpu/build.sh  # A100
#
# Output: target/cuda/release/volgen, which
# tools/gpu/check.sh runs on the GPU machine. The binaries load the driver (libcuda), cuBLAS and
# cuRAND from the machine they run on; they link the CUDA 13 runtime (libcudart.so.13), which the
# venv provides here and tools/gpu/check.sh looks for beside the binary (lib/).
set -euo pipefail
cd "$(dirname "$0")/../.."

: "${CUDA_COMPUTE_CAP:=90}"
# CUDA 13.0: the oldest CUDA 13, so the widest range of drivers (R580 or newer) can load its PTX.
# PyPI's CUDA 12 compiler wheels hold ptxas only, no nvcc; the CUDA 13 ones hold the whole compiler.
CUDA_PIP=("nvidia-cuda-nvcc==13.0.88" "nvidia-nvvm==13.0.88" "nvidia-cuda-crt==13.0.88"
          "nvidia-cuda-runtime==13.0.96" "nvidia-cuda-cccl==13.0.85")
VENV="${VOLGEN_CUDA_VENV:-target/cuda-venv}"

if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
"$VENV/bin/pip" install --quiet --disable-pip-version-check "${CUDA_PIP[@]}"

CUDA_HOME="$("$VENV/bin/python" -c 'import nvidia, os; print(os.path.join(nvidia.__path__[0], "cu13"))')"
[ -x "$CUDA_HOME/bin/nvcc" ] || { echo "build.sh: no nvcc at $CUDA_HOME/bin/nvcc" >&2; exit 1; }
# The linker wants the unversioned name of the runtime library.
ln -sf libcudart.so.13 "$CUDA_HOME/lib/libcudart.so"

export CUDA_HOME CUDA_PATH="$CUDA_HOME" CUDA_COMPUTE_CAP
export PATH="$CUDA_HOME/bin:$PATH"
export LIBRARY_PATH="$CUDA_HOME/lib${LIBRARY_PATH:+:$LIBRARY_PATH}"
export LD_LIBRARY_PATH="$CUDA_HOME/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
export CUDARC_CUDA_VERSION=13000
export CARGO_TARGET_DIR=target/cuda
nvcc --version | tail -2

cargo build --release --features cuda --bin volgen "$@"

# What the GPU machine needs beside the binaries: the runtime they link.
mkdir -p target/cuda/release/lib
cp -L "$CUDA_HOME/lib/libcudart.so.13" target/cuda/release/lib/
ls -l target/cuda/release/volgen target/cuda/release/lib
