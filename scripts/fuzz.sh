#!/usr/bin/env bash
# Fuzzes the pickle / .npy / .npz readers (fuzz/pickle_fuzz.cpp) with libFuzzer, ASan and UBSan.
#
#   scripts/fuzz.sh [seconds]        (default 60)
#
# Builds a separate clang tree in build-fuzz/ (needs: apt-get install clang libclang-rt-14-dev),
# seeds fuzz/corpus/ with the small fixtures tests/python/make_io_fixtures.py writes, runs for
# the given time and prints the result; crashing inputs land in fuzz/crashes/. Exit status 0
# when the run was clean. TH_FUZZ_JOBS sets the build parallelism (default 2).
set -euo pipefail

seconds="${1:-60}"
root="$(cd "$(dirname "$0")/.." && pwd)"
build="$root/build-fuzz"
corpus="$root/fuzz/corpus"
crashes="$root/fuzz/crashes"
python="${TH_PYTHON:-/usr/bin/python3}"

mkdir -p "$build"
cmake -S "$root" -B "$build" -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DTH_BUILD_FUZZ=ON -DTH_BUILD_TESTS=OFF -DTH_BUILD_BENCH=OFF >"$build/configure.log" 2>&1 ||
  { cat "$build/configure.log"; exit 1; }
cmake --build "$build" --target pickle_fuzz -j "${TH_FUZZ_JOBS:-2}"

mkdir -p "$corpus" "$crashes"
seeds="$build/seeds"
if [ ! -f "$seeds/DONE" ]; then
  (cd "$root" && "$python" tests/python/make_io_fixtures.py "$seeds")
fi
find "$seeds" -type f -size -16k \( -name '*.pkl' -o -name '*.npy' -o -name '*.npz' \) -exec cp {} "$corpus/" \;

log="$build/fuzz.log"
echo "fuzz: running pickle_fuzz for ${seconds}s on $(ls "$corpus" | wc -l) corpus files (log: $log)"
set +e
ASAN_OPTIONS="detect_leaks=1:allocator_may_return_null=1" \
  "$build/fuzz/pickle_fuzz" "$corpus" -max_total_time="$seconds" -max_len=16384 -timeout=20 \
  -rss_limit_mb=4096 -artifact_prefix="$crashes/" -print_final_stats=1 >"$log" 2>&1
status=$?
set -e
grep -E "^Done|INITED|stat::number_of_executed_units|stat::peak_rss_mb|ERROR|SUMMARY|Test unit written|deadly" "$log" || true
if [ "$status" -eq 0 ]; then
  echo "fuzz: clean after ${seconds}s"
else
  echo "fuzz: FAILED (exit $status); see $log and $crashes/"
fi
exit "$status"
