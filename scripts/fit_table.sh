#!/usr/bin/env bash
# Re-measures the fitting table of BENCHMARKS.md: every face-grouped fine tessellation of the
# shared corpus, fandisk (segmented) and the NIST export, encoded at the default tolerance by
# the release binary, with Draco `-qp 10 -cl 10` on the same file when draco_encoder is on PATH.
# Usage: scripts/fit_table.sh [OUT_DIR] [MODEL_SUBSTRING...]
#   SCODE=path/to/scode overrides the binary; THREADS=1 runs the encoder on one thread.
# Prints a Markdown table (and writes OUT_DIR/fit_table.md, OUT_DIR/*.log, OUT_DIR/*.scode).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-/tmp/scode-fit-table}
shift || true
SCODE=${SCODE:-target/release/scode}
CORPUS=../shared/corpus
mkdir -p "$OUT"
[ -x "$SCODE" ] || { echo "no binary at $SCODE: run cargo build --release first" >&2; exit 2; }
models=("$CORPUS/tess/nist_ftc_08_asme1_ap242-2_cadexport.obj" "$CORPUS/meshes/fandisk.obj")
for f in "$CORPUS"/tess/*_fine.obj; do models+=("$f"); done
{
  echo "| model | input triangles | control vertices | \`.scode\` bytes | max error / diag | RMS error / diag | encode time (wall) | Draco \`-qp 10 -cl 10\` bytes | Draco / scode | tolerance |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"
} >"$OUT/fit_table.md"
for m in "${models[@]}"; do
  name=$(basename "$m" .obj)
  if [ $# -gt 0 ]; then
    hit=0
    for s in "$@"; do [[ "$name" == *"$s"* ]] && hit=1; done
    [ $hit = 1 ] || continue
  fi
  log="$OUT/$name.log"
  start=$(date +%s.%N)
  if ! RAYON_NUM_THREADS=${THREADS:-${RAYON_NUM_THREADS:-2}} "$SCODE" encode -v "$m" "$OUT/$name.scode" >"$log" 2>&1; then
    echo "| $name | | | | | | | | | FAILED: $(tail -1 "$log") |" >>"$OUT/fit_table.md"
    continue
  fi
  secs=$(echo "$(date +%s.%N) - $start" | bc)
  tris=$(sed -n 's/^read .*: [0-9]* vertices, \([0-9]*\) faces.*/\1/p' "$log" | head -1)
  cv=$(sed -n 's/^fitted .* with \([0-9]*\) control vertices.*/\1/p' "$log" | head -1)
  bytes=$(sed -n 's/^wrote .*: \([0-9]*\) bytes.*/\1/p' "$log" | head -1)
  line=$(grep '^decoded surface at level' "$log" | head -1)
  lvl=$(echo "$line" | sed -n 's/^decoded surface at level \([0-9]*\).*/\1/p')
  maxd=$(echo "$line" | sed -n 's/.*max [^ ]* (\([^ ]*\) of the diagonal).*/\1/p')
  rms=$(echo "$line" | sed -n 's/.*, rms \([^,]*\),.*/\1/p')
  diag=$(echo "$line" | sed -n 's/.*max \([^ ]*\) (\([^ ]*\) of the diagonal).*/\1 \2/p' | awk '{printf "%.10g", $1/$2}')
  rmsd=$(awk -v r="$rms" -v d="$diag" 'BEGIN{printf "%.2e", r/d}')
  if echo "$line" | grep -q 'NOT met'; then
    verdict="NOT met ($(echo "$line" | sed -n 's/.*NOT met: \([0-9.]*x\) the tolerance.*/\1/p')), level $lvl"
  else verdict="met, level $lvl"; fi
  draco="" ratio=""
  if command -v draco_encoder >/dev/null 2>&1; then
    draco_encoder -i "$m" -o "$OUT/$name.drc" -qp 10 -cl 10 >/dev/null 2>&1 && draco=$(stat -c %s "$OUT/$name.drc")
    [ -n "$draco" ] && ratio=$(awk -v a="$draco" -v b="$bytes" 'BEGIN{printf "%.1fx", a/b}')
  fi
  printf '| %s | %s | %s | %s | %s | %s | %.0f s | %s | %s | %s |\n' "$name" "$tris" "$cv" "$bytes" "$maxd" "$rmsd" "$secs" "$draco" "$ratio" "$verdict" >>"$OUT/fit_table.md"
  tail -1 "$OUT/fit_table.md"
done
echo
cat "$OUT/fit_table.md"
