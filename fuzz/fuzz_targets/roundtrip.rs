//! Structured random polygon meshes (any mix of degrees, holes, several components,
//! non-manifold places, random groups / patch kinds / sharp edges / corners) -> encode ->
//! decode -> same connectivity (through the encoder's renumbering), same attributes, and
//! every vertex within half a quantisation step.
#![no_main]

use std::collections::BTreeSet;

use arbitrary::Arbitrary;
use glam::DVec3;
use libfuzzer_sys::fuzz_target;
use scode::codec::{decode, encode_with_map, Content, EncodeOptions, Limits};
use scode::mesh::{edge_key, Axis, BoundarySurface, ControlMesh, PatchKind};

#[derive(Arbitrary, Debug)]
struct Input {
    positions: Vec<(i16, i16, i16)>,
    faces: Vec<(u8, Vec<u8>)>,
    patch_kinds: Vec<u8>,
    sharp: Vec<(u8, u8)>,
    corners: Vec<u8>,
    bits: u8,
    control: bool,
    scale: u8,
}

fn build(inp: &Input) -> Option<ControlMesh> {
    if inp.positions.is_empty() || inp.positions.len() > 200 {
        return None;
    }
    let mut m = ControlMesh::new();
    let s = 1.0 + f64::from(inp.scale) * 0.37;
    for &(x, y, z) in &inp.positions {
        m.push_vertex(DVec3::new(f64::from(x), f64::from(y), f64::from(z)) * s / 1000.0);
    }
    let ng = inp.patch_kinds.len().clamp(1, 8);
    for g in 0..ng {
        let patch = match inp.patch_kinds.get(g).copied().unwrap_or(0) % 4 {
            0 => PatchKind::Closed,
            1 => PatchKind::Boundary(BoundarySurface::Plane),
            k => {
                let axis = Axis {
                    origin: DVec3::new(0.1, -0.2, 0.3 * g as f64),
                    direction: DVec3::new(1.0, g as f64, -2.0),
                };
                PatchKind::Boundary(if k == 2 {
                    BoundarySurface::Cylinder { axis }
                } else {
                    BoundarySurface::Cone { axis }
                })
            }
        };
        m.push_group(format!("g{g}"), patch);
    }
    let nv = m.vertex_count();
    for (g, f) in inp.faces.iter().take(300) {
        let face: Vec<u32> = f.iter().map(|&v| u32::from(v) % nv as u32).collect();
        let distinct: BTreeSet<u32> = face.iter().copied().collect();
        if face.len() < 3 || face.len() > 12 || distinct.len() != face.len() {
            continue;
        }
        m.push_face(&face, u32::from(*g) % ng as u32);
    }
    let mut edges = BTreeSet::new();
    for f in m.faces() {
        for i in 0..f.len() {
            edges.insert(edge_key(f[i], f[(i + 1) % f.len()]));
        }
    }
    for &(a, b) in &inp.sharp {
        let e = edge_key(u32::from(a) % nv as u32, u32::from(b) % nv as u32);
        if edges.contains(&e) {
            m.sharp_edges.insert(e);
        }
    }
    for &c in &inp.corners {
        m.corners.insert(u32::from(c) % nv as u32);
    }
    Some(m)
}

fn cyclic_eq(a: &[u32], b: &[u32]) -> bool {
    a.len() == b.len() && (0..a.len()).any(|r| (0..a.len()).all(|i| a[(i + r) % a.len()] == b[i]))
}

fuzz_target!(|inp: Input| {
    let Some(m) = build(&inp) else { return };
    let opts = EncodeOptions {
        quantization_bits: 4 + inp.bits % 21,
        content: if inp.control {
            Content::ControlMesh { default_level: 2 }
        } else {
            Content::RawMesh
        },
        store_group_names: true,
        // Steps between whole bit counts (the fitting encoder's half bits among them).
        step_scale: 1.0 + f64::from(inp.bits / 21) * 0.125,
        grid_covers: None,
    };
    // Non-manifold control meshes and non-orientable raw meshes are refused: fine.
    let Ok((bytes, map)) = encode_with_map(&m, &opts) else { return };
    let d = decode(&bytes, &Limits::default()).expect("own output decodes");
    let out = &d.mesh;
    assert_eq!(out.vertex_count(), m.vertex_count());
    assert_eq!(out.face_count(), m.face_count());
    for f in 0..m.face_count() {
        let expected: Vec<u32> = m.face(f).iter().map(|&v| map.vertex[v as usize]).collect();
        assert!(cyclic_eq(&expected, out.face(map.face[f] as usize)));
        assert_eq!(out.face_groups[map.face[f] as usize], map.group[m.face_groups[f] as usize]);
    }
    for (g, grp) in m.groups.iter().enumerate() {
        assert_eq!(out.groups[map.group[g] as usize].name, grp.name);
    }
    let sharp: BTreeSet<_> = m
        .sharp_edges
        .iter()
        .map(|&(a, b)| edge_key(map.vertex[a as usize], map.vertex[b as usize]))
        .collect();
    assert_eq!(sharp, out.sharp_edges);
    let corners: BTreeSet<_> = m.corners.iter().map(|&c| map.vertex[c as usize]).collect();
    assert_eq!(corners, out.corners);
    let step = d.header.quantization_step();
    for (v, p) in m.positions.iter().enumerate() {
        let e = (out.positions[map.vertex[v] as usize] - *p).abs().max_element();
        assert!(e <= step / 2.0 * (1.0 + 1e-9) + 1e-12, "vertex {v} off by {e}");
    }
});
