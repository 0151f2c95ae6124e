//! Test-only helpers: corpus access (through `crate::io`) and small generated meshes.

use std::collections::BTreeMap;

use glam::DVec3;

use crate::mesh::{ControlMesh, PatchKind};

pub(crate) use crate::io::test_support::{corpus_dir, load_corpus};

/// Axis-aligned cube [0,1]^3, each side an n x n grid of quads split into triangles,
/// one group per side, outward orientation.
pub(crate) fn grid_cube(n: usize) -> ControlMesh {
    let mut m = ControlMesh::new();
    let mut index: BTreeMap<(i64, i64, i64), u32> = BTreeMap::new();
    let mut vid = |m: &mut ControlMesh, p: DVec3| {
        let key = (
            (p.x * 1e6).round() as i64,
            (p.y * 1e6).round() as i64,
            (p.z * 1e6).round() as i64,
        );
        *index.entry(key).or_insert_with(|| m.push_vertex(p))
    };
    // (origin, u, v) with u x v pointing outward.
    let sides = [
        (DVec3::ZERO, DVec3::Y, DVec3::X), // z = 0, normal -z
        (DVec3::Z, DVec3::X, DVec3::Y),    // z = 1
        (DVec3::ZERO, DVec3::X, DVec3::Z), // y = 0, normal -y
        (DVec3::Y, DVec3::Z, DVec3::X),    // y = 1
        (DVec3::ZERO, DVec3::Z, DVec3::Y), // x = 0
        (DVec3::X, DVec3::Y, DVec3::Z),    // x = 1
    ];
    for (s, (o, u, v)) in sides.iter().enumerate() {
        let g = m.push_group(format!("face_{s}"), PatchKind::Closed);
        for i in 0..n {
            for j in 0..n {
                let p = |a: usize, b: usize| {
                    *o + *u * (a as f64 / n as f64) + *v * (b as f64 / n as f64)
                };
                let a = vid(&mut m, p(i, j));
                let b = vid(&mut m, p(i + 1, j));
                let c = vid(&mut m, p(i + 1, j + 1));
                let d = vid(&mut m, p(i, j + 1));
                m.push_face(&[a, b, c], g);
                m.push_face(&[a, c, d], g);
            }
        }
    }
    m
}
