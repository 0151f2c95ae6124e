//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};

/// The shared corpus: `<repo>/../shared/corpus`, else `/work/shared/corpus`; `None` (with a
/// message) when neither exists, so corpus tests report that they were skipped.
pub fn corpus_dir() -> Option<PathBuf> {
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
