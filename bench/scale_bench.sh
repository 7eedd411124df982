#!/usr/bin/env bash
# How dispmvs_colmap's planning, geometric filter and fusion scale with the
# number of images, on large synthetic workspaces with exact photometric maps
# (dispmvs_make_large_workspace: no network runs). For each size N the
# workspace is generated (not measured), then
#   dispmvs_colmap --workspace_path WS --mode plan
#   dispmvs_colmap --workspace_path WS --mode fuse
# each run under /usr/bin/time for wall time, CPU time (user + system) and
# peak resident memory, with default options (CPU time is the steadier
# figure on a busy machine). The table in OUT/scale_bench.md has per-image
# columns, so that linear time (constant per image) and bounded memory
# (falling per image) can be read off directly.
#
# Usage: bench/scale_bench.sh BUILD OUT [--sizes "200 1000 2000"]
#            [--points_per_image P] [--keep_workspaces] [--fusion_cache_mb MB]
#   BUILD  a build folder holding src/dispmvs_colmap and
#          bench/dispmvs_make_large_workspace
#   OUT    output folder: scale_bench.md, and per size the logs
#          generate_N.log, plan_N.log, fuse_N.log and their .time files.
#          Workspaces (OUT/ws_N, 2000 images at 160 x 120 are about 1.6 GB
#          once fused) are deleted after their size is measured unless
#          --keep_workspaces.
#   --fusion_cache_mb MB  passed to --mode fuse (default 1024). The run
#          report is not written (--no_report): it is not what is measured.
set -euo pipefail

# All in one function, parsed in full before it runs, and called on the
# script's last line with the exit: editing this file while a long run is
# going does not change what that run does.
main() {

  usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; }

  if [[ $# -ge 1 && ( $1 == -h || $1 == --help ) ]]; then usage; exit 0; fi
  if [[ $# -lt 2 ]]; then usage >&2; exit 2; fi
  build=$1
  out=$2
  shift 2
  sizes="200 1000 2000"
  points_per_image=100
  keep=0
  fusion_cache_mb=1024
  while [[ $# -gt 0 ]]; do
    case $1 in
      --sizes) sizes=$2; shift 2 ;;
      --points_per_image) points_per_image=$2; shift 2 ;;
      --keep_workspaces) keep=1; shift ;;
      --fusion_cache_mb) fusion_cache_mb=$2; shift 2 ;;
      *) echo "error: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
  done

  colmap=$build/src/dispmvs_colmap
  generator=$build/bench/dispmvs_make_large_workspace
  for program in "$colmap" "$generator"; do
    [[ -x $program ]] || { echo "error: $program not found: build it first" >&2; exit 1; }
  done
  for n in $sizes; do
    [[ $n =~ ^[0-9]+$ && $n -ge 2 ]] || { echo "error: --sizes: '$n' is not a count >= 2" >&2; exit 2; }
  done
  mkdir -p "$out"

  # GNU time gives peak RSS (%M, KiB); bash's time keyword gives times only.
  gnu_time=
  if [[ -x /usr/bin/time ]] && /usr/bin/time -f '%e %M %U %S' true 2>/dev/null; then
    gnu_time=/usr/bin/time
  else
    echo "note: /usr/bin/time (GNU time) not found: peak memory is not measured" >&2
  fi

  # measure TIME_FILE LOG COMMAND...: runs COMMAND with its output in LOG and
  # writes "WALL_S PEAK_KIB CPU_S" (PEAK_KIB "n/a" without GNU time) to TIME_FILE.
  # The command's failure stops the script, its log's tail shown.
  measure() {
    local time_file=$1 log=$2
    shift 2
    local status=0
    if [[ -n $gnu_time ]]; then
      "$gnu_time" -f '%e %M %U %S' -o "$time_file" "$@" >"$log" 2>&1 || status=$?
    else
      local TIMEFORMAT='%R n/a %U %S'
      { time "$@" >"$log" 2>&1 || status=$?; } 2>"$time_file.wall"
      tail -n 1 "$time_file.wall" >"$time_file"
      rm -f "$time_file.wall"
    fi
    if [[ $status -ne 0 ]]; then
      echo "error: exit status $status: $*" >&2
      tail -n 20 "$log" >&2
      exit 1
    fi
    # GNU time may put a "Command exited ..." line first; the numbers are last.
    tail -n 1 "$time_file" | awk '{ printf "%s %s %.2f\n", $1, $2, $3 + $4 }' >"$time_file.tmp"
    mv "$time_file.tmp" "$time_file"
  }

  mib() { [[ $1 == n/a ]] && echo n/a || awk -v k="$1" 'BEGIN { printf "%.1f", k / 1024 }'; }
  per_image() {  # VALUE N SCALE FORMAT: VALUE * SCALE / N
    [[ $1 == n/a || -z $1 ]] && { echo n/a; return; }
    awk -v v="$1" -v n="$2" -v s="$3" -v f="$4" 'BEGIN { printf f, v * s / n }'
  }

  # What every run pays before any work (loading LibTorch and the other
  # libraries), to subtract when reading the small sizes.
  measure "$out/startup.time" "$out/startup.log" "$colmap" --help
  read -r startup_s startup_kib startup_cpu <"$out/startup.time"

  rows=()
  for n in $sizes; do
    ws=$out/ws_$n
    rm -rf "$ws"
    echo "== $n images: generating $ws" >&2
    gen_start=$(date +%s.%N)
    "$generator" --output_path "$ws" --images "$n" --points_per_image "$points_per_image" \
      >"$out/generate_$n.log" 2>&1 || { tail -n 20 "$out/generate_$n.log" >&2; exit 1; }
    gen_seconds=$(awk -v a="$gen_start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
    ws_size=$(du -sm "$ws" | cut -f1)

    echo "== $n images: --mode plan" >&2
    measure "$out/plan_$n.time" "$out/plan_$n.log" "$colmap" --workspace_path "$ws" --mode plan
    read -r plan_s plan_kib plan_cpu <"$out/plan_$n.time"

    echo "== $n images: --mode fuse" >&2
    measure "$out/fuse_$n.time" "$out/fuse_$n.log" "$colmap" --workspace_path "$ws" --mode fuse \
      --fusion_cache_mb "$fusion_cache_mb" --no_report
    read -r fuse_s fuse_kib fuse_cpu <"$out/fuse_$n.time"
    # summary: geometric: N done, ..., 0 failed, X s
    geometric_s=$(sed -n 's/^summary: geometric: .*, \([0-9.]*\) s$/\1/p' "$out/fuse_$n.log" | tail -n 1)
    # fusion: N points from M image(s) -> PATH (+ .vis), X s[; L map loads, at most Y MB of maps held ...]
    fusion_line=$(grep '^fusion: [0-9]* points from ' "$out/fuse_$n.log" | tail -n 1 || true)
    fused_points=$(sed -n 's/^fusion: \([0-9]*\) points from .*/\1/p' <<<"$fusion_line")
    fusion_s=$(sed -n 's/.*(+ \.vis), \([0-9.]*\) s\($\|;.*\)/\1/p' <<<"$fusion_line")
    # Where fusion reads maps on demand, how often and how much it held.
    map_loads=$(sed -n 's/.*; \([0-9]*\) map loads.*/\1/p' <<<"$fusion_line")
    maps_held=$(sed -n 's/.*at most \([0-9.]*\) MB of maps held.*/\1/p' <<<"$fusion_line")
    if [[ -z $geometric_s || -z $fused_points || -z $fusion_s ]]; then
      echo "error: no geometric or fusion summary line in $out/fuse_$n.log" >&2
      exit 1
    fi

    rows+=("| $n | $plan_s | $plan_cpu | $(mib "$plan_kib") | $fuse_s | $fuse_cpu | $(mib "$fuse_kib") | $geometric_s | $fusion_s | $fused_points | ${map_loads:-n/a} | ${maps_held:-n/a} | $(per_image "$plan_cpu" "$n" 1000 %.2f) | $(per_image "$fuse_cpu" "$n" 1000 %.1f) | $(per_image "$fuse_kib" "$n" 1 %.0f) | $gen_seconds | $ws_size |")
    echo "${rows[-1]}" >&2
    [[ $keep -eq 1 ]] || rm -rf "$ws"
  done

  {
    echo "# dispmvs_colmap planning, geometric filter and fusion against the number of images"
    echo
    echo "Workspaces from \`dispmvs_make_large_workspace --images N --points_per_image $points_per_image\`"
    echo "(160 x 120 PINHOLE views on a grid of 20 per row over a textured plane, 70% overlap,"
    echo "exact photometric maps; no patch-match.cfg, so \`__auto__\` sources for every image)."
    echo "Each mode runs with default options under GNU time: wall time, CPU time (user + system,"
    echo "steadier than wall time on a busy machine) and peak RSS, the process's maximum resident"
    echo "set. Fuse = geometric filter + fusion in one process (\`--mode fuse\`); geometric s and"
    echo "fusion s are the wall times the program reports for each; fusion map loads and maps held"
    echo "are what fusion reports when it reads maps on demand (n/a: a fusion that loads every view)."
    echo
    echo "Command: \`bench/scale_bench.sh $build $out --sizes \"$sizes\"\`"
    echo
    echo "Machine: $(nproc) CPU(s), $(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | cut -d: -f2- | sed 's/^ *//' || echo unknown CPU),"
    echo "$(awk '/MemTotal/ { printf "%.1f GiB", $2 / 1048576 }' /proc/meminfo 2>/dev/null) memory, load average at the end: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo n/a); $(date -u '+%Y-%m-%d %H:%M UTC')."
    [[ -n $gnu_time ]] || echo "Peak memory: not measured (no GNU time at /usr/bin/time)."
    echo "Start-up alone (\`dispmvs_colmap --help\`): $startup_s s wall, $startup_cpu s CPU, $(mib "$startup_kib") MiB peak RSS; every"
    echo "plan and fuse figure below includes it."
    echo
    echo "| images | plan wall s | plan CPU s | plan peak RSS MiB | fuse wall s | fuse CPU s | fuse peak RSS MiB | geometric s | fusion s | fused points | fusion map loads | fusion maps held MB | plan CPU ms/image | fuse CPU ms/image | fuse peak RSS KiB/image | generate s (not measured) | workspace MiB |"
    echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    printf '%s\n' "${rows[@]}"
    echo
    echo "Linear time: CPU ms/image stays constant as N grows. Memory bounded by one reference and"
    echo "its sources: peak RSS stays flat, so KiB/image falls as 1/N; memory that holds every"
    echo "view keeps KiB/image constant instead."
  } >"$out/scale_bench.md"
  echo "wrote $out/scale_bench.md" >&2
}

main "$@"; exit $?  # one line: bash has read it whole before running main
