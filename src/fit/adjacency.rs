//! Edge and face adjacency of a polygon mesh, built by sorting (no hashing), so every
//! traversal order is deterministic.
//!
//! Private to `fit`: its input may have edges with more than two faces, which this table
//! lists where `mesh::topology`'s half-edge structure needs an oriented 2-manifold.

use crate::mesh::{edge_key, ControlMesh};

/// Every undirected edge once, with the faces using it.
///
/// CSR layout (`edge_face_offsets` into `edge_faces`) because almost every edge has one or
/// two faces, and a flat array keeps 100k-face meshes to a few allocations. Edges are sorted
/// by their `(min, max)` key, so `find` is a binary search.
pub(crate) struct EdgeTable {
    pub keys: Vec<(u32, u32)>,
    pub edge_face_offsets: Vec<u32>,
    /// `(face, local edge index)`: edge `i` of a face joins its vertices `i` and `i + 1`.
    pub edge_faces: Vec<(u32, u8)>,
    /// For every face corner (indexed like `mesh.face_vertices`): the edge leaving it.
    pub face_edge: Vec<u32>,
}

impl EdgeTable {
    pub fn new(mesh: &ControlMesh) -> EdgeTable {
        let mut half: Vec<((u32, u32), u32, u8, u32)> =
            Vec::with_capacity(mesh.face_vertices.len());
        for f in 0..mesh.face_count() {
            let face = mesh.face(f);
            let base = mesh.face_offsets[f];
            for i in 0..face.len() {
                let (a, b) = (face[i], face[(i + 1) % face.len()]);
                half.push((edge_key(a, b), f as u32, i as u8, base + i as u32));
            }
        }
        half.sort_unstable();
        let mut keys = Vec::new();
        let mut offsets = vec![0u32];
        let mut edge_faces = Vec::with_capacity(half.len());
        let mut face_edge = vec![0u32; mesh.face_vertices.len()];
        for (i, h) in half.iter().enumerate() {
            if i == 0 || half[i - 1].0 != h.0 {
                if i > 0 {
                    offsets.push(edge_faces.len() as u32);
                }
                keys.push(h.0);
            }
            edge_faces.push((h.1, h.2));
            face_edge[h.3 as usize] = (keys.len() - 1) as u32;
        }
        if !half.is_empty() {
            offsets.push(edge_faces.len() as u32);
        }
        EdgeTable {
            keys,
            edge_face_offsets: offsets,
            edge_faces,
            face_edge,
        }
    }

    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// Faces (with local edge index) around edge `e`.
    pub fn faces(&self, e: usize) -> &[(u32, u8)] {
        &self.edge_faces[self.edge_face_offsets[e] as usize..self.edge_face_offsets[e + 1] as usize]
    }

    /// Index of the edge `a`-`b`, if it exists.
    pub fn find(&self, a: u32, b: u32) -> Option<usize> {
        self.keys.binary_search(&edge_key(a, b)).ok()
    }
}

/// Unit normal (Newell's method, robust for polygons) and area of every face; degenerate
/// faces get a zero normal.
pub(crate) fn face_normals_and_areas(mesh: &ControlMesh) -> (Vec<glam::DVec3>, Vec<f64>) {
    let mut normals = Vec::with_capacity(mesh.face_count());
    let mut areas = Vec::with_capacity(mesh.face_count());
    for face in mesh.faces() {
        let mut n = glam::DVec3::ZERO;
        for i in 0..face.len() {
            let p = mesh.positions[face[i] as usize];
            let q = mesh.positions[face[(i + 1) % face.len()] as usize];
            n += p.cross(q);
        }
        let len = n.length();
        areas.push(0.5 * len);
        normals.push(if len > 0.0 {
            n / len
        } else {
            glam::DVec3::ZERO
        });
    }
    (normals, areas)
}
