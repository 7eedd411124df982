#!/usr/bin/env bash
# ctest `dispmvs_package` (label package): the Debian package, without
# installing it. Makes it with cpack in a scratch folder, checks that it holds
# exactly what `cmake --install` installs (programs, weights, documentation),
# that its Depends names the runtime packages of LibTorch and OpenCV, then
# unpacks it with dpkg-deb -x and runs the unpacked dispmvs_colmap on the
# example: without --model_path it must use the weights of the unpacked tree.
#   package_test.sh CPACK BUILD_DIR MAKE_EXAMPLE WORK_DIR
set -euo pipefail
cpack=$1 build_dir=$2 make_example=$3 work=$4
source "$(dirname "$0")/common.sh"

cmake=$(dirname "$cpack")/cmake  # the cmake beside the cpack of the build
command -v dpkg-deb >/dev/null || fail "dpkg-deb not found"
rm -rf "$work"
mkdir -p "$work"
work=$(cd "$work" && pwd -P)  # the path /proc/self/exe will give

deb=$(build_deb "$cpack" "$build_dir" "$work/cpack")
echo "package: $deb ($(du -h "$deb" | cut -f1))"
dpkg-deb -I "$deb"

# The control fields.
field() { dpkg-deb -f "$deb" "$1"; }
[ "$(field Package)" = dispmvs ] || fail "Package: $(field Package)"
[[ "$(field Version)" =~ ^[0-9]+\.[0-9]+\.[0-9]+$ ]] || fail "Version: $(field Version)"
[ "$(field Section)" = science ] || fail "Section: $(field Section)"
[ -n "$(field Maintainer)" ] || fail "no Maintainer"
[[ "$(field Description)" == "DispMVS dense reconstruction for COLMAP workspaces"* ]] ||
  fail "Description: $(field Description)"
depends=$(field Depends)
echo "Depends: $depends"
[ -n "$depends" ] || fail "empty Depends (dpkg-shlibdeps or file missing when cpack ran?)"
for want in libtorch libopencv-core libopencv-imgcodecs libboost-program-options libc6; do
  [[ ", $depends" == *", $want"* ]] || fail "Depends does not name $want*"
done

# The files: the listing has the key paths, and is the same list of files as
# `cmake --install` into a prefix.
dpkg-deb -c "$deb" >"$work/contents.txt"
for path in usr/bin/dispmvs_colmap usr/bin/dispmvs_eval usr/bin/dispmvs_report \
            usr/bin/dispmvs_synth usr/bin/dispmvs_train usr/bin/dispmvs_make_example \
            usr/share/dispmvs/models/dispmvs_small.safetensors \
            usr/share/dispmvs/models/dispmvs_small_paper.safetensors \
            usr/share/dispmvs/models/README.md \
            usr/share/doc/dispmvs/README.md usr/share/doc/dispmvs/docs/dense.md \
            usr/share/doc/dispmvs/docs/packaging.md usr/share/doc/dispmvs/models/README.md; do
  grep -q " \./$path\$" "$work/contents.txt" || fail "the package lacks /$path"
done
awk '$1 !~ /^d/ {print substr($6, 3)}' "$work/contents.txt" | sort >"$work/deb_files.txt"
if ! "$cmake" --install "$build_dir" --prefix "$work/prefix" >"$work/install.log" 2>&1; then
  cat "$work/install.log" >&2
  fail "cmake --install failed"
fi
(cd "$work/prefix" && find . ! -type d | sed 's|^\./|usr/|' | sort) >"$work/install_files.txt"
diff -u "$work/install_files.txt" "$work/deb_files.txt" ||
  fail "the package's files differ from what cmake --install installs (- install, + package)"
echo "files: $(wc -l <"$work/deb_files.txt") (as cmake --install)"

# Unpacked elsewhere, the programs run and find the packaged weights.
dpkg-deb -x "$deb" "$work/unpacked"
for program in "$work"/unpacked/usr/bin/*; do
  "$program" --help >/dev/null || fail "$program --help failed"
done
run_example "$make_example" "$work/unpacked/usr/bin/dispmvs_colmap" "$work/example" \
  "$work/unpacked/usr/share/dispmvs/models/dispmvs_small.safetensors"
# Passed: the unpacked copies go (the .deb and the logs stay).
rm -rf "$work/unpacked" "$work/prefix" "$work/cpack/_CPack_Packages"
echo "package built, checked, unpacked and run: ok"
