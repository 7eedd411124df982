#!/usr/bin/env bash
# Builds and runs the sparse-model fuzzers (see docs/fuzzing.md).
#
#   tests/fuzz/run_fuzzers.sh [SECONDS_PER_TARGET]   (default 60)
#
# Configures a separate clang build directory (build-fuzz in the repository
# root, or $DISPMVS_FUZZ_BUILD_DIR), builds the libFuzzer targets, seeds a
# corpus from files our writers produce, runs each target for the given time
# with a 512 MB RSS limit, and exits non-zero if any target found a crash
# (crashing inputs are kept under BUILD/fuzz-work/artifacts/).
#
# Needs clang and its sanitizer runtimes, besides .ci/install_deps.sh:
#   apt-get install clang libclang-rt-14-dev
set -euo pipefail

seconds="${1:-60}"
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
build="${DISPMVS_FUZZ_BUILD_DIR:-${repo}/build-fuzz}"
cxx="${DISPMVS_FUZZ_CXX:-clang++}"
work="${build}/fuzz-work"

generator=()
if command -v ninja > /dev/null; then generator=(-G Ninja); fi

mkdir -p "${build}"
cmake -S "${repo}" -B "${build}" "${generator[@]}" \
  -DCMAKE_CXX_COMPILER="${cxx}" \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DDISPMVS_BUILD_FUZZERS=ON > "${build}/configure.log" 2>&1 ||
  { cat "${build}/configure.log"; exit 1; }
cmake --build "${build}" -j2 --target \
  sparse_model_binary_fuzzer sparse_model_text_fuzzer sparse_model_fuzz_seeds

mkdir -p "${work}/artifacts"
"${build}/tests/fuzz/sparse_model_fuzz_seeds" "${work}/corpus_binary" "${work}/corpus_text"

failed=0
for kind in binary text; do
  target="sparse_model_${kind}_fuzzer"
  echo "=== ${target}: ${seconds} s"
  set +e
  "${build}/tests/fuzz/${target}" \
    -max_total_time="${seconds}" \
    -rss_limit_mb=512 \
    -max_len=4096 \
    -timeout=10 \
    -print_final_stats=1 \
    -artifact_prefix="${work}/artifacts/${target}-" \
    "${work}/corpus_${kind}" 2>&1 | tee "${work}/${target}.log" |
    grep -E '^(#[0-9]+[[:space:]]+(INITED|DONE)|==[0-9]+==|SUMMARY|stat::)'
  # The fuzzer's exit status decides, not grep's.
  status="${PIPESTATUS[0]}"
  set -e
  if [[ "${status}" -ne 0 ]]; then
    echo "!!! ${target} failed (exit ${status}); see ${work}/${target}.log and ${work}/artifacts/"
    failed=1
  fi
done
exit "${failed}"
