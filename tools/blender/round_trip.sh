#!/usr/bin/env bash
# Blender -> volgen -> Blender, end to end (docs/blender.md):
#   1. build a small scene with bpy (a few primitives on a ground plane, away from the origin;
#      make_test_scene.py),
#   2. render a dataset from it with export_dataset.py (Cycles, Z-pass depth, depth_kind "z"),
#   3. volgen train --preset PRESET --bounds auto (micro by default), 4. volgen sample --vdb
#      --mesh glb,
#   5. import the VDB into the scene with import_volume.py, and in another copy of the scene the
#      mesh with import_mesh.py (Blender's glTF importer),
#   6. render each in Cycles from a dataset view and check it is non-empty where the scene was
#      (check_round_trip.py), writing side-by-side pictures.
# Too slow for the default test run (minutes): run it by hand or in CI when time allows.
#
#   tools/blender/round_trip.sh [WORKDIR]
#
# Environment: PYTHON (default: the venv of ../shared/validators/setup.sh, which installs
# bpy 5.0.1), VOLGEN (default: cargo's release binary), PRESET (micro), ITERATIONS (300 per
# scale: micro's own schedule leaves fog), VIEWS (24), SIZE (64),
# SAMPLES (16, Cycles samples per pixel).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
work="${1:-$(mktemp -d)}"
mkdir -p "$work"
PYTHON="${PYTHON:-${VALIDATORS_VENV:-$HOME/.cache/vdb-exr-validators/venv}/bin/python}"
PRESET="${PRESET:-micro}"
VIEWS="${VIEWS:-24}"
SIZE="${SIZE:-64}"
SAMPLES="${SAMPLES:-16}"
ITERATIONS="${ITERATIONS:-300}"
if [ -z "${VOLGEN:-}" ]; then
  (cd "$root" && cargo build --release --quiet)
  VOLGEN="${CARGO_TARGET_DIR:-$root/target}/release/volgen"
fi
"$PYTHON" -c 'import bpy' 2>/dev/null || {
  echo "error: $PYTHON cannot import bpy; install it with ../shared/validators/setup.sh or set PYTHON" >&2
  exit 2
}
step() { echo "== $(date +%T) $*"; }

step "scene: $work/scene.blend"
"$PYTHON" "$here/make_test_scene.py" "$work/scene.blend" >/dev/null
step "export: $VIEWS views of $SIZE x $SIZE"
"$PYTHON" "$here/export_dataset.py" "$work/scene.blend" --out "$work/data" \
  --views "$VIEWS" --size "$SIZE" --samples "$SAMPLES" | grep -E "^(scene bounds|wrote)"
step "train --preset $PRESET --iterations $ITERATIONS --bounds auto"
"$VOLGEN" train "$work/data" --out "$work/run" --preset "$PRESET" --iterations "$ITERATIONS" \
  --bounds auto
step "sample --vdb --mesh glb"
"$VOLGEN" sample "$work/run" --out "$work/samples" --count 1 --vdb --mesh glb
step "import into $work/with_volume.blend"
"$PYTHON" "$here/import_volume.py" "$work/scene.blend" "$work/samples/scene_0.vdb" \
  --out "$work/with_volume.blend" | grep -E "^(imported|saved)"
step "render and check"
"$PYTHON" "$here/check_round_trip.py" "$work/with_volume.blend" "$work/data" --view 0 \
  --samples "$SAMPLES" --picture "$work/round_trip.png" | grep -vE "^(Fra:|[0-9:.]+ +[a-z]+ +\|)"
step "import the mesh into $work/with_mesh.blend"
"$PYTHON" "$here/import_mesh.py" "$work/scene.blend" "$work/samples/scene_0.glb" \
  --out "$work/with_mesh.blend" | grep -E "^(imported|saved)"
step "render the mesh and check"
"$PYTHON" "$here/check_round_trip.py" "$work/with_mesh.blend" "$work/data" --view 0 \
  --samples "$SAMPLES" --picture "$work/round_trip_mesh.png" | grep -vE "^(Fra:|[0-9:.]+ +[a-z]+ +\|)"
