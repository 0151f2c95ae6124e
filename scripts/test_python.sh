#!/usr/bin/env bash
# Tests of the Python package (python/): builds it into a fresh virtual environment the way
# the README installs it (`pip install ./python`, maturin, release build) and runs pytest on
# corpus models, plus the Ray batch conversion (python/tests/test_batch.py) unless BATCH=0.
# Kept out of scripts/test.sh: the extension's release build and the Python packages (numpy,
# and Ray Data with pyarrow for the batch test) would take it beyond its time budget.
# Usage: scripts/test_python.sh        (VENV=DIR reuses a virtual environment; BATCH=0 skips
#                                       installing Ray and the batch test)
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}
VENV=${VENV:-$(mktemp -d)/venv}
"$PYTHON" -m venv "$VENV"
# shellcheck disable=SC1091
source "$VENV/bin/activate"
python -m pip install -q --upgrade pip
EXTRAS="test"
if [ "${BATCH:-1}" != "0" ]; then
  EXTRAS="test,batch"
fi
echo "== pip install ./python[$EXTRAS] into $VENV"
pip install -q "./python[$EXTRAS]"
echo "== pytest python/tests"
cd python/tests
python -m pytest -q
