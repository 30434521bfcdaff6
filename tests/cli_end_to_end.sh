#!/usr/bin/env bash
# The `filigree` CLI end to end on a shipped mesh, and its errors on bad input.
# Usage: cli_end_to_end.sh DATA_DIR OUT_DIR   (FILIGREE=path/to/filigree)
set -euo pipefail
DATA=$1
OUT=$2
rm -rf "$OUT" && mkdir -p "$OUT"
fail() { echo "FAIL: $*" >&2; exit 1; }

# Preprocess, inspect, export.
"$FILIGREE" preprocess "$DATA/bunny_small.obj" -o "$OUT/bunny.fgh" --base-vertices 150 --threads 2 > "$OUT/pre.txt"
grep -q "base       150 vertices" "$OUT/pre.txt" || fail "preprocess summary: $(cat "$OUT/pre.txt")"
grep -q "peak" "$OUT/pre.txt" || fail "no peak memory in summary"
"$FILIGREE" inspect "$OUT/bunny.fgh" > "$OUT/inspect.txt"
grep -q "original      1839 vertices, 3674 faces" "$OUT/inspect.txt" || fail "inspect: $(cat "$OUT/inspect.txt")"
grep -q "bytes/vertex in memory (.*), .* bytes/vertex on disk" "$OUT/inspect.txt" || fail "inspect size: $(cat "$OUT/inspect.txt")"
grep -q "node graph    derived and checked in .* ms; .* bytes/vertex more" "$OUT/inspect.txt" || fail "inspect graph: $(cat "$OUT/inspect.txt")"
"$FILIGREE" export-base "$OUT/bunny.fgh" -o "$OUT/base.obj" --ids "$OUT/ids.txt" > /dev/null
[ "$(wc -l < "$OUT/ids.txt")" -eq 150 ] || fail "ids file does not have 150 lines"
[ "$(grep -c '^v ' "$OUT/base.obj")" -eq 150 ] || fail "base.obj does not have 150 vertices"
"$FILIGREE" export-base "$OUT/bunny.fgh" -o "$OUT/base.glb" > /dev/null
"$FILIGREE" export-base "$OUT/bunny.fgh" -o "$OUT/base.ply" > /dev/null
"$FILIGREE" export-cut "$OUT/bunny.fgh" --recover 500 -o "$OUT/cut500.obj" > "$OUT/cut.txt"
grep -q "650 vertices" "$OUT/cut.txt" || fail "cut of 500 nodes: $(cat "$OUT/cut.txt")"
"$FILIGREE" export-cut "$OUT/bunny.fgh" --recover all -o "$OUT/full.obj" > /dev/null
[ "$(grep -c '^f ' "$OUT/full.obj")" -eq 3674 ] || fail "full cut does not have the original 3674 faces"

# Deform: the rest pose (the exported base mesh) gives back the rest mesh.
"$FILIGREE" deform "$OUT/bunny.fgh" --pose "$OUT/base.obj" -o "$OUT/rest.obj" --stats > "$OUT/stats.json"
grep -q '"cut_nodes"' "$OUT/stats.json" || fail "deform --stats: $(cat "$OUT/stats.json")"
"$FILIGREE" compare "$OUT/rest.obj" "$OUT/full.obj" > "$OUT/compare.json"
python3 - "$OUT/compare.json" <<'PY' || fail "rest pose did not give the rest mesh: $(cat "$OUT/compare.json")"
import json, sys
m = json.load(open(sys.argv[1]))
sys.exit(0 if m["max_distance"] < 1e-6 and m["vertex_count"] == 1839 else 1)
PY
# A bent pose, whole-mesh optimisation vs direct recovery: both valid, different.
"$FILIGREE" animate "$OUT/bunny.fgh" --motion bend --frames 3 -o "$OUT/bend.obj" --threshold inf > /dev/null
[ -f "$OUT/bend_0002.obj" ] || fail "animate did not write a file per frame"
"$FILIGREE" animate "$OUT/bunny.fgh" --motion twist --frames 4 -o "$OUT/twist.glb" > "$OUT/animate.txt"
grep -q "4 frames of 'twist'" "$OUT/animate.txt" || fail "animate: $(cat "$OUT/animate.txt")"
"$FILIGREE" compare "$OUT/twist.glb" "$OUT/full.obj" > /dev/null || fail "the animated GLB does not read back"

# Errors: a clear message and exit status 1, never a crash.
expect_error() {  # expect_error PATTERN COMMAND...
  local pattern=$1; shift
  set +e
  "$@" > "$OUT/err.out" 2> "$OUT/err.txt"
  local status=$?
  set -e
  [ $status -eq 1 ] || fail "expected exit 1 from '$*', got $status: $(cat "$OUT/err.txt")"
  grep -q "$pattern" "$OUT/err.txt" || fail "expected '$pattern' from '$*', got: $(cat "$OUT/err.txt")"
}
printf 'v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n' > "$OUT/nan.obj"
expect_error "NaN" "$FILIGREE" preprocess "$OUT/nan.obj" -o "$OUT/x.fgh"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n' > "$OUT/index.obj"
expect_error "out of range" "$FILIGREE" preprocess "$OUT/index.obj" -o "$OUT/x.fgh"
head -c 1000 "$OUT/bunny.fgh" > "$OUT/truncated.fgh"
expect_error "truncated" "$FILIGREE" inspect "$OUT/truncated.fgh"
cp "$OUT/bunny.fgh" "$OUT/v1.fgh"  # the same file claiming format version 1
printf '\001\000\000\000' | dd of="$OUT/v1.fgh" bs=1 seek=8 conv=notrunc status=none
expect_error "format version 1.*rebuild it" "$FILIGREE" inspect "$OUT/v1.fgh"
expect_error "node count or 'all'" "$FILIGREE" export-cut "$OUT/bunny.fgh" --recover lots -o "$OUT/x.obj"
expect_error "only" "$FILIGREE" export-cut "$OUT/bunny.fgh" --recover 999999 -o "$OUT/x.obj"
head -c 100 /dev/zero > "$OUT/short.pose"
expect_error "needs 12" "$FILIGREE" deform "$OUT/bunny.fgh" --pose "$OUT/short.pose" -o "$OUT/x.obj"
expect_error "threshold" "$FILIGREE" deform "$OUT/bunny.fgh" --pose "$OUT/base.obj" --threshold fast -o "$OUT/x.obj"
expect_error "terms takes edge or vertex, not 'both'" "$FILIGREE" deform "$OUT/bunny.fgh" --pose "$OUT/base.obj" --threshold inf --terms both -o "$OUT/x.obj"
"$FILIGREE" deform "$OUT/bunny.fgh" --pose "$OUT/base.obj" --threshold inf --terms vertex --iterations 2 -o "$OUT/vertex_terms.obj" > /dev/null
expect_error "motion" "$FILIGREE" animate "$OUT/bunny.fgh" --motion dance -o "$OUT/x.glb"
# Skinned input: rig → preprocess (writes H.rig) → animate a clip; a rig that is not one is refused.
"$FILIGREE" rig "$DATA/bunny_small.obj" -o "$OUT/rigged.glb" --joints 3 > /dev/null
# inspect of an upload lists its joints and clips (what `play --clip` names).
"$FILIGREE" inspect "$OUT/rigged.glb" > "$OUT/inspect_glb.txt"
grep -q "skeleton      3 joints" "$OUT/inspect_glb.txt" || fail "inspect glb: $(cat "$OUT/inspect_glb.txt")"
grep -q "clip        bend, 2.000 s" "$OUT/inspect_glb.txt" || fail "inspect glb clips: $(cat "$OUT/inspect_glb.txt")"
"$FILIGREE" preprocess "$OUT/rigged.glb" -o "$OUT/rigged.fgh" > "$OUT/rigged.txt"
[ -f "$OUT/rigged.rig" ] || fail "preprocess of a skinned glTF wrote no .rig: $(cat "$OUT/rigged.txt")"
"$FILIGREE" animate "$OUT/rigged.fgh" --clip bend --frames 4 -o "$OUT/clip.glb" > "$OUT/clip.txt"
grep -q "4 frames of 'clip bend'" "$OUT/clip.txt" || fail "animate --clip: $(cat "$OUT/clip.txt")"
expect_error "no clip 'dance' (the rig has: bend, twist)" "$FILIGREE" animate "$OUT/rigged.fgh" --clip dance -o "$OUT/x.glb"
expect_error "does not exist: --clip needs the rig" "$FILIGREE" animate "$OUT/bunny.fgh" --clip bend -o "$OUT/x.glb"
head -c 50 "$OUT/rigged.rig" > "$OUT/short.rig"
expect_error "short.rig" "$FILIGREE" animate "$OUT/rigged.fgh" --clip bend --rig "$OUT/short.rig" -o "$OUT/x.glb"
printf 'not a mesh' > "$OUT/garbage.off"
expect_error "garbage.off" "$FILIGREE" preprocess "$OUT/garbage.off" -o "$OUT/x.fgh"
echo "cli end to end: ok"
