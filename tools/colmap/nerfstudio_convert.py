"""nerfstudio's own COLMAP -> transforms.json conversion, the last step of `ns-process-data`
(`nerfstudio.process_data.colmap_utils.colmap_to_json`: poses turned into nerfstudio's axes and
frame, `applied_transform`, `sparse_pc.ply`), run on a sparse model without installing all of
nerfstudio: the modules it imports but this function does not use (raw photo readers, colour
maps, which need matplotlib and jaxtyping) are stubbed. tools/colmap/sfm_check.sh (NERFSTUDIO=1)
installs nerfstudio 1.1.5 without dependencies, and the few it needs, on PYTHONPATH.

    python nerfstudio_convert.py SPARSE_DIR OUT_DIR
"""

import sys
import types
from pathlib import Path

for unused in ("rawpy", "newrawpy", "nerfstudio.utils.colormaps"):
    sys.modules[unused] = types.ModuleType(unused)
import nerfstudio.utils  # noqa: E402

nerfstudio.utils.colormaps = sys.modules["nerfstudio.utils.colormaps"]
from nerfstudio.process_data.colmap_utils import colmap_to_json  # noqa: E402

sparse, out = Path(sys.argv[1]), Path(sys.argv[2])
out.mkdir(parents=True, exist_ok=True)
print("nerfstudio wrote", colmap_to_json(recon_dir=sparse, output_dir=out), "frames to", out / "transforms.json")
