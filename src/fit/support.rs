//! One CAD face's decoded surface made from its control support alone.
//!
//! The triangles a Loop patch decodes to over a control face depend only on the face's
//! one-ring: the faces around its corners, their positions, sharp edges and corner tags, and
//! the patch kinds of the faces there (an analytic neighbour's frame shapes the crease they
//! share). So a CAD face's decoded triangles are the triangles of its faces in the
//! subdivision of its *support* (its faces and every face touching one of their vertices)
//! cut out as a mesh of its own; and while its support is the same, so are they.
//!
//! The measurement uses both: a face is subdivided anew only when its support changed (a
//! refinement elsewhere renumbers the control mesh but leaves the support's positions,
//! links and tags as they were), from its support alone, instead of the whole model at the
//! finest level every round. The key is conservative: a neighbour's new control points
//! change it, though across a sharp edge they leave the face's triangles as they were; the
//! measurement compares those triangles before measuring them again.

use std::collections::HashMap;

use rustc_hash::FxBuildHasher;

use crate::error::Result;
use crate::mesh::{edge_key, ControlMesh, Group};
use crate::subdiv::{UniformSurface, DEFAULT_MAX_FACES};

/// The supports of every group of one decoded control mesh. Faces around each vertex and
/// faces of each group are kept as flat offset arrays (a control mesh has thousands of
/// faces and each support query walks a few dozen of them).
pub(super) struct Supports<'a> {
    mesh: &'a ControlMesh,
    level: u32,
    /// Faces around vertex v: `vertex_faces[vertex_offsets[v]..vertex_offsets[v + 1]]`.
    vertex_offsets: Vec<u32>,
    vertex_faces: Vec<u32>,
    /// Faces of group g, ascending: `group_faces[group_offsets[g]..group_offsets[g + 1]]`.
    group_offsets: Vec<u32>,
    group_faces: Vec<u32>,
    /// Per group: a hash of its patch kind (which fixes the frame of an analytic patch).
    patch_keys: Vec<u64>,
}

impl<'a> Supports<'a> {
    /// The supports of `mesh`'s groups, decoded at `level` (`Error::Mesh` for a mesh that
    /// breaks [`ControlMesh::validate`]).
    pub fn new(mesh: &'a ControlMesh, level: u32) -> Result<Self> {
        mesh.validate()?;
        let nv = mesh.vertex_count();
        let nf = mesh.face_count();
        let n_groups = mesh
            .face_groups
            .iter()
            .map(|&g| g as usize + 1)
            .max()
            .unwrap_or(0)
            .max(mesh.groups.len());
        let vertex_items = (0..nf).flat_map(|f| mesh.face(f).iter().map(move |&v| (v as usize, f)));
        let (vertex_offsets, vertex_faces) = csr(nv, vertex_items);
        let group_items = (0..nf).map(|f| (mesh.face_groups[f] as usize, f));
        let (group_offsets, group_faces) = csr(n_groups, group_items);
        let patch_keys = (0..n_groups)
            .map(|g| match mesh.groups.get(g) {
                Some(Group { patch, .. }) => text_hash(&format!("{patch:?}")),
                None => 0,
            })
            .collect();
        Ok(Supports {
            mesh,
            level,
            vertex_offsets,
            vertex_faces,
            group_offsets,
            group_faces,
            patch_keys,
        })
    }

    /// One more than the largest group index in use.
    pub fn group_count(&self) -> usize {
        self.group_offsets.len() - 1
    }

    /// Faces of the control mesh.
    pub fn face_count(&self) -> usize {
        self.mesh.face_count()
    }

    /// Faces in group `g`'s support.
    pub fn support_size(&self, g: usize) -> usize {
        self.support_faces(g).len()
    }

    /// The whole model's decoded surface at the level.
    pub fn whole_surface(&self) -> Result<UniformSurface> {
        UniformSurface::new(self.mesh, self.level, DEFAULT_MAX_FACES)
    }

    fn faces_of_group(&self, g: usize) -> &[u32] {
        match self.group_offsets.get(g..g + 2) {
            Some(r) => &self.group_faces[r[0] as usize..r[1] as usize],
            None => &[],
        }
    }

    /// Group `g`'s support: its faces and every face sharing a vertex with one, ascending.
    fn support_faces(&self, g: usize) -> Vec<u32> {
        let mut faces = Vec::new();
        for &f in self.faces_of_group(g) {
            for &v in self.mesh.face(f as usize) {
                if let Some(r) = self.vertex_offsets.get(v as usize..v as usize + 2) {
                    faces.extend_from_slice(&self.vertex_faces[r[0] as usize..r[1] as usize]);
                }
            }
        }
        faces.sort_unstable();
        faces.dedup();
        faces
    }

    /// What identifies group `g`'s decoded triangles: a hash of its support as a set of
    /// faces, each by its corners' positions (bit for bit, starting at the smallest, order
    /// kept), their corner tags, its edges' sharpness, its patch kind and whether it is one
    /// of g's, with the level. `None` when two vertices of the support share a position:
    /// positions would then not tell the links apart, so the face is always measured anew.
    pub fn key(&self, g: usize) -> Option<u64> {
        let faces = self.support_faces(g);
        let m = self.mesh;
        let mut seen: Vec<(u32, [u64; 3])> = faces
            .iter()
            .flat_map(|&f| m.face(f as usize).iter())
            .map(|&v| (v, bits(m.positions[v as usize])))
            .collect();
        seen.sort_unstable();
        seen.dedup();
        if seen.windows(2).any(|w| w[0].1 == w[1].1) {
            return None;
        }
        let mut sum = mix(faces.len() as u64 ^ (u64::from(self.level) << 40));
        for &f in &faces {
            let corners = m.face(f as usize);
            let n = corners.len();
            let first = (0..n)
                .min_by_key(|&k| bits(m.positions[corners[k] as usize]))
                .unwrap_or(0);
            let group = m.face_groups[f as usize] as usize;
            let mut h = mix(self.patch_keys.get(group).copied().unwrap_or(0) ^ (group == g) as u64);
            for k in 0..n {
                let v = corners[(first + k) % n];
                let w = corners[(first + k + 1) % n];
                let tags = u64::from(m.corners.contains(&v))
                    | u64::from(m.sharp_edges.contains(&edge_key(v, w))) << 1;
                for x in bits(m.positions[v as usize]) {
                    h = (h.rotate_left(5) ^ x).wrapping_mul(0x517C_C1B7_2722_0A95);
                }
                h = (h.rotate_left(5) ^ tags).wrapping_mul(0x517C_C1B7_2722_0A95);
            }
            sum = sum.wrapping_add(mix(h));
        }
        Some(sum)
    }

    /// Group `g`'s support as a mesh of its own, and g's group there: the groups in use,
    /// in their order (patch kinds kept, names dropped: where two analytic patches meet,
    /// the group order picks the frame of their shared vertices), vertices in order of
    /// first use, with the sharp edges and corners among them.
    pub fn support_mesh(&self, g: usize) -> (ControlMesh, u32) {
        let m = self.mesh;
        let faces = self.support_faces(g);
        let mut used: Vec<u32> = faces.iter().map(|&f| m.face_groups[f as usize]).collect();
        used.sort_unstable();
        used.dedup();
        let mut out = ControlMesh::new();
        for &u in &used {
            let patch = m.groups.get(u as usize).map(|x| x.patch);
            out.groups.push(Group {
                name: String::new(),
                patch: patch.unwrap_or_default(),
            });
        }
        let local_group = |u: u32| used.binary_search(&u).unwrap_or(0) as u32;
        let fans = self.fans(g, &faces);
        let mut vertex: HashMap<(u32, u32), u32, FxBuildHasher> = HashMap::default();
        let mut originals = Vec::new();
        for (k, &f) in faces.iter().enumerate() {
            let local: Vec<u32> = m
                .face(f as usize)
                .iter()
                .map(|&v| {
                    let fan = fans.get(&(v, k as u32)).copied().unwrap_or(0);
                    *vertex.entry((v, fan)).or_insert_with(|| {
                        originals.push(v);
                        out.push_vertex(m.positions[v as usize])
                    })
                })
                .collect();
            out.push_face(&local, local_group(m.face_groups[f as usize]));
        }
        for (local, &v) in originals.iter().enumerate() {
            if m.corners.contains(&v) {
                out.corners.insert(local as u32);
            }
        }
        let edges: Vec<(u32, u32)> = out
            .faces()
            .flat_map(|f| (0..f.len()).map(move |k| edge_key(f[k], f[(k + 1) % f.len()])))
            .collect();
        for (a, b) in edges {
            if m.sharp_edges
                .contains(&edge_key(originals[a as usize], originals[b as usize]))
            {
                out.sharp_edges.insert((a, b));
            }
        }
        (out, local_group(g as u32))
    }

    /// Where a vertex outside group `g`'s faces has support faces in several fans (the
    /// support cuts its ring apart), which fan each of those faces is in: `(vertex, index of
    /// the face in faces) -> smallest such index in its fan`. The support mesh gives each fan
    /// a vertex of its own, so that it stays manifold; these vertices' own rules never reach
    /// g's triangles.
    fn fans(&self, g: usize, faces: &[u32]) -> HashMap<(u32, u32), u32, FxBuildHasher> {
        let m = self.mesh;
        let mut own: Vec<u32> = self
            .faces_of_group(g)
            .iter()
            .flat_map(|&f| m.face(f as usize).iter().copied())
            .collect();
        own.sort_unstable();
        own.dedup();
        let mut around: Vec<(u32, u32)> = faces
            .iter()
            .enumerate()
            .flat_map(|(k, &f)| m.face(f as usize).iter().map(move |&v| (v, k as u32)))
            .filter(|(v, _)| own.binary_search(v).is_err())
            .collect();
        around.sort_unstable();
        let mut fans = HashMap::default();
        for run in around.chunk_by(|a, b| a.0 == b.0) {
            if run.len() < 2 {
                continue;
            }
            let v = run[0].0;
            // Union-find over the run's faces: two faces around v are in one fan when they
            // share an edge from v.
            let mut parent: Vec<usize> = (0..run.len()).collect();
            fn root(parent: &mut [usize], mut i: usize) -> usize {
                while parent[i] != i {
                    parent[i] = parent[parent[i]];
                    i = parent[i];
                }
                i
            }
            let neighbours = |k: u32| {
                let f = m.face(faces[k as usize] as usize);
                let at = f.iter().position(|&x| x == v).unwrap_or(0);
                [f[(at + 1) % f.len()], f[(at + f.len() - 1) % f.len()]]
            };
            for i in 0..run.len() {
                for j in i + 1..run.len() {
                    let (a, b) = (neighbours(run[i].1), neighbours(run[j].1));
                    if a.iter().any(|x| b.contains(x)) {
                        let (ri, rj) = (root(&mut parent, i), root(&mut parent, j));
                        parent[ri.max(rj)] = ri.min(rj);
                    }
                }
            }
            for i in 0..run.len() {
                let r = root(&mut parent, i);
                fans.insert((v, run[i].1), run[r].1);
            }
        }
        fans
    }

    /// Group `g`'s decoded surface: the subdivision of its support at the level, and g's
    /// group in it.
    pub fn surface(&self, g: usize) -> Result<(UniformSurface, usize)> {
        let (mesh, local) = self.support_mesh(g);
        Ok((
            UniformSurface::new(&mesh, self.level, DEFAULT_MAX_FACES)?,
            local as usize,
        ))
    }
}

/// Offsets and items of `(key, item)` pairs grouped by key (`n` keys; keys out of range
/// dropped), items in the order given.
fn csr(n: usize, pairs: impl Iterator<Item = (usize, usize)> + Clone) -> (Vec<u32>, Vec<u32>) {
    let mut offsets = vec![0u32; n + 1];
    for (k, _) in pairs.clone() {
        if k < n {
            offsets[k + 1] += 1;
        }
    }
    for k in 0..n {
        offsets[k + 1] += offsets[k];
    }
    let mut fill = offsets.clone();
    let mut items = vec![0u32; offsets[n] as usize];
    for (k, item) in pairs {
        if k < n {
            items[fill[k] as usize] = item as u32;
            fill[k] += 1;
        }
    }
    (offsets, items)
}

fn bits(p: glam::DVec3) -> [u64; 3] {
    p.to_array().map(f64::to_bits)
}

fn text_hash(s: &str) -> u64 {
    s.bytes().fold(0xCBF2_9CE4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x100_0000_01B3)
    })
}

/// SplitMix64's finaliser: every input bit moves every output bit.
pub(super) fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::fit::test_support::grid_cube;

    /// A cube's sides with bumps, so that no two vertices decode alike.
    fn bumpy_cube(sharp: bool) -> ControlMesh {
        let mut m = grid_cube(4);
        for p in &mut m.positions {
            *p += DVec3::new(0.011, -0.006, 0.004) * (p.x * 3.1 + p.y * 1.7 + p.z * 0.9).sin();
        }
        if sharp {
            m.sharpen_group_boundaries();
            m.corners.insert(0);
        }
        m
    }

    /// Group g's triangles by their corners, rounded far below the cube's size, sorted.
    fn triangles(surface: &UniformSurface, g: usize) -> Vec<[[i64; 3]; 3]> {
        let mut out = Vec::new();
        surface.visit_group_triangles(g, |block| {
            out.extend(block.iter().map(|t| {
                t.map(|v| {
                    surface.positions()[v as usize]
                        .to_array()
                        .map(|x| (x * 1e9).round() as i64)
                })
            }));
            true
        });
        out.sort_unstable();
        out
    }

    /// Each group decodes from its support to the triangles the whole model decodes it to:
    /// with smooth group boundaries (the support's other faces shape it) and sharp ones.
    #[test]
    fn a_support_decodes_to_the_whole_models_triangles() {
        for sharp in [false, true] {
            let mesh = bumpy_cube(sharp);
            let supports = Supports::new(&mesh, 3).unwrap();
            let whole = supports.whole_surface().unwrap();
            for g in 0..mesh.groups.len() {
                let (surface, local) = supports.surface(g).unwrap();
                assert_eq!(
                    triangles(&surface, local),
                    triangles(&whole, g),
                    "group {g}"
                );
                assert!(supports.support_size(g) < mesh.face_count());
            }
        }
    }

    /// Keys see positions, links and tags, not numbers: renumbering keeps them; moving a
    /// vertex changes the keys of the groups whose support holds it and no other.
    #[test]
    fn keys_change_with_the_support_only() {
        let mesh = bumpy_cube(true);
        let keys = |m: &ControlMesh| {
            let s = Supports::new(m, 3).unwrap();
            (0..m.groups.len()).map(|g| s.key(g)).collect::<Vec<_>>()
        };
        let before = keys(&mesh);
        assert!(before.iter().all(Option::is_some));
        let mut renumbered = ControlMesh::new();
        let n = mesh.vertex_count();
        for v in (0..n).rev() {
            renumbered.push_vertex(mesh.positions[v]);
        }
        renumbered.groups = mesh.groups.clone();
        let flip = |v: u32| (n - 1) as u32 - v;
        for f in (0..mesh.face_count()).rev() {
            let face: Vec<u32> = mesh.face(f).iter().map(|&v| flip(v)).collect();
            renumbered.push_face(&face, mesh.face_groups[f]);
        }
        renumbered.sharp_edges = mesh
            .sharp_edges
            .iter()
            .map(|&(a, b)| edge_key(flip(a), flip(b)))
            .collect();
        renumbered.corners = mesh.corners.iter().map(|&v| flip(v)).collect();
        assert_eq!(keys(&renumbered), before);
        // The middle of side 1 (z = 1): only that side's support holds it.
        let inside = (0..n)
            .find(|&v| (mesh.positions[v] - DVec3::new(0.5, 0.5, 1.0)).length() < 0.05)
            .unwrap();
        let mut moved = mesh.clone();
        moved.positions[inside].z += 0.01;
        let after = keys(&moved);
        let changed: Vec<usize> = (0..6).filter(|&g| after[g] != before[g]).collect();
        assert_eq!(changed, vec![1]);
        // Two vertices on one position: links cannot be told from positions.
        let mut doubled = mesh.clone();
        doubled.positions[inside] = doubled.positions[(inside + 1) % n];
        assert!(keys(&doubled).iter().any(Option::is_none));
    }
}
