//! Half-edge connectivity of a [`ControlMesh`]: twins, next/prev, faces, boundary loops
//! (closed by *hole faces*), connected components and manifoldness checks.
//!
//! Layout, and why: every array is flat and indexed by half-edge, face or vertex id, so a
//! 100k-face mesh costs a handful of allocations and the structure can be shared read-only.
//! Half-edge `h < corner_count` *is* face corner `h` of the mesh (index into
//! `face_vertices`): it runs from `face_vertices[h]` to the next corner's vertex, so no mapping
//! table is needed between the mesh and its half-edges. Half-edges of hole faces (the twins of
//! mesh-boundary half-edges) follow, so after construction **every half-edge has a twin**, which
//! keeps traversals (Face Fixer, one-ring walks, subdivision) free of boundary special cases.

#[cfg(any(feature = "encoder", feature = "internals"))]
use crate::error::{Error, Result};
#[cfg(any(feature = "encoder", feature = "internals"))]
use crate::mesh::{edge_key, ControlMesh};

/// Marker for "no half-edge".
pub const NONE: u32 = u32::MAX;

/// Oriented 2-manifold half-edge structure with hole faces. See the module docs.
#[cfg(any(feature = "encoder", feature = "internals"))]
#[derive(Clone, Debug, Default)]
pub struct HalfEdgeMesh {
    /// Number of vertices of the source mesh (isolated vertices included).
    pub vertex_count: usize,
    /// Faces `0..real_face_count` are the mesh faces (same ids); the rest are hole faces.
    pub real_face_count: usize,
    /// Half-edges `0..real_half_edge_count` are the mesh face corners.
    pub real_half_edge_count: usize,
    /// Tail vertex of each half-edge.
    pub origin: Vec<u32>,
    /// Next half-edge in the same face (counter-clockwise).
    pub next: Vec<u32>,
    /// Previous half-edge in the same face.
    pub prev: Vec<u32>,
    /// Opposite half-edge (never `NONE` after construction).
    pub twin: Vec<u32>,
    /// Face of each half-edge.
    pub face: Vec<u32>,
    /// One half-edge of each face: its first corner for mesh faces.
    pub face_first: Vec<u32>,
    /// Number of half-edges of each face.
    pub face_degree: Vec<u32>,
    /// One outgoing half-edge per vertex (a mesh half-edge), `NONE` for isolated vertices.
    pub vertex_out: Vec<u32>,
}

/// How twins are paired when an undirected edge does not have exactly one half-edge in each
/// direction.
#[cfg(any(feature = "encoder", feature = "internals"))]
#[derive(Clone, Copy, PartialEq, Eq)]
enum Pairing {
    /// Fail with an error naming the edge.
    Strict,
    /// Pair the first opposite pair; leave the other half-edges unpaired (boundary).
    Tolerant,
}

#[cfg(any(feature = "encoder", feature = "internals"))]
impl HalfEdgeMesh {
    /// Builds the structure, failing with [`Error::Mesh`] on a non-manifold edge (more than two
    /// faces), inconsistently oriented neighbours, or a non-manifold vertex (two surface sheets
    /// touching at one vertex). Indices must be valid (see [`ControlMesh::validate`]).
    pub fn build(mesh: &ControlMesh) -> Result<Self> {
        let mut he = Self::corners(mesh)?;
        he.pair_twins(Pairing::Strict)?;
        he.close_holes()?;
        he.check_vertices()?;
        Ok(he)
    }

    /// Mesh half-edges only (no twins yet).
    fn corners(mesh: &ControlMesh) -> Result<Self> {
        let nc = mesh.face_vertices.len();
        let nf = mesh.face_count();
        if nc >= NONE as usize / 2 || mesh.vertex_count() >= NONE as usize {
            return Err(Error::Mesh(
                "mesh too large for 32-bit half-edge ids".into(),
            ));
        }
        let mut he = HalfEdgeMesh {
            vertex_count: mesh.vertex_count(),
            real_face_count: nf,
            real_half_edge_count: nc,
            origin: mesh.face_vertices.clone(),
            next: vec![NONE; nc],
            prev: vec![NONE; nc],
            twin: vec![NONE; nc],
            face: vec![NONE; nc],
            face_first: Vec::with_capacity(nf),
            face_degree: Vec::with_capacity(nf),
            vertex_out: vec![NONE; mesh.vertex_count()],
        };
        for f in 0..nf {
            let (s, e) = (mesh.face_offsets[f], mesh.face_offsets[f + 1]);
            if e < s + 3 || e as usize > nc {
                return Err(Error::Mesh(format!("face {f} has invalid offsets")));
            }
            he.face_first.push(s);
            he.face_degree.push(e - s);
            for h in s..e {
                let n = if h + 1 == e { s } else { h + 1 };
                let p = if h == s { e - 1 } else { h - 1 };
                he.next[h as usize] = n;
                he.prev[h as usize] = p;
                he.face[h as usize] = f as u32;
                let v = he.origin[h as usize] as usize;
                if v >= he.vertex_count {
                    return Err(Error::Mesh(format!(
                        "face {f} references missing vertex {v}"
                    )));
                }
                if he.vertex_out[v] == NONE {
                    he.vertex_out[v] = h;
                }
            }
        }
        Ok(he)
    }

    /// Head (target vertex) of half-edge `h`.
    #[inline]
    pub fn dest(&self, h: u32) -> u32 {
        self.origin[self.next[h as usize] as usize]
    }

    /// True for half-edges of hole faces.
    #[cfg(test)]
    #[inline]
    pub fn is_hole_half_edge(&self, h: u32) -> bool {
        h as usize >= self.real_half_edge_count
    }

    /// True for hole faces.
    #[inline]
    pub fn is_hole_face(&self, f: u32) -> bool {
        f as usize >= self.real_face_count
    }

    /// Total number of faces (mesh faces + hole faces).
    pub fn face_count(&self) -> usize {
        self.face_first.len()
    }

    /// Number of hole faces = number of mesh boundary loops.
    #[cfg(test)]
    pub fn boundary_loop_count(&self) -> usize {
        self.face_count() - self.real_face_count
    }

    /// Half-edges of face `f` in order, starting at `face_first[f]`.
    pub fn face_half_edges(&self, f: u32) -> impl Iterator<Item = u32> + '_ {
        let first = self.face_first[f as usize];
        let n = self.face_degree[f as usize];
        let mut h = first;
        (0..n).map(move |_| {
            let cur = h;
            h = self.next[h as usize];
            cur
        })
    }

    /// Boundary loops as vertex cycles (each cycle follows the mesh boundary half-edges, so
    /// the mesh lies on the left).
    #[cfg(test)]
    pub fn boundary_loops(&self) -> Vec<Vec<u32>> {
        (self.real_face_count..self.face_count())
            .map(|f| {
                let mut l: Vec<u32> = self
                    .face_half_edges(f as u32)
                    .map(|h| self.origin[self.twin[h as usize] as usize])
                    .collect();
                l.reverse();
                l
            })
            .collect()
    }

    /// Connected component id of every mesh face (components numbered by their lowest face),
    /// and the number of components.
    #[cfg(test)]
    pub fn face_components(&self) -> (Vec<u32>, usize) {
        let nf = self.real_face_count;
        let mut comp = vec![NONE; nf];
        let mut count = 0u32;
        let mut stack = Vec::new();
        for f0 in 0..nf {
            if comp[f0] != NONE {
                continue;
            }
            comp[f0] = count;
            stack.push(f0 as u32);
            while let Some(f) = stack.pop() {
                for h in self.face_half_edges(f) {
                    let g = self.face[self.twin[h as usize] as usize];
                    if (g as usize) < nf && comp[g as usize] == NONE {
                        comp[g as usize] = count;
                        stack.push(g);
                    }
                }
            }
            count += 1;
        }
        (comp, count as usize)
    }

    /// Outgoing half-edges of vertex `v` in rotation order (including hole half-edges).
    #[cfg(test)]
    pub fn vertex_out_half_edges(&self, v: u32) -> Vec<u32> {
        let start = self.vertex_out[v as usize];
        let mut out = Vec::new();
        if start == NONE {
            return out;
        }
        let mut h = start;
        loop {
            out.push(h);
            h = self.twin[self.prev[h as usize] as usize];
            if h == start || out.len() > self.origin.len() {
                break;
            }
        }
        out
    }

    fn pair_twins(&mut self, mode: Pairing) -> Result<()> {
        let nc = self.real_half_edge_count;
        let mut keys: Vec<(u32, u32, u32)> = (0..nc as u32)
            .map(|h| {
                let (a, b) = edge_key(self.origin[h as usize], self.dest(h));
                (a, b, h)
            })
            .collect();
        keys.sort_unstable();
        let mut i = 0;
        while i < keys.len() {
            let mut j = i + 1;
            while j < keys.len() && keys[j].0 == keys[i].0 && keys[j].1 == keys[i].1 {
                j += 1;
            }
            let run = &keys[i..j];
            let (a, b) = (run[0].0, run[0].1);
            let forward: Vec<u32> = run
                .iter()
                .map(|k| k.2)
                .filter(|&h| self.origin[h as usize] == a)
                .collect();
            let backward: Vec<u32> = run
                .iter()
                .map(|k| k.2)
                .filter(|&h| self.origin[h as usize] == b)
                .collect();
            if mode == Pairing::Strict {
                if run.len() > 2 {
                    return Err(Error::Mesh(format!(
                        "non-manifold edge ({a}, {b}): shared by {} faces",
                        run.len()
                    )));
                }
                if forward.len() == 2 || backward.len() == 2 {
                    let h = run[0].2;
                    let g = run[1].2;
                    return Err(Error::Mesh(format!(
                        "edge ({a}, {b}) is used in the same direction by faces {} and {}: \
                         inconsistent face orientation",
                        self.face[h as usize], self.face[g as usize]
                    )));
                }
            }
            if let (Some(&h), Some(&g)) = (forward.first(), backward.first()) {
                self.twin[h as usize] = g;
                self.twin[g as usize] = h;
            }
            i = j;
        }
        Ok(())
    }

    /// Adds one hole face per boundary loop so every half-edge gets a twin.
    fn close_holes(&mut self) -> Result<()> {
        let nc = self.real_half_edge_count;
        // The unique mesh boundary half-edge ending at each vertex.
        let mut boundary_in = vec![NONE; self.vertex_count];
        let mut boundary: Vec<u32> = Vec::new();
        for h in 0..nc as u32 {
            if self.twin[h as usize] == NONE {
                let b = self.dest(h) as usize;
                if boundary_in[b] != NONE {
                    return Err(Error::Mesh(format!(
                        "non-manifold vertex {b}: two boundary edges end at it \
                         (surface sheets touch at this vertex)"
                    )));
                }
                boundary_in[b] = h;
                boundary.push(h);
            }
        }
        // Hole half-edge for boundary half-edge h (a -> b) runs b -> a.
        let mut hole_of = vec![NONE; nc];
        for (i, &h) in boundary.iter().enumerate() {
            hole_of[h as usize] = (nc + i) as u32;
        }
        for &h in &boundary {
            let hole = hole_of[h as usize];
            self.origin.push(self.dest(h));
            self.twin.push(h);
            self.twin[h as usize] = hole;
            self.next.push(NONE);
            self.prev.push(NONE);
            self.face.push(NONE);
        }
        for &h in &boundary {
            let hole = hole_of[h as usize] as usize;
            let a = self.origin[h as usize] as usize;
            let into_a = boundary_in[a];
            if into_a == NONE {
                return Err(Error::Mesh(format!(
                    "non-manifold vertex {a}: boundary does not continue through it"
                )));
            }
            let n = hole_of[into_a as usize];
            self.next[hole] = n;
            self.prev[n as usize] = hole as u32;
        }
        // Number the hole faces by walking each loop once, in boundary order.
        for &h in &boundary {
            let start = hole_of[h as usize];
            if self.face[start as usize] != NONE {
                continue;
            }
            let f = self.face_first.len() as u32;
            let mut deg = 0u32;
            let mut x = start;
            loop {
                if self.face[x as usize] != NONE || deg as usize > boundary.len() {
                    return Err(Error::Mesh("malformed boundary loop".into()));
                }
                self.face[x as usize] = f;
                deg += 1;
                x = self.next[x as usize];
                if x == start {
                    break;
                }
            }
            self.face_first.push(start);
            self.face_degree.push(deg);
        }
        Ok(())
    }

    /// Every vertex's outgoing half-edges must form one rotation cycle.
    fn check_vertices(&self) -> Result<()> {
        let mut out_degree = vec![0u32; self.vertex_count];
        for &v in &self.origin {
            out_degree[v as usize] += 1;
        }
        for (v, &degree) in out_degree.iter().enumerate() {
            let start = self.vertex_out[v];
            if start == NONE {
                continue;
            }
            let mut h = start;
            let mut n = 0u32;
            loop {
                n += 1;
                h = self.twin[self.prev[h as usize] as usize];
                if h == start || n > degree {
                    break;
                }
            }
            if n != degree {
                return Err(Error::Mesh(format!(
                    "non-manifold vertex {v}: its faces form more than one fan \
                     (surface sheets touch at this vertex)"
                )));
            }
        }
        Ok(())
    }
}

/// Cuts a mesh apart at non-manifold edges and vertices so that [`HalfEdgeMesh::build`]
/// succeeds: an edge shared by more than two faces (or used twice in one direction) keeps one
/// opposite pair of faces and becomes a boundary for the others; then every vertex whose faces
/// form several fans is duplicated, one copy per extra fan.
///
/// Returns the cut mesh (vertices `0..n` keep their ids, copies are appended) and for every
/// vertex of the cut mesh the original vertex it came from. Faces, groups, sharp edges and
/// corners are carried over (sharp edges and corners are NOT copied to the duplicates; callers
/// map through the returned table). Non-orientable input (e.g. a Möbius strip) may still fail
/// to build afterwards.
#[cfg(any(feature = "encoder", feature = "internals"))]
pub fn cut_non_manifold(mesh: &ControlMesh) -> Result<(ControlMesh, Vec<u32>)> {
    let mut he = HalfEdgeMesh::corners(mesh)?;
    he.pair_twins(Pairing::Tolerant)?;
    let nc = he.real_half_edge_count;
    // Union-find over corners (corner h = vertex origin[h] in face face[h]): two corners at
    // the same vertex are in one fan when their faces share a paired edge at that vertex.
    let mut parent: Vec<u32> = (0..nc as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    for h in 0..nc as u32 {
        let t = he.twin[h as usize];
        if t == NONE || t < h {
            continue;
        }
        // h: a -> b, t: b -> a. At b: corner next(h) and corner t. At a: corner h and next(t).
        for (x, y) in [(he.next[h as usize], t), (h, he.next[t as usize])] {
            let (rx, ry) = (find(&mut parent, x), find(&mut parent, y));
            if rx != ry {
                parent[rx.max(ry) as usize] = rx.min(ry);
            }
        }
    }
    let mut out = mesh.clone();
    let mut source: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
    // First fan (lowest corner) of a vertex keeps the vertex; others get a copy.
    let mut fan_vertex = vec![NONE; nc];
    let mut vertex_has_fan = vec![false; mesh.vertex_count()];
    for h in 0..nc as u32 {
        let root = find(&mut parent, h) as usize;
        let v = he.origin[h as usize];
        if fan_vertex[root] == NONE {
            if !vertex_has_fan[v as usize] {
                vertex_has_fan[v as usize] = true;
                fan_vertex[root] = v;
            } else {
                fan_vertex[root] = out.push_vertex(mesh.positions[v as usize]);
                source.push(v);
            }
        }
        out.face_vertices[h as usize] = fan_vertex[root];
    }
    Ok((out, source))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn mesh_from(nv: usize, faces: &[&[u32]]) -> ControlMesh {
        let mut m = ControlMesh::new();
        for i in 0..nv {
            m.push_vertex(DVec3::new(i as f64, (i * i) as f64, 0.0));
        }
        let g = m.push_group("", Default::default());
        for f in faces {
            m.push_face(f, g);
        }
        m
    }

    fn cube() -> ControlMesh {
        mesh_from(
            8,
            &[
                &[0, 2, 3, 1],
                &[4, 5, 7, 6],
                &[0, 1, 5, 4],
                &[2, 6, 7, 3],
                &[0, 4, 6, 2],
                &[1, 3, 7, 5],
            ],
        )
    }

    #[test]
    fn closed_cube_has_twins_and_no_holes() {
        let he = HalfEdgeMesh::build(&cube()).unwrap();
        assert_eq!(he.boundary_loop_count(), 0);
        for h in 0..he.origin.len() as u32 {
            let t = he.twin[h as usize];
            assert_eq!(he.twin[t as usize], h);
            assert_eq!(he.origin[t as usize], he.dest(h));
        }
        assert_eq!(he.face_components().1, 1);
        for v in 0..8 {
            assert_eq!(he.vertex_out_half_edges(v).len(), 3);
        }
    }

    #[test]
    fn open_box_has_one_hole_of_four() {
        let mut m = cube();
        // Drop face 1 (the top).
        let faces: Vec<Vec<u32>> = m.faces().map(|f| f.to_vec()).collect();
        let refs: Vec<&[u32]> = faces
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != 1)
            .map(|(_, f)| f.as_slice())
            .collect();
        m = mesh_from(8, &refs);
        let he = HalfEdgeMesh::build(&m).unwrap();
        assert_eq!(he.boundary_loop_count(), 1);
        let loops = he.boundary_loops();
        assert_eq!(loops[0].len(), 4);
        let mut sorted = loops[0].clone();
        sorted.sort();
        assert_eq!(sorted, vec![4, 5, 6, 7]);
    }

    #[test]
    fn two_components() {
        let m = mesh_from(6, &[&[0, 1, 2], &[3, 4, 5]]);
        let he = HalfEdgeMesh::build(&m).unwrap();
        assert_eq!(he.face_components(), (vec![0, 1], 2));
        assert_eq!(he.boundary_loop_count(), 2);
    }

    #[test]
    fn rejects_non_manifold_edge_and_vertex_and_orientation() {
        // Three triangles on edge (0,1).
        let m = mesh_from(5, &[&[0, 1, 2], &[1, 0, 3], &[0, 1, 4]]);
        let e = HalfEdgeMesh::build(&m).unwrap_err().to_string();
        assert!(e.contains("non-manifold edge (0, 1)"), "{e}");
        // Bow-tie: two triangles touching at vertex 0.
        let m = mesh_from(5, &[&[0, 1, 2], &[0, 3, 4]]);
        let e = HalfEdgeMesh::build(&m).unwrap_err().to_string();
        assert!(e.contains("non-manifold vertex 0"), "{e}");
        // Flipped neighbour.
        let m = mesh_from(4, &[&[0, 1, 2], &[0, 1, 3]]);
        let e = HalfEdgeMesh::build(&m).unwrap_err().to_string();
        assert!(e.contains("inconsistent face orientation"), "{e}");
    }

    #[test]
    fn cutting_makes_meshes_buildable() {
        for faces in [
            vec![vec![0u32, 1, 2], vec![1, 0, 3], vec![0, 1, 4]],
            vec![vec![0, 1, 2], vec![0, 3, 4]],
        ] {
            let refs: Vec<&[u32]> = faces.iter().map(|f| f.as_slice()).collect();
            let m = mesh_from(5, &refs);
            let (cut, source) = cut_non_manifold(&m).unwrap();
            HalfEdgeMesh::build(&cut).unwrap();
            assert!(cut.vertex_count() > 5);
            assert_eq!(source.len(), cut.vertex_count());
            // Mapping the cut mesh back gives the input faces.
            for (f, g) in m.faces().zip(cut.faces()) {
                let back: Vec<u32> = g.iter().map(|&v| source[v as usize]).collect();
                assert_eq!(f, back.as_slice());
            }
        }
        // A manifold mesh is left alone.
        let (cut, source) = cut_non_manifold(&cube()).unwrap();
        assert_eq!(cut, cube());
        assert_eq!(source, (0..8).collect::<Vec<_>>());
    }
}
