//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};

/// The shared corpus: `$SCODE_CORPUS`, else `<repo>/../shared/corpus`, else
/// `/work/shared/corpus`; `None` (with a message) when none exists, so corpus tests report that
/// they were skipped. Also used by the benches.
pub fn corpus_dir() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("SCODE_CORPUS") {
        return Some(PathBuf::from(p));
    }
    let found = [
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus"),
        PathBuf::from("/work/shared/corpus"),
    ]
    .into_iter()
    .find(|p| p.join("MANIFEST.md").is_file());
    if found.is_none() {
        eprintln!("corpus not found; skipping");
    }
    found
}
