#!/bin/sh
# Seeds the decode corpus with the frozen spec vectors.
set -e
cd "$(dirname "$0")"
mkdir -p corpus/decode
cp ../spec/vectors/*.scode corpus/decode/
echo "seeded corpus/decode with $(ls ../spec/vectors/*.scode | wc -l) vectors"
