//! Test helpers: corpus meshes read with `crate::io`, with CAD-face boundaries made sharp.

pub(crate) use crate::io::test_support::corpus_dir;
use crate::mesh::{ControlMesh, PatchKind};

/// Loads a corpus mesh with every group a closed patch and CAD-face boundaries sharp, or
/// `None` (with a message) when the corpus is absent.
pub(crate) fn load_corpus(rel: &str) -> Option<ControlMesh> {
    let mut m = crate::io::test_support::load_corpus(rel)?;
    for g in &mut m.groups {
        g.patch = PatchKind::Closed;
    }
    m.sharpen_group_boundaries();
    Some(m)
}
