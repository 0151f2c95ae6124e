#!/usr/bin/env bash
# Regenerates BENCHMARKS.md: what scode costs and how well it fits, measured by the `scode`
# binary on the shared corpus. The file is this script's output; edit the script, not it.
#
# Usage: scripts/benchmarks.sh
#   SCODE=path          scode binary (default target/release/scode, built when missing)
#   SCODE_CORPUS=dir    the shared corpus (default ../shared/corpus)
#   THREADS=n           RAYON_NUM_THREADS for every scode run (default: all cores)
#   RUNS=n              encode runs per model; encode times are their median (default 1)
#   DECODE_RUNS=n       decode runs per model; decode times are their median (default 3)
#   ONLY=section        measure one section: mesh, step, raw or decode (default: all four)
#   MODELS="a b"        only files whose name contains one of these words (default: all)
#   OUT=dir             encoded files, logs and section fragments (default /tmp/scode-benchmarks)
#   DOC=file            the document to write (default BENCHMARKS.md)
# Example: ONLY=mesh MODELS="four_cone screw" THREADS=1 scripts/benchmarks.sh
#
# Sections: mesh (fitted mesh path), step (STEP path), raw (raw path), decode, and a last one
# naming the commands of the other measurements (criterion benches, viewer, rate-distortion).
# Each section sits between `<!-- benchmarks.sh: NAME -->` and `<!-- /benchmarks.sh: NAME -->`
# and starts with the commit, date, machine and options it was measured with. A run with ONLY
# rewrites its section and keeps the others from the existing DOC, so the document stays
# complete (a section DOC does not hold yet says "not measured yet"); every section says which
# models it covers. MODELS matches substrings: "block" takes block.off and block_fillet3_*.
#
# Draco: when `draco_encoder` is on PATH (Debian package `draco`), the mesh and raw tables
# compare with `draco_encoder -qp 10 -cl 10` on the same input; otherwise their Draco
# column says it was not installed. Needs bash, awk, sed, git and /usr/bin/time (GNU time).
#
# The tables are read off what the commands print: `scode encode -v` (its `read ...`,
# `fitted N faces ... with N control vertices`, `decoded surface at level ... met` and
# `wrote ...: N bytes` lines), `scode info --against` (`symmetric: max ...`) and `scode
# decode` (`decode and subdivide N ms`). An empty cell means one of those lines changed.
set -euo pipefail
cd "$(dirname "$0")/.."

CORPUS=${SCODE_CORPUS:-../shared/corpus}
RUNS=${RUNS:-1}
DECODE_RUNS=${DECODE_RUNS:-3}
OUT=${OUT:-/tmp/scode-benchmarks}
DOC=${DOC:-BENCHMARKS.md}
MODELS=${MODELS:-}
SECTIONS=(mesh step raw decode)
ONLY=${ONLY:-}
if [ -n "$ONLY" ] && [[ " ${SECTIONS[*]} " != *" $ONLY "* ]]; then
  echo "ONLY must be one of: ${SECTIONS[*]}" >&2
  exit 2
fi
if [ -n "${THREADS:-}" ]; then export RAYON_NUM_THREADS=$THREADS; fi
if [ -z "${SCODE:-}" ]; then
  SCODE=target/release/scode
  [ -x "$SCODE" ] || cargo build --release
fi
[ -x "$SCODE" ] || { echo "no scode binary at $SCODE" >&2; exit 2; }
[ -d "$CORPUS" ] || { echo "no corpus at $CORPUS (set SCODE_CORPUS)" >&2; exit 2; }
[ -x /usr/bin/time ] || { echo "needs GNU time at /usr/bin/time (Debian package time)" >&2; exit 2; }
mkdir -p "$OUT"
DRACO=$(command -v draco_encoder || true)
NO_DRACO="not installed"

# ---------------------------------------------------------------- helpers

# Whether file name $1 passes the MODELS filter.
wanted() {
  [ -z "$MODELS" ] && return 0
  local w
  for w in $MODELS; do [[ "$1" == *"$w"* ]] && return 0; done
  return 1
}

# Median of the numbers on stdin (one per line).
median() {
  sort -g | awk '{ v[NR] = $1 } END { if (NR == 0) print ""; else if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'
}

# The first capture of sed expression $1 in file $2 (empty when there is none).
grab() { sed -n "$1" "$2" | head -1 || true; }

# Runs a command RUNS times ($1 = count, $2 = log file, then the command) under GNU time and
# prints "median-seconds max-KiB"; the log holds the last run's output. Fails when a run fails;
# exit status 5 (`scode encode`: tolerance not met, the file is written) is a result the
# tables report, not a failure.
timed() {
  local n=$1 log=$2 i rc
  shift 2
  : >"$OUT/times"
  for ((i = 0; i < n; i++)); do
    rc=0
    /usr/bin/time -f '%e %M' -o "$OUT/time" "$@" >"$log" 2>&1 || rc=$?
    if [ "$rc" != 0 ] && [ "$rc" != 5 ]; then return 1; fi
    # GNU time puts "Command exited with non-zero status N" before its own line.
    tail -1 "$OUT/time" >>"$OUT/times"
  done
  echo "$(cut -d' ' -f1 "$OUT/times" | median) $(cut -d' ' -f2 "$OUT/times" | sort -g | tail -1)"
}

# Draco bytes of mesh $1 (OFF converted to OBJ first), or "$NO_DRACO".
draco_bytes() {
  [ -n "$DRACO" ] || { echo "$NO_DRACO"; return; }
  local in=$1 name
  name=$(basename "${1%.*}")
  if [[ "$in" == *.off ]]; then
    # OFF: counts after the header, then vertices, then "n i j k ..." faces (0-based).
    awk 'NR == 1 { next } /^#/ || NF == 0 { next }
         !c { nv = $1; nf = $2; c = 1; next }
         nv > 0 { print "v", $1, $2, $3; nv--; next }
         nf > 0 { s = "f"; for (i = 2; i <= $1 + 1; i++) s = s " " ($i + 1); print s; nf-- }' \
      "$in" >"$OUT/$name.off.obj"
    in="$OUT/$name.off.obj"
  fi
  if "$DRACO" -i "$in" -o "$OUT/$name.drc" -qp 10 -cl 10 >/dev/null 2>&1; then
    stat -c %s "$OUT/$name.drc"
  else
    echo "failed"
  fi
}

# A note under a table of $1 rows when MODELS left none.
no_rows() {
  if [ "$1" = 0 ]; then
    echo
    echo "(No corpus file of this section matches MODELS=\"$MODELS\".)"
  fi
}

# a / b to $3 decimals, empty when either is not a number.
ratio() {
  awk -v a="$1" -v b="$2" -v d="${3:-2}" \
    'BEGIN { if (a ~ /^[0-9.]+$/ && b ~ /^[0-9.]+$/ && b > 0) printf "%.*f", d, a / b }'
}

# Commit of the working tree ("+dirty" when tracked files other than BENCHMARKS.md differ
# from it).
commit() {
  local c
  c=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
  if [ -n "$(git status --porcelain --untracked-files=no -- . ':(exclude)BENCHMARKS.md' 2>/dev/null)" ]; then
    c="$c+dirty"
  fi
  echo "$c"
}

CPU=$(sed -n 's/^model name[[:space:]]*: //p' /proc/cpuinfo | head -1)
CORES=$(grep -c '^processor' /proc/cpuinfo)
MEM=$(awk '/^MemTotal/ { printf "%.0f GiB", $2 / 1048576 }' /proc/meminfo)
STAMP="$(date -u +%Y-%m-%d) at commit \`$(commit)\`, $CPU ($CORES cores, $MEM), load average \
$(cut -d' ' -f1-3 /proc/loadavg) at the start, threads: ${RAYON_NUM_THREADS:-all $CORES}, \
models: ${MODELS:-all}"

# Title of section $1.
title() {
  case $1 in
    mesh) echo "Fitted mesh path" ;;
    step) echo "STEP path" ;;
    raw) echo "Raw path" ;;
    decode) echo "Decode" ;;
  esac
}

# The first lines of section $1: its title, command and measurement conditions.
section_head() {
  echo "## $(title "$1")"
  echo
  echo "Regenerate: \`ONLY=$1 scripts/benchmarks.sh\`. Measured $STAMP."
  echo
}

# ---------------------------------------------------------------- sections

# Fitted mesh path: every face-grouped corpus model (the fine tessellations with their
# sidecars, and the NIST export) and fandisk (no groups: segmented first), at the default
# tolerance; errors as `scode info --against` measures them.
section_mesh() {
  local dir="$OUT/mesh" m name log s secs faces cv bytes tris verdict sym maxd rmsd draco r
  local n=0 met=0 t_faces=0 t_tris=0 t_cv=0 t_bytes=0 t_secs=0 t_draco=0
  mkdir -p "$dir"
  section_head mesh
  echo "\`scode encode -v MODEL.obj\` at the default tolerance (1e-3 of the bounding-box diagonal,"
  echo "held to the input mesh itself), then \`scode info FILE.scode --against MODEL.obj\` for"
  echo "the symmetric max and RMS distance between the decoded surface (default level) and the input,"
  echo "relative to the diagonal. Encode time: wall time of \`scode encode\`, median of $RUNS run(s)."
  echo "Draco: \`draco_encoder -qp 10 -cl 10\` on the same OBJ file."
  echo
  echo "| model | CAD faces | input triangles | control vertices | bytes | max / diag | RMS / diag | tolerance | encode (s) | Draco bytes | Draco / scode |"
  echo "|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|"
  for m in "$CORPUS/tess/nist_ftc_08_asme1_ap242-2_cadexport.obj" "$CORPUS/meshes/fandisk.obj" \
    "$CORPUS"/tess/*_fine.obj; do
    name=$(basename "$m" .obj)
    [ -f "$m" ] && wanted "$name" || continue
    log="$dir/$name.log"
    echo "mesh: $name" >&2
    if ! s=$(timed "$RUNS" "$log" "$SCODE" encode -v "$m" "$dir/$name.scode"); then
      echo "| $name | | | | | | | failed: $(tail -1 "$log") | | | |"
      continue
    fi
    secs=${s% *}
    faces=$(grab 's/^fitted \([0-9]*\) faces.*/\1/p' "$log")
    cv=$(grab 's/^fitted .* with \([0-9]*\) control vertices.*/\1/p' "$log")
    bytes=$(grab 's/^wrote .*: \([0-9]*\) bytes.*/\1/p' "$log")
    tris=$(grab 's/^wrote .*; input [0-9]* vertices, \([0-9]*\) faces.*/\1/p' "$log")
    verdict=$(grab 's/^decoded surface at level .* \(met\)$/\1/p; s/^decoded surface at level .*NOT met: \([0-9.]*x\).*/NOT met (\1)/p' "$log")
    "$SCODE" info "$dir/$name.scode" --against "$m" >"$dir/$name.info" 2>&1 || true
    sym=$(grep 'symmetric:' "$dir/$name.info" || true)
    maxd=$(echo "$sym" | sed -n 's/.*max [^ ]* (\([^ ]*\) of the diagonal).*/\1/p')
    rmsd=$(echo "$sym" | sed -n 's/.*, rms [^ ]* (\([^ ]*\)).*/\1/p')
    if [ "$name" = fandisk ]; then name="fandisk (segmented)"; fi
    draco=$(draco_bytes "$m")
    r=$(ratio "$draco" "$bytes" 1)
    echo "| $name | $faces | $tris | $cv | $bytes | $maxd | $rmsd | $verdict | $secs | $draco | ${r:+${r}x} |"
    n=$((n + 1))
    if [ "$verdict" = met ]; then met=$((met + 1)); fi
    t_faces=$((t_faces + ${faces:-0})) t_tris=$((t_tris + ${tris:-0}))
    t_cv=$((t_cv + ${cv:-0})) t_bytes=$((t_bytes + ${bytes:-0}))
    t_secs=$(awk -v a="$t_secs" -v b="$secs" 'BEGIN { print a + b }')
    if [[ "$draco" =~ ^[0-9]+$ ]]; then t_draco=$((t_draco + draco)); fi
  done
  if [ -n "$DRACO" ]; then r=$(ratio "$t_draco" "$t_bytes" 1); r=${r:+${r}x}; else t_draco=$NO_DRACO r=""; fi
  echo "| **total ($n models)** | $t_faces | $t_tris | $t_cv | **$t_bytes** | | | $met of $n met | $t_secs | $t_draco | $r |"
  no_rows "$n"
}

# STEP path: every corpus STEP file read, tessellated and fitted by `scode encode -v
# --allow-skipped` at the default tolerance, with the peak memory of the process.
section_step() {
  local dir="$OUT/step" f name log s secs rss faces skipped bytes verdict why
  local n=0 met=0 t_faces=0 t_bytes=0 t_secs=0 max_rss=0
  mkdir -p "$dir"
  section_head step
  echo "\`scode encode -v --allow-skipped PART.step\` at the default tolerance (1e-3 of the diagonal of the file's own"
  echo "tessellation): faces read (and skipped, each named in the log), bytes, wall time (median of"
  echo "$RUNS run(s)), peak resident memory (\`/usr/bin/time -f %M\`, largest of the runs), and whether"
  echo "the decoded surface is within the tolerance."
  echo
  echo "| file | faces | skipped | bytes | encode (s) | peak RSS (MiB) | tolerance |"
  echo "|---|---:|---:|---:|---:|---:|---|"
  for f in "$CORPUS"/step/*; do
    name=$(basename "$f")
    wanted "$name" || continue
    log="$dir/$name.log"
    echo "step: $name" >&2
    if ! s=$(timed "$RUNS" "$log" "$SCODE" encode -v --allow-skipped "$f" "$dir/$name.scode"); then
      why=$(tail -1 "$log" | sed -e 's/^scode: error: //' -e "s|cannot encode $f: ||" -e "s|$f: ||g")
      echo "| $name | | | | | | not encoded: ${why//|/\\|} |"
      continue
    fi
    secs=${s% *}
    rss=$(awk -v k="${s#* }" 'BEGIN { printf "%.0f", k / 1024 }')
    faces=$(grab 's/^read .*: [0-9]* bodies, \([0-9]*\) faces.*/\1/p' "$log")
    skipped=$(grab 's/^warning: \([0-9]*\) faces skipped.*/\1/p' "$log")
    bytes=$(grab 's/^wrote .*: \([0-9]*\) bytes.*/\1/p' "$log")
    verdict=$(grab 's/^decoded surface at level .* met$/within/p; s/^decoded surface at level .*NOT met: \([0-9.]*x\).*/NOT within (\1)/p' "$log")
    echo "| $name | $faces | ${skipped:-0} | $bytes | $secs | $rss | $verdict |"
    n=$((n + 1))
    if [ "$verdict" = within ]; then met=$((met + 1)); fi
    t_faces=$((t_faces + ${faces:-0})) t_bytes=$((t_bytes + ${bytes:-0}))
    t_secs=$(awk -v a="$t_secs" -v b="$secs" 'BEGIN { print a + b }')
    if [ "$rss" -gt "$max_rss" ]; then max_rss=$rss; fi
  done
  echo "| **total ($n encoded)** | $t_faces | | **$t_bytes** | $t_secs | $max_rss (largest) | $met of $n within |"
  no_rows "$n"
}

# Raw path: every corpus mesh stored as it is (`--raw`, 10-bit positions).
section_raw() {
  local dir="$OUT/raw" m name log bytes bpv nv nf ng draco r
  local n=0 t_bytes=0 t_draco=0
  mkdir -p "$dir"
  section_head raw
  echo "\`scode encode --raw MESH\` (10-bit positions, connectivity, CAD-face groups and their names)"
  echo "of every corpus mesh: the meshes, the ABC models, the coarse tessellations and the NIST export."
  echo "Bits per vertex count the whole file. Draco: \`draco_encoder -qp 10 -cl 10\` (it stores no"
  echo "groups)."
  echo
  echo "| mesh | vertices | faces | groups | bytes | bits / vertex | Draco bytes | scode / Draco |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|"
  for m in "$CORPUS"/meshes/* "$CORPUS"/abc/*.obj "$CORPUS"/tess/*_coarse.obj "$CORPUS"/tess/*_cadexport.obj; do
    name=$(basename "$m")
    [ -f "$m" ] && wanted "$name" || continue
    log="$dir/$name.log"
    echo "raw: $name" >&2
    if ! "$SCODE" encode --raw "$m" "$dir/$name.scode" >"$log" 2>&1; then
      echo "| $name | | | | failed: $(tail -1 "$log") | | | |"
      continue
    fi
    bytes=$(grab 's/^wrote .*: \([0-9]*\) bytes.*/\1/p' "$log")
    bpv=$(grab 's/^wrote .*(\([0-9.]*\) bits per input vertex.*/\1/p' "$log")
    nv=$(grab 's/^wrote .*; input \([0-9]*\) vertices.*/\1/p' "$log")
    nf=$(grab 's/^wrote .*; input [0-9]* vertices, \([0-9]*\) faces.*/\1/p' "$log")
    ng=$(grab 's/^wrote .* faces, \([0-9]*\) groups.*/\1/p' "$log")
    draco=$(draco_bytes "$m")
    r=$(ratio "$bytes" "$draco" 3)
    echo "| $name | $nv | $nf | $ng | $bytes | $bpv | $draco | $r |"
    n=$((n + 1)) t_bytes=$((t_bytes + ${bytes:-0}))
    if [[ "$draco" =~ ^[0-9]+$ ]]; then t_draco=$((t_draco + draco)); fi
  done
  if [ -n "$DRACO" ]; then r=$(ratio "$t_bytes" "$t_draco" 3); else t_draco=$NO_DRACO r=""; fi
  echo "| **total ($n meshes)** | | | | **$t_bytes** | | $t_draco | $r |"
  no_rows "$n"
}

# Decode: `scode decode` of fitted files at their default level, and to their tolerance (the
# default), of the files of the mesh section (encoded first when missing).
section_decode() {
  local dir="$OUT/mesh" name m log ms tris rate n level acc_ms acc_tris rows=0
  mkdir -p "$dir" "$OUT/decode"
  section_head decode
  echo "\`scode decode --level L FILE.scode OUT.obj\` of fitted files at their default level L with"
  echo "limit positions and normals: the decode and subdivision time \`scode decode\` reports (file"
  echo "writing excluded), median of $DECODE_RUNS runs, and output triangles per second; and"
  echo "\`scode decode FILE.scode OUT.obj\`, to the file's tolerance (the default): its triangles"
  echo "and time; beside it \`draco_decoder\` on the input's Draco file (\`-qp 10 -cl 10\`): the"
  echo "decode time it reports (whole milliseconds), median of $DECODE_RUNS runs, and scode's time to the"
  echo "tolerance over it where Draco's is at least 10 ms (both in-process times; \`farm-bench --vs\`"
  echo "gives the whole processes' ratio)."
  echo
  echo "| model | bytes | level | output triangles | decode + subdivide (ms) | M triangles / s | to the tolerance: triangles | ms | Draco decode (ms) | ratio |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
  for name in fandisk four_cone_fine screw_fine block_fillet3_fine bug3883_xr2-ct-214_plate_fine bug33398_fine; do
    wanted "$name" || continue
    m="$CORPUS/tess/$name.obj"
    if [ "$name" = fandisk ]; then m="$CORPUS/meshes/fandisk.obj"; fi
    [ -f "$m" ] || continue
    echo "decode: $name" >&2
    if [ ! -s "$dir/$name.scode" ]; then
      "$SCODE" encode "$m" "$dir/$name.scode" >"$dir/$name.log" 2>&1 || [ $? = 5 ] || {
        echo "| $name | | | | encode failed | | | |"
        continue
      }
    fi
    level=$("$SCODE" info "$dir/$name.scode" | grab 's/.*default decode level \([0-9]*\).*/\1/p' /dev/stdin)
    log="$OUT/decode/$name.log"
    : >"$OUT/decode/$name.ms"
    for ((n = 0; n < DECODE_RUNS; n++)); do
      "$SCODE" decode --level "$level" "$dir/$name.scode" "$OUT/decode/$name.obj" >"$log" 2>&1 || break
      grab 's/.*decode and subdivide \([0-9.]*\) ms.*/\1/p' "$log" >>"$OUT/decode/$name.ms"
    done
    ms=$(median <"$OUT/decode/$name.ms")
    tris=$(grab 's/^wrote .*: [0-9]* vertices, \([0-9]*\) faces.*/\1/p' "$log")
    rate=$(awk -v t="$tris" -v ms="$ms" 'BEGIN { if (ms > 0) printf "%.1f", t / ms / 1000 }')
    : >"$OUT/decode/$name.acc.ms"
    for ((n = 0; n < DECODE_RUNS; n++)); do
      "$SCODE" decode "$dir/$name.scode" "$OUT/decode/$name.acc.obj" >"$log.acc" 2>&1 || break
      grab 's/.*decode and subdivide \([0-9.]*\) ms.*/\1/p' "$log.acc" >>"$OUT/decode/$name.acc.ms"
    done
    acc_ms=$(median <"$OUT/decode/$name.acc.ms")
    acc_tris=$(grab 's/^wrote .*: [0-9]* vertices, \([0-9]*\) faces.*/\1/p' "$log.acc")
    local draco_ms="" ratio=""
    if [ -n "$DRACO" ] && command -v draco_decoder >/dev/null &&
      "$DRACO" -i "$m" -o "$OUT/decode/$name.drc" -qp 10 -cl 10 >/dev/null 2>&1; then
      : >"$OUT/decode/$name.draco.ms"
      for ((n = 0; n < DECODE_RUNS; n++)); do
        draco_decoder -i "$OUT/decode/$name.drc" -o "$OUT/decode/$name.draco.ply" >"$log.draco" 2>&1 || break
        grab 's/.*(\([0-9.]*\) ms to decode).*/\1/p' "$log.draco" >>"$OUT/decode/$name.draco.ms"
      done
      draco_ms=$(median <"$OUT/decode/$name.draco.ms")
      ratio=$(awk -v a="$acc_ms" -v b="$draco_ms" 'BEGIN { if (b >= 10) printf "%.1fx", a / b }')
    fi
    echo "| $name | $(stat -c %s "$dir/$name.scode") | $level | $tris | $ms | $rate | $acc_tris | $acc_ms | ${draco_ms:-$NO_DRACO} | $ratio |"
    rows=$((rows + 1))
  done
  no_rows "$rows"
}

# The measurements this script does not make, and the commands that make them.
section_other() {
  local gz raw
  gz=$(sed -n 's/^gzipped-bytes: //p' viewer/pkg/SOURCES 2>/dev/null || true)
  raw=$(sed -n 's/^wasm-bytes: //p' viewer/pkg/SOURCES 2>/dev/null || true)
  echo "## Other measurements"
  echo
  echo "These take longer or need more than the binary; each command prints or writes its own"
  echo "figures, which are not copied here."
  echo
  echo "* Subdivision throughput (output triangles per second, levels 1-5, 1 thread and all"
  echo "  threads; positions only, topology and positions, full decode, limit and normals):"
  echo "  \`cargo bench --bench subdivide\`. Criterion's report: \`target/criterion/report/index.html\`."
  echo "* Library encode and decode times on two corpus models (fitted and raw encode, bitstream"
  echo "  decode, decode to the viewer's surface): \`cargo bench --bench codec\`."
  echo "* The viewer in headless Chromium (decode, refinement to about a million triangles, WebGL"
  echo "  arrays; wall and main-thread CPU time): \`node viewer/test/e2e.mjs\`. The WebAssembly"
  echo "  module, as committed in \`viewer/pkg/\`: ${raw:-?} bytes, ${gz:-?} bytes gzipped (\`viewer/build.sh\`"
  echo "  rebuilds it and prints both)."
  echo "* Rate-distortion against Draco at equal error (tolerances 4e-3..5e-4, Draco \`-qp 6..14\`):"
  echo "  \`scode report ../shared/corpus -o report/\` (\`--quick\` for a shorter pass)."
}

# ---------------------------------------------------------------- the document

# The part of DOC between the markers of section $1, markers included (empty when absent).
kept_section() {
  [ -f "$DOC" ] || return 0
  awk -v b="<!-- benchmarks.sh: $1 -->" -v e="<!-- /benchmarks.sh: $1 -->" \
    '$0 == b { on = 1 } on { print } $0 == e { on = 0 }' "$DOC"
}

for s in "${SECTIONS[@]}"; do
  if [ -z "$ONLY" ] || [ "$ONLY" = "$s" ]; then
    {
      echo "<!-- benchmarks.sh: $s -->"
      "section_$s"
      echo "<!-- /benchmarks.sh: $s -->"
    } >"$OUT/$s.md"
  else
    kept_section "$s" >"$OUT/$s.md"
  fi
done

{
  echo "# Benchmarks"
  echo
  echo "Generated by \`scripts/benchmarks.sh\` (its header lists the options); do not edit by hand."
  echo "Each section names the command that regenerates it and the commit, date, machine and"
  echo "models it was measured with. Times are wall times on that machine: on a shared machine"
  echo "they vary by 10-25% between runs, sizes and errors do not."
  for s in "${SECTIONS[@]}"; do
    echo
    if [ -s "$OUT/$s.md" ]; then
      cat "$OUT/$s.md"
    else
      echo "<!-- benchmarks.sh: $s -->"
      echo "## $(title "$s")"
      echo
      echo "Not measured yet: run \`ONLY=$s scripts/benchmarks.sh\`."
      echo "<!-- /benchmarks.sh: $s -->"
    fi
  done
  echo
  section_other
} >"$OUT/document.md"
cp "$OUT/document.md" "$DOC"
echo "wrote $DOC" >&2
