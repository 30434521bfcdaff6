#!/usr/bin/env bash
# The Node.js client end to end: a grpc-js + draco3d client written against
# proto/filigree/v1/filigree.proto alone, against a real filigree-server.
#
#   tests/node_client/run.sh SERVER_BINARY REPO_ROOT
#
# Installs the pinned packages of package-lock.json (npm ci) when node_modules
# is missing or older than the lock file, then runs `node --test` (Node >= 18).
set -euo pipefail

if [ $# -ne 2 ]; then
  echo "usage: $0 SERVER_BINARY REPO_ROOT" >&2
  exit 2
fi
server=$(realpath "$1")
root=$(realpath "$2")
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)

for tool in node npm; do
  if ! command -v "$tool" >/dev/null; then
    echo "node_client: $tool not found (Debian: apt-get install nodejs npm)" >&2
    exit 1
  fi
done
major=$(node -p 'process.versions.node.split(".")[0]')
if [ "$major" -lt 18 ]; then
  echo "node_client: Node.js $(node --version) is too old, 18 or newer is needed" >&2
  exit 1
fi

cd "$here"
# npm ci writes node_modules/.package-lock.json; a newer package-lock.json
# means the pinned packages changed since the last install.
if [ ! -f node_modules/.package-lock.json ] || [ package-lock.json -nt node_modules/.package-lock.json ]; then
  echo "node_client: npm ci"
  # No package here needs an install script (draco3d is WebAssembly).
  timeout 600 npm ci --ignore-scripts --no-audit --no-fund
fi

echo "node_client: $(node --version), server $server"
export FILIGREE_SERVER="$server" FILIGREE_ROOT="$root"
exec timeout --kill-after=10 420 node --test e2e.test.mjs
