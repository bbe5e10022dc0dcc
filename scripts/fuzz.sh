#!/usr/bin/env bash
# Fuzzes the readers of untrusted input with libFuzzer, ASan and UBSan (fuzz/*_fuzz.cpp).
#
#   scripts/fuzz.sh [target|all] [seconds]     (default: pickle, 60 s; `scripts/fuzz.sh 60` works)
#
# Targets, one input kind each:
#   pickle       pickles, .npy and .npz (lib/io)
#   zip          zip archives (lib/io/zip.cpp) and reference .pth checkpoints (read_torch_state_dict)
#   config       YAML config files (lib/core/config_io.cpp, with configs/default.yaml as parent)
#   camera_path  camera path files (lib/video/camera_path.cpp)
#   all          each of them in turn, `seconds` each
#
# Builds a separate clang tree in build-fuzz/ (needs: apt-get install clang libclang-rt-14-dev),
# seeds fuzz/corpus/<target>/ with small valid files (tests/python/make_io_fixtures.py,
# fuzz/make_seeds.py, configs/*.yaml), runs the target(s) one at a time and prints, per target,
# executions, executions per second, peak RSS, corpus size and whether the run was clean (no
# crash, sanitizer report, escaping exception other than th::Error, input slower than 20 s or
# memory above 2 GB). Crashing inputs land in fuzz/crashes/<target>-*; the full log of each run
# is build-fuzz/fuzz-<target>.log and a Markdown table row per run is appended to
# build-fuzz/fuzz-results.md. Exit status 0 when every run was clean. TH_FUZZ_JOBS sets the build
# parallelism (default 2).
set -euo pipefail

targets_all=(pickle zip config camera_path)
target="pickle"
if [ $# -gt 0 ] && ! [[ "$1" =~ ^[0-9]+$ ]]; then
  target="$1"
  shift
fi
seconds="${1:-60}"
case "$target" in
  all) targets=("${targets_all[@]}") ;;
  pickle | zip | config | camera_path) targets=("$target") ;;
  *) echo "fuzz: unknown target '$target' (one of: ${targets_all[*]} all)" >&2; exit 2 ;;
esac

root="$(cd "$(dirname "$0")/.." && pwd)"
build="$root/build-fuzz"
crashes="$root/fuzz/crashes"
python="${TH_PYTHON:-/usr/bin/python3}"

mkdir -p "$build" "$crashes"
cmake -S "$root" -B "$build" -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DTH_BUILD_FUZZ=ON -DTH_BUILD_TESTS=OFF -DTH_BUILD_BENCH=OFF >"$build/configure.log" 2>&1 ||
  { cat "$build/configure.log"; exit 1; }
for t in "${targets[@]}"; do
  cmake --build "$build" --target "${t}_fuzz" -j "${TH_FUZZ_JOBS:-2}"
done

# Seeds: generated once per build tree, copied into the corpus before every run.
seeds="$build/seeds"
needs_fixtures=0
needs_seeds=0
for t in "${targets[@]}"; do
  if [[ "$t" == pickle || "$t" == zip ]]; then needs_fixtures=1; fi
  if [[ "$t" == zip || "$t" == camera_path ]]; then needs_seeds=1; fi
done
if [ "$needs_fixtures" -eq 1 ] && [ ! -f "$seeds/DONE" ]; then
  (cd "$root" && "$python" tests/python/make_io_fixtures.py "$seeds" >/dev/null)
fi
if [ "$needs_seeds" -eq 1 ] && [ ! -f "$seeds/camera_path/flat.yaml" ]; then
  (cd "$root" && "$python" fuzz/make_seeds.py "$seeds")
fi

seed() {  # seed <target> <corpus dir>
  case "$1" in
    pickle) find "$seeds" -maxdepth 1 -type f -size -16k \( -name '*.pkl' -o -name '*.npy' -o -name '*.npz' \) \
              -exec cp {} "$2/" \; ;;
    zip) find "$seeds" -maxdepth 1 -type f -size -16k -name '*.npz' -exec cp {} "$2/" \;
         cp "$seeds"/zip/* "$2/" ;;
    config) find "$root/configs" -type f -name '*.yaml' -size -16k |
              while read -r f; do cp "$f" "$2/$(echo "${f#"$root/configs/"}" | tr / _)"; done ;;
    camera_path) cp "$seeds"/camera_path/* "$2/" ;;
  esac
}

results="$build/fuzz-results.md"
[ -f "$results" ] || {
  echo "| target | seconds | executions | execs/s | peak RSS MB | corpus files | result |"
  echo "|---|---:|---:|---:|---:|---:|---|"
} >"$results"

failed=0
for t in "${targets[@]}"; do
  corpus="$root/fuzz/corpus/$t"
  mkdir -p "$corpus"
  seed "$t" "$corpus"
  extra=()
  if [ "$t" = config ]; then  # the key names of the config tree, as a libFuzzer dictionary
    grep -oE '^ *[a-z_0-9]+:' "$root/configs/default.yaml" | tr -d ' ' | sort -u |
      sed 's/.*/"&"/' >"$build/config.dict"
    extra+=(-dict="$build/config.dict")
  fi
  log="$build/fuzz-$t.log"
  echo "fuzz: running ${t}_fuzz for ${seconds}s on $(ls "$corpus" | wc -l) corpus files (log: $log)"
  set +e
  # The slow unwinder (fast_unwind_on_malloc=0) costs executions per second but gives leak
  # reports whole stacks through LibTorch, which the narrow suppression in fuzz/lsan.supp needs.
  ASAN_OPTIONS="detect_leaks=1:allocator_may_return_null=1" \
    LSAN_OPTIONS="suppressions=$root/fuzz/lsan.supp:print_suppressions=0:fast_unwind_on_malloc=0" \
    "$build/fuzz/${t}_fuzz" "$corpus" -max_total_time="$seconds" -max_len=16384 -timeout=20 \
    -rss_limit_mb=2048 -malloc_limit_mb=2048 -artifact_prefix="$crashes/$t-" \
    -print_final_stats=1 "${extra[@]}" >"$log" 2>&1
  status=$?
  set -e
  grep -E "ERROR|SUMMARY|Test unit written|deadly|terminate called|what\(\)" "$log" | head -20 || true
  stat() { grep -oE "^stat::$1: *[0-9]+" "$log" | grep -oE '[0-9]+$' | tail -1; }
  execs="$(stat number_of_executed_units)"
  execs="${execs:-$(grep -oE '^#[0-9]+' "$log" | tail -1 | tr -d '#')}"
  rss="$(stat peak_rss_mb)"
  rss="${rss:-$(grep -oE 'rss: [0-9]+Mb' "$log" | tail -1 | grep -oE '[0-9]+')}"
  elapsed="$(grep -oE 'Done [0-9]+ runs in [0-9]+ second' "$log" | grep -oE '[0-9]+ second' | grep -oE '[0-9]+')"
  elapsed="${elapsed:-$seconds}"
  rate=$(( ${execs:-0} / (elapsed > 0 ? elapsed : 1) ))
  files="$(ls "$corpus" | wc -l)"
  if [ "$status" -eq 0 ]; then result="clean"; else result="FAILED (exit $status)"; failed=1; fi
  echo "fuzz: $t: ${elapsed}s, ${execs:-?} executions, ${rate} execs/s, peak RSS ${rss:-?} MB," \
    "corpus $files files: $result"
  echo "| $t | $elapsed | ${execs:-?} | $rate | ${rss:-?} | $files | $result |" >>"$results"
  [ "$status" -eq 0 ] || echo "fuzz: see $log and $crashes/$t-*"
done
exit "$failed"
