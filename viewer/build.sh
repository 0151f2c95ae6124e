#!/usr/bin/env bash
# Builds the viewer's WebAssembly module into viewer/pkg/ (committed, so `cargo build` of the
# main crate embeds it for `scode view` without a wasm toolchain) and prints its gzipped size.
#
#   viewer/build.sh           rebuild viewer/pkg/ and its stamp viewer/pkg/SOURCES
#   viewer/build.sh --check   only check (no build) that viewer/pkg/ was built from the current
#                             sources: the stamp holds a SHA-256 over every file the module is
#                             built from. (The .wasm bytes themselves also depend on the checkout
#                             path through crate metadata, so comparing bytes across machines
#                             would not work.)
#
# Needs the wasm32-unknown-unknown target and wasm-bindgen-cli of exactly the version pinned in
# wasm/Cargo.toml (both installed here when missing). Paths are remapped so the bytes do not
# depend on where the repository or the cargo home lives.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)

# Everything the module is compiled from (test-only files excluded), hashed in a fixed order.
sources_hash() {
  {
    ls wasm/Cargo.toml wasm/Cargo.lock wasm/crc32-small/Cargo.toml viewer/build.sh
    find wasm/src wasm/crc32-small/src src/lib.rs src/error.rs src/api.rs src/surface.rs \
      src/mesh src/codec src/subdiv \
      -type f -name '*.rs' ! -name tests.rs ! -name test_support.rs ! -path '*/tests/*'
  } | LC_ALL=C sort | xargs sha256sum | sha256sum | cut -d' ' -f1
}

if [ "${1:-}" = "--check" ]; then
  want=$(sources_hash)
  have=$(sed -n 's/^sources-sha256: //p' viewer/pkg/SOURCES 2>/dev/null || true)
  if [ "$want" != "$have" ]; then
    echo "error: viewer/pkg/ was not built from the current decoder sources (wasm/, src/codec," >&2
    echo "src/mesh, src/subdiv, ...): run viewer/build.sh and commit viewer/pkg/" >&2
    exit 1
  fi
  echo "viewer/pkg/ matches the sources ($(sed -n 's/^gzipped-bytes: //p' viewer/pkg/SOURCES) bytes gzipped)"
  exit 0
fi
WBG_VERSION=$(sed -n 's/^wasm-bindgen = "=\([0-9.]*\)".*/\1/p' wasm/Cargo.toml)

rustup target add wasm32-unknown-unknown >/dev/null 2>&1 || true
if [ "$(wasm-bindgen --version 2>/dev/null | awk '{print $2}')" != "$WBG_VERSION" ]; then
  echo "== installing wasm-bindgen-cli $WBG_VERSION (its lockfile pins a crate missing here, so not --locked)"
  cargo install wasm-bindgen-cli --version "$WBG_VERSION"
fi

TARGET_DIR=${WASM_TARGET_DIR:-$ROOT/target/wasm-viewer}
CARGO_HOME_DIR=${CARGO_HOME:-$HOME/.cargo}
# -Z flags (stable compiler, RUSTC_BOOTSTRAP): drop panic file/line strings and Debug formatting
# code, about 15% of the module.
export RUSTC_BOOTSTRAP=1
export RUSTFLAGS="-Zlocation-detail=none -Zfmt-debug=none --remap-path-prefix=$ROOT=/scode --remap-path-prefix=$CARGO_HOME_DIR=/cargo --remap-path-prefix=$HOME=/home"
echo "== cargo build wasm32 (release)"
cargo build --manifest-path wasm/Cargo.toml --release --target wasm32-unknown-unknown \
  --target-dir "$TARGET_DIR" --locked
wasm-bindgen "$TARGET_DIR/wasm32-unknown-unknown/release/scode_wasm.wasm" \
  --out-dir viewer/pkg --target web --no-typescript --remove-name-section --remove-producers-section
rm -f viewer/pkg/.gitignore viewer/pkg/package.json

RAW=$(wc -c < viewer/pkg/scode_wasm_bg.wasm)
GZ=$(gzip -9 -n -c viewer/pkg/scode_wasm_bg.wasm | wc -c)
echo "viewer/pkg/scode_wasm_bg.wasm: $RAW bytes raw, $GZ bytes gzipped (gzip -9)"
if [ "$GZ" -gt 110000 ]; then
  echo "error: the gzipped module exceeds 110,000 bytes" >&2
  exit 1
fi

{
  echo "sources-sha256: $(sources_hash)"
  echo "wasm-bytes: $RAW"
  echo "gzipped-bytes: $GZ"
  echo "rustc: $(rustc --version)"
  echo "wasm-bindgen: $WBG_VERSION"
} > viewer/pkg/SOURCES
