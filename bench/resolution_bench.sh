#!/usr/bin/env bash
# Time and memory of the dense step against the image size, with and without
# the large-block cache (model/large_block_cache.h) and the fine stage in
# bands (--band_megapixels), alternated.
#
# For every size WxH (in order) and every cache budget and band size
# (alternated within the size, so all see the same state of the machine):
#   network  dispmvs_bench --sizes WxH --sources 4 --config small_v2
#            --precision P --warmup 1 --reps R --memory 0 --block_cache_mb C
#            --band_megapixels B:
#            seconds per view of the forward pass (median), per megapixel,
#            and the shares of the encoders and the GRU update
#   program  (with --program) one generated workspace per size
#            (dispmvs_make_large_workspace --images 5 at WxH: a textured plane
#            seen from a row of cameras, written in seconds even at 24
#            megapixels, not measured; its first image the reference, the
#            other four its sources), then
#            dispmvs_colmap --mode photometric --image_list (its first image)
#            --overwrite --tensor_cache_mb C --band_megapixels B under GNU
#            time: the view's
#            seconds as the program logs them (network + refinement +
#            writing), per megapixel, and the process's peak resident set
#            and whether its maps are bit for bit those of the size's first
#            variant
#   memory   (with --memory) dispmvs_bench's peak memory of a pass (live
#            tensors, measured with glibc's mappings, so once per size)
#
# Usage: bench/resolution_bench.sh BUILD OUT [--sizes "640x480 1600x1200"]
#            [--cache_mb "512 0"] [--band_mp "4"] [--precision auto] [--reps 1]
#            [--program] [--memory] [--max_uncached_mp MP]
#   BUILD  a build folder with bench/dispmvs_bench (and, for --program,
#          src/dispmvs_colmap and bench/dispmvs_make_large_workspace)
#   OUT    output folder: resolution_bench.md (the table), the logs,
#          resolution_bench.tsv (one line per size and variant) and, where
#          python3 is, resolution_bench.svg (bench/plot_resolution.py)
#   --max_uncached_mp MP  sizes above MP megapixels run with the cache only
#          (without it they take minutes a pass) (default 5)
set -euo pipefail

main() {
  usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; }
  if [[ $# -ge 1 && ( $1 == -h || $1 == --help ) ]]; then usage; exit 0; fi
  if [[ $# -lt 2 ]]; then usage >&2; exit 2; fi
  build=$1
  out=$2
  shift 2
  sizes="640x480 1600x1200 2000x1500 2400x1800 2835x2128 4000x3000 6000x4000"
  cache_mb="512 0"
  band_mp=4
  precision=auto
  reps=1
  program=0
  memory=0
  max_uncached_mp=5
  while [[ $# -gt 0 ]]; do
    case $1 in
      --sizes) sizes=$2; shift 2 ;;
      --cache_mb) cache_mb=$2; shift 2 ;;
      --band_mp) band_mp=$2; shift 2 ;;
      --precision) precision=$2; shift 2 ;;
      --reps) reps=$2; shift 2 ;;
      --program) program=1; shift ;;
      --memory) memory=1; shift ;;
      --max_uncached_mp) max_uncached_mp=$2; shift 2 ;;
      *) echo "error: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
  done
  for size in $sizes; do
    [[ $size =~ ^[0-9]+x[0-9]+$ ]] || { echo "error: --sizes: '$size' is not WxH" >&2; exit 2; }
  done
  for c in $cache_mb; do
    [[ $c =~ ^[0-9]+$ ]] || { echo "error: --cache_mb: '$c' is not a whole number of MiB" >&2; exit 2; }
  done
  for b in $band_mp; do
    [[ $b =~ ^[0-9]+([.][0-9]+)?$ ]] || { echo "error: --band_mp: '$b' is not a number of megapixels" >&2; exit 2; }
  done
  [[ $reps =~ ^[1-9][0-9]*$ ]] || { echo "error: --reps must be a positive integer" >&2; exit 2; }

  bench=$build/bench/dispmvs_bench
  colmap=$build/src/dispmvs_colmap
  generator=$build/bench/dispmvs_make_large_workspace
  programs=("$bench")
  [[ $program -eq 0 ]] || programs+=("$colmap" "$generator")
  for p in "${programs[@]}"; do
    [[ -x $p ]] || { echo "error: $p not found: build it first" >&2; exit 1; }
  done
  if [[ $program -eq 1 ]] && ! /usr/bin/time -f '%M' true >/dev/null 2>&1; then
    echo "error: --program needs GNU time at /usr/bin/time (Debian package time)" >&2
    exit 1
  fi
  mkdir -p "$out"
  tsv=$out/resolution_bench.tsv
  printf 'size\tmegapixels\tcache_mb\tband_mp\tnet_s\tnet_s_per_mp\tencoders_share\tupdate_share\tview_s\tview_s_per_mp\tpeak_rss_mib\tlive_peak_mib\n' >"$tsv"
  rows=()

  for size in $sizes; do
    w=${size%x*}
    h=${size#*x}
    mp=$(awk -v w="$w" -v h="$h" 'BEGIN { printf "%.2f", w * h / 1e6 }')
    live_peak=n/a
    if [[ $memory -eq 1 ]]; then
      log=$out/memory_$size.log
      "$bench" --sizes "$size" --sources 4 --config small_v2 --precision "$precision" \
        --warmup 0 --reps 1 >"$log" 2>&1 || { tail -n 20 "$log" >&2; exit 1; }
      live_peak=$(awk -F'|' '/^\| small_v2 /{ gsub(/ /, "", $10); print $10 }' "$log")
    fi
    ws=$out/ws_$size
    if [[ $program -eq 1 ]]; then
      rm -rf "$ws"
      echo "== $size: generating a workspace" >&2
      "$generator" --output_path "$ws" --images 5 --width "$w" --height "$h" \
        >"$out/generate_$size.log" 2>&1 || { tail -n 20 "$out/generate_$size.log" >&2; exit 1; }
      scene=$ws
      reference_sums=
      # The first image the reference, the other four its sources: the
      # same problem at every size, whatever the automatic selection picks.
      mapfile -t names < <(find "$scene/images" -maxdepth 1 -type f -printf '%f\n' | sort)
      [[ ${#names[@]} -eq 5 ]] || { echo "error: $scene/images has ${#names[@]} images, not 5" >&2; exit 1; }
      { echo "${names[0]}"; (IFS=,; echo "${names[*]:1}" | sed 's/,/, /g'); } >"$scene/stereo/patch-match.cfg"
      echo "${names[0]}" >"$out/image_list_$size.txt"
    fi
    for variant in $(for c in $cache_mb; do for b in $band_mp; do echo "$c/$b"; done; done); do
      c=${variant%/*}
      band=${variant#*/}
      if [[ $c -eq 0 ]] && awk -v m="$mp" -v x="$max_uncached_mp" 'BEGIN { exit !(m > x) }'; then
        echo "== $size: without the cache skipped (above $max_uncached_mp MP)" >&2
        continue
      fi
      echo "== $size: network, cache $c MiB, bands of $band MP" >&2
      log=$out/net_${size}_cache${c}_band$band.log
      "$bench" --sizes "$size" --sources 4 --config small_v2 --precision "$precision" \
        --warmup 1 --reps "$reps" --memory 0 --block_cache_mb "$c" \
        --band_megapixels "$band" >"$log" 2>&1 ||
        { tail -n 20 "$log" >&2; exit 1; }
      # | config | precision | params | iters | size | threads | median s | min s | peak MiB |
      #   encoders | correlation | update | ...
      read -r net_s encoders update < <(awk -F'|' '/^\| small_v2 /{
          gsub(/ /, "", $8); gsub(/[ %]/, "", $11); gsub(/[ %]/, "", $13); print $8, $11, $13 }' "$log")
      net_per_mp=$(awk -v s="$net_s" -v m="$mp" 'BEGIN { printf "%.2f", s / m }')
      view_s=n/a
      view_per_mp=n/a
      peak=n/a
      same=n/a
      if [[ $program -eq 1 ]]; then
        echo "== $size: dispmvs_colmap, cache $c MiB, bands of $band MP" >&2
        log=$out/colmap_${size}_cache${c}_band$band.log
        /usr/bin/time -f '%e %M' -o "$log.time" "$colmap" --workspace_path "$scene" \
          --mode photometric --image_list "$out/image_list_$size.txt" --overwrite \
          --tensor_cache_mb "$c" --band_megapixels "$band" >"$log" 2>&1 || { tail -n 20 "$log" >&2; exit 1; }
        # photometric: [1/1] NAME (4 sources): 12.3 s, WxH, ...
        view_s=$(sed -n 's/^photometric: \[1\/1\] .*: \([0-9.]*\) s, [0-9]*x[0-9]*, .*/\1/p' "$log" | head -n 1)
        [[ -n $view_s ]] || { echo "error: no view time in $log" >&2; exit 1; }
        view_per_mp=$(awk -v s="$view_s" -v m="$mp" 'BEGIN { printf "%.2f", s / m }')
        peak=$(tail -n 1 "$log.time" | awk '{ printf "%.0f", $2 / 1024 }')
        # The maps of every variant must be the same bits: the cache changes
        # where memory comes from, not the arithmetic, and the bands run the
        # same arithmetic on the same values (in bf16; in fp32 a convolution
        # of another height may round differently).
        sums=$(cd "$scene/stereo" && find depth_maps normal_maps confidence_maps -type f -name '*.photometric.bin' \
          | sort | xargs md5sum)
        if [[ -z ${reference_sums:-} ]]; then
          reference_sums=$sums
          same=reference
        elif [[ $sums == "$reference_sums" ]]; then
          same=yes
        else
          same=NO
        fi
      fi
      printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$size" "$mp" "$c" "$band" "$net_s" "$net_per_mp" \
        "$encoders" "$update" "$view_s" "$view_per_mp" "$peak" "$live_peak" >>"$tsv"
      rows+=("| $size | $mp | $c | $band | $net_s | $net_per_mp | $encoders % | $update % | $view_s | $view_per_mp | $peak | $live_peak | $same |")
      echo "${rows[-1]}" >&2
    done
    [[ $program -eq 0 ]] || rm -rf "$ws"
  done

  {
    echo "# Time and memory against the image size"
    echo
    echo "Command: \`bench/resolution_bench.sh $build $out --sizes \"$sizes\" --cache_mb \"$cache_mb\" --band_mp \"$band_mp\" --precision $precision --reps $reps$([[ $program -eq 1 ]] && echo ' --program')$([[ $memory -eq 1 ]] && echo ' --memory')\`"
    echo
    echo "Machine: $(nproc) CPU(s), $(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | cut -d: -f2- | sed 's/^ *//' || echo unknown CPU),"
    echo "$(awk '/MemTotal/ { printf "%.1f GiB", $2 / 1048576 }' /proc/meminfo 2>/dev/null) memory; $(date -u '+%Y-%m-%d %H:%M UTC')."
    echo
    echo "Network: one forward pass, N = 4 sources, small_v2, random weights and images, after one"
    echo "warm-up pass (median of $reps). Cache: the budget of freed tensor blocks of 32 MiB and more"
    echo "kept for reuse (0: glibc maps each afresh). Band MP: the fine stage in bands of rows of"
    echo "about that many megapixels (0: the whole image). View: dispmvs_colmap's own time for one view"
    echo "of a generated workspace (network, refinement, writing the maps), and the whole"
    echo "process's peak RSS. Live peak: the largest growth of the live tensors during a pass"
    echo "(dispmvs_bench's memory measurement). Same maps: the view's depth, normal and confidence"
    echo "maps bit for bit those of the size's first variant (reference)."
    echo
    echo "| size | MP | cache MiB | band MP | network s | network s/MP | encoders | update | view s | view s/MP | peak RSS MiB | live peak MiB | same maps |"
    echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    printf '%s\n' "${rows[@]}"
  } >"$out/resolution_bench.md"
  # The plot (s/MP and peak memory against megapixels), standard-library
  # Python only.
  if command -v python3 >/dev/null; then
    python3 "$(dirname "$0")/plot_resolution.py" "$tsv" "$out/resolution_bench.svg"
    echo "wrote $out/resolution_bench.md, $out/resolution_bench.svg and $tsv" >&2
  else
    echo "wrote $out/resolution_bench.md and $tsv (no python3: no plot)" >&2
  fi
}

main "$@"; exit $?  # one line: bash has read it whole before running main
