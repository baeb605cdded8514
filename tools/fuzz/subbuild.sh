#!/usr/bin/env bash
# The fuzz/* and sanitize/* CTest tests (tests/fuzz/CMakeLists.txt) call this:
#   subbuild.sh build         SRC BIN          one clang build (IMR_FUZZ=ON: everything with ASan +
#                                              UBSan + coverage) of the libFuzzer targets and of the
#                                              engine and io tests; without clang/libFuzzer, a g++
#                                              IMR_SANITIZE=address,undefined build of those tests in
#                                              BIN/gcc-sanitize, and BIN/SKIPPED says why
#   subbuild.sh smoke         SRC BIN NAME SEC run BIN/fuzz/NAME_fuzz for SEC seconds on
#                                              tests/fuzz/corpus/NAME + tests/fuzz/regressions/NAME
#                                              (exit 77, skipped, when BIN/SKIPPED)
#   subbuild.sh sanitize-test SRC BIN TEST     run one of those tests (its ctest name) there
#   subbuild.sh tsan-build    SRC BIN          a g++ ThreadSanitizer build (BIN/tsan) of the tests
#                                              of the threaded code: the thread pool, the engine
#   subbuild.sh tsan-test     SRC BIN REGEX    run the ctest tests matching REGEX there
# The sub-build uses ccache (the top-level CMakeLists sets it as launcher) and -j2
# (IMR_SUBBUILD_JOBS); it lives under the main build folder.
set -euo pipefail
mode=$1 src=$2 bin=$3
jobs=${IMR_SUBBUILD_JOBS:-2}
sanitize_targets=(engine_engine_test engine_engine_property_test io_job_test io_readers_test
                  io_image_sequence_test io_stream_recorder_test)
# -O1 with assertions (no NDEBUG): fast enough to run, and CGAL's and our asserts stay armed.
common=(-G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1
        -DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -DIMR_BUILD_BENCH=OFF -DIMR_BUILD_TESTS=ON -Wno-dev)
# -gline-tables-only makes ccache hash the build folder; the sub-build's objects do not care.
export CCACHE_NOHASHDIR=${CCACHE_NOHASHDIR:-1}
export ASAN_OPTIONS=${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1}
# ubsan.supp: one known, harmless report inside CGAL (see there).
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1:suppressions=$src/tools/fuzz/ubsan.supp}

# The tests are discovered when ctest first reads the tree (gtest DISCOVERY_MODE PRE_TEST): each
# test executable newer than its list is run and the list rewritten. The sanitize tests run as
# parallel ctest calls on one tree, and one of them read a list another was writing (CI, a
# "Parse error" in io_readers_test[1]_tests.cmake). So the build, a fixture every one of them
# waits for, writes the lists once; later calls only read them.
list_tests() {
  ctest --test-dir "$1" -N >"$1/discovery.log" 2>&1 || { cat "$1/discovery.log"; exit 1; }
}

case $mode in
  build)
    mkdir -p "$bin"
    rm -f "$bin/SKIPPED"
    probe=$(mktemp -d)
    trap 'rm -rf "$probe"' EXIT
    echo 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }' \
      >"$probe/p.cc"
    if command -v clang++ >/dev/null &&
       clang++ -fsanitize=fuzzer,address,undefined "$probe/p.cc" -o "$probe/p" 2>"$probe/err"; then
      time cmake -S "$src" -B "$bin" "${common[@]}" -DCMAKE_C_COMPILER=clang \
        -DCMAKE_CXX_COMPILER=clang++ -DIMR_FUZZ=ON >"$bin/configure.log" 2>&1 ||
        { cat "$bin/configure.log"; exit 1; }
      time cmake --build "$bin" --target imr_fuzzers "${sanitize_targets[@]}" -j "$jobs"
      list_tests "$bin"
    else
      echo "clang++ with libFuzzer is not available (Debian: clang libclang-rt-14-dev; tools/setup.sh" \
           "installs them): $(head -c 300 "$probe/err" 2>/dev/null)" | tee "$bin/SKIPPED"
      echo "fuzzers skipped; building the sanitized tests with g++ in $bin/gcc-sanitize"
      mkdir -p "$bin/gcc-sanitize"
      time cmake -S "$src" -B "$bin/gcc-sanitize" "${common[@]}" -DCMAKE_C_COMPILER=gcc \
        -DCMAKE_CXX_COMPILER=g++ -DIMR_SANITIZE=address,undefined >"$bin/gcc-configure.log" 2>&1 ||
        { cat "$bin/gcc-configure.log"; exit 1; }
      time cmake --build "$bin/gcc-sanitize" --target "${sanitize_targets[@]}" -j "$jobs"
      list_tests "$bin/gcc-sanitize"
    fi
    ;;
  smoke)
    name=$4 seconds=$5
    fuzzer="$bin/fuzz/${name}_fuzz"
    if [ ! -x "$fuzzer" ]; then
      if [ -f "$bin/SKIPPED" ]; then echo "skipped: $(cat "$bin/SKIPPED")"; exit 77; fi
      echo "$fuzzer: not built (see the test fuzz/build)"; exit 1
    fi
    work=$(mktemp -d)
    trap 'rm -rf "$work"' EXIT
    corpora=("$src/tests/fuzz/corpus/$name")
    [ -d "$src/tests/fuzz/regressions/$name" ] && corpora+=("$src/tests/fuzz/regressions/$name")
    mkdir -p "$bin/artifacts"
    # New inputs go to the scratch folder (first), never into the committed corpus. A finding
    # must fail the test: libFuzzer's own error exit code is 77, CTest's skip code here.
    set -x
    "$fuzzer" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=1024 \
      -print_final_stats=1 -error_exitcode=1 -timeout_exitcode=1 -artifact_prefix="$bin/artifacts/${name}-" "$work" "${corpora[@]}"
    ;;
  sanitize-test)
    test=$4
    if [ -f "$bin/SKIPPED" ]; then bin="$bin/gcc-sanitize"; fi
    # Under ASan the three accuracy comparisons of engine_property_test take most of its time
    # and add no code path the invariant tests miss; IMR_SANITIZE_FULL=1 runs them too.
    exclude=()
    if [ "$test" = engine/engine_property_test ] && [ -z "${IMR_SANITIZE_FULL:-}" ]; then
      # ThreadsTest (one-two-four-thread runs) too: the ThreadSanitizer run covers the threads;
      # so are the comparisons of whole runs whose both sides other tests walk (80-180 s each
      # under ASan): PlannedMovesTest (every exact-mode test on two threads plans its moves),
      # FilteredWalkTest.SameCellsAsCgalsWalk (check_invariants compares every filtered walk
      # with CGAL's), ManifoldTestTest (the link-based test is a reference only) and
      # DeterminismTest; of the invariant tests, the first seed of each mode and scene.
      exclude=(-E 'GeometryTest\.(ClosedRoomSeenFromInside|EfficientPolicyComparableToBaseline|ExactModeOnBothScenes)|ThreadsTest\.|PlannedMovesTest\.|FilteredWalkTest\.SameCellsAsCgalsWalk|ManifoldTestTest\.|DeterminismTest\.|InvariantTest\..*_7( |$)')
    fi
    ctest --test-dir "$bin" -R "^${test}\\." "${exclude[@]}" --output-on-failure --no-tests=error \
      -j "$jobs"
    ;;
  tsan-build)
    # g++'s ThreadSanitizer (libtsan, part of gcc): the engine casts rays on a thread pool.
    mkdir -p "$bin/tsan"
    time cmake -S "$src" -B "$bin/tsan" "${common[@]}" -DCMAKE_C_COMPILER=gcc \
      -DCMAKE_CXX_COMPILER=g++ -DIMR_SANITIZE=thread >"$bin/tsan-configure.log" 2>&1 ||
      { cat "$bin/tsan-configure.log"; exit 1; }
    time cmake --build "$bin/tsan" --target util_thread_pool_test engine_engine_property_test -j "$jobs"
    list_tests "$bin/tsan"
    ;;
  tsan-test)
    regex=$4
    export TSAN_OPTIONS=${TSAN_OPTIONS:-halt_on_error=1:second_deadlock_stack=1}
    ctest --test-dir "$bin/tsan" -R "$regex" --output-on-failure --no-tests=error -j "$jobs"
    ;;
  *)
    echo "usage: $0 build|smoke|sanitize-test|tsan-build|tsan-test SRC BIN [NAME SECONDS | TEST | REGEX]" >&2
    exit 2
    ;;
esac
