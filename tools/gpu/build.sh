#!/usr/bin/env bash
# Builds volgen's `cuda` binary (and the GPU check program) on a machine without a GPU or a
# CUDA toolkit: NVIDIA's compiler, headers and runtime come from PyPI into a venv, the compute
# capability from the environment (no nvidia-smi needed).
#
#   tools/gpu/build.sh                    # H100/H200 (compute capability 90)
#   CUDA_COMPUTE_CAP=80 tools/gpu/build.sh  # A100
#
# Output: target/cuda/release/volgen, which tools/gpu/check.sh runs on the GPU machine. The
# binary loads the driver (libcuda.so.1), cuBLAS and cuBLASLt (.so.13) and cuRAND (.so.10) from
# the machine it runs on: a CUDA 13 installation there (driver R580 or newer). The CUDA runtime
# (libcudart.so.13), small, is copied beside it (lib/), where check.sh looks.
set -euo pipefail
cd "$(dirname "$0")/../.."

: "${CUDA_COMPUTE_CAP:=90}"
# CUDA 13.0: the oldest CUDA 13, so the widest range of drivers (R580 or newer) can load its PTX.
# PyPI's CUDA 12 compiler wheels hold ptxas only, no nvcc; the CUDA 13 ones hold the whole compiler.
# candle links cuBLAS, cuRAND and NVRTC by name (cudarc's `dynamic-linking`): their wheels give
# the linker the libraries; the GPU machine's own copies are loaded at run time.
CUDA_PIP=("nvidia-cuda-nvcc==13.0.88" "nvidia-nvvm==13.0.88" "nvidia-cuda-crt==13.0.88"
          "nvidia-cuda-runtime==13.0.96" "nvidia-cuda-cccl==13.0.85"
          "nvidia-cublas==13.0.2.14" "nvidia-curand==10.4.0.35" "nvidia-cuda-nvrtc==13.0.88")
VENV="${VOLGEN_CUDA_VENV:-target/cuda-venv}"

if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
"$VENV/bin/pip" install --quiet --disable-pip-version-check "${CUDA_PIP[@]}"

CUDA_HOME="$("$VENV/bin/python" -c 'import nvidia, os; print(os.path.join(nvidia.__path__[0], "cu13"))')"
[ -x "$CUDA_HOME/bin/nvcc" ] || { echo "build.sh: no nvcc at $CUDA_HOME/bin/nvcc" >&2; exit 1; }
# The linker wants the unversioned names of the libraries.
for lib in libcudart.so.13 libcublas.so.13 libcublasLt.so.13 libcurand.so.10 libnvrtc.so.13; do
  [ -e "$CUDA_HOME/lib/$lib" ] || { echo "build.sh: the wheels gave no $CUDA_HOME/lib/$lib" >&2; exit 1; }
  ln -sf "$lib" "$CUDA_HOME/lib/${lib%.so.*}.so"
done
# The driver (libcuda) comes with the GPU's driver, not with a wheel: link against a stub that
# defines every driver function cudarc declares, under the driver's own name (libcuda.so.1),
# so the machine's real driver is what the binary loads.
STUBS="$VENV/stubs"
mkdir -p "$STUBS"
CUDARC_SYS=$(cargo metadata --format-version 1 --features cuda \
  | "$VENV/bin/python" -c 'import json, os, sys
pkgs = json.load(sys.stdin)["packages"]
cudarc = [p for p in pkgs if p["name"] == "cudarc"]
if not cudarc:
    sys.exit("build.sh: cargo metadata lists no cudarc (candle-core cuda feature?)")
print(os.path.join(os.path.dirname(cudarc[0]["manifest_path"]), "src/driver/sys/mod.rs"))')
grep -oE '^pub unsafe fn cu[A-Za-z0-9_]+' "$CUDARC_SYS" | sed 's/^pub unsafe fn //' | sort -u \
  | sed 's/.*/int &(void) { return 999; }/' > "$STUBS/libcuda.c"
cc -shared -fPIC -Wl,-soname,libcuda.so.1 -o "$STUBS/libcuda.so" "$STUBS/libcuda.c"

export CUDA_HOME CUDA_PATH="$CUDA_HOME" CUDA_COMPUTE_CAP
export PATH="$CUDA_HOME/bin:$PATH"
export LIBRARY_PATH="$CUDA_HOME/lib:$STUBS${LIBRARY_PATH:+:$LIBRARY_PATH}"
export LD_LIBRARY_PATH="$CUDA_HOME/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
export CUDARC_CUDA_VERSION=13000
export CARGO_TARGET_DIR=target/cuda
nvcc --version | tail -2

cargo build --release --features cuda --bin volgen "$@"

# What the GPU machine needs beside the binaries: the runtime they link.
mkdir -p target/cuda/release/lib
cp -L "$CUDA_HOME/lib/libcudart.so.13" target/cuda/release/lib/
# The same, stripped and compressed, to move to a GPU machine (about 17 MB; tools/gpu/check.sh
# unpacks it when there is no target/cuda/release/volgen).
rm -rf target/cuda/dist && mkdir -p target/cuda/dist/lib
strip -o target/cuda/dist/volgen target/cuda/release/volgen
cp target/cuda/release/lib/libcudart.so.13 target/cuda/dist/lib/
tar -C target/cuda/dist -czf target/cuda/volgen-cuda.tar.gz volgen lib
ls -l target/cuda/release/volgen target/cuda/release/lib target/cuda/volgen-cuda.tar.gz
echo "libraries the binary needs on the GPU machine:"
readelf -d target/cuda/release/volgen | grep -oE 'lib(cuda|cublas|curand|nvrtc|cudart)[^]]*' || true
