#!/usr/bin/env bash
# Photos in through real structure from motion, end to end (docs/photos.md):
#   1. build a textured scene with bpy (make_test_scene.py --textured) and render RGBA photos of
#      it with export_dataset.py (its true poses and depth stay aside, for the checks only),
#   2. COLMAP 3.8 on the photos alone: feature_extractor (one PINHOLE camera), exhaustive_matcher,
#      mapper; with LENS=opencv the photos are first warped as an OPENCV lens with distortion
#      takes them (research example lens_photos, coefficients LENS_COEFFS) and COLMAP estimates
#      an OPENCV camera, which the import undistorts; LENS=ignored warps them the same and tells
#      COLMAP the camera is a PINHOLE (the control: the lens ignored); with KNOWN_CAMERA=1 COLMAP
#      is given the true camera (Blender's intrinsics, and the lens for OPENCV) and keeps it,
#      as with a calibrated camera,
#   3. volgen import colmap, then check the poses against Blender's up to a similarity
#      (research example pose_alignment: median rotation error <= MAX_ROT degrees, median centre
#      error <= MAX_CENTRE of the cameras' spread),
#   4. volgen fit on the imported photos and on the same photos with Blender's true poses (no
#      depth either way, held-out views every 10th): the imported fit's held-out PSNR must be within
#      MARGIN_DB of the true one's,
#   5. volgen train --preset micro on the imported dataset and volgen sample from it.
#   With NERFSTUDIO=1, also: nerfstudio's own conversion of the model (tools/colmap/
#   nerfstudio_convert.py: nerfstudio 1.1.5 from PyPI without its dependencies, run by the peer
#   venv's Python, ../shared/peer/setup.sh, which has torch), `volgen import nerfstudio` of its
#   transforms.json, the same pose check, a placement scale within 2% of the COLMAP import's
#   and a fit within 1 dB of its held-out PSNR.
# Minutes (mostly the two fits), so not in `cargo test`: run it by hand, or in CI when time allows.
#
#   tools/colmap/sfm_check.sh [WORKDIR]
#
# Needs Debian's colmap (apt-get install colmap) and bpy (../shared/validators/setup.sh).
# Environment: PYTHON (the validators' venv), VOLGEN (cargo's release binary), VIEWS (40),
# SIZE (192), MAX_ROT (2), MAX_CENTRE (0.03), MARGIN_DB (4), LENS (pinhole or opencv),
# LENS_COEFFS ("-0.15 0.04 0.001 -0.0008": k1 k2 p1 p2), KNOWN_CAMERA (0 or 1), NERFSTUDIO (0
# or 1), PEER_VENV (/tmp/peer/venv).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
work="${1:-$(mktemp -d)}"
mkdir -p "$work"
PYTHON="${PYTHON:-${VALIDATORS_VENV:-$HOME/.cache/vdb-exr-validators/venv}/bin/python}"
VIEWS="${VIEWS:-40}"
SIZE="${SIZE:-192}"
MAX_ROT="${MAX_ROT:-2}"
MAX_CENTRE="${MAX_CENTRE:-0.03}"
MARGIN_DB="${MARGIN_DB:-4}"
LENS="${LENS:-pinhole}"
LENS_COEFFS="${LENS_COEFFS:--0.15 0.04 0.001 -0.0008}"
case "$LENS" in
  pinhole | ignored) camera_model=PINHOLE ;;
  opencv) camera_model=OPENCV ;;
  *) echo "LENS must be pinhole, opencv or ignored, got $LENS" >&2; exit 2 ;;
esac
export QT_QPA_PLATFORM=offscreen

(cd "$root" && cargo build --release --bin volgen && cargo build --release -p research --example pose_alignment --example lens_photos)
VOLGEN="${VOLGEN:-$root/target/release/volgen}"
ALIGN="$root/target/release/examples/pose_alignment"

echo "== scene and photos ($VIEWS views at $SIZE^2)"
"$PYTHON" "$root/tools/blender/make_test_scene.py" "$work/scene.blend" --textured
"$PYTHON" "$root/tools/blender/export_dataset.py" "$work/scene.blend" --out "$work/blender" \
  --views "$VIEWS" --size "$SIZE" --samples 16 > "$work/export.log"

photos="$work/blender/images"
if [ "$LENS" != pinhole ]; then
  echo "== photos through an OPENCV lens (k1 k2 p1 p2 = $LENS_COEFFS)"
  # shellcheck disable=SC2086
  "$root/target/release/examples/lens_photos" "$work/blender" "$work/lens_photos" $LENS_COEFFS
  photos="$work/lens_photos"
fi

known=()
mapper_known=()
if [ "${KNOWN_CAMERA:-0}" = "1" ]; then
  # Blender's intrinsics (pixel centres at +0.5 in both), and the lens when COLMAP models it.
  params=$(python3 - "$work/blender/transforms.json" <<'PY'
import json, math, sys
t = json.load(open(sys.argv[1]))
w, h = t["w"], t["h"]
fx = t.get("fl_x") or 0.5 * w / math.tan(0.5 * t["camera_angle_x"])
fy = t.get("fl_y") or fx
print(f"{fx},{fy},{t.get('cx', w / 2)},{t.get('cy', h / 2)}")
PY
)
  if [ "$camera_model" = OPENCV ]; then params="$params,$(echo "$LENS_COEFFS" | tr ' ' ',')"; fi
  known=(--ImageReader.camera_params "$params")
  mapper_known=(--Mapper.ba_refine_focal_length 0 --Mapper.ba_refine_principal_point 0 --Mapper.ba_refine_extra_params 0)
  echo "== COLMAP ($camera_model camera, known: $params)"
else
  echo "== COLMAP ($camera_model camera)"
fi
rm -rf "$work/db.db" "$work/sparse" && mkdir -p "$work/sparse"
colmap feature_extractor --database_path "$work/db.db" --image_path "$photos" \
  --ImageReader.single_camera 1 --ImageReader.camera_model "$camera_model" "${known[@]}" --SiftExtraction.use_gpu 0 > "$work/colmap.log" 2>&1
colmap exhaustive_matcher --database_path "$work/db.db" --SiftMatching.use_gpu 0 >> "$work/colmap.log" 2>&1
colmap mapper --database_path "$work/db.db" --image_path "$photos" --output_path "$work/sparse" "${mapper_known[@]}" >> "$work/colmap.log" 2>&1

echo "== import and poses"
"$VOLGEN" import colmap "$work/sparse/0" --images "$photos" --out "$work/imported"
"$ALIGN" "$work/blender" "$work/imported" "$MAX_ROT" "$MAX_CENTRE"

echo "== fits (true poses against COLMAP's, the same photos)"
python3 - "$work" <<'PY'
import json, os, sys
work = sys.argv[1]
imported = json.load(open(os.path.join(work, "imported/transforms.json")))
order = [os.path.basename(f["colmap_name"]) for f in imported["frames"]]
truth = json.load(open(os.path.join(work, "blender/transforms.json")))
by_name = {os.path.basename(f["file_path"]): f for f in truth["frames"]}
truth["frames"] = [by_name[n] for n in order]
json.dump(truth, open(os.path.join(work, "blender/registered.json"), "w"))
PY
"$VOLGEN" fit "$work/blender/registered.json" --out "$work/fit_true.safetensors" --holdout 10 --no-depth --bounds auto | tail -2
"$VOLGEN" fit "$work/imported" --out "$work/fit_imported.safetensors" --holdout 10 | tail -2
python3 - "$work" "$MARGIN_DB" <<'PY'
import json, sys
work, margin = sys.argv[1], float(sys.argv[2])
held = lambda name: json.load(open(f"{work}/{name}.fit.json"))["held_out_psnr"]
true, imported = held("fit_true"), held("fit_imported")
print(f"held-out PSNR: true poses {true:.2f} dB, COLMAP's {imported:.2f} dB")
if imported < true - margin:
    sys.exit(f"COLMAP's poses fit {true - imported:.2f} dB worse than the true ones (margin {margin} dB)")
PY

if [ "${NERFSTUDIO:-0}" = "1" ]; then
  echo "== nerfstudio's conversion of the model, imported"
  PEER_VENV="${PEER_VENV:-/tmp/peer/venv}"
  VENV="$PEER_VENV" bash "$root/../shared/peer/setup.sh" > /dev/null
  "$PEER_VENV/bin/pip" install -q --target "$work/nerfstudio_pkgs" nerfstudio==1.1.5 --no-deps
  "$PEER_VENV/bin/pip" install -q --target "$work/nerfstudio_pkgs" rich appdirs requests packaging imageio opencv-python-headless
  rm -rf "$work/nerfstudio" "$work/imported_ns" && mkdir -p "$work/nerfstudio"
  cp -r "$photos" "$work/nerfstudio/images"
  PYTHONPATH="$work/nerfstudio_pkgs" "$PEER_VENV/bin/python" "$here/nerfstudio_convert.py" "$work/sparse/0" "$work/nerfstudio"
  "$VOLGEN" import nerfstudio "$work/nerfstudio" --out "$work/imported_ns"
  "$ALIGN" "$work/blender" "$work/imported_ns" "$MAX_ROT" "$MAX_CENTRE"
  "$VOLGEN" fit "$work/imported_ns" --out "$work/fit_imported_ns.safetensors" --holdout 10 | tail -2
  python3 - "$work" <<'PY'
import json, sys
work = sys.argv[1]
scale = lambda d: json.load(open(f"{work}/{d}/transforms.json"))["volgen_import"]["scale"]
held = lambda name: json.load(open(f"{work}/{name}.fit.json"))["held_out_psnr"]
colmap, ns = scale("imported"), scale("imported_ns")
print(f"placement scale: COLMAP import {colmap:.4f}, nerfstudio import {ns:.4f}")
print(f"held-out PSNR: COLMAP import {held('fit_imported'):.2f} dB, nerfstudio import {held('fit_imported_ns'):.2f} dB")
if abs(ns / colmap - 1) > 0.02:
    sys.exit("the two imports of one reconstruction placed it differently")
if abs(held("fit_imported_ns") - held("fit_imported")) > 1.0:
    sys.exit("the two imports of one reconstruction fit more than 1 dB apart")
PY
fi

echo "== train micro and sample"
"$VOLGEN" train "$work/imported" --out "$work/run" --preset micro --iterations 40 > "$work/train.log" 2>&1
"$VOLGEN" sample "$work/run" --count 1 --out "$work/samples"
echo "sfm check passed: $work"
