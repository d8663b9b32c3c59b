#!/usr/bin/env bash
# Post the example frame (3 views of 640x480: colour JPEG + 16-bit depth PNG in mm) to a running service.
#   examples/curl.sh                      # detector mode, http://localhost:8000
#   examples/curl.sh scene_boxes.json     # reference-box mode: the annotated boxes of the 2 persons with a 3D pose
# truth.json holds those 2 persons' joints. Each view also shows 2 persons MVOR boxes without a pose (too few
# joints visible), and detector mode answers them too, so it returns more persons than truth.json lists.
#   URL=http://host:8000 ORPOSE_TOKEN=secret examples/curl.sh
set -euo pipefail
cd "$(dirname "$0")/frame"
SCENE="${1:-scene.json}"
URL="${URL:-http://localhost:8000}"
AUTH=()
if [[ -n "${ORPOSE_TOKEN:-}" ]]; then AUTH=(-H "Authorization: Bearer ${ORPOSE_TOKEN}"); fi
curl --fail-with-body -sS "${AUTH[@]}" "${URL}/scenes" \
    -F "scene=<${SCENE};type=application/json" \
    -F color_0=@color_0.jpg -F depth_0=@depth_0.png \
    -F color_1=@color_1.jpg -F depth_1=@depth_1.png \
    -F color_2=@color_2.jpg -F depth_2=@depth_2.png
echo
