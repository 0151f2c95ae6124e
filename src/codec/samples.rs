//! Small sample meshes: the spec vectors (`examples/make_vectors.rs`), the tests and the fuzz
//! seeds all use these, so they live in the library. Also the canonical hash of a decoded
//! mesh used by `spec/vectors/EXPECTED.txt`.

use glam::DVec3;

use crate::mesh::{Axis, BoundarySurface, ControlMesh, PatchKind};

/// A mesh with one closed group from positions and face vertex lists.
pub fn from_faces(positions: &[[f64; 3]], faces: &[Vec<u32>]) -> ControlMesh {
    let mut m = ControlMesh::new();
    for p in positions {
        m.push_vertex(DVec3::from(*p));
    }
    let g = m.push_group("", PatchKind::Closed);
    for f in faces {
        m.push_face(f, g);
    }
    m
}

pub fn tetrahedron() -> ControlMesh {
    from_faces(
        &[[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
        &[vec![0, 2, 1], vec![0, 1, 3], vec![0, 3, 2], vec![1, 2, 3]],
    )
}

pub fn cube() -> ControlMesh {
    let pos: Vec<[f64; 3]> = (0..8)
        .map(|v| [(v & 1) as f64, ((v >> 1) & 1) as f64, ((v >> 2) & 1) as f64])
        .collect();
    from_faces(
        &pos,
        &[
            vec![0, 2, 3, 1],
            vec![4, 5, 7, 6],
            vec![0, 1, 5, 4],
            vec![2, 6, 7, 3],
            vec![0, 4, 6, 2],
            vec![1, 3, 7, 5],
        ],
    )
}

pub fn open_box() -> ControlMesh {
    let c = cube();
    let faces: Vec<Vec<u32>> = c
        .faces()
        .enumerate()
        .filter(|(i, _)| *i != 1)
        .map(|(_, f)| f.to_vec())
        .collect();
    from_faces(
        &c.positions.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
        &faces,
    )
}

/// Quad torus with `n` x `m` vertices (major radius 2, minor 0.7).
pub fn torus(n: u32, m: u32) -> ControlMesh {
    let mut pos = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (u, v) = (
                i as f64 / n as f64 * std::f64::consts::TAU,
                j as f64 / m as f64 * std::f64::consts::TAU,
            );
            let r = 2.0 + 0.7 * v.cos();
            pos.push([r * u.cos(), r * u.sin(), 0.7 * v.sin()]);
        }
    }
    let mut faces = Vec::new();
    for i in 0..n {
        for j in 0..m {
            faces.push(vec![
                i * m + j,
                ((i + 1) % n) * m + j,
                ((i + 1) % n) * m + (j + 1) % m,
                i * m + (j + 1) % m,
            ]);
        }
    }
    from_faces(&pos, &faces)
}

/// A box split into groups with sharp edges, corners, plane and cylinder patches, a
/// pentagon and triangles.
pub fn multi_group() -> ControlMesh {
    let mut m = cube();
    m.groups.clear();
    let plane = m.push_group("top", PatchKind::Boundary(BoundarySurface::Plane));
    let cyl = m.push_group(
        "side",
        PatchKind::Boundary(BoundarySurface::Cylinder {
            axis: Axis {
                origin: DVec3::new(0.5, 0.5, 0.0),
                direction: DVec3::new(0.0, 0.0, 1.0),
            },
        }),
    );
    let free = m.push_group("rest", PatchKind::Closed);
    m.face_groups = vec![plane, plane, cyl, cyl, free, free];
    // Split the last quad into a triangle fan around a new vertex, and a pentagon.
    let c = m.push_vertex(DVec3::new(1.0, 0.5, 0.5));
    let last: Vec<u32> = m.face(5).to_vec();
    m.face_offsets.pop();
    m.face_vertices.truncate(m.face_offsets[5] as usize);
    m.face_groups.pop();
    for k in 0..4 {
        m.push_face(&[last[k], last[(k + 1) % 4], c], free);
    }
    for (a, b) in [(0, 1), (1, 3), (3, 2), (2, 0), (4, 5), (5, 7)] {
        m.set_sharp(a, b);
    }
    m.corners.extend([0, 1, 3, 7]);
    m
}

/// A turned part: a quad torus whose rings of faces (around the z axis) are groups with
/// cylinder and cone patches on z (one coaxial pair, one reversed direction, one apex so far
/// away that its coordinate needs the escape code), sharp edges between the rings. Exercises
/// version 3's arc predictions and every branch of the coded patches section.
pub fn turned_part() -> ControlMesh {
    let (n, m_) = (12u32, 6u32);
    let mut m = torus(n, m_);
    m.groups.clear();
    let axis = |z: f64, dz: f64| Axis {
        origin: DVec3::new(0.0, 0.0, z),
        direction: DVec3::new(0.0, 0.0, dz),
    };
    let kinds = [
        PatchKind::Boundary(BoundarySurface::Cylinder {
            axis: axis(0.0, 1.0),
        }),
        PatchKind::Boundary(BoundarySurface::Cylinder {
            axis: axis(5.0, 2.0),
        }),
        PatchKind::Boundary(BoundarySurface::Cone {
            axis: axis(3.0, 1.0),
        }),
        PatchKind::Boundary(BoundarySurface::Cylinder {
            axis: axis(1.0, -1.0),
        }),
        PatchKind::Boundary(BoundarySurface::Cone {
            axis: axis(1e7, -1.0),
        }),
        PatchKind::Closed,
    ];
    for (j, k) in kinds.into_iter().enumerate() {
        m.push_group(format!("ring_{j}"), k);
    }
    for i in 0..n {
        for j in 0..m_ {
            m.face_groups[(i * m_ + j) as usize] = j;
        }
    }
    for i in 0..n {
        for j in 0..m_ {
            m.set_sharp(i * m_ + j, ((i + 1) % n) * m_ + j);
        }
    }
    m
}

/// A rounded part: the turned part's quad torus with rings of sphere and torus groups
/// (format version 4): tori about z of two major radii (one the torus's own, so its ring
/// stays on it), a sphere whose axis is off z and one about z, a closed ring; sharp edges
/// between the rings. Exercises every branch of the version-4 patch kinds and the sphere and
/// torus frames.
pub fn rounded_part() -> ControlMesh {
    let mut m = turned_part();
    let axis = |o: DVec3, d: DVec3| Axis {
        origin: o,
        direction: d,
    };
    let kinds = [
        PatchKind::Boundary(BoundarySurface::Torus {
            axis: axis(DVec3::ZERO, DVec3::Z),
            major_radius: 2.0,
        }),
        PatchKind::Boundary(BoundarySurface::Torus {
            axis: axis(DVec3::ZERO, DVec3::Z),
            major_radius: 2.0,
        }),
        PatchKind::Boundary(BoundarySurface::Sphere {
            axis: axis(DVec3::new(0.0, 0.0, 0.5), DVec3::new(1.0, 0.5, 0.0)),
        }),
        PatchKind::Boundary(BoundarySurface::Torus {
            axis: axis(DVec3::new(0.0, 0.0, -0.25), DVec3::new(0.0, 0.0, -1.0)),
            major_radius: 1.5,
        }),
        PatchKind::Boundary(BoundarySurface::Sphere {
            axis: axis(DVec3::ZERO, DVec3::Z),
        }),
        PatchKind::Closed,
    ];
    for (g, k) in m.groups.iter_mut().zip(kinds) {
        g.patch = k;
    }
    m
}

/// A small CAD part: a box (one group per side) with a cylindrical boss on top, sharp
/// edges on all group boundaries, corners at the box corners.
pub fn cad_part() -> ControlMesh {
    let mut m = ControlMesh::new();
    let segs = 12u32;
    let (w, d, h) = (4.0, 3.0, 1.0);
    // Box corners 0..8 (v = x + 2y + 4z).
    for v in 0..8u32 {
        m.push_vertex(DVec3::new(
            w * (v & 1) as f64,
            d * ((v >> 1) & 1) as f64,
            h * ((v >> 2) & 1) as f64,
        ));
    }
    let plane = PatchKind::Boundary(BoundarySurface::Plane);
    let names = ["bottom", "top", "front", "back", "left", "right"];
    let gs: Vec<u32> = names.iter().map(|n| m.push_group(*n, plane)).collect();
    let axis = Axis {
        origin: DVec3::new(2.0, 1.5, 1.0),
        direction: DVec3::Z,
    };
    let g_side = m.push_group(
        "boss_side",
        PatchKind::Boundary(BoundarySurface::Cylinder { axis }),
    );
    let g_cap = m.push_group("boss_cap", plane);
    // Boss circles: bottom ring on the top face, top ring at z = 1.8.
    let ring = |m: &mut ControlMesh, z: f64| -> Vec<u32> {
        (0..segs)
            .map(|k| {
                let a = k as f64 / segs as f64 * std::f64::consts::TAU;
                m.push_vertex(DVec3::new(2.0 + 0.8 * a.cos(), 1.5 + 0.8 * a.sin(), z))
            })
            .collect()
    };
    let low = ring(&mut m, h);
    let high = ring(&mut m, 1.8);
    m.push_face(&[0, 2, 3, 1], gs[0]);
    m.push_face(&[0, 1, 5, 4], gs[2]);
    m.push_face(&[2, 6, 7, 3], gs[3]);
    m.push_face(&[0, 4, 6, 2], gs[4]);
    m.push_face(&[1, 3, 7, 5], gs[5]);
    // Top face with a circular hole: fan the annulus between the square 4,5,7,6 and the
    // ring into triangles, assigning each ring vertex to its nearest square corner.
    let square = [4u32, 5, 7, 6];
    let corner_of = |k: u32| -> usize { ((k * 4 + segs / 8) / segs % 4) as usize };
    for k in 0..segs {
        let (a, b) = (low[k as usize], low[((k + 1) % segs) as usize]);
        let ca = corner_of(k);
        let cb = corner_of((k + 1) % segs);
        m.push_face(&[square[ca], b, a], gs[1]);
        if ca != cb {
            m.push_face(&[square[ca], square[cb], b], gs[1]);
        }
    }
    for k in 0..segs {
        let k1 = (k + 1) % segs;
        m.push_face(
            &[
                low[k as usize],
                low[k1 as usize],
                high[k1 as usize],
                high[k as usize],
            ],
            g_side,
        );
    }
    m.push_face(&high, g_cap);
    // Sharp edges: all box edges, both rings.
    for (a, b) in [
        (0, 1),
        (1, 3),
        (3, 2),
        (2, 0),
        (4, 5),
        (5, 7),
        (7, 6),
        (6, 4),
        (0, 4),
        (1, 5),
        (2, 6),
        (3, 7),
    ] {
        m.set_sharp(a, b);
    }
    for k in 0..segs as usize {
        let k1 = (k + 1) % segs as usize;
        m.set_sharp(low[k], low[k1]);
        m.set_sharp(high[k], high[k1]);
    }
    m.corners.extend(0..8);
    m
}

/// FNV-1a 64-bit hash of the canonical serialisation of a mesh (spec §11): all integers
/// little-endian, floats as their IEEE-754 bit patterns:
/// `u64 V, V x (f64 x, y, z), u64 F, F x (u32 degree, degree x u32 vertex), F x u32 group,
/// u64 G, G x (u64 name length, name bytes, u8 kind [0 closed, 1 plane, 2 cylinder, 3 cone],
/// for cylinder/cone 6 x f64 origin then direction), u64 S, S x (u32, u32) sharp edges in
/// ascending order, u64 C, C x u32 corners ascending`.
pub fn canonical_hash(m: &ControlMesh) -> u64 {
    let mut h = Fnv(0xcbf2_9ce4_8422_2325);
    h.u64(m.positions.len() as u64);
    for p in &m.positions {
        for c in p.to_array() {
            h.u64(c.to_bits());
        }
    }
    h.u64(m.face_count() as u64);
    for f in m.faces() {
        h.u32(f.len() as u32);
        for &v in f {
            h.u32(v);
        }
    }
    for &g in &m.face_groups {
        h.u32(g);
    }
    h.u64(m.groups.len() as u64);
    for g in &m.groups {
        h.u64(g.name.len() as u64);
        h.bytes(g.name.as_bytes());
        let (kind, axis) = match g.patch {
            PatchKind::Closed => (0u8, None),
            PatchKind::Boundary(BoundarySurface::Plane) => (1, None),
            PatchKind::Boundary(BoundarySurface::Cylinder { axis }) => (2, Some(axis)),
            PatchKind::Boundary(BoundarySurface::Cone { axis }) => (3, Some(axis)),
            PatchKind::Boundary(BoundarySurface::Sphere { axis }) => (4, Some(axis)),
            PatchKind::Boundary(BoundarySurface::Torus { axis, .. }) => (5, Some(axis)),
        };
        h.bytes(&[kind]);
        if let PatchKind::Boundary(BoundarySurface::Torus { major_radius, .. }) = g.patch {
            h.u64(major_radius.to_bits());
        }
        if let Some(a) = axis {
            for c in a
                .origin
                .to_array()
                .into_iter()
                .chain(a.direction.to_array())
            {
                h.u64(c.to_bits());
            }
        }
    }
    h.u64(m.sharp_edges.len() as u64);
    for &(a, b) in &m.sharp_edges {
        h.u32(a);
        h.u32(b);
    }
    h.u64(m.corners.len() as u64);
    for &c in &m.corners {
        h.u32(c);
    }
    h.0
}

struct Fnv(u64);

impl Fnv {
    fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 ^= u64::from(x);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv_known_answer_and_sensitivity() {
        let mut h = Fnv(0xcbf2_9ce4_8422_2325);
        h.bytes(b"a");
        assert_eq!(h.0, 0xaf63_dc4c_8601_ec8c);
        let a = canonical_hash(&cube());
        let mut c = cube();
        c.corners.insert(0);
        assert_ne!(a, canonical_hash(&c));
        assert_eq!(a, canonical_hash(&cube()));
    }
}
