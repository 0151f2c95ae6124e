#!/bin/sh
# Fills each target's seed list (corpus/<target>.seeds: valid inputs that must read, see
# run.sh) and its working corpus (corpus/<target>/): the frozen spec vectors for `decode`,
# the small files in seeds/<target>/ for the mesh readers, the STEP files of tests/data for
# `read_step`, and from the shared CAD corpus (when found: $SCODE_CORPUS, ../shared/corpus,
# /work/shared/corpus) its STEP and OBJ files of at most 64 KB (the fuzzers' -max_len). The
# corpus files are read in place, never copied into the repository.
set -e
cd "$(dirname "$0")"
MAX=65536
for c in "${SCODE_CORPUS:-}" ../../shared/corpus /work/shared/corpus; do
    if [ -n "$c" ] && [ -f "$c/MANIFEST.md" ]; then CORPUS="$c"; break; fi
done
small() { # files of at most MAX bytes among the arguments that exist
    for f in "$@"; do
        if [ -f "$f" ] && [ "$(wc -c < "$f")" -le "$MAX" ]; then echo "$f"; fi
    done
}
mkdir -p corpus
small ../spec/vectors/*.scode ../spec/vectors/v3/*.scode > corpus/decode.seeds
for t in read_obj read_ply read_stl read_gltf read_off; do
    small seeds/$t/* > corpus/$t.seeds
done
small ../tests/data/*.step > corpus/read_step.seeds
if [ -n "${CORPUS:-}" ]; then
    small "$CORPUS"/step/*.step "$CORPUS"/step/*.stp >> corpus/read_step.seeds
    small "$CORPUS"/tess/*.obj "$CORPUS"/meshes/*.obj >> corpus/read_obj.seeds
else
    echo "note: CAD corpus not found; seeding from the repository's files only" >&2
fi
for list in corpus/*.seeds; do
    t=$(basename "$list" .seeds)
    mkdir -p "corpus/$t"
    # Copies named by content, so a seed already fuzzed from is not added twice.
    while read -r f; do
        cp "$f" "corpus/$t/seed-$(cksum < "$f" | cut -d' ' -f1)"
    done < "$list"
    echo "seeded corpus/$t with $(wc -l < "$list") files"
done
