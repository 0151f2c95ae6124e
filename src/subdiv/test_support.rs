//! Test helpers: a minimal OBJ reader (v / f / g lines) and the corpus location. The `io`
//! module is written in parallel; at merge these can switch to `crate::io`.

use std::collections::BTreeMap;
use std::path::PathBuf;

use glam::DVec3;

use crate::mesh::{edge_key, ControlMesh, PatchKind};

/// `../shared/corpus` next to the repo, else `/work/shared/corpus`.
pub(crate) fn corpus_dir() -> Option<PathBuf> {
    let local = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus");
    if local.is_dir() {
        return Some(local);
    }
    let abs = PathBuf::from("/work/shared/corpus");
    abs.is_dir().then_some(abs)
}

/// Reads `v`, `f` and `g` lines; every group is a closed patch; edges between different
/// groups are flagged sharp (CAD-face boundaries).
pub(crate) fn parse_obj(text: &str) -> ControlMesh {
    let mut m = ControlMesh::new();
    let mut group_ids: BTreeMap<String, u32> = BTreeMap::new();
    let mut current = None;
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it.take(3).map(|s| s.parse().unwrap()).collect();
                m.push_vertex(DVec3::new(c[0], c[1], c[2]));
            }
            Some("g") | Some("o") if line.starts_with('g') => {
                let name = it.next().unwrap_or("").to_string();
                let next = group_ids.len() as u32;
                let id = *group_ids.entry(name.clone()).or_insert(next);
                if id == next {
                    m.push_group(name, PatchKind::Closed);
                }
                current = Some(id);
            }
            Some("f") => {
                let nv = m.positions.len() as i64;
                let idx: Vec<u32> = it
                    .map(|s| {
                        let i: i64 = s.split('/').next().unwrap().parse().unwrap();
                        (if i < 0 { nv + i } else { i - 1 }) as u32
                    })
                    .collect();
                let g = *current.get_or_insert_with(|| m.push_group("default", PatchKind::Closed));
                m.push_face(&idx, g);
            }
            _ => {}
        }
    }
    // sharp edges between groups
    let mut edge_group: BTreeMap<(u32, u32), u32> = BTreeMap::new();
    let mut sharp = Vec::new();
    for f in 0..m.face_count() {
        let face = m.face(f).to_vec();
        let g = m.face_groups[f];
        for i in 0..face.len() {
            let k = edge_key(face[i], face[(i + 1) % face.len()]);
            match edge_group.get(&k) {
                Some(&g2) if g2 != g => sharp.push(k),
                Some(_) => {}
                None => {
                    edge_group.insert(k, g);
                }
            }
        }
    }
    for (a, b) in sharp {
        m.set_sharp(a, b);
    }
    m
}

/// Loads a corpus file by relative path, or `None` (with a message) when the corpus is absent.
pub(crate) fn load_corpus(rel: &str) -> Option<ControlMesh> {
    let Some(dir) = corpus_dir() else {
        eprintln!("corpus not found; skipping {rel}");
        return None;
    };
    let text = std::fs::read_to_string(dir.join(rel)).ok()?;
    Some(parse_obj(&text))
}
