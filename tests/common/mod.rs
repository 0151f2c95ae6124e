//! Helpers shared by the integration tests of the library and of the command-line tool
//! (`cli/tests`, through `#[path]`), also used by the benches and examples.

use std::path::{Path, PathBuf};

/// The repository's root (the workspace's, holding `Cargo.lock`): the including package's
/// folder, or the folder above it for the command-line tool in `cli/`.
pub fn repo_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .find(|p| p.join("Cargo.lock").is_file())
        .expect("no Cargo.lock above the package: not in the scode repository")
}

/// The shared corpus: `$SCODE_CORPUS`, else `<repo>/../shared/corpus`, else
/// `/work/shared/corpus`.
///
/// A corpus test must not pass without having run: under CI (`CI` set and not empty) a
/// missing corpus panics, naming where it was looked for. Elsewhere it returns `None` with a
/// message, so a checkout without the corpus can still run the other tests. A `SCODE_CORPUS`
/// that is not a directory always panics: it was asked for explicitly.
pub fn corpus_dir() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("SCODE_CORPUS") {
        let p = PathBuf::from(p);
        assert!(
            p.is_dir(),
            "SCODE_CORPUS={} is not a directory",
            p.display()
        );
        return Some(p);
    }
    let candidates = [
        repo_dir().join("../shared/corpus"),
        PathBuf::from("/work/shared/corpus"),
    ];
    if let Some(found) = candidates.iter().find(|p| p.join("MANIFEST.md").is_file()) {
        return Some(found.clone());
    }
    let looked: Vec<String> = candidates
        .iter()
        .map(|p| p.join("MANIFEST.md").display().to_string())
        .collect();
    let message = format!(
        "corpus not found: SCODE_CORPUS is not set and there is no {}",
        looked.join(" nor ")
    );
    if std::env::var_os("CI").is_some_and(|v| !v.is_empty()) {
        panic!("{message} (CI is set, so corpus tests must run; set SCODE_CORPUS to the corpus folder)");
    }
    eprintln!("{message}; skipping this corpus test (set SCODE_CORPUS to run it)");
    None
}
