#!/bin/sh
# Runs each fuzz target for SECONDS (default 60), one after the other in one process each (no
# -jobs/-workers), on inputs of up to 64 KB with the command-line tool's default limits. An
# input that takes longer than -timeout is a finding: 60 s, and for STEP 330 s (its reader's
# own budget is 60 s of parsing and 300 s of tessellation).
# Usage: fuzz/run.sh [SECONDS] [TARGET...]   (needs cargo-fuzz and a nightly toolchain; set
# FUZZ_TOOLCHAIN="" with RUSTC_BOOTSTRAP=1 to use the stable toolchain instead;
# FUZZ_BUILD_FLAGS, e.g. "--dev -s none", builds faster for short runs: the long runs keep
# cargo-fuzz's default, optimised with AddressSanitizer)
#
# A reader target is first run once on each of its seeds (valid files, see seed.sh) with
# SCODE_FUZZ_SEEDS=1, under which a seed that fails to read is a crash: a target whose reader
# refused everything would otherwise fuzz its first error path and pass.
set -e
SECONDS_PER_TARGET="${1:-60}"
[ $# -gt 0 ] && shift
TARGETS="${*:-decode decode_crafted roundtrip read_obj read_ply read_stl read_gltf read_off read_step}"
cd "$(dirname "$0")"
sh ./seed.sh
TOOLCHAIN=${FUZZ_TOOLCHAIN-+nightly}
# shellcheck disable=SC2086 # flags split on spaces
cargo $TOOLCHAIN fuzz build ${FUZZ_BUILD_FLAGS:-}
for t in $TARGETS; do
    mkdir -p "corpus/$t"
    if [ -s "corpus/$t.seeds" ] && [ "${t#read_}" != "$t" ]; then
        # shellcheck disable=SC2046 # one argument per seed file
        echo "== $t: every seed must read ($(wc -l < "corpus/$t.seeds") files)"
        SCODE_FUZZ_SEEDS=1 cargo $TOOLCHAIN fuzz run ${FUZZ_BUILD_FLAGS:-} "$t" $(cat "corpus/$t.seeds") -- \
            -rss_limit_mb=2048 > "corpus/$t.seeds.log" 2>&1 ||
            { tail -n 30 "corpus/$t.seeds.log"; exit 1; }
    fi
    timeout=60
    [ "$t" = read_step ] && timeout=330
    echo "== $t: fuzzing for ${SECONDS_PER_TARGET}s"
    # shellcheck disable=SC2086
    cargo $TOOLCHAIN fuzz run ${FUZZ_BUILD_FLAGS:-} "$t" "corpus/$t" -- -max_total_time="$SECONDS_PER_TARGET" \
        -rss_limit_mb=2048 -max_len=65536 -len_control=10 -timeout="$timeout" \
        -print_final_stats=1
done
