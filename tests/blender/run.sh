#!/usr/bin/env bash
# The Blender add-on, headless (Debian's blender, --background): installs the
# add-on zip as a user would (with the Python package bundled in vendor/),
# starts filigree-server on an ephemeral loopback port, then
#   1. one Blender uploads the bunny, edits its base object, and checks the
#      detailed object against the server's frame (an independent watcher);
#   2. a second Blender process joins that session as a viewer and sees the edit;
#   3. a skinned bunny: posing its armature poses the base, the detailed mesh follows.
set -euo pipefail
server=$1 library=$2 source=$3 work=$4
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
kill -0 "$server_pid"  # the server is still up
echo "blender add-on: upload, edit, follow, join and armature passed"
