#!/usr/bin/env bash
# The demo: preprocess the bundled Armadillo (Stanford scan, CGAL data, CC0),
# inspect the hierarchy, export the base mesh and check that recovering every
# node gives back the original mesh.
set -euo pipefail
BUILD=${1:-build}
cd "$(dirname "$0")/.."
OUT=out/demo
mkdir -p "$OUT"
FILIGREE="$BUILD/client/filigree"

echo "== preprocess data/armadillo.off"
"$FILIGREE" preprocess data/armadillo.off -o "$OUT/armadillo.fgh"
echo
echo "== inspect"
"$FILIGREE" inspect "$OUT/armadillo.fgh"
echo
echo "== export"
"$FILIGREE" export-base "$OUT/armadillo.fgh" -o "$OUT/armadillo_base.glb" --ids "$OUT/armadillo_base_ids.txt"
"$FILIGREE" export-base "$OUT/armadillo.fgh" -o "$OUT/armadillo_base.obj"
"$FILIGREE" export-cut "$OUT/armadillo.fgh" --recover 10000 -o "$OUT/armadillo_cut10000.obj"
"$FILIGREE" export-cut "$OUT/armadillo.fgh" --recover all -o "$OUT/armadillo_full.ply"
"$FILIGREE" animate "$OUT/armadillo.fgh" --motion bend --frames 30 -o "$OUT/armadillo_bend.glb"

echo
echo "== service: filigree-server on 127.0.0.1, upload, drive a bend at 60 Hz, record it"
SERVER_OUT="$OUT/server.out"
rm -rf "$OUT/server-data"
"$BUILD/server/filigree-server" --listen 127.0.0.1:0 --http 127.0.0.1:0 --data-dir "$OUT/server-data" \
  > "$SERVER_OUT" 2> "$OUT/server.log" &
SERVER_PID=$!
trap 'kill $SERVER_PID 2>/dev/null || true' EXIT
# The server prints "listening on HOST:PORT" once it accepts calls.
for _ in $(seq 200); do grep -q "http on" "$SERVER_OUT" && break; sleep 0.05; done
ADDRESS=$(sed -n 's/^listening on //p' "$SERVER_OUT")
HTTP=$(sed -n 's/^http on //p' "$SERVER_OUT")
[ -n "$ADDRESS" ] || { echo "filigree-server did not start:"; cat "$OUT/server.log"; exit 1; }
"$FILIGREE" upload data/armadillo.off --server "$ADDRESS" --name demo > "$OUT/session.txt"
cat "$OUT/session.txt"
SESSION=$(sed -n 's/^session_id: //p' "$OUT/session.txt")
EDITOR=$(sed -n 's/^editor_token: //p' "$OUT/session.txt")
VIEWER=$(sed -n 's/^viewer_token: //p' "$OUT/session.txt")
echo "viewer (while the server runs): http://$HTTP/?session=$SESSION&token=$VIEWER"
echo "editor view (handles, threshold): http://$HTTP/?session=$SESSION&token=$EDITOR"
echo "  (in the page: Overlays → Regions and set T = 1000000 to see the regions; press on the mesh and drag to pull it)"
FILIGREE_TOKEN="$EDITOR" "$FILIGREE" drive --server "$ADDRESS" --session "$SESSION" --motion bend --frames 120 --rate 60 \
  -o "$OUT/armadillo_driven.glb"

echo
echo "== skeletal: rig the Armadillo (a chain of joints, bend and twist clips), upload the skinned GLB, play a clip on the server"
"$FILIGREE" rig data/armadillo.off -o "$OUT/armadillo_rigged.glb" --joints 6
"$FILIGREE" preprocess "$OUT/armadillo_rigged.glb" -o "$OUT/armadillo_rigged.fgh" | grep -E '^(rig|base) '
"$FILIGREE" animate "$OUT/armadillo_rigged.fgh" --clip twist --frames 30 -o "$OUT/armadillo_clip_twist.glb"
"$FILIGREE" upload "$OUT/armadillo_rigged.glb" --server "$ADDRESS" --name demo-rig > "$OUT/rig_session.txt"
grep -E '^(session_id|joints|clips)' "$OUT/rig_session.txt"
RIG_SESSION=$(sed -n 's/^session_id: //p' "$OUT/rig_session.txt")
RIG_EDITOR=$(sed -n 's/^editor_token: //p' "$OUT/rig_session.txt")
FILIGREE_TOKEN="$RIG_EDITOR" "$FILIGREE" play --server "$ADDRESS" --session "$RIG_SESSION" --clip bend --fps 30 \
  -o "$OUT/armadillo_clip_bend.glb" | tail -n 2
kill -TERM $SERVER_PID
wait $SERVER_PID
trap - EXIT
echo "server stopped (exit 0); its log is $OUT/server.log. To keep one running with this session: make serve"

echo
echo "Demo outputs are in $OUT/: base mesh (GLB/OBJ), a partial cut, the fully recovered mesh,"
echo "a local bend animation (armadillo_bend.glb), the frames received from the server (armadillo_driven.glb)"
echo "and the skinned Armadillo's bend clip played by the server (armadillo_clip_bend.glb)."
