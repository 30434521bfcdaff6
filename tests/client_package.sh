#!/usr/bin/env bash
# The installed client package works for a consumer: install BUILD_DIR's
# filigree_client component into a temporary prefix, then configure and build
# client/examples (engine_loop) against that prefix only. No server is run:
# engine_loop is only started with --help, to see that it loads.
# Usage: client_package.sh BUILD_DIR SRC_DIR
set -euo pipefail
BUILD=$1
SRC=$2
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

# The libraries must be built (a no-op after a full build).
cmake --build "$BUILD" -j 2 --target filigree_client filigree_proto filigree_codec
cmake --install "$BUILD" --prefix "$TMP/prefix" --component filigree_client > "$TMP/install.log"

for f in include/filigree/client.h include/filigree/v1/filigree.pb.h include/filigree/v1/filigree.grpc.pb.h \
         lib/cmake/filigree/filigreeConfig.cmake lib/cmake/filigree/filigreeTargets.cmake; do
  [ -f "$TMP/prefix/$f" ] || { echo "FAIL: $f not installed" >&2; cat "$TMP/install.log" >&2; exit 1; }
done
# The installed CMake files must not point back into the source or build tree.
if grep -rn -e "$SRC" -e "$BUILD" "$TMP/prefix/lib/cmake/filigree" >&2; then
  echo "FAIL: the installed package refers to the source or build tree" >&2
  exit 1
fi

GEN=()
command -v ninja > /dev/null && GEN=(-G Ninja)
cmake -S "$SRC/client/examples" -B "$TMP/examples" "${GEN[@]}" -DCMAKE_BUILD_TYPE=Release \
      -DCMAKE_PREFIX_PATH="$TMP/prefix"
cmake --build "$TMP/examples" -j 2
[ -x "$TMP/examples/engine_loop" ] || { echo "FAIL: engine_loop was not built" >&2; exit 1; }
"$TMP/examples/engine_loop" --help > "$TMP/help.txt"
grep -q "usage: engine_loop" "$TMP/help.txt" || { echo "FAIL: engine_loop --help: $(cat "$TMP/help.txt")" >&2; exit 1; }
echo "client_package: engine_loop built against the installed package in $TMP/prefix"
