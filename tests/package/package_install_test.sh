#!/usr/bin/env bash
# ctest `dispmvs_package_install` (label package_install): installs the Debian
# package on this machine with apt-get, runs the example with the programs in
# /usr/bin (the weights from /usr/share/dispmvs/models), removes the package
# and checks that its files are gone. It changes the system, so it runs as
# root only, and not where dispmvs is installed already; otherwise it is
# skipped (exit status 77, ctest's SKIP_RETURN_CODE).
#   package_install_test.sh CPACK BUILD_DIR MAKE_EXAMPLE WORK_DIR
# (MAKE_EXAMPLE is unused: the installed dispmvs_make_example is run.)
set -euo pipefail
cpack=$1 build_dir=$2 work=$4
source "$(dirname "$0")/common.sh"

skip() {
  echo "SKIP: $*"
  exit 77
}
[ "$(id -u)" = 0 ] || skip "installs a package system-wide: run as root (id -u is $(id -u))"
for tool in apt-get dpkg dpkg-deb; do
  command -v "$tool" >/dev/null || skip "$tool not found (not a Debian system?)"
done
if dpkg-query -W -f '${db:Status-Status}' dispmvs 2>/dev/null | grep -qv '^not-installed$'; then
  skip "the package dispmvs is on this system already; this test would replace and remove it"
fi
for path in /usr/bin/dispmvs_colmap /usr/share/dispmvs; do
  [ ! -e "$path" ] || skip "$path exists (installed without the package?); this test would replace and remove it"
done

rm -rf "$work"
mkdir -p "$work"
work=$(cd "$work" && pwd -P)
deb=$(build_deb "$cpack" "$build_dir" "$work/cpack")
echo "package: $deb"

export DEBIAN_FRONTEND=noninteractive
apt=(apt-get -y -q -o DPkg::Lock::Timeout=300)
installed=0
cleanup() {
  if [ "$installed" = 1 ]; then "${apt[@]}" remove dispmvs >/dev/null 2>&1 || true; fi
}
trap cleanup EXIT

installed=1
"${apt[@]}" install "$deb" || fail "apt-get install $deb failed"
[ "$(dpkg-query -W -f '${db:Status-Status}' dispmvs)" = installed ] || fail "dispmvs not installed"
echo "installed: dispmvs $(dpkg-query -W -f '${Version}' dispmvs)"

/usr/bin/dispmvs_colmap --help >"$work/help.txt" || fail "dispmvs_colmap --help failed"
grep -q -- --workspace_path "$work/help.txt" || fail "--help does not mention --workspace_path"
[ -f /usr/share/doc/dispmvs/README.md ] || fail "no /usr/share/doc/dispmvs/README.md"
run_example /usr/bin/dispmvs_make_example /usr/bin/dispmvs_colmap "$work/example" \
  /usr/share/dispmvs/models/dispmvs_small.safetensors

"${apt[@]}" remove dispmvs || fail "apt-get remove dispmvs failed"
installed=0
[ "$(dpkg-query -W -f '${db:Status-Status}' dispmvs 2>/dev/null || echo not-installed)" = not-installed ] ||
  fail "dispmvs is still known to dpkg after removal: $(dpkg -s dispmvs 2>&1)"
for path in /usr/bin/dispmvs_colmap /usr/bin/dispmvs_make_example /usr/share/dispmvs /usr/share/doc/dispmvs; do
  [ ! -e "$path" ] || fail "$path is still there after apt-get remove"
done
rm -rf "$work/cpack/_CPack_Packages"  # passed: the staged copy goes
echo "package installed, run from /usr/bin and removed: ok"
