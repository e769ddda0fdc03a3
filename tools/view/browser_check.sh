#!/usr/bin/env bash
# The browser check of `volgen view` (docs/cli.md, "Explore in the browser"): headless
# Chromium with software WebGL loads the page, orbits, zooms, draws a new scene, varies from
# scale 2, downloads the VDB and the camera, and compares every screenshot with volrender's
# rendering of the same volume and with `volgen render` of the download (PSNR, printed).
# It trains a `micro` run first (seconds); a minute or two with the build done.
#
#   tools/view/browser_check.sh                  # micro, trained in the test
#   VIEW_BROWSER_RUN=out/demo/run VIEW_BROWSER_DATASET=out/demo/dataset \
#     VIEW_BROWSER_SHOTS=shots/ tools/view/browser_check.sh   # an existing run; keep screenshots
#
# Needs Debian's chromium (apt-get install chromium).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
command -v chromium >/dev/null || {
  echo "error: no chromium on PATH (apt-get install chromium)" >&2
  exit 2
}
cd "$root"
VIEW_BROWSER_CHECK=1 cargo test --test view_browser -- --nocapture
