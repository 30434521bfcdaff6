#!/usr/bin/env bash
# The libFuzzer targets of tests/fuzz (ASan + UBSan), built in FUZZ_BUILD.
#   run.sh replay FUZZ_BUILD   every input of tests/fuzz/corpus once (make test)
#   run.sh fuzz FUZZ_BUILD     each target for FUZZ_SECONDS (default 600), two at
#                              a time (FUZZ_TARGETS: a subset); new inputs go to out/fuzz/TARGET, crashes to
#                              out/fuzz/crashes/ (make fuzz); prints execs and crashes
set -euo pipefail
mode=$1
build=$(cd "$2" && pwd)
root=$(cd "$(dirname "$0")/../.." && pwd)
corpus=$root/tests/fuzz/corpus
targets=(obj ply off gltf glb hierarchy_file rig_file pose_file frame grpc_web session_record)
# FUZZ_TARGETS="ply frame": only those (e.g. again after a fix).
if [ -n "${FUZZ_TARGETS:-}" ]; then read -r -a targets <<<"$FUZZ_TARGETS"; fi
# Limits that turn a runaway allocation or a hang into a finding, not a stall.
limits=(-rss_limit_mb=2048 -malloc_limit_mb=1024 -timeout=20 -report_slow_units=60)
export ASAN_OPTIONS=${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

case $mode in
replay)
  total=0
  for t in "${targets[@]}"; do
    files=("$corpus/$t"/*)
    [ -e "${files[0]}" ] || { echo "replay: no corpus for $t" >&2; exit 1; }
    "$build/tests/fuzz/fuzz_$t" "${limits[@]}" "${files[@]}" > "$build/replay_$t.log" 2>&1 ||
      { echo "replay: fuzz_$t failed on its corpus:" >&2; tail -n 40 "$build/replay_$t.log" >&2; exit 1; }
    echo "replay: fuzz_$t ran ${#files[@]} inputs"
    total=$((total + ${#files[@]}))
  done
  echo "replay: ${#targets[@]} targets, $total inputs, no finding"
  ;;
fuzz)
  seconds=${FUZZ_SECONDS:-600}
  out=$root/out/fuzz
  mkdir -p "$out/crashes"
  run_one() {
    local t=$1
    mkdir -p "$out/$t"
    "$build/tests/fuzz/fuzz_$t" "${limits[@]}" -max_total_time="$seconds" -print_final_stats=1 \
      -artifact_prefix="$out/crashes/$t-" "$out/$t" "$corpus/$t" > "$out/$t.log" 2>&1 || true
    local execs crashes
    execs=$(awk '/stat::number_of_executed_units/ { print $2 }' "$out/$t.log" | tail -n 1)
    crashes=$(find "$out/crashes" -name "$t-*" | wc -l)
    printf '%-16s %12s execs in %ss  %s crash/leak/timeout/oom inputs\n' "fuzz_$t" "${execs:-?}" "$seconds" "$crashes"
  }
  export -f run_one
  export out seconds corpus build
  export limits_string="${limits[*]}"
  printf '%s\n' "${targets[@]}" | xargs -P 2 -I{} bash -c 'limits=($limits_string); run_one {}'
  found=$(find "$out/crashes" -type f | wc -l)
  echo "fuzz: $found finding(s) in $out/crashes"
  [ "$found" -eq 0 ]
  ;;
*)
  echo "usage: run.sh replay|fuzz FUZZ_BUILD" >&2
  exit 2
  ;;
esac
