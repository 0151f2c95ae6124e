#!/usr/bin/env bash
# Runs the slow corpus sweeps: the STEP-path and fitted-mesh corpus checks of scripts/test.sh
# on the larger corpus models (tests/sweep.rs, built only with the `sweep` feature), in a
# release build, printing one line per model. They need the corpus (SCODE_CORPUS, else
# ../shared/corpus, else /work/shared/corpus); under CI a missing corpus fails.
# Usage: scripts/sweep.sh [FILTER]    (FILTER: a test name or part of one, e.g. step_path)
# The per-file table of every corpus STEP file, which asserts nothing, is an example:
# cargo run --release --example step_sweep
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test -p scode --release --features sweep --test sweep -- --nocapture "$@"
