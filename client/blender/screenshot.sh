#!/usr/bin/env bash
# docs/blender_addon.png: Blender's own window under Xvfb (apt-get install
# xvfb xauth) with the add-on on a live session. Usage: screenshot.sh BUILD_DIR
set -euo pipefail
build=${1:-build}
source=$(cd "$(dirname "$0")/../.." && pwd)
work=$(mktemp -d)
trap 'kill ${server_pid:-0} 2>/dev/null || true; rm -rf "$work"' EXIT
/usr/bin/python3 "$source/client/blender/make_addon_zip.py" "$work/filigree_blender.zip"
exec 3< <(exec "$build/server/filigree-server" --listen 127.0.0.1:0 --data-dir "$work/data" --log-level warn 2>/dev/null)
server_pid=$!
read -r line <&3
# Preferences without the first-run splash (a UI run reads the user's, so no --factory-startup).
HOME="$work" blender --background --factory-startup --python-expr \
  "import bpy; bpy.context.preferences.view.show_splash = False; bpy.ops.wm.save_userpref()" > /dev/null
HOME="$work" FILIGREE_LIBRARY="$source/$build/client/lib/libfiligree.so" \
  xvfb-run -a -s "-screen 0 1600x900x24" blender --enable-event-simulate \
  --python "$source/client/blender/screenshot.py" -- "${line##* }" "$work/filigree_blender.zip" \
  "$source/tests/data/bunny_small.obj" "$source/docs/blender_addon.png"
