#!/usr/bin/env bash
# The installed client package works for a consumer: install BUILD_DIR's
# filigree_client component into a temporary prefix, then configure and build
# client/examples (engine_loop, and engine_loop_c on the C API) against that
# prefix only, and engine_loop_c once more with a bare `cc` and pkg-config.
# engine_loop is only started with --help, to see that it loads; both builds
# of engine_loop_c drive a filigree-server started here (127.0.0.1, an
# ephemeral port) through the installed libfiligree.so.
# Usage: client_package.sh BUILD_DIR SRC_DIR
set -euo pipefail
BUILD=$1
SRC=$2
TMP=$(mktemp -d)
SERVER_PID=
cleanup() {
  if [ -n "$SERVER_PID" ]; then kill "$SERVER_PID" 2> /dev/null || true; wait "$SERVER_PID" 2> /dev/null || true; fi
  rm -rf "$TMP"
}
trap cleanup EXIT

# The libraries and the server must be built (a no-op after a full build).
cmake --build "$BUILD" -j 2 --target filigree_client filigree_proto filigree_codec filigree_c filigree-server
cmake --install "$BUILD" --prefix "$TMP/prefix" --component filigree_client > "$TMP/install.log"

for f in include/filigree/client.h include/filigree/v1/filigree.pb.h include/filigree/v1/filigree.grpc.pb.h \
         include/filigree/filigree.h \
         lib/cmake/filigree/filigreeConfig.cmake lib/cmake/filigree/filigreeTargets.cmake; do
  [ -f "$TMP/prefix/$f" ] || { echo "FAIL: $f not installed" >&2; cat "$TMP/install.log" >&2; exit 1; }
done
# The C API: libfiligree.so (its name link, soname and file) and filigree.pc.
PC=$(find "$TMP/prefix" -name filigree.pc -path '*/pkgconfig/*' | head -n 1)
[ -n "$PC" ] || { echo "FAIL: filigree.pc not installed" >&2; cat "$TMP/install.log" >&2; exit 1; }
LIBDIR=$(dirname "$(dirname "$PC")")
for f in libfiligree.so libfiligree.so.0; do
  [ -e "$LIBDIR/$f" ] || { echo "FAIL: $LIBDIR/$f not installed" >&2; cat "$TMP/install.log" >&2; exit 1; }
done
# The installed CMake and pkg-config files must not point back into the source or build tree.
if grep -rn -e "$SRC" -e "$BUILD" "$TMP/prefix/lib/cmake/filigree" "$PC" >&2; then
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
[ -x "$TMP/examples/engine_loop_c" ] || { echo "FAIL: engine_loop_c was not built" >&2; exit 1; }

# engine_loop_c again, with nothing but a C compiler and pkg-config (-lm: the
# example's own sin/cos).
export PKG_CONFIG_PATH="$(dirname "$PC")"
# shellcheck disable=SC2046 # pkg-config's flags are meant to split
cc -std=c99 -Wall -Wextra -Werror -pedantic "$SRC/client/examples/engine_loop_c.c" -o "$TMP/engine_loop_c_pc" \
   $(pkg-config --cflags --libs filigree) -lm
"$TMP/examples/engine_loop_c" --help > "$TMP/help_c.txt"
grep -q "usage: engine_loop_c" "$TMP/help_c.txt" || { echo "FAIL: engine_loop_c --help: $(cat "$TMP/help_c.txt")" >&2; exit 1; }

# A server to drive: filigree-server prints "listening on HOST:PORT" once it listens.
mkdir "$TMP/data"
"$BUILD/server/filigree-server" --listen 127.0.0.1:0 --log-level warn --data-dir "$TMP/data" \
  > "$TMP/server.out" 2> "$TMP/server.err" &
SERVER_PID=$!
ADDRESS=
for _ in $(seq 300); do
  ADDRESS=$(sed -n 's/^listening on \(.*\)$/\1/p' "$TMP/server.out" | head -n 1)
  [ -n "$ADDRESS" ] && break
  kill -0 "$SERVER_PID" 2> /dev/null || break
  sleep 0.1
done
[ -n "$ADDRESS" ] || { echo "FAIL: filigree-server did not start: $(cat "$TMP/server.err")" >&2; exit 1; }

# Both builds of engine_loop_c and the C++ engine_loop upload
# tests/data/bunny_small.obj, drive 30 poses (the same flags) and must
# receive frames. The pkg-config build finds libfiligree.so through
# LD_LIBRARY_PATH (the CMake builds have it in their RPATH).
for exe in "$TMP/examples/engine_loop_c" "$TMP/engine_loop_c_pc" "$TMP/examples/engine_loop"; do
  if ! LD_LIBRARY_PATH="$LIBDIR" timeout 120 "$exe" --server "$ADDRESS" --mesh "$SRC/tests/data/bunny_small.obj" \
         --frames 30 --rate 60 > "$TMP/run.txt" 2>&1; then
    echo "FAIL: $exe: $(cat "$TMP/run.txt")" >&2
    exit 1
  fi
  grep -E "^frames received +[1-9]" "$TMP/run.txt" > /dev/null || { echo "FAIL: $exe: $(cat "$TMP/run.txt")" >&2; exit 1; }
  # It must have loaded the installed library, not the build tree's.
  if LD_LIBRARY_PATH="$LIBDIR" ldd "$exe" | grep -q "$BUILD"; then
    echo "FAIL: $exe loads libfiligree.so from the build tree" >&2
    exit 1
  fi
  sed "s|^|  $(basename "$exe"): |" "$TMP/run.txt"
done
echo "client_package: engine_loop and engine_loop_c built against the installed package in $TMP/prefix"
