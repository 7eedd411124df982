# Sourced by depth_range_robustness.sh and filter_sweep.sh: how both pool
# dispmvs_eval's per-scene scores into one table row, so that their tables
# are computed the same way.

# Depth maps of TYPE from the eval.tsv lines on stdin, pixel counts added over
# all views of all scenes: "coverage | AbsRel | <1 % | <2 % | <5 %", with
# coverage and the fractions of all ground-truth pixels and AbsRel over the
# predicted ones ("n/a" when there are none).
pooled_depth_columns() {
  awk -F'\t' -v type="$1" '
    $1 == "depth" && $2 == type { gt += $4; pred += $5; w1 += $6; w2 += $7; w5 += $8; rel += $9 }
    END { if (gt == 0) { print "n/a | n/a | n/a | n/a | n/a"; exit }
          printf "%.4f | %s | %.4f | %.4f | %.4f", pred / gt,
                 (pred > 0 ? sprintf("%.4f", rel / pred) : "n/a"), w1 / gt, w2 / gt, w5 / gt }'
}

# Clouds: the means over the workspaces WS... of each one's WS/TSV and WS/JSON
# (dispmvs_eval's --tsv and --json file names, given first):
# "points | accuracy / diag | completeness / diag | overall / diag | precision
# | recall | F-score", distances divided by the scene's ground-truth
# bounding-box diagonal (scenes have random metric scales). Returns 1 when a
# JSON file has no diagonal.
mean_cloud_columns() {
  local tsv=$1 json=$2 ws diagonal
  shift 2
  for ws in "$@"; do
    diagonal=$(grep -o '"bbox_diagonal": *[0-9.eE+-]*' "$ws/$json" | head -n 1 | sed 's/.*: *//')
    if [ -z "$diagonal" ]; then
      echo "no bbox_diagonal in $ws/$json" >&2
      return 1
    fi
    awk -F'\t' -v d="$diagonal" '$1 == "cloud" { print $3, $5 / d, $6 / d, $7 / d, $8, $9, $10 }' \
      "$ws/$tsv"
  done | awk '
    { n += 1; p += $1; a += $2; c += $3; o += $4; pr += ($5 == "nan" ? 0 : $5); r += $6; f += $7 }
    END { if (n > 0) printf "%.0f | %.5f | %.5f | %.5f | %.4f | %.4f | %.4f",
                            p / n, a / n, c / n, o / n, pr / n, r / n, f / n }'
}
