#!/usr/bin/env bash
# The Blender add-on, headless (Debian's blender, --background): installs the
# add-on zip as a user would (with the Python package bundled in vendor/),
# starts filigree-server on an ephemeral loopback port, then
#   1. one Blender uploads the bunny, edits its base object, and checks the
#      detailed object against the server's frame (an independent watcher);
#   2. a second Blender process joins that session as a viewer and sees the edit;
#   3. a skinned bunny: posing its armature poses the base, the detailed mesh follows;
#   4. undo: two gestures from edit mode, the session's undo and redo from
#      Blender (the base follows), an undo that keeps another's work,
#      Blender's own undo, who is here;
#   5. that session's history exported by `filigree export-history` (the CLI)
#      and imported into Blender: a frame per entry, each the entry's state;
#   6. Ctrl+Z / Ctrl+Shift+Z pressed in Blender's window reach the add-on.
set -euo pipefail
server=$1 library=$2 source=$3 work=$4 cli=$5
rm -rf "$work"
mkdir -p "$work/home" "$work/data"

# The add-on zip: filigree_blender/ with the filigree package in vendor/.
/usr/bin/python3 "$source/client/blender/make_addon_zip.py" "$work/filigree_blender.zip"

# The server prints "listening on ADDRESS" once it listens: read that line.
exec 3< <(exec "$server" --listen 127.0.0.1:0 --data-dir "$work/data" --log-level warn 2>"$work/server.err")
server_pid=$!
trap 'kill $server_pid 2>/dev/null || true' EXIT
read -r line <&3
address=${line##* }
[[ $line == "listening on "* ]] || { echo "server did not start: $line" >&2; cat "$work/server.err" >&2; exit 1; }

run_blender() {
  # HOME: the add-on installs into this test's own Blender user folder.
  HOME="$work/home" FILIGREE_LIBRARY="$library" PYTHONDONTWRITEBYTECODE=1 timeout 300 \
    blender --background --factory-startup --python-exit-code 1 \
    --python "$source/tests/blender/addon_test.py" -- "$@"
}
run_blender upload "$address" "$work" "$work/filigree_blender.zip" "$source/tests/data/bunny_small.obj"
run_blender join "$address" "$work" "$work/filigree_blender.zip" "$source/tests/data/bunny_small.obj"
run_blender armature "$address" "$work" "$work/filigree_blender.zip" "$source/tests/data/bunny_small.obj"
run_blender undo "$address" "$work" "$work/filigree_blender.zip" "$source/tests/data/bunny_small.obj"
read -r session viewer_token < <(/usr/bin/python3 -c \
  'import json, sys; s = json.load(open(sys.argv[1])); print(s["session"], s["viewer_token"])' "$work/undo_state.json")
FILIGREE_TOKEN=$viewer_token "$cli" export-history "$session" --server "$address" -o "$work/history.glb" \
  > "$work/export.out"
run_blender export "$address" "$work" "$work/filigree_blender.zip" "$source/tests/data/bunny_small.obj"

# 6. Ctrl+Z and Ctrl+Shift+Z pressed in Blender's own window (under Xvfb:
# scripts/install-deps.sh installs xvfb and xauth; events simulated), so
# Blender's keymaps decide. Its own user folder, without the splash.
mkdir -p "$work/ui_home"
HOME="$work/ui_home" blender --background --factory-startup --python-expr "import bpy; \
p = bpy.context.preferences; p.view.show_splash = False; p.use_preferences_save = False; bpy.ops.wm.save_userpref()" \
  > /dev/null
HOME="$work/ui_home" FILIGREE_LIBRARY="$library" PYTHONDONTWRITEBYTECODE=1 timeout 300 \
  xvfb-run -a -s "-screen 0 1280x800x24" blender --enable-event-simulate \
  --python "$source/tests/blender/keys_test.py" -- "$address" "$work/filigree_blender.zip" \
  "$source/tests/data/bunny_small.obj" "$work/keys.result"
[[ $(head -n 1 "$work/keys.result" 2>/dev/null) == ok ]] || { echo "keys failed:" >&2; cat "$work/keys.result" >&2; exit 1; }
kill -0 "$server_pid"  # the server is still up
echo "blender add-on: upload, edit, follow, join, armature, undo, export and keys passed"
