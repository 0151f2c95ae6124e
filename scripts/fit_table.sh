#!/usr/bin/env bash
# Prints the fitted mesh path table of BENCHMARKS.md (every face-grouped corpus model and
# fandisk at the default tolerance, with Draco when draco_encoder is on PATH) without
# rewriting BENCHMARKS.md: the `mesh` section of scripts/benchmarks.sh, made in OUT_DIR.
# Usage: scripts/fit_table.sh [OUT_DIR] [MODEL_SUBSTRING...]
#   SCODE, SCODE_CORPUS, THREADS and RUNS as for scripts/benchmarks.sh. OUT_DIR (default
#   /tmp/scode-fit-table) keeps the .scode files, the logs and mesh.md.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-/tmp/scode-fit-table}
shift || true
mkdir -p "$OUT"
OUT=$OUT DOC="$OUT/BENCHMARKS.md" ONLY=mesh MODELS="$*" scripts/benchmarks.sh
grep '^|' "$OUT/mesh.md"
