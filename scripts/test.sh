#!/usr/bin/env bash
# Sets up what the tests need on a fresh machine and runs them: formatting, lints, the whole
# test suite (unit, property, corpus round-trips, spec vectors) and a short fuzzing pass.
# Usage: scripts/test.sh            (FUZZ_SECONDS=30 by default; FUZZ_SECONDS=0 skips fuzzing)
set -euo pipefail
cd "$(dirname "$0")/.."

FUZZ_SECONDS=${FUZZ_SECONDS:-30}

echo "== toolchain"
rustup component add rustfmt clippy >/dev/null 2>&1 || true
cargo --version

if [ ! -d ../shared/corpus ]; then
  echo "note: ../shared/corpus not found; corpus tests will report that they were skipped" >&2
fi

echo "== cargo fmt --check"
cargo fmt --all -- --check

echo "== cargo clippy"
cargo clippy --all-targets -- -D warnings

echo "== cargo test"
PROPTEST_CASES=${PROPTEST_CASES:-64} cargo test --all-targets

if [ -d fuzz ] && [ "$FUZZ_SECONDS" != "0" ]; then
  echo "== fuzz (${FUZZ_SECONDS}s per target)"
  if ! rustup toolchain list | grep -q nightly; then
    echo "nightly toolchain missing: building fuzz targets with RUSTC_BOOTSTRAP=1 on stable" >&2
    export RUSTC_BOOTSTRAP=1
    FUZZ_TOOLCHAIN=""
  else
    FUZZ_TOOLCHAIN="+nightly"
  fi
  if ! command -v cargo-fuzz >/dev/null 2>&1; then
    cargo install cargo-fuzz --locked
  fi
  FUZZ_TOOLCHAIN="$FUZZ_TOOLCHAIN" fuzz/run.sh "$FUZZ_SECONDS"
fi
echo "== all checks passed"
