# A Debian package of dispmvs with CPack: in the build folder,
#   cpack -G DEB          (or plain `cpack`, or `cmake --build . --target package`)
# writes dispmvs_<version>_<arch>.deb there. It holds exactly what
# `cmake --install` installs (the install() rules of CMakeLists.txt and of each
# program's folder), under /usr: the programs in /usr/bin, the shipped weights
# in /usr/share/dispmvs/models (where an installed dispmvs_colmap finds them,
# src/shipped_model.h) and the documentation in /usr/share/doc/dispmvs.
# Depends is computed by dpkg-shlibdeps (Debian's dpkg-dev, and `file`, which
# CPack uses to find the binaries) from the libraries the programs link.
# docs/packaging.md says more; tests/package/ holds the ctests.

set(DISPMVS_PACKAGE_CONTACT "dispmvs maintainers <dispmvs-maintainers@example.org>"
    CACHE STRING "Maintainer of the Debian package (name <email>)")

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME dispmvs)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VERSION_MAJOR ${PROJECT_VERSION_MAJOR})
set(CPACK_PACKAGE_VERSION_MINOR ${PROJECT_VERSION_MINOR})
set(CPACK_PACKAGE_VERSION_PATCH ${PROJECT_VERSION_PATCH})
set(CPACK_PACKAGE_CONTACT "${DISPMVS_PACKAGE_CONTACT}")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "DispMVS dense reconstruction for COLMAP workspaces")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)

# Debian's control fields. The description's first line is the summary above.
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION
"dispmvs estimates dense depth and normal maps of a COLMAP dense workspace
with DispMVS, a learned multi-view stereo network that needs no depth range,
and fuses them into a point cloud. It reads and writes COLMAP's stereo layout,
so COLMAP's own fusion, meshers and viewer keep working on its results.
Programs: dispmvs_colmap (the dense step), dispmvs_eval, dispmvs_report,
dispmvs_synth, dispmvs_train and dispmvs_make_example. The shipped weights
are in /usr/share/dispmvs/models.")
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # dispmvs_0.1.0_amd64.deb
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)

# Without dpkg-shlibdeps or `file`, CPack writes a package with an empty
# Depends and says so only in passing: say it here, where it can be fixed.
find_program(DISPMVS_DPKG_SHLIBDEPS dpkg-shlibdeps)
find_program(DISPMVS_FILE_PROGRAM file)
if(NOT DISPMVS_DPKG_SHLIBDEPS OR NOT DISPMVS_FILE_PROGRAM)
  message(WARNING "dispmvs: dpkg-shlibdeps or file not found: a Debian package "
    "made with cpack would list no dependencies (apt-get install dpkg-dev file)")
endif()

include(CPack)

# ctests (tests/package/): `package` makes the .deb from a scratch CPack
# output folder, checks its files and Depends, unpacks it and runs the
# unpacked dispmvs_colmap on the example with the weights it holds;
# `package_install` installs it with apt-get, runs it from /usr/bin and
# removes it (as root only, skipped otherwise).
if(DISPMVS_FULL_BUILD)
  foreach(_kind package package_install)
    add_test(NAME dispmvs_${_kind}
      COMMAND bash ${PROJECT_SOURCE_DIR}/tests/package/${_kind}_test.sh
        ${CMAKE_CPACK_COMMAND}
        ${PROJECT_BINARY_DIR}
        $<TARGET_FILE:dispmvs_make_example>
        ${PROJECT_BINARY_DIR}/tests/package/${_kind})
    # cpack and `cmake --install` both rewrite build/install_manifest.txt:
    # one of them at a time (dispmvs_install holds the same lock).
    set_tests_properties(dispmvs_${_kind} PROPERTIES LABELS ${_kind} SKIP_RETURN_CODE 77
      RESOURCE_LOCK dispmvs_install_manifest)
  endforeach()
  # cpack (about 20 MB to compress), then the example at 64 pixels.
  set_tests_properties(dispmvs_package PROPERTIES TIMEOUT 300)
  # The same, and apt-get, which may fetch missing dependencies.
  set_tests_properties(dispmvs_package_install PROPERTIES TIMEOUT 600)
endif()
