#!/usr/bin/env bash
# The workflow users have, end to end, on the rendered example scene:
#   COLMAP sparse reconstruction on the CPU (feature_extractor,
#   exhaustive_matcher, mapper) from the images alone,
#   model_aligner: the SfM frame aligned to the ground truth by the camera
#   centres (a similarity), so that the ground-truth depth maps apply,
#   image_undistorter -> a dense workspace,
#   dispmvs_colmap on it, then dispmvs_eval against the ground truth.
#
# usage: examples/colmap_pipeline.sh BUILD_DIR OUTPUT_DIR [extra dispmvs_colmap options]
# Needs the colmap binary (Debian's colmap package). OUTPUT_DIR is replaced.
set -euo pipefail

if [ $# -lt 2 ]; then
  echo "usage: $0 BUILD_DIR OUTPUT_DIR [dispmvs_colmap options]" >&2
  exit 2
fi
build=$(cd "$1" && pwd)
out=$2
shift 2
command -v colmap > /dev/null || { echo "error: colmap is not on PATH (.ci/install_deps.sh installs it)" >&2; exit 1; }
export QT_QPA_PLATFORM=offscreen

rm -rf "$out"
mkdir -p "$out"
out=$(cd "$out" && pwd)
truth=$out/truth

step() { echo "== $*"; }

step "rendering the example scene with ground truth"
"$build/examples/dispmvs_make_example" --output_path "$truth" --seed 1 \
  --ground_truth_sampling colmap-dense > "$out/make_example.log"

# The intrinsics are known (as from a calibrated camera): PINHOLE, held fixed
# in bundle adjustment, so that undistortion leaves the images untouched and
# the ground-truth depth maps stay pixel-aligned with them.
mkdir -p "$out/truth_txt"
colmap model_converter --input_path "$truth/sparse" --output_path "$out/truth_txt" \
  --output_type TXT > "$out/colmap.log" 2>&1
camera_params=$(awk '!/^#/ && NF >= 8 {print $5 "," $6 "," $7 "," $8; exit}' "$out/truth_txt/cameras.txt")

step "colmap feature_extractor / exhaustive_matcher / mapper (CPU)"
db=$out/database.db
colmap feature_extractor --database_path "$db" --image_path "$truth/images" \
  --ImageReader.camera_model PINHOLE --ImageReader.single_camera 1 \
  --ImageReader.camera_params "$camera_params" --SiftExtraction.use_gpu 0 >> "$out/colmap.log" 2>&1
colmap exhaustive_matcher --database_path "$db" --SiftMatching.use_gpu 0 >> "$out/colmap.log" 2>&1
mkdir -p "$out/sparse"
colmap mapper --database_path "$db" --image_path "$truth/images" --output_path "$out/sparse" \
  --Mapper.ba_refine_focal_length 0 --Mapper.ba_refine_principal_point 0 \
  --Mapper.ba_refine_extra_params 0 >> "$out/colmap.log" 2>&1
[ -f "$out/sparse/0/images.bin" ] || { echo "error: the mapper reconstructed nothing (see $out/colmap.log)" >&2; exit 1; }

step "colmap model_aligner: SfM frame -> ground-truth frame (camera centres)"
# Camera centre C = -R^T t from each ground-truth pose (COLMAP's quaternion
# convention, QW QX QY QZ).
awk '!/^#/ && NF >= 10 {
  w = $2; x = $3; y = $4; z = $5; tx = $6; ty = $7; tz = $8;
  r00 = 1 - 2*(y*y + z*z); r01 = 2*(x*y - z*w);     r02 = 2*(x*z + y*w);
  r10 = 2*(x*y + z*w);     r11 = 1 - 2*(x*x + z*z); r12 = 2*(y*z - x*w);
  r20 = 2*(x*z - y*w);     r21 = 2*(y*z + x*w);     r22 = 1 - 2*(x*x + y*y);
  printf "%s %.12g %.12g %.12g\n", $10, -(r00*tx + r10*ty + r20*tz), -(r01*tx + r11*ty + r21*tz), -(r02*tx + r12*ty + r22*tz);
  getline;  # the POINTS2D line
}' "$out/truth_txt/images.txt" > "$out/reference_centres.txt"
mkdir -p "$out/aligned"
colmap model_aligner --input_path "$out/sparse/0" --output_path "$out/aligned" \
  --ref_images_path "$out/reference_centres.txt" --ref_is_gps 0 --alignment_type custom \
  --robust_alignment 1 --robust_alignment_max_error 0.05 > "$out/aligner.log" 2>&1
cat "$out/aligner.log" >> "$out/colmap.log"
registered=$(colmap model_analyzer --path "$out/aligned" 2>&1 | awk -F': ' '/Registered images/ {print $2}')
alignment_error=$(awk '/Alignment error/ {print $4; exit}' "$out/aligner.log")
num_images=$(ls "$truth/images" | wc -l)
echo "registered images: ${registered:-?} of $num_images; mean camera-centre alignment error: ${alignment_error:-?} (scene depths 3 to 10)"
[ "${registered:-0}" = "$num_images" ] || {
  echo "error: the mapper registered ${registered:-0} of $num_images images (see $out/colmap.log)" >&2; exit 1; }
# The example's cameras are 1 to 3 units apart: an SfM frame off by more
# than 0.05 would make the ground-truth comparison meaningless.
awk -v e="${alignment_error:-1e9}" 'BEGIN { exit !(e < 0.05) }' || {
  echo "error: the SfM model does not align with the ground truth (see $out/aligner.log)" >&2; exit 1; }

step "colmap image_undistorter"
colmap image_undistorter --image_path "$truth/images" --input_path "$out/aligned" \
  --output_path "$out/dense" --output_type COLMAP >> "$out/colmap.log" 2>&1
cp -r "$truth/ground_truth" "$out/dense/ground_truth"

step "dispmvs_colmap"
"$build/src/dispmvs_colmap" --workspace_path "$out/dense" "$@"

step "dispmvs_eval against the ground truth"
"$build/src/dispmvs_eval" --workspace_path "$out/dense" \
  --types dispmvs.photometric,dispmvs.geometric --ply "$out/dense/fused.ply" \
  --json "$out/eval.json"
