#!/usr/bin/env bash
# Builds and runs the libFuzzer targets (see docs/fuzzing.md).
#
#   tests/fuzz/run_fuzzers.sh [SECONDS_PER_TARGET [TARGET...]]   (default 60, all)
#
# Configures a separate clang build directory, builds the targets, and runs
# each for the given time from a scratch corpus seeded with the committed one
# (tests/fuzz/corpus/<target>/, never written to). Exits non-zero if any
# target found a crash, a sanitizer report, a leak, an oversized allocation or
# a failed property check; crashing inputs are kept under
# BUILD/fuzz-work/artifacts/, full logs in BUILD/fuzz-work/<target>.log.
#
# Environment:
#   DISPMVS_FUZZ_BUILD_DIR  build directory (default: build-fuzz in the repository)
#   DISPMVS_FUZZ_CXX        clang++ to build with (default: clang++)
#   DISPMVS_FUZZ_JOBS       targets run at the same time (default 1)
#   DISPMVS_FUZZ_FRESH=1    start from the committed corpus only; otherwise a
#                           rerun keeps and grows the scratch corpus
#
# Needs clang and its sanitizer runtimes besides the project's dependencies;
# .ci/install_deps.sh installs them (clang, libclang-rt-14-dev).
set -euo pipefail

all_targets=(
  sparse_model_binary_fuzzer sparse_model_text_fuzzer dense_array_fuzzer
  stereo_config_fuzzer ply_fuzzer safetensors_fuzzer image_fuzzer
)

seconds="${1:-60}"
if [[ $# -gt 1 ]]; then targets=("${@:2}"); else targets=("${all_targets[@]}"); fi
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
build="${DISPMVS_FUZZ_BUILD_DIR:-${repo}/build-fuzz}"
cxx="${DISPMVS_FUZZ_CXX:-clang++}"
jobs="${DISPMVS_FUZZ_JOBS:-1}"
work="${build}/fuzz-work"
seeds="${repo}/tests/fuzz/corpus"

generator=()
if command -v ninja > /dev/null; then generator=(-G Ninja); fi

start=${SECONDS}
mkdir -p "${build}"
echo "=== configuring ${build} with ${cxx}"
cmake -S "${repo}" -B "${build}" "${generator[@]}" \
  -DCMAKE_CXX_COMPILER="${cxx}" \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DDISPMVS_BUILD_FUZZERS=ON > "${build}/configure.log" 2>&1 ||
  { cat "${build}/configure.log"; exit 1; }
echo "=== building ${targets[*]}"
cmake --build "${build}" -j2 --target "${targets[@]}" > "${build}/build.log" 2>&1 ||
  { tail -n 100 "${build}/build.log"; exit 1; }
echo "=== built in $((SECONDS - start)) s;" \
  "fuzzing ${#targets[@]} targets for ${seconds} s each, ${jobs} at a time"

mkdir -p "${work}/artifacts"
# Where the targets that need files keep them (tests/fuzz/fuzz_support.h): in
# memory where possible, since creating and renaming files on a disk file
# system makes those targets about four times slower.
if scratch="$(mktemp -d /dev/shm/dispmvs-fuzz.XXXXXX 2> /dev/null)"; then
  trap 'rm -rf "${scratch}"' EXIT
else
  scratch="${work}/tmp"
  mkdir -p "${scratch}"
fi
export TMPDIR="${scratch}"

# Runs one target; its exit status is the fuzzer's.
run_target() {
  local target="$1"
  local corpus="${work}/corpus/${target}"
  # Every target allocates little; the safetensors one also holds LibTorch
  # (about 330 MB resident before the first input).
  local rss_limit=512
  if [[ "${target}" == safetensors_fuzzer ]]; then rss_limit=1024; fi
  if [[ "${DISPMVS_FUZZ_FRESH:-0}" == 1 ]]; then rm -rf "${corpus}"; fi
  mkdir -p "${corpus}"
  cp -n "${seeds}/${target}/"* "${corpus}/" ||
    { echo "no committed corpus in ${seeds}/${target}" > "${work}/${target}.log"; return 2; }
  "${build}/tests/fuzz/${target}" \
    -max_total_time="${seconds}" \
    -rss_limit_mb="${rss_limit}" \
    -malloc_limit_mb=512 \
    -max_len=4096 \
    -timeout=10 \
    -print_final_stats=1 \
    -artifact_prefix="${work}/artifacts/${target}-" \
    "${corpus}" > "${work}/${target}.log" 2>&1
}

# Start the targets, at most ${jobs} at a time; each leaves its exit status
# in ${work}/<target>.status.
for target in "${targets[@]}"; do
  rm -f "${work}/${target}.status"
  while [[ $(jobs -rp | wc -l) -ge ${jobs} ]]; do wait -n || true; done
  ( set +e; run_target "${target}"; echo $? > "${work}/${target}.status" ) &
done
wait

# One line per target from libFuzzer's final report.
done_field() { sed -nE "s/.*[[:space:]]$2: ([^ ]+).*/\1/p" <<< "$1"; }
final_stat() { sed -nE "s/^stat::$2:[[:space:]]*([0-9]+).*/\1/p" "$1" | tail -n 1; }
declare -A status=()
failed=0
printf '%-28s %10s %8s %6s %6s %14s %8s  %s\n' target runs exec/s cov ft corpus rss result
for target in "${targets[@]}"; do
  log="${work}/${target}.log"
  status[${target}]="$(cat "${work}/${target}.status" 2> /dev/null || echo missing)"
  done_line="$(grep -E '^#[0-9]+[[:space:]]+DONE' "${log}" | tail -n 1 || true)"
  result=ok
  if [[ "${status[${target}]}" != 0 ]]; then
    result="FAILED (exit ${status[${target}]})"
    failed=1
  fi
  printf '%-28s %10s %8s %6s %6s %14s %8s  %s\n' "${target}" \
    "$(final_stat "${log}" number_of_executed_units)" \
    "$(final_stat "${log}" average_exec_per_sec)" \
    "$(done_field "${done_line}" cov)" "$(done_field "${done_line}" ft)" \
    "$(done_field "${done_line}" corp)" "$(final_stat "${log}" peak_rss_mb | sed 's/$/MB/')" \
    "${result}"
done
for target in "${targets[@]}"; do
  if [[ "${status[${target}]}" != 0 ]]; then
    echo "!!! ${target}: see ${work}/${target}.log and ${work}/artifacts/; its report:"
    # The sanitizer or libFuzzer report, without the run's progress lines.
    grep -vE '^#[0-9]+[[:space:]]+(NEW|REDUCE|pulse|RELOAD)' "${work}/${target}.log" | tail -n 80
  fi
done
echo "=== done in $((SECONDS - start)) s"
exit "${failed}"
