#!/usr/bin/env bash
# Keeps filigree-server running with a demo session for a person: the
# Armadillo uploaded once (the session survives restarts in out/serve/), the
# viewer on http://127.0.0.1:8080. Ctrl-C stops it (exit 0).
set -euo pipefail
BUILD=${1:-build}
cd "$(dirname "$0")/.."
OUT=out/serve
mkdir -p "$OUT"
SERVER_OUT="$OUT/server.out"
"$BUILD/server/filigree-server" --listen 127.0.0.1:50051 --http 127.0.0.1:8080 --data-dir "$OUT/data" \
  > "$SERVER_OUT" 2> "$OUT/server.log" &
SERVER_PID=$!
trap 'kill -TERM $SERVER_PID 2>/dev/null; wait $SERVER_PID' INT TERM EXIT
for _ in $(seq 200); do grep -q "http on" "$SERVER_OUT" && break; sleep 0.05; done
grep -q "http on" "$SERVER_OUT" || { echo "filigree-server did not start:"; cat "$OUT/server.log"; exit 1; }
if [ ! -s "$OUT/session.txt" ] || ! grep -q "$(sed -n 's/^session_id: //p' "$OUT/session.txt")" <("$BUILD/client/filigree" sessions --server 127.0.0.1:50051); then
  "$BUILD/client/filigree" upload data/armadillo.off --server 127.0.0.1:50051 --name demo --threshold 1000000 > "$OUT/session.txt"
fi
SESSION=$(sed -n 's/^session_id: //p' "$OUT/session.txt")
EDITOR=$(sed -n 's/^editor_token: //p' "$OUT/session.txt")
VIEWER=$(sed -n 's/^viewer_token: //p' "$OUT/session.txt")
echo "viewer:      http://127.0.0.1:8080/?session=$SESSION&token=$VIEWER"
echo "editor view: http://127.0.0.1:8080/?session=$SESSION&token=$EDITOR   (drag handles, change T)"
echo "drive it:    FILIGREE_TOKEN=$EDITOR $BUILD/client/filigree drive --session $SESSION --motion bend --rate 30 --frames 600"
echo "Ctrl-C stops the server."
wait $SERVER_PID
