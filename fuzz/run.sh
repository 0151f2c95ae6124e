#!/bin/sh
# Runs each fuzz target for SECONDS (default 60), one after the other.
# Usage: fuzz/run.sh [SECONDS]   (needs cargo-fuzz and a nightly toolchain; set
# FUZZ_TOOLCHAIN="" with RUSTC_BOOTSTRAP=1 to use the stable toolchain instead)
set -e
SECONDS_PER_TARGET="${1:-60}"
cd "$(dirname "$0")"
sh ./seed.sh
for t in decode roundtrip; do
    mkdir -p "corpus/$t"
    cargo ${FUZZ_TOOLCHAIN-+nightly} fuzz run "$t" "corpus/$t" -- -max_total_time="$SECONDS_PER_TARGET" -rss_limit_mb=2048 -max_len=65536 -len_control=10
done
