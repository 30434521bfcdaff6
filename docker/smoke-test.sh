#!/usr/bin/env bash
# Smoke test of the Filigree image (what `make test-container` runs):
# builds it with docker/build-image.sh unless it is there, runs one container on
# loopback (host network, free ports), waits for its health check, checks the
# binaries' libraries, uploads the bundled Armadillo and drives a bend through
# the CLI inside the container, fetches the web viewer over HTTP, checks that
# the server runs as non-root and persists into its data directory, and stops it
# (SIGTERM must drain and exit 0). The container is removed on any exit.
#
# Environment: FILIGREE_IMAGE (localhost/filigree:latest), CONTAINERS_CONF
# (docker/podman/containers.conf), FILIGREE_SMOKE_REBUILD=1 to run
# build-image.sh even when the image exists (the layer cache keeps it quick).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
IMAGE=${FILIGREE_IMAGE:-localhost/filigree:latest}
export CONTAINERS_CONF=${CONTAINERS_CONF:-$here/podman/containers.conf}
HEALTH_TIMEOUT=${FILIGREE_SMOKE_HEALTH_TIMEOUT:-60}

ctr=""
tmp=$(mktemp -d)
fail() {
  echo "smoke-test: FAIL: $*" >&2
  if [ -n "$ctr" ] && podman container exists "$ctr" 2>/dev/null; then
    echo "smoke-test: last lines of the container's log:" >&2
    podman logs --tail 40 "$ctr" >&2 2>&1 || true
  fi
  exit 1
}
step() { echo "smoke-test: $*"; }
cleanup() {
  if [ -n "$ctr" ] && podman container exists "$ctr" 2>/dev/null; then
    podman rm -f -v -t 5 "$ctr" >/dev/null 2>&1 || true
  fi
  rm -rf "$tmp"
}
trap cleanup EXIT

command -v podman >/dev/null || fail "podman not found"
command -v curl >/dev/null || fail "curl not found"

if [ "${FILIGREE_SMOKE_REBUILD:-0}" = 1 ] || ! podman image exists "$IMAGE"; then
  step "building $IMAGE (docker/build-image.sh)"
  FILIGREE_IMAGE=$IMAGE "$here/build-image.sh" || fail "docker/build-image.sh failed"
fi
step "image $IMAGE ($(($(podman image inspect --format '{{.Size}}' "$IMAGE") / 1024 / 1024)) MiB)"

# Two free loopback ports: let the kernel pick them.
free_port() {
  if command -v python3 >/dev/null; then
    python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
  else
    local p
    for _ in $(seq 200); do
      p=$((20000 + RANDOM % 30000))
      ss -Hltn "sport = :$p" | grep -q . || { echo "$p"; return; }
    done
    return 1
  fi
}
port=$(free_port) || fail "no free port"
hport=$(free_port) || fail "no free port"
while [ "$hport" = "$port" ]; do hport=$(free_port); done
addr=127.0.0.1:$port

hc=$(podman image inspect --format '{{if .Config.Healthcheck}}{{join .Config.Healthcheck.Test " "}}{{end}}' "$IMAGE" 2>/dev/null || true)
case "$hc" in
  *"filigree health"*) step "image HEALTHCHECK: $hc" ;;
  *) fail "the image has no 'filigree health' HEALTHCHECK (built without --format docker?): '$hc'" ;;
esac

# The image's HEALTHCHECK asks 127.0.0.1:50051; this container listens elsewhere,
# so the same check is given with its port. --health-interval disable: no
# periodic timer (podman schedules those with systemd, absent on build hosts);
# the test runs the check itself with `podman healthcheck run`.
ctr=filigree-smoke-$$
step "starting container $ctr: gRPC $addr, HTTP 127.0.0.1:$hport"
podman run -d --name "$ctr" --network=host \
  --health-cmd "filigree health --server $addr" --health-interval disable \
  "$IMAGE" \
  --listen "$addr" --http "127.0.0.1:$hport" \
  --web-root /usr/share/filigree/web --data-dir /var/lib/filigree >/dev/null ||
  fail "podman run failed"

running() { [ "$(podman inspect --format '{{.State.Running}}' "$ctr" 2>/dev/null)" = true ]; }
exec_in() { podman exec "$ctr" "$@"; }

# The health check: `filigree health --server ADDR` in the container, exit 0
# when the gRPC health service says SERVING.
health=(podman healthcheck run "$ctr")
health_desc="podman healthcheck run (filigree health --server $addr)"

step "waiting for the health check: $health_desc"
started=$SECONDS
deadline=$((SECONDS + HEALTH_TIMEOUT))
until "${health[@]}" >/dev/null 2>&1; do
  running || fail "the container exited before it became healthy (exit code $(podman inspect --format '{{.State.ExitCode}}' "$ctr"))"
  if [ "$SECONDS" -ge "$deadline" ]; then
    out=$(podman inspect --format '{{range .State.Health.Log}}{{.Output}}{{println}}{{end}}' "$ctr" 2>/dev/null |
      grep -v '^$' | tail -n 3 || true)
    fail "not healthy after ${HEALTH_TIMEOUT}s ($health_desc); the last check said:
${out:-  (nothing)}"
  fi
  sleep 1
done
step "healthy after $((SECONDS - started))s"

missing=$(exec_in sh -c 'ldd /usr/local/bin/filigree-server /usr/local/bin/filigree | grep "not found"' || true)
[ -z "$missing" ] || fail "shared libraries missing in the image: $missing"

uid=$(exec_in id -u) || fail "podman exec id -u failed"
[ "$uid" != 0 ] || fail "the server runs as root"
step "runs as uid $uid ($(exec_in id -un))"

step "upload /usr/share/filigree/armadillo.off"
# stdout holds the answer; the progress bars go to stderr.
upload=$(exec_in filigree upload /usr/share/filigree/armadillo.off --server "$addr" --name smoke-test 2>"$tmp/upload.err") ||
  fail "filigree upload failed: $(tr '\r' '\n' <"$tmp/upload.err" | tail -n 3)"
echo "$upload" | sed 's/^/  /'
field() { awk -v k="$1:" '$1 == k { print $2; exit }' <<<"$upload"; }
session=$(field session_id)
editor=$(field editor_token)
viewer=$(field viewer_token)
[ -n "$session" ] && [ -n "$editor" ] && [ -n "$viewer" ] || fail "upload printed no session_id/editor_token/viewer_token"

step "drive --motion bend --frames 30 --rate 60"
# The token through the environment (`-e NAME` copies it from here), never an argument.
drive=$(FILIGREE_TOKEN="$editor" podman exec -e FILIGREE_TOKEN "$ctr" filigree drive --server "$addr" --session "$session" \
  --motion bend --frames 30 --rate 60 --name smoke-test 2>"$tmp/drive.err") ||
  fail "filigree drive failed: $(tail -n 3 "$tmp/drive.err")"
echo "$drive" | sed 's/^/  /'
frames=$(awk '$1 == "frames_received:" { print $2 }' <<<"$drive")
answered=$(awk '$1 == "poses_answered:" { print $2 }' <<<"$drive")
[ "${frames:-0}" -gt 0 ] && [ "${answered:-0}" -gt 0 ] || fail "drive received no frames"

step "sessions"
exec_in filigree sessions --server "$addr" | sed 's/^/  /' || fail "filigree sessions failed"

step "GET http://127.0.0.1:$hport/"
page=$(curl -fsS --max-time 10 "http://127.0.0.1:$hport/?session=$session&token=$viewer") ||
  fail "the web viewer page did not load from http://127.0.0.1:$hport/"
grep -q '<title>Filigree viewer</title>' <<<"$page" || fail "http://127.0.0.1:$hport/ is not the web viewer's page"
# The bundle the page loads (vite writes src="./assets/index-HASH.js").
script=$(grep -o 'src="[^"]*assets/[^"]*\.js"' <<<"$page" | head -n 1 | cut -d'"' -f2)
script=${script#.}
if [ -n "$script" ]; then
  curl -fsS --max-time 10 -o /dev/null "http://127.0.0.1:$hport$script" || fail "viewer script $script did not load"
fi
step "viewer page ok (${#page} bytes${script:+, $script})"

records=$(exec_in sh -c 'find /var/lib/filigree -type f | wc -l')
[ "${records:-0}" -gt 0 ] || fail "nothing was written under --data-dir /var/lib/filigree"
step "data dir holds $records file(s) written by uid $uid"

step "stopping (SIGTERM drains)"
podman stop -t 30 "$ctr" >/dev/null || fail "podman stop failed"
code=$(podman inspect --format '{{.State.ExitCode}}' "$ctr")
[ "$code" = 0 ] || fail "filigree-server exited with $code after SIGTERM"
podman rm -v "$ctr" >/dev/null || fail "podman rm failed"
ctr=""
step "PASS"
