#!/usr/bin/env bash
# Builds and runs the libFuzzer targets (see docs/fuzzing.md). Two modes:
#
#   tests/fuzz/run_fuzzers.sh replay [TARGET...]
#       What CI runs (the fuzz_readers ctest): deterministic, so that its
#       verdict depends on the tree alone. Per target: every committed input
#       (tests/fuzz/corpus/<target>/ and tests/fuzz/regressions/<target>/)
#       once, then a fixed number of mutations from a fixed seed
#       (-seed=1 -runs=N, N from the table below). Two runs on the same tree
#       execute the same inputs.
#
#   tests/fuzz/run_fuzzers.sh campaign SECONDS [TARGET...]
#       A search for new bugs, run on purpose: each target for SECONDS from a
#       random seed, growing a scratch corpus kept between runs (unless
#       DISPMVS_FUZZ_FRESH=1). Every finding becomes a regression input:
#       reduce it, fix the code, commit it under tests/fuzz/regressions/.
#       (A bare number as the first argument means campaign.)
#
# Exits non-zero if any target found a crash, a sanitizer report, a leak, an
# oversized allocation or a failed property check; crashing inputs are kept
# under BUILD/fuzz-work/artifacts/, full logs in BUILD/fuzz-work/<target>.log.
#
# Environment:
#   DISPMVS_FUZZ_BUILD_DIR  build directory (default: build-fuzz in the repository)
#   DISPMVS_FUZZ_CXX        clang++ to build with (default: clang++)
#   DISPMVS_FUZZ_JOBS       targets run at the same time (default 1)
#   DISPMVS_FUZZ_FRESH=1    campaign: start from the committed inputs only
#
# Needs clang and its sanitizer runtimes besides the project's dependencies;
# .ci/install_deps.sh installs them (clang, libclang-rt-14-dev).
set -euo pipefail

all_targets=(
  sparse_model_binary_fuzzer sparse_model_text_fuzzer dense_array_fuzzer
  stereo_config_fuzzer ply_fuzzer safetensors_fuzzer image_fuzzer
)
# Mutations per target in replay mode: 3 to 17 s each on one core of the
# 2-core development machine (docs/fuzzing.md has the measured times).
# safetensors_fuzzer has none: its coverage varies from run to run however
# the run is pinned (LibTorch's inline code in the loader's translation
# unit), so in replay mode it only runs its committed inputs.
declare -A replay_runs=(
  [sparse_model_binary_fuzzer]=100000 [sparse_model_text_fuzzer]=80000
  [dense_array_fuzzer]=80000 [stereo_config_fuzzer]=20000 [ply_fuzzer]=100000
  [safetensors_fuzzer]=0 [image_fuzzer]=30000
)

mode="${1:-replay}"
if [[ "${mode}" =~ ^[0-9]+$ ]]; then
  mode=campaign
else
  shift || true
fi
seconds=0
case "${mode}" in
  replay) ;;
  campaign)
    seconds="${1:?campaign needs SECONDS}"
    shift
    ;;
  *) echo "usage: $0 replay [TARGET...] | campaign SECONDS [TARGET...]" >&2; exit 2 ;;
esac
if [[ $# -gt 0 ]]; then targets=("$@"); else targets=("${all_targets[@]}"); fi
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
build="${DISPMVS_FUZZ_BUILD_DIR:-${repo}/build-fuzz}"
cxx="${DISPMVS_FUZZ_CXX:-clang++}"
jobs="${DISPMVS_FUZZ_JOBS:-1}"
work="${build}/fuzz-work"
seeds="${repo}/tests/fuzz/corpus"
regressions="${repo}/tests/fuzz/regressions"

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
# A compiler that crashes once is not a verdict on the code: a CI run saw
# clang stop with a stack dump ('<eof> parser at end of file') on a tree that
# builds cleanly here and on every other run. A failed build is therefore
# tried once more, one job at a time, after the first failure's report is
# shown; code that does not compile fails both times.
if ! cmake --build "${build}" -j2 --target "${targets[@]}" > "${build}/build.log" 2>&1; then
  cp "${build}/build.log" "${build}/build-first-try.log"
  echo "=== the build failed; its first failure (full log: ${build}/build-first-try.log):"
  grep -m 1 -B 2 -A 40 -E 'FAILED:|error:|Stack dump|PLEASE submit' "${build}/build.log" || tail -n 60 "${build}/build.log"
  echo "=== building again, one job at a time"
  cmake --build "${build}" -j1 --target "${targets[@]}" > "${build}/build.log" 2>&1 ||
    { tail -n 100 "${build}/build.log"; exit 1; }
fi
if [[ "${mode}" == replay ]]; then
  what="replaying the committed inputs, then a fixed number of mutations from seed 1"
else
  what="fuzzing for ${seconds} s each from random seeds"
fi
echo "=== built in $((SECONDS - start)) s; ${#targets[@]} targets, ${jobs} at a time: ${what}"

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

# The committed inputs of a target, one per line.
committed_inputs() {
  find "${seeds}/$1" "${regressions}/$1" -maxdepth 1 -type f 2> /dev/null | sort
}

# Runs one target; its exit status is the fuzzer's.
run_target() {
  local target="$1"
  local corpus="${work}/corpus/${target}"
  # Every target allocates little; the safetensors one also holds LibTorch
  # (about 330 MB resident before the first input).
  local rss_limit=512
  if [[ "${target}" == safetensors_fuzzer ]]; then rss_limit=1024; fi
  local limits=(-rss_limit_mb="${rss_limit}" -malloc_limit_mb=512 -timeout=10)
  local inputs
  mapfile -t inputs < <(committed_inputs "${target}")
  if [[ ${#inputs[@]} -eq 0 ]]; then
    echo "no committed inputs in ${seeds}/${target}" > "${work}/${target}.log"
    return 2
  fi
  if [[ "${mode}" == replay || "${DISPMVS_FUZZ_FRESH:-0}" == 1 ]]; then rm -rf "${corpus}"; fi
  mkdir -p "${corpus}"
  cp -n "${inputs[@]}" "${corpus}/"
  if [[ "${mode}" == replay ]]; then
    # Each committed input once, whatever its length (regressions are never
    # cut to -max_len), then the mutations.
    "${build}/tests/fuzz/${target}" "${limits[@]}" \
      -artifact_prefix="${work}/artifacts/${target}-" \
      "${inputs[@]}" > "${work}/${target}.log" 2>&1 || return $?
    [[ "${replay_runs[${target}]:-20000}" -gt 0 ]] || return 0
    # Deterministic: a fixed seed and count, no time-driven corpus reload,
    # and no mutations from the operands of intercepted comparisons (memcmp,
    # strcmp and the like), which include the scratch files' names (process
    # ids, temporary folders). The coverage of some targets also depends on
    # addresses (measured: two runs of ply_fuzzer from the same seed kept
    # different inputs), so the run has address randomisation off (setarch
    # -R), an empty environment and relative paths: the same addresses
    # whatever the build folder, the user or the shell.
    ( cd "${work}" && env -i PATH=/usr/bin:/bin TMPDIR="${TMPDIR}" OMP_NUM_THREADS=1 \
        setarch "$(uname -m)" -R "../tests/fuzz/${target}" "${limits[@]}" \
        -seed=1 -runs="${replay_runs[${target}]:-20000}" -reload=0 -use_cmp=0 -use_memmem=0 \
        -max_len=4096 -print_final_stats=1 -artifact_prefix="artifacts/${target}-" \
        "corpus/${target}" ) >> "${work}/${target}.log" 2>&1
  else
    "${build}/tests/fuzz/${target}" "${limits[@]}" \
      -max_total_time="${seconds}" -max_len=4096 \
      -print_final_stats=1 -artifact_prefix="${work}/artifacts/${target}-" \
      "${corpus}" > "${work}/${target}.log" 2>&1
  fi
}

# Start the targets, at most ${jobs} at a time; each leaves its exit status
# in ${work}/<target>.status and its wall time in ${work}/<target>.seconds.
for target in "${targets[@]}"; do
  rm -f "${work}/${target}.status"
  while [[ $(jobs -rp | wc -l) -ge ${jobs} ]]; do wait -n || true; done
  (
    set +e
    target_start=${SECONDS}
    run_target "${target}"
    echo $? > "${work}/${target}.status"
    echo $((SECONDS - target_start)) > "${work}/${target}.seconds"
  ) &
done
wait

# One line per target from libFuzzer's final report.
done_field() { sed -nE "s/.*[[:space:]]$2: ([^ ]+).*/\1/p" <<< "$1"; }
final_stat() { sed -nE "s/^stat::$2:[[:space:]]*([0-9]+).*/\1/p" "$1" | tail -n 1; }
declare -A status=()
failed=0
printf '%-28s %7s %10s %8s %6s %6s %8s %8s %5s  %s\n' \
  target inputs runs exec/s cov ft corpus rss s result
for target in "${targets[@]}"; do
  log="${work}/${target}.log"
  status[${target}]="$(cat "${work}/${target}.status" 2> /dev/null || echo missing)"
  done_line="$(grep -E '^#[0-9]+[[:space:]]+DONE' "${log}" | tail -n 1 || true)"
  result=ok
  if [[ "${status[${target}]}" != 0 ]]; then
    result="FAILED (exit ${status[${target}]})"
    failed=1
  fi
  printf '%-28s %7s %10s %8s %6s %6s %8s %8s %5s  %s\n' "${target}" \
    "$(committed_inputs "${target}" | wc -l)" \
    "$(final_stat "${log}" number_of_executed_units)" \
    "$(final_stat "${log}" average_exec_per_sec)" \
    "$(done_field "${done_line}" cov)" "$(done_field "${done_line}" ft)" \
    "$(done_field "${done_line}" corp)" "$(final_stat "${log}" peak_rss_mb | sed 's/$/MB/')" \
    "$(cat "${work}/${target}.seconds" 2> /dev/null)" "${result}"
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
