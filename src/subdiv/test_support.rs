//! Test helpers: corpus meshes read with `crate::io`, with CAD-face boundaries made sharp.

pub(crate) use crate::io::test_support::corpus_dir;
use crate::mesh::{edge_key, ControlMesh, PatchKind};

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

/// `m` with its faces in the order `order` (a permutation of its face ids).
pub(crate) fn with_face_order(m: &ControlMesh, order: &[usize]) -> ControlMesh {
    let mut out = ControlMesh::new();
    out.positions = m.positions.clone();
    out.groups = m.groups.clone();
    for &f in order {
        out.push_face(m.face(f), m.face_groups[f]);
    }
    out.sharp_edges = m.sharp_edges.clone();
    out.corners = m.corners.clone();
    out
}

/// The same control mesh numbered the other way round: vertices reversed, faces reversed,
/// each face's corners rotated by one.
pub(crate) fn renumbered(mesh: &ControlMesh) -> ControlMesh {
    let n = mesh.vertex_count() as u32;
    let flip = |v: u32| n - 1 - v;
    let mut out = ControlMesh {
        positions: mesh.positions.iter().rev().copied().collect(),
        groups: mesh.groups.clone(),
        sharp_edges: mesh
            .sharp_edges
            .iter()
            .map(|&(a, b)| edge_key(flip(a), flip(b)))
            .collect(),
        corners: mesh.corners.iter().map(|&v| flip(v)).collect(),
        ..ControlMesh::new()
    };
    for f in (0..mesh.face_count()).rev() {
        let face = mesh.face(f);
        let rotated: Vec<u32> = face
            .iter()
            .cycle()
            .skip(1)
            .take(face.len())
            .map(|&v| flip(v))
            .collect();
        out.push_face(&rotated, mesh.face_groups[f]);
    }
    out
}
