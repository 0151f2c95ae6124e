//! What a group's subdivided surface depends on.
//!
//! Every rule that places a point inside a control face at any level (smooth, crease and
//! corner masks, limit masks, the sparse output of boundary patches, the cylindrical frame of
//! a crease) reads control vertices at most one ring of faces away (Loop's masks reach one
//! ring, and each finer level halves the reach), and which rule applies depends on the class
//! of each vertex it reads (corner, crease, dart, smooth; next to a plane or not), which
//! depends on the faces around that vertex. Across a sharp edge only crease masks apply,
//! and they read the crease alone. So the level-n triangles of a group whose boundary edges
//! are all sharp (every fitted group: CAD-face boundaries are sharp) are a function of its
//! own faces' corners, the classes and frames of its vertices and edges and how the sparse
//! output joins its faces, and subdividing the faces around its vertices alone makes them
//! bit for bit as the whole mesh does (the one global input, the model's size that scales
//! the frames' apex test, is kept by keeping every vertex). The encoder's measurement uses
//! this twice: a group whose fingerprint is unchanged keeps its measurement
//! ([`Supports::fingerprints`]), and the groups that changed are subdivided on the faces
//! around them alone ([`Supports::submesh`]).

use std::collections::HashMap;

use rustc_hash::FxBuildHasher;

use super::masks::eclass;
use super::sparse::{SparsePlan, DENSE};
use super::topology::build_level0;
use crate::error::Result;
use crate::mesh::{edge_key, Buckets, ControlMesh};

/// SplitMix64's finaliser: every input bit moves every output bit.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn absorb(h: u64, x: u64) -> u64 {
    mix(h ^ x)
}

/// Union-find over the corners of the submesh's faces, for splitting vertices whose faces
/// in the submesh form several fans.
struct Fans {
    parent: Vec<u32>,
}

impl Fans {
    fn root(&mut self, mut i: u32) -> u32 {
        while self.parent[i as usize] != i {
            let up = self.parent[self.parent[i as usize] as usize];
            self.parent[i as usize] = up;
            i = up;
        }
        i
    }

    fn join(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.root(a), self.root(b));
        if ra != rb {
            // The smaller root stays, so the result does not depend on the order of joins.
            let (lo, hi) = (ra.min(rb), ra.max(rb));
            self.parent[hi as usize] = lo;
        }
    }
}

/// The groups of one control mesh with what their supports are made of.
pub(crate) struct Supports<'a> {
    mesh: &'a ControlMesh,
    /// Faces around each vertex, in mesh order.
    around: Buckets,
    /// Faces of each group, in mesh order.
    by_group: Vec<Vec<usize>>,
    /// Per group: every edge between one of its faces and a face of another group is sharp
    /// (or the group has no such edge). Such a group's surface reads no position across its
    /// boundary, and of the faces outside it only what they make of its vertices' and
    /// edges' classes counts. Otherwise smooth masks reach across, and neither a
    /// fingerprint nor a submesh of the group is made.
    sharp_bounded: Vec<bool>,
    /// Per group: its vertices have distinct positions, so its faces described by their
    /// corners' positions name its connectivity (a group with coincident vertices could
    /// be numbered into another connectivity with the same description).
    distinct: Vec<bool>,
    /// A hash of each group's patch kind.
    patch_hash: Vec<u64>,
}

impl<'a> Supports<'a> {
    pub fn new(mesh: &'a ControlMesh) -> Self {
        let around = Buckets::new(mesh.vertex_count(), || {
            (0..mesh.face_count()).flat_map(|f| mesh.face(f).iter().map(move |&v| (v, f as u32)))
        });
        let mut by_group: Vec<Vec<usize>> = vec![Vec::new(); mesh.groups.len()];
        for (f, &g) in mesh.face_groups.iter().enumerate() {
            if let Some(list) = by_group.get_mut(g as usize) {
                list.push(f);
            }
        }
        let crosses_softly = |f: usize| {
            let face = mesh.face(f);
            (0..face.len()).any(|k| {
                let (a, b) = (face[k], face[(k + 1) % face.len()]);
                !mesh.sharp_edges.contains(&edge_key(a, b))
                    && around.of(a as usize).iter().any(|&n| {
                        n as usize != f
                            && mesh.face_groups[n as usize] != mesh.face_groups[f]
                            && mesh.face(n as usize).contains(&b)
                    })
            })
        };
        let sharp_bounded = by_group
            .iter()
            .map(|own| !own.iter().any(|&f| crosses_softly(f)))
            .collect();
        let distinct = by_group
            .iter()
            .map(|own| {
                let mut corners: Vec<u32> = own
                    .iter()
                    .flat_map(|&f| mesh.face(f).iter().copied())
                    .collect();
                corners.sort_unstable();
                corners.dedup();
                let mut at: Vec<[u64; 3]> = corners
                    .iter()
                    .map(|&v| mesh.positions[v as usize].to_array().map(f64::to_bits))
                    .collect();
                at.sort_unstable();
                at.windows(2).all(|w| w[0] != w[1])
            })
            .collect();
        let patch_hash = mesh
            .groups
            .iter()
            .map(|g| {
                format!("{:?}", g.patch)
                    .bytes()
                    .fold(0u64, |h, b| absorb(h, u64::from(b)))
            })
            .collect();
        Supports {
            mesh,
            around,
            by_group,
            sharp_bounded,
            distinct,
            patch_hash,
        }
    }

    /// Whether group `g` has a fingerprint: sharp-bounded, with distinct vertex positions.
    fn identified(&self, g: usize) -> bool {
        self.sharp_bounded.get(g).copied().unwrap_or(false)
            && self.distinct.get(g).copied().unwrap_or(false)
    }

    /// Per group, a value that changes whenever anything its subdivided surface depends on
    /// changes, and stays the same when the mesh is only renumbered: its triangles as
    /// subdivision starts from them, each corner with its position, class and frame, each
    /// edge with its rule, sharpness and frame (the classes, which read the faces around
    /// each vertex, as the subdivision computes them), and how the sparse output joins the
    /// triangle. Summed as a set; equal values of different surfaces take a 64-bit
    /// coincidence. `None` for a group that is not sharp-bounded or has coincident vertices:
    /// it is to be measured every time.
    pub fn fingerprints(&self) -> Result<Vec<Option<u64>>> {
        let mesh = self.mesh;
        let (l0, base) = build_level0(mesh)?;
        let plan = SparsePlan::new(&l0, &base);
        // A frame by its axis and kind. Its apex radius (a fixed fraction of the model's
        // size, which changes with any vertex) is left out: it decides only for points
        // within 1e-12 of the size of a cone's axis, and the apex itself is on the axis.
        let frame_hash = |id: u16| match id {
            0 => 0,
            id => base.frames.get(usize::from(id) - 1).map_or(1, |f| {
                [f.origin, f.axis, f.e1, f.e2]
                    .iter()
                    .flat_map(|p| p.to_array())
                    .fold(
                        absorb(absorb(2, f.kind_bits().0), f.kind_bits().1),
                        |h, x| absorb(h, x.to_bits()),
                    )
            }),
        };
        let n_groups = self.by_group.len();
        let mut sums = vec![(0u64, 0u64); n_groups];
        for t in 0..l0.nf() {
            let g = base.group[t] as usize;
            if !self.identified(g) {
                continue;
            }
            let corners = &l0.faces[3 * t..3 * t + 3];
            let edges = &l0.face_edges[3 * t..3 * t + 3];
            let key = |v: u32| mesh.positions[v as usize].to_array().map(f64::to_bits);
            let first = (0..3).min_by_key(|&k| key(corners[k])).unwrap_or(0);
            let mut h = absorb(g as u64, self.patch_hash[g]);
            for k in 0..3 {
                let c = (first + k) % 3;
                let (v, e) = (corners[c] as usize, edges[c] as usize);
                for x in key(corners[c]) {
                    h = absorb(h, x);
                }
                h = absorb(h, u64::from(l0.vclass[v]));
                h = absorb(h, frame_hash(l0.vframe(v)));
                // A crease rule names the edge's ends in its stored direction: as seen
                // from this corner, so that another numbering gives the same value.
                let mut class = l0.eclass[e];
                if l0.edges[e][0] != corners[c] {
                    class = match class & eclass::RULE_MASK {
                        eclass::W58A => class & !eclass::RULE_MASK | eclass::W58B,
                        eclass::W58B => class & !eclass::RULE_MASK | eclass::W58A,
                        _ => class,
                    };
                }
                h = absorb(h, u64::from(class));
                h = absorb(h, frame_hash(l0.eframe(e)));
            }
            // How the sparse output joins this face: densely, alone, or as the emitting or
            // the other face of a belt quad across one of its slots.
            let output = plan.as_ref().map_or(0, |plan| match plan.unit[t] {
                DENSE => 1,
                u if u as usize == t => 2,
                u => {
                    let across = &l0.face_edges[3 * u as usize..3 * u as usize + 3];
                    let slot = (0..3).find(|&k| across.contains(&edges[(first + k) % 3]));
                    3 + 2 * slot.unwrap_or(3) as u64 + u64::from(t < u as usize)
                }
            });
            h = absorb(h, output);
            let (sum, count) = &mut sums[g];
            *sum = sum.wrapping_add(mix(h));
            *count += 1;
        }
        Ok(sums
            .into_iter()
            .enumerate()
            .map(|(g, (sum, n))| self.identified(g).then(|| absorb(sum, n)))
            .collect())
    }

    /// `groups` cut into consecutive runs of at most `max_triangles` level-`level`
    /// triangles each (a group larger than that alone), so that their submeshes can be
    /// subdivided one at a time; one run when one of them is not sharp-bounded (it is
    /// subdivided with the whole mesh).
    pub fn runs<'g>(&self, groups: &'g [usize], level: u8, max_triangles: u64) -> Vec<&'g [usize]> {
        let sharp = |g: usize| self.sharp_bounded.get(g).copied().unwrap_or(true);
        if !groups.iter().all(|&g| sharp(g)) {
            return vec![groups];
        }
        let per_face = 1u64 << (2 * u32::from(level.min(31)));
        let triangles = |g: usize| -> u64 {
            let faces = self.by_group.get(g).map_or(&[][..], Vec::as_slice);
            let fan: usize = faces.iter().map(|&f| self.mesh.face(f).len() - 2).sum();
            (fan as u64).saturating_mul(per_face)
        };
        let (mut runs, mut start, mut held) = (Vec::new(), 0, 0u64);
        for (i, &g) in groups.iter().enumerate() {
            let n = triangles(g);
            if held > 0 && held.saturating_add(n) > max_triangles {
                runs.push(&groups[start..i]);
                (start, held) = (i, 0);
            }
            held = held.saturating_add(n);
        }
        if start < groups.len() {
            runs.push(&groups[start..]);
        }
        runs
    }

    /// The faces around the vertices of `groups` (in mesh order), as a mesh whose subdivided
    /// surface over those groups' faces is the whole mesh's; `None` when one of them is not
    /// sharp-bounded. Every vertex is kept (unused ones are isolated), so vertex ids, groups
    /// and the model's size stay those of `mesh`; the sharp edges are those among the kept
    /// faces' edges. Along the outer edge a vertex may keep faces that touch only at it; a
    /// mesh needs one fan per vertex, so such a vertex gets a copy for each further fan (its
    /// position, tags and sharp edges carried over). No point of the groups' faces depends on
    /// those vertices' own rules, only on their positions.
    pub fn submesh(&self, groups: &[usize]) -> Option<ControlMesh> {
        let (mesh, around) = (self.mesh, &self.around);
        if groups
            .iter()
            .any(|&g| !self.sharp_bounded.get(g).copied().unwrap_or(true))
        {
            return None;
        }
        let mut near = vec![false; mesh.vertex_count()];
        for &g in groups.iter().filter(|&&g| g < self.by_group.len()) {
            for &f in &self.by_group[g] {
                for &v in mesh.face(f) {
                    near[v as usize] = true;
                }
            }
        }
        let kept: Vec<usize> = (0..mesh.face_count())
            .filter(|&f| mesh.face(f).iter().any(|&v| near[v as usize]))
            .collect();

        // Faces kept around each vertex; a vertex that keeps all of its faces keeps its one fan.
        let mut kept_around = vec![0u32; mesh.vertex_count()];
        for &f in &kept {
            for &v in mesh.face(f) {
                kept_around[v as usize] += 1;
            }
        }
        let partial = |v: u32| (kept_around[v as usize] as usize) < around.of(v as usize).len();
        // Corners of kept faces at partial vertices, joined across the edges they share.
        let mut slot_of: HashMap<(usize, usize), u32, FxBuildHasher> = HashMap::default();
        let mut slots: Vec<(usize, usize)> = Vec::new();
        for (i, &f) in kept.iter().enumerate() {
            for (k, &v) in mesh.face(f).iter().enumerate() {
                if partial(v) {
                    slot_of.insert((i, k), slots.len() as u32);
                    slots.push((i, k));
                }
            }
        }
        let mut fans = Fans {
            parent: (0..slots.len() as u32).collect(),
        };
        let mut by_edge: HashMap<(u32, u32), u32, FxBuildHasher> = HashMap::default();
        for (s, &(i, k)) in slots.iter().enumerate() {
            let face = mesh.face(kept[i]);
            let n = face.len();
            let v = face[k];
            for w in [face[(k + 1) % n], face[(k + n - 1) % n]] {
                match by_edge.entry((v, w)) {
                    std::collections::hash_map::Entry::Occupied(e) => fans.join(*e.get(), s as u32),
                    std::collections::hash_map::Entry::Vacant(e) => {
                        e.insert(s as u32);
                    }
                }
            }
        }
        // The fan of each vertex's first slot keeps its id; each further fan gets a copy.
        let mut out = ControlMesh {
            positions: mesh.positions.clone(),
            face_offsets: vec![0],
            face_vertices: Vec::new(),
            face_groups: Vec::new(),
            groups: mesh.groups.clone(),
            sharp_edges: Default::default(),
            corners: mesh.corners.clone(),
        };
        let mut first_fan: HashMap<u32, u32, FxBuildHasher> = HashMap::default();
        let mut copy_of_fan: HashMap<u32, u32, FxBuildHasher> = HashMap::default();
        let mut vertex_of_slot = vec![0u32; slots.len()];
        for s in 0..slots.len() {
            let (i, k) = slots[s];
            let v = mesh.face(kept[i])[k];
            let fan = fans.root(s as u32);
            let id = match first_fan.get(&v) {
                None => {
                    first_fan.insert(v, fan);
                    v
                }
                Some(&first) if first == fan => v,
                Some(_) => *copy_of_fan.entry(fan).or_insert_with(|| {
                    out.positions.push(mesh.positions[v as usize]);
                    let copy = (out.positions.len() - 1) as u32;
                    if mesh.corners.contains(&v) {
                        out.corners.insert(copy);
                    }
                    copy
                }),
            };
            vertex_of_slot[s] = id;
        }
        for (i, &f) in kept.iter().enumerate() {
            let face = mesh.face(f);
            let renamed: Vec<u32> = (0..face.len())
                .map(|k| {
                    slot_of
                        .get(&(i, k))
                        .map_or(face[k], |&s| vertex_of_slot[s as usize])
                })
                .collect();
            for k in 0..face.len() {
                let (a, b) = (renamed[k], renamed[(k + 1) % face.len()]);
                let (oa, ob) = (face[k], face[(k + 1) % face.len()]);
                if mesh.sharp_edges.contains(&edge_key(oa, ob)) {
                    out.sharp_edges.insert(edge_key(a, b));
                }
            }
            out.push_face(&renamed, mesh.face_groups[f]);
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{BoundarySurface, PatchKind};
    use crate::subdiv::UniformSurface;
    use glam::DVec3;

    /// The vertices of an n x n grid of unit quads at heights `z(x, y)`, vertex `i + (n+1) j`
    /// at `(i, j)`; no faces yet.
    fn bumpy_grid(n: u32, z: impl Fn(f64, f64) -> f64) -> ControlMesh {
        let mut m = ControlMesh::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (f64::from(i), f64::from(j));
                m.push_vertex(DVec3::new(x, y, z(x, y)));
            }
        }
        m
    }

    /// A bumpy 8x8 grid of quads split into triangles, in four groups (quadrants) of
    /// different kinds, with sharp quadrant boundaries and a corner tag.
    fn quadrants() -> ControlMesh {
        let n = 8u32;
        let mut m = bumpy_grid(n, |x, y| 0.3 * (x * 0.7).sin() * (y * 0.4).cos());
        let kinds = [
            PatchKind::Closed,
            PatchKind::Boundary(BoundarySurface::Plane),
            PatchKind::Closed,
            PatchKind::Closed,
        ];
        let groups: Vec<u32> = kinds
            .iter()
            .enumerate()
            .map(|(k, &kind)| m.push_group(format!("q{k}"), kind))
            .collect();
        let id = |i: u32, j: u32| i + (n + 1) * j;
        for j in 0..n {
            for i in 0..n {
                let g = groups[usize::from(i >= n / 2) + 2 * usize::from(j >= n / 2)];
                m.push_face(&[id(i, j), id(i + 1, j), id(i + 1, j + 1)], g);
                m.push_face(&[id(i, j), id(i + 1, j + 1), id(i, j + 1)], g);
            }
        }
        for k in 0..n {
            m.set_sharp(id(n / 2, k), id(n / 2, k + 1));
            m.set_sharp(id(k, n / 2), id(k + 1, n / 2));
        }
        m.corners.insert(id(n / 2, n / 2));
        m
    }

    fn fingerprints(m: &ControlMesh) -> Vec<Option<u64>> {
        Supports::new(m).fingerprints().unwrap()
    }

    /// Group `g`'s triangles of `s` as corner positions, sorted.
    fn triangles_of(s: &UniformSurface, g: usize) -> Vec<[[u64; 3]; 3]> {
        let mut tris = Vec::new();
        s.group_triangles(g, &mut tris);
        let mut out: Vec<[[u64; 3]; 3]> = tris
            .iter()
            .map(|t| t.map(|v| s.positions()[v as usize].to_array().map(f64::to_bits)))
            .collect();
        out.sort_unstable();
        out
    }

    #[test]
    fn a_support_submesh_subdivides_its_groups_as_the_whole_mesh_does() {
        let m = quadrants();
        for level in [1, 3] {
            let whole = UniformSurface::new(&m, level, 1 << 24).unwrap();
            for groups in [vec![0], vec![1], vec![3], vec![0, 3], vec![1, 2]] {
                let sub = Supports::new(&m).submesh(&groups).unwrap();
                assert!(sub.face_count() < m.face_count(), "{groups:?}");
                let part = UniformSurface::new(&sub, level, 1 << 24).unwrap();
                for &g in &groups {
                    assert_eq!(
                        triangles_of(&part, g),
                        triangles_of(&whole, g),
                        "group {g} of {groups:?} at level {level}"
                    );
                }
            }
        }
    }

    /// A bumpy 8x8 grid of quads with alternating diagonals (vertices of valence 4 and 8)
    /// in sixteen groups of 2x2 quads (closed, planes and a cylinder) with sharp boundaries.
    fn checkerboard() -> ControlMesh {
        let n = 8u32;
        let mut m = bumpy_grid(n, |x, y| 0.4 * (x * 0.9).cos() * (y * 0.6).sin());
        let cylinder = PatchKind::Boundary(BoundarySurface::Cylinder {
            axis: crate::mesh::Axis {
                origin: DVec3::new(0.0, 4.0, -3.0),
                direction: DVec3::X,
            },
        });
        for b in 0..16 {
            let kind = match b {
                5 => cylinder,
                _ if b % 3 == 0 => PatchKind::Boundary(BoundarySurface::Plane),
                _ => PatchKind::Closed,
            };
            m.push_group(format!("b{b}"), kind);
        }
        let id = |i: u32, j: u32| i + (n + 1) * j;
        for j in 0..n {
            for i in 0..n {
                let g = i / 2 + 4 * (j / 2);
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                if (i + j) % 2 == 0 {
                    m.push_face(&[a, b, c], g);
                    m.push_face(&[a, c, d], g);
                } else {
                    m.push_face(&[a, b, d], g);
                    m.push_face(&[b, c, d], g);
                }
            }
        }
        for k in 0..n {
            for line in (2..n).step_by(2) {
                m.set_sharp(id(line, k), id(line, k + 1));
                m.set_sharp(id(k, line), id(k + 1, line));
            }
        }
        m
    }

    #[test]
    fn fans_that_touch_at_one_vertex_are_split() {
        let m = checkerboard();
        let supports = Supports::new(&m);
        let mut split = 0;
        for level in [2, 4] {
            let whole = UniformSurface::new(&m, level, 1 << 24).unwrap();
            for g in 0..m.groups.len() {
                for h in g + 1..m.groups.len() {
                    let sub = supports.submesh(&[g, h]).unwrap();
                    split += usize::from(sub.vertex_count() > m.vertex_count());
                    let part = UniformSurface::new(&sub, level, 1 << 24).unwrap();
                    for k in [g, h] {
                        assert_eq!(
                            triangles_of(&part, k),
                            triangles_of(&whole, k),
                            "group {k} of {g}, {h} at level {level}"
                        );
                    }
                }
            }
        }
        // The supports of two groups that touch at a corner meet at single vertices.
        assert!(split > 0);
    }

    #[test]
    fn runs_hold_at_most_the_given_triangles() {
        let m = checkerboard();
        let supports = Supports::new(&m);
        let groups: Vec<usize> = (0..16).collect();
        // Every group has 8 triangles: 8 * 4^2 = 128 at level 2.
        let runs = supports.runs(&groups, 2, 300);
        assert_eq!(runs.iter().map(|r| r.len()).collect::<Vec<_>>(), [2; 8]);
        assert_eq!(runs.concat(), groups);
        assert_eq!(supports.runs(&groups, 2, 100).len(), 16);
        assert_eq!(supports.runs(&groups, 2, u64::MAX).len(), 1);
        let mut soft = checkerboard();
        soft.sharp_edges.clear();
        assert_eq!(Supports::new(&soft).runs(&groups, 2, 300).len(), 1);
    }

    #[test]
    fn groups_without_a_local_surface_are_named() {
        // Soft boundaries: smooth masks reach across, no submesh.
        let mut m = checkerboard();
        m.sharp_edges.clear();
        let supports = Supports::new(&m);
        assert!(supports.submesh(&[0]).is_none());
        assert!(supports.fingerprints().unwrap().iter().all(Option::is_none));
        // Coincident vertices: a submesh, but no fingerprint for that group.
        let mut m = checkerboard();
        m.positions[1] = m.positions[0];
        let supports = Supports::new(&m);
        assert!(supports.submesh(&[0]).is_some());
        let prints = supports.fingerprints().unwrap();
        assert!(prints[0].is_none());
        assert!(prints[1..].iter().all(Option::is_some));
    }

    #[test]
    fn fingerprints_follow_the_support_and_ignore_numbering() {
        let m = quadrants();
        let before = fingerprints(&m);
        assert!(before.iter().all(Option::is_some));
        // A vertex inside group 3, away from the others' supports.
        let mut moved = m.clone();
        moved.positions[7 + 9 * 7].z += 1e-9;
        let after = fingerprints(&moved);
        assert_eq!(after[..3], before[..3]);
        assert_ne!(after[3], before[3]);
        // A vertex on the boundary between groups 0 and 1 is in both supports.
        let mut shared = m.clone();
        shared.positions[4 + 9 * 2].z += 1e-9;
        let after = fingerprints(&shared);
        assert_ne!(after[0], before[0]);
        assert_ne!(after[1], before[1]);
        // Across a sharp boundary only the boundary's vertices count: a vertex of group 1 next
        // to it moves group 1 alone, and group 0's triangles stay as they were.
        let mut across = m.clone();
        across.positions[5 + 9 * 2].z += 0.25;
        let after = fingerprints(&across);
        assert_eq!(after[0], before[0]);
        assert_ne!(after[1], before[1]);
        let triangles =
            |m: &ControlMesh| triangles_of(&UniformSurface::new(m, 3, 1 << 24).unwrap(), 0);
        assert_eq!(triangles(&across), triangles(&m));
        // A soft edge on a boundary leaves a group without a fingerprint.
        let mut soft = m.clone();
        soft.sharp_edges.remove(&edge_key(4 + 9 * 6, 4 + 9 * 7));
        let after = fingerprints(&soft);
        assert_eq!(after[..2], before[..2]);
        assert!(after[2].is_none());
        // Untagging the centre, a corner by its four creases anyway, changes no surface;
        // tagging a vertex of the crease between groups 0 and 1 changes those two.
        let mut tags = m.clone();
        tags.corners.clear();
        assert_eq!(fingerprints(&tags), before);
        tags.corners.insert(4 + 9 * 2);
        let after = fingerprints(&tags);
        assert!(after[0] != before[0] && after[1] != before[1]);
        assert_eq!(after[2..], before[2..]);
        // Reversed vertex order and rotated faces: the same supports.
        let renumbered = crate::subdiv::test_support::renumbered(&m);
        assert_eq!(fingerprints(&renumbered), before);
    }

    /// The spec's fitted parts (planes, cylinders, cones, a closed patch; quads and an
    /// n-gon): every group's support alone subdivides it as the whole part does.
    #[test]
    fn fitted_parts_subdivide_on_their_supports_as_a_whole() {
        for name in ["cad_part", "turned_part"] {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join(format!("spec/vectors/{name}.scode"));
            let bytes = std::fs::read(path).unwrap();
            let limits = crate::codec::Limits::default();
            let mesh = crate::codec::decode(&bytes, &limits).unwrap().mesh;
            let supports = Supports::new(&mesh);
            assert!(supports.fingerprints().unwrap().iter().all(Option::is_some));
            for level in [1, 3, 5] {
                let whole = UniformSurface::new(&mesh, level, 1 << 24).unwrap();
                for g in 0..mesh.groups.len() {
                    let sub = supports.submesh(&[g]).unwrap();
                    let part = UniformSurface::new(&sub, level, 1 << 24).unwrap();
                    assert_eq!(
                        triangles_of(&part, g),
                        triangles_of(&whole, g),
                        "{name} group {g} at level {level}"
                    );
                }
            }
        }
    }
}
