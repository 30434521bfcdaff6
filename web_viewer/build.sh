#!/usr/bin/env bash
# Builds the web viewer into web_viewer/dist (what `filigree-server --http`
# serves by default): installs the pinned npm packages of package-lock.json
# (npm ci) when node_modules is missing or older than the lock file, then
# generates the client code from ../proto, type-checks and bundles.
# Needs Node.js >= 18 with npm, and protoc (Debian: protobuf-compiler).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
fail() { echo "web_viewer: $*" >&2; exit 1; }

for tool in node npm protoc; do
  command -v "$tool" >/dev/null || fail "$tool not found (Debian: apt-get install nodejs npm protobuf-compiler)"
done
major=$(node -p 'process.versions.node.split(".")[0]')
[ "$major" -ge 18 ] || fail "Node.js $(node --version) is too old, 18 or newer is needed"

cd "$here"
# npm ci writes node_modules/.package-lock.json; a newer package-lock.json
# means the pinned packages changed since the last install.
if [ ! -f node_modules/.package-lock.json ] || [ package-lock.json -nt node_modules/.package-lock.json ]; then
  echo "web_viewer: npm ci"
  # No install script is needed: esbuild's and rollup's binaries come as
  # optional dependency packages, draco3d is WebAssembly, the browser is Debian's.
  timeout 600 npm ci --ignore-scripts --no-audit --no-fund
fi

echo "web_viewer: build ($(node --version))"
timeout 300 npm run build
