#!/usr/bin/env bash
# The web viewer's tests: build it (build.sh), run the unit tests (vitest:
# frame decoding and delta application, a frame captured from the server, the
# panel's pure parts), then the browser test (Debian's Chromium +
# playwright-core against a real filigree-server serving the build).
#
#   web_viewer/run-tests.sh [SERVER_BINARY [CLI_BINARY]]
#
# Defaults: build/server/filigree-server and build/client/filigree of this
# repository. Needs what build.sh needs, and chromium (CHROMIUM overrides
# /usr/bin/chromium). Nothing is skipped: a missing tool fails with its name.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/.." && pwd)
server=$(realpath "${1:-$root/build/server/filigree-server}")
cli=$(realpath "${2:-$root/build/client/filigree}")
chromium=${CHROMIUM:-/usr/bin/chromium}

fail() { echo "web_viewer: $*" >&2; exit 1; }
[ -x "$chromium" ] || fail "no browser at $chromium: apt-get install chromium (or set CHROMIUM)"
[ -x "$server" ] || fail "no filigree-server at $server (build it, or pass its path)"
[ -x "$cli" ] || fail "no filigree CLI at $cli (build it, or pass its path)"
# Captured first: `--help | grep -q` would end the server's write early (SIGPIPE), a failure under pipefail.
server_help=$("$server" --help)
grep -q -- '--http' <<<"$server_help" || fail "$server has no --http option (gRPC-Web and the viewer's files)"

bash "$here/build.sh"

cd "$here"
echo "web_viewer: unit tests"
timeout 300 npx vitest run

echo "web_viewer: browser test, server $server"
export FILIGREE_SERVER="$server" FILIGREE_CLI="$cli" CHROMIUM="$chromium"
exec timeout --kill-after=10 900 node --test --test-concurrency=1 test/browser.test.mjs test/front-door.test.mjs test/large-mesh.test.mjs test/detail.test.mjs test/history.test.mjs
