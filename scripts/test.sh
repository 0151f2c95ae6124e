#!/usr/bin/env bash
# Sets up what the tests need on a fresh machine and runs them: formatting, lints, the whole
# test suite of the library and of the command-line tool (`cli/`): unit, property, corpus
# round-trips and encodes of the small corpus models, spec vectors, the Khronos glTF
# validator on decoded glTF; the decoder-only, library-dependency and WebAssembly-viewer
# checks, the viewer's end-to-end test in headless Chromium, and a short fuzzing pass. The same corpus checks on the larger models are scripts/sweep.sh.
# Usage: scripts/test.sh            (FUZZ_SECONDS=10 per fuzz target by default, nine targets;
#                                    FUZZ_SECONDS=0 skips fuzzing; E2E=0 skips the browser test)
set -euo pipefail
cd "$(dirname "$0")/.."

# Nine targets (fuzz/run.sh): 10 s each keeps the step, with building them, to a few
# minutes; the long runs are `fuzz/run.sh 1800`.
FUZZ_SECONDS=${FUZZ_SECONDS:-10}

echo "== toolchain"
rustup component add rustfmt clippy >/dev/null 2>&1 || true
cargo --version

if [ -z "${SCODE_CORPUS:-}" ] && [ ! -d ../shared/corpus ] && [ ! -d /work/shared/corpus ]; then
  if [ -n "${CI:-}" ]; then
    echo "error: corpus not found (../shared/corpus, /work/shared/corpus; or set SCODE_CORPUS)" >&2
    exit 1
  fi
  echo "note: corpus not found; corpus tests will report that they were skipped" >&2
fi

echo "== cargo fmt --check"
cargo fmt --all -- --check
cargo fmt --manifest-path wasm/Cargo.toml --all -- --check
cargo fmt --manifest-path tests/embed/Cargo.toml -- --check

echo "== viewer/pkg built from the current decoder sources"
viewer/build.sh --check

echo "== the library alone, without its feature internals (lints, dead code): default features, decoder"
# Test, bench and example builds turn `internals` on (the crate's dev-dependency on itself),
# so the clippy run over all targets below never sees the library without it.
cargo clippy -p scode --lib -- -D warnings
cargo clippy -p scode --lib --no-default-features -- -D warnings

echo "== the library's default features: none of the command-line tool's dependencies"
LIB_DEPS=$(cargo tree -p scode --locked -e normal --prefix none)
if echo "$LIB_DEPS" | grep -E '^(clap|anyhow|indicatif|plotters|png|mimalloc) '; then
  echo "error: the library's default build pulls in the dependencies above" >&2
  exit 1
fi

echo "== an embedder of the library (tests/embed: no default features, plus the mesh encoder)"
# It builds through the documented API alone, and none of the command-line tool's, the
# plots' or the STEP reader's dependencies come with it.
cargo check --manifest-path tests/embed/Cargo.toml --target-dir "${CARGO_TARGET_DIR:-target}" --locked
EMBED_DEPS=$(cargo tree --manifest-path tests/embed/Cargo.toml --locked -e normal --prefix none)
if echo "$EMBED_DEPS" | grep -E '^(clap|anyhow|indicatif|plotters|png|mimalloc|truck-[a-z]+|ruststep) '; then
  echo "error: the embedder's build pulls in the dependencies above" >&2
  exit 1
fi
# Without `internals` the internal modules are private: each `use` of
# tests/embed/examples/internal_module.rs must fail to resolve.
EMBED_USES=$(grep -c '^use scode::' tests/embed/examples/internal_module.rs)
if EMBED_ERRORS=$(cargo check --manifest-path tests/embed/Cargo.toml --target-dir "${CARGO_TARGET_DIR:-target}" \
    --locked --example internal_module --features compile-fail 2>&1); then
  echo "error: an embedder can name the library's internal modules" >&2
  exit 1
fi
EMBED_REFUSED=$(echo "$EMBED_ERRORS" | grep -cE '^error\[E0(603|432)\]' || true)
if [ "$EMBED_REFUSED" != "$EMBED_USES" ]; then
  echo "$EMBED_ERRORS" >&2
  echo "error: $EMBED_REFUSED of the $EMBED_USES internal paths were refused" >&2
  exit 1
fi

# The library and the command-line tool; the Python package (`python/`, which needs a Python
# interpreter to build) is scripts/test_python.sh's.
CRATES=(--workspace --exclude scode-python)

echo "== cargo clippy: library and command-line tool (with the sweep tests, which cargo test leaves out)"
cargo clippy "${CRATES[@]}" --all-targets --features scode/sweep -- -D warnings

echo "== npm packages of the tests: gltf-validator (cli/tests/gltf_output.rs)"
# Under CI the validator test fails without them; elsewhere it says it was skipped.
if command -v npm >/dev/null 2>&1; then
  (cd cli/tests/gltf_validator && npm ci --no-audit --no-fund --loglevel=error)
elif [ -n "${CI:-}" ]; then
  echo "error: npm not found: the glTF validator test needs Node.js 20 with npm" >&2
  exit 1
else
  echo "note: npm not found; the glTF validator test will report that it was skipped" >&2
fi

echo "== cargo test: library and command-line tool"
PROPTEST_CASES=${PROPTEST_CASES:-64} cargo test "${CRATES[@]}" --all-targets
echo "== cargo test --doc (the API's examples)"
cargo test "${CRATES[@]}" --doc

echo "== wasm/ engine (native): clippy and tests"
WASM_NATIVE_TARGET="${CARGO_TARGET_DIR:-$PWD/target}"
cargo clippy --manifest-path wasm/Cargo.toml --target-dir "$WASM_NATIVE_TARGET" --workspace --all-targets -- -D warnings
cargo test --manifest-path wasm/Cargo.toml --target-dir "$WASM_NATIVE_TARGET" --workspace

if [ "${E2E:-1}" != "0" ]; then
  echo "== viewer end-to-end test (headless Chromium)"
  if ! command -v chromium >/dev/null 2>&1; then
    SUDO=""
    if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
    $SUDO apt-get update -qq && $SUDO apt-get install -y -qq chromium >/dev/null
  fi
  (cd viewer/test && npm ci --no-audit --no-fund --loglevel=error)
  # cargo test built the scode binary (package scode-cli; `scode view` embeds viewer/pkg).
  SCODE_BIN="${CARGO_TARGET_DIR:-target}/debug/scode" node viewer/test/e2e.mjs
fi

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
  # Unoptimised and without AddressSanitizer: the readers' dependencies (truck, parry3d,
  # gltf) build several times faster so, and seconds of fuzzing need no speed (the codec
  # forbids unsafe code; overflow checks and assertions stay on).
  FUZZ_BUILD_FLAGS=${FUZZ_BUILD_FLAGS:---dev -s none} FUZZ_TOOLCHAIN="$FUZZ_TOOLCHAIN" \
    fuzz/run.sh "$FUZZ_SECONDS"
fi
echo "== all checks passed"
