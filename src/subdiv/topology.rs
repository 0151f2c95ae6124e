//! Topological refinement with S-CODE's nested index numbering (reference §1.2) and the
//! per-level vertex/edge classification the masks need.
//!
//! Everything is flat arrays indexed by vertex / edge / face id. Level j+1 is derived from
//! level j by index arithmetic only (no hashing, no per-vertex allocation), which makes each
//! step a set of independent per-element writes that parallelise trivially.

use std::collections::HashMap;
use std::sync::OnceLock;

use crate::error::{Error, Result};
use crate::mesh::{edge_key, ControlMesh, PatchKind};

use super::frame::Frame;
use super::masks::{eclass, vclass};
use super::next_level::{child_face_edges, child_faces};
use super::par;

/// Marker for "no face" in `edge_faces`.
pub(crate) const NONE: u32 = u32::MAX;

/// Connectivity and classification of one level.
///
/// Shaped for gathers: the position of a new vertex reads only its own entries
/// (`edges`, `edge_faces`, `faces`, or its `ring`), so position evaluation writes each output
/// slot exactly once and needs no synchronisation.
#[derive(Clone, Debug, Default)]
pub(crate) struct Level {
    pub nv: usize,
    /// Triangle corners, 3 per face, counter-clockwise.
    pub faces: Vec<u32>,
    /// Edge ids of each face: `(e(c0,c1), e(c1,c2), e(c2,c0))`.
    pub face_edges: Vec<u32>,
    /// Stored orientation `(a, b)` of each edge.
    pub edges: Vec<[u32; 2]>,
    /// `[left, right]`: `left` traverses the edge `a -> b` (always present), `right` the other
    /// way or `NONE` on the mesh boundary.
    pub edge_faces: Vec<[u32; 2]>,
    /// Vertex rings; built lazily for the finest level (plain positions do not need them).
    pub rings: OnceLock<Rings>,
    pub vclass: Vec<u8>,
    pub eclass: Vec<u8>,
    /// Frame id (0 = Cartesian) per vertex / edge; empty when the mesh has no frames.
    pub vframe: Vec<u16>,
    pub eframe: Vec<u16>,
}

/// CSR ring of incident edges per vertex, counter-clockwise; for a boundary vertex it starts
/// and ends with the two boundary edges (so it has one more edge than faces). CSR rather than
/// a fixed stride because control meshes have arbitrary valences.
#[derive(Clone, Debug, Default)]
pub(crate) struct Rings {
    pub offsets: Vec<u32>,
    pub edges: Vec<u32>,
}

impl Level {
    pub fn ne(&self) -> usize {
        self.edges.len()
    }
    pub fn nf(&self) -> usize {
        self.faces.len() / 3
    }
    #[inline]
    pub fn ring(&self, v: usize) -> &[u32] {
        // Internal invariant: `Refinement` builds the rings of a level before evaluating it.
        let r = self.rings.get().expect("rings are built before use");
        &r.edges[r.offsets[v] as usize..r.offsets[v + 1] as usize]
    }
    /// Vertex of face `f` opposite to its edge `e`.
    #[inline]
    pub fn opposite(&self, f: u32, e: u32) -> u32 {
        let f = f as usize;
        let fe = &self.face_edges[3 * f..3 * f + 3];
        let s = if fe[0] == e {
            0
        } else if fe[1] == e {
            1
        } else {
            2
        };
        self.faces[3 * f + (s + 2) % 3]
    }
    #[inline]
    pub fn vframe(&self, v: usize) -> u16 {
        self.vframe.get(v).copied().unwrap_or(0)
    }
    #[inline]
    pub fn eframe(&self, e: usize) -> u16 {
        self.eframe.get(e).copied().unwrap_or(0)
    }
    /// Slot of edge `e` in face `f`.
    #[inline]
    fn slot(&self, f: usize, e: u32) -> usize {
        let fe = &self.face_edges[3 * f..3 * f + 3];
        if fe[0] == e {
            0
        } else if fe[1] == e {
            1
        } else {
            2
        }
    }
}

/// Static data of level 0 shared by all levels.
#[derive(Clone, Debug, Default)]
pub(crate) struct Base {
    /// Control-mesh face of each base triangle (fan triangulation).
    pub control_face: Vec<u32>,
    /// Group of each base triangle.
    pub group: Vec<u32>,
    /// True when the base triangle's group is a boundary patch.
    pub boundary_patch: Vec<bool>,
    /// Frame id of each group (0 = none).
    pub group_frame: Vec<u16>,
    pub frames: Vec<Frame>,
    /// Per base triangle, the other triangle of its belt quad (`NONE` if it has none); empty
    /// when the mesh has no framed group. Decided here, where the control positions are
    /// known, because the choice between a closed belt's two pairings reads them
    /// ([`super::sparse::belt_partners`]).
    pub belt: Vec<u32>,
}

/// Fan-triangulates the control mesh and builds level 0.
pub(crate) fn build_level0(mesh: &ControlMesh) -> Result<(Level, Base)> {
    mesh.validate()?;
    let nv = mesh.vertex_count();
    if nv >= u32::MAX as usize / 2 {
        return Err(Error::Mesh(format!("{nv} vertices is too many")));
    }
    let (frames, group_frame) = group_frames(mesh)?;
    let has_frames = !frames.is_empty();
    let mut base = Base {
        group_frame,
        frames,
        ..Default::default()
    };
    let faces = fan_triangulate(mesh, &mut base)?;
    let EdgeIndex {
        edges,
        edge_faces,
        face_edges,
    } = index_edges(mesh, &faces, &base)?;
    let (vf_off, vf) = vertex_corners(nv, &faces);
    let mut lvl = Level {
        nv,
        faces,
        face_edges,
        edges,
        edge_faces,
        ..Default::default()
    };
    let mut ecls = crease_flags(&lvl, mesh);
    let rings = level0_rings(&lvl, &vf_off, &vf)?;
    let _ = lvl.rings.set(rings);
    let vcls: Vec<u8> = (0..nv)
        .map(|v| classify_vertex(&lvl, v, &ecls, &base, mesh))
        .collect();
    let eframe = add_edge_rules(&lvl, &base, &vcls, &mut ecls, has_frames);
    let vframe = if has_frames {
        vertex_frames(&lvl, &vcls, &ecls, &eframe)
    } else {
        Vec::new()
    };
    lvl.vclass = vcls;
    lvl.eclass = ecls;
    lvl.vframe = vframe;
    lvl.eframe = eframe;
    base.belt = super::sparse::belt_partners(&lvl, &base, &mesh.positions);
    Ok((lvl, base))
}

/// Frames, one per Cylinder/Cone group, in group order, and the frame id of every group
/// (0 = none; frame `i` has id `i + 1`).
fn group_frames(mesh: &ControlMesh) -> Result<(Vec<Frame>, Vec<u16>)> {
    let scale = mesh.diagonal().max(1e-300);
    let mut frames = Vec::new();
    let mut group_frame = vec![0u16; mesh.groups.len()];
    for (g, group) in mesh.groups.iter().enumerate() {
        if let PatchKind::Boundary(s) = &group.patch {
            if let Some(fr) = Frame::of_surface(s, scale) {
                let fr =
                    fr.map_err(|e| Error::Mesh(format!("group {g} (`{}`): {e}", group.name)))?;
                if frames.len() >= u16::MAX as usize - 1 {
                    return Err(Error::Mesh("too many cylinder/cone groups".into()));
                }
                frames.push(fr);
                group_frame[g] = frames.len() as u16;
            }
        }
    }
    Ok((frames, group_frame))
}

/// Fan triangulation: the corners of the base triangles, 3 per triangle; fills `base`'s
/// control face, group and boundary-patch flag of each.
fn fan_triangulate(mesh: &ControlMesh, base: &mut Base) -> Result<Vec<u32>> {
    let mut faces = Vec::with_capacity(mesh.face_vertices.len() * 3);
    for (f, poly) in mesh.faces().enumerate() {
        let g = mesh.face_groups[f];
        let bp = matches!(mesh.groups[g as usize].patch, PatchKind::Boundary(_));
        for i in 1..poly.len() - 1 {
            faces.extend_from_slice(&[poly[0], poly[i], poly[i + 1]]);
            base.control_face.push(f as u32);
            base.group.push(g);
            base.boundary_patch.push(bp);
        }
    }
    let nf = faces.len() / 3;
    if nf >= (u32::MAX / 4) as usize {
        return Err(Error::Mesh(format!("{nf} triangles is too many")));
    }
    Ok(faces)
}

/// The edges of the base triangles (see [`Level`] for the three arrays).
struct EdgeIndex {
    edges: Vec<[u32; 2]>,
    edge_faces: Vec<[u32; 2]>,
    face_edges: Vec<u32>,
}

/// Numbers the edges of the triangles `faces` in first-met order (orientation: the
/// direction first met). Fails on an edge traversed twice the same way or by more than two
/// faces, and on a sharp edge of `mesh` that is not an edge.
fn index_edges(mesh: &ControlMesh, faces: &[u32], base: &Base) -> Result<EdgeIndex> {
    let nf = faces.len() / 3;
    let mut edge_index: HashMap<(u32, u32), u32> = HashMap::with_capacity(nf * 2);
    let mut edges: Vec<[u32; 2]> = Vec::with_capacity(nf * 3 / 2 + 8);
    let mut edge_faces: Vec<[u32; 2]> = Vec::with_capacity(nf * 3 / 2 + 8);
    let mut face_edges = vec![0u32; nf * 3];
    for f in 0..nf {
        for s in 0..3 {
            let (u, w) = (faces[3 * f + s], faces[3 * f + (s + 1) % 3]);
            let key = edge_key(u, w);
            let e = match edge_index.get(&key) {
                None => {
                    let e = edges.len() as u32;
                    edge_index.insert(key, e);
                    edges.push([u, w]);
                    edge_faces.push([f as u32, NONE]);
                    e
                }
                Some(&e) => {
                    let ef = &mut edge_faces[e as usize];
                    if edges[e as usize] == [u, w] {
                        return Err(Error::Mesh(format!(
                            "edge ({u}, {w}) is traversed in the same direction by two faces \
                             (control faces {} and {}): inconsistent orientation or non-manifold",
                            base.control_face[ef[0] as usize], base.control_face[f]
                        )));
                    }
                    if ef[1] != NONE {
                        return Err(Error::Mesh(format!(
                            "edge ({u}, {w}) has more than two faces (non-manifold)"
                        )));
                    }
                    ef[1] = f as u32;
                    e
                }
            };
            face_edges[3 * f + s] = e;
        }
    }
    for &(a, b) in &mesh.sharp_edges {
        if !edge_index.contains_key(&(a, b)) {
            return Err(Error::Mesh(format!(
                "sharp edge ({a}, {b}) is not an edge of the mesh"
            )));
        }
    }
    Ok(EdgeIndex {
        edges,
        edge_faces,
        face_edges,
    })
}

/// Vertex -> incident corners (index `3f + s`) as CSR: offsets (`nv + 1`) and corners.
fn vertex_corners(nv: usize, faces: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let mut vf_off = vec![0u32; nv + 1];
    for &v in faces {
        vf_off[v as usize + 1] += 1;
    }
    for i in 0..nv {
        vf_off[i + 1] += vf_off[i];
    }
    let mut vf = vec![0u32; faces.len()];
    let mut fill = vf_off.clone();
    for (i, &v) in faces.iter().enumerate() {
        vf[fill[v as usize] as usize] = i as u32; // corner index 3f+s
        fill[v as usize] += 1;
    }
    (vf_off, vf)
}

/// Crease flags of every edge: mesh boundary, or sharp in `mesh`.
fn crease_flags(lvl: &Level, mesh: &ControlMesh) -> Vec<u8> {
    (0..lvl.ne())
        .map(|e| {
            let [a, b] = lvl.edges[e];
            let mut c = 0;
            if lvl.edge_faces[e][1] == NONE {
                c |= eclass::CREASE | eclass::BOUNDARY;
            }
            if mesh.sharp_edges.contains(&edge_key(a, b)) {
                c |= eclass::CREASE | eclass::SHARP;
            }
            c
        })
        .collect()
}

/// The ring (CCW fan of edges) of every level-0 vertex, from its corners (`vf_off`, `vf`:
/// see [`vertex_corners`]). Fails at a vertex whose faces do not form a single fan.
fn level0_rings(lvl: &Level, vf_off: &[u32], vf: &[u32]) -> Result<Rings> {
    let nv = lvl.nv;
    let mut ring_offsets = Vec::with_capacity(nv + 1);
    ring_offsets.push(0u32);
    let mut ring_edges = Vec::with_capacity(lvl.ne() * 2);
    for v in 0..nv {
        let corners = &vf[vf_off[v] as usize..vf_off[v + 1] as usize];
        if !corners.is_empty() {
            push_vertex_ring(lvl, v, corners, &mut ring_edges)?;
        }
        ring_offsets.push(ring_edges.len() as u32);
    }
    Ok(Rings {
        offsets: ring_offsets,
        edges: ring_edges,
    })
}

/// Appends the ring of vertex `v` (incident at `corners`, at least one) to `ring_edges`.
/// Fails when its faces do not form a single fan (a non-manifold vertex).
fn push_vertex_ring(
    lvl: &Level,
    v: usize,
    corners: &[u32],
    ring_edges: &mut Vec<u32>,
) -> Result<()> {
    let nfaces = corners.len();
    // A wedge (f, s) spans from edge e_out = FE[f][s] (v -> next) to e_in = FE[f][s+2].
    // Start at the wedge whose e_out is a boundary edge, else at the first corner.
    let mut start = None;
    for &c in corners {
        let (f, s) = (c as usize / 3, c as usize % 3);
        let e_out = lvl.face_edges[3 * f + s];
        if lvl.edge_faces[e_out as usize][1] == NONE {
            if start.is_some() {
                return Err(Error::Mesh(format!(
                    "vertex {v} has more than one boundary fan (non-manifold vertex)"
                )));
            }
            start = Some(c);
        }
    }
    let is_boundary = start.is_some();
    let first = start.unwrap_or(corners[0]) as usize;
    let mut c = first;
    let mut count = 0usize;
    let mut last_in = NONE;
    loop {
        let (f, s) = (c / 3, c % 3);
        ring_edges.push(lvl.face_edges[3 * f + s]);
        count += 1;
        let e_in = lvl.face_edges[3 * f + (s + 2) % 3];
        let ef = lvl.edge_faces[e_in as usize];
        let nf2 = if ef[0] as usize == f { ef[1] } else { ef[0] };
        if nf2 == NONE {
            last_in = e_in;
            break;
        }
        // the slot of v in the next face
        let nf2 = nf2 as usize;
        let s2 = (0..3).find(|&k| lvl.faces[3 * nf2 + k] as usize == v);
        let Some(s2) = s2 else {
            return Err(Error::Mesh(format!("corrupt fan at vertex {v}")));
        };
        c = 3 * nf2 + s2;
        if c == first || count > nfaces {
            break;
        }
    }
    if is_boundary {
        ring_edges.push(last_in);
    }
    if count != nfaces || (!is_boundary && c != first) {
        return Err(Error::Mesh(format!(
            "vertex {v}: its {nfaces} faces do not form a single fan (non-manifold vertex)"
        )));
    }
    Ok(())
}

/// The face of wedge `i` of vertex `v`'s ring (between `ring[i]` and `ring[i+1]`): the one
/// on the counter-clockwise side of `ring[i]` seen from `v`.
fn wedge_face(lvl: &Level, v: usize, ring: &[u32], i: usize) -> u32 {
    let e = ring[i] as usize;
    let [a, _] = lvl.edges[e];
    let ef = lvl.edge_faces[e];
    // the face in which v -> other: left if a == v
    if a as usize == v {
        ef[0]
    } else {
        ef[1]
    }
}

/// Class of vertex `v` from its crease edges (`ecls`), its corner tag and whether it touches
/// a boundary patch; an isolated vertex is FIXED.
fn classify_vertex(lvl: &Level, v: usize, ecls: &[u8], base: &Base, mesh: &ControlMesh) -> u8 {
    let ring = lvl.ring(v);
    if ring.is_empty() {
        return vclass::FIXED;
    }
    let is_boundary = ecls[ring[0] as usize] & eclass::BOUNDARY != 0;
    let s = ring
        .iter()
        .filter(|&&e| ecls[e as usize] & eclass::CREASE != 0)
        .count();
    let nwedges = if is_boundary {
        ring.len() - 1
    } else {
        ring.len()
    };
    let touches_bp =
        (0..nwedges).any(|i| base.boundary_patch[wedge_face(lvl, v, ring, i) as usize]);
    let tagged = mesh.corners.contains(&(v as u32));
    if tagged || s >= 3 {
        vclass::CORNER
    } else if s == 2 {
        crease_vertex_class(lvl, v, ecls, base, is_boundary)
    } else if touches_bp {
        if s == 1 {
            vclass::CORNER
        } else {
            vclass::FIXED
        }
    } else if s == 1 {
        vclass::DART
    } else {
        vclass::SMOOTH
    }
}

/// Class of vertex `v` on two crease edges: regular when every sector between them that
/// has a closed-patch face is three triangles.
fn crease_vertex_class(lvl: &Level, v: usize, ecls: &[u8], base: &Base, is_boundary: bool) -> u8 {
    let ring = lvl.ring(v);
    let nwedges = if is_boundary {
        ring.len() - 1
    } else {
        ring.len()
    };
    // sectors: walk wedges starting after a crease edge
    let k0 = (0..ring.len())
        .find(|&i| ecls[ring[i] as usize] & eclass::CREASE != 0)
        .unwrap_or(0);
    let mut regular = true;
    let mut nt = 0usize;
    let mut closed = false;
    for step in 0..nwedges {
        let i = (k0 + step) % ring.len();
        let f = wedge_face(lvl, v, ring, i);
        nt += 1;
        closed |= !base.boundary_patch[f as usize];
        let next = (i + 1) % ring.len();
        let ends_sector = ecls[ring[next] as usize] & eclass::CREASE != 0
            || (is_boundary && next == ring.len() - 1);
        if ends_sector {
            if closed && nt != 3 {
                regular = false;
            }
            nt = 0;
            closed = false;
        }
    }
    if regular {
        vclass::CREASE_REGULAR
    } else {
        vclass::CREASE_NONREG
    }
}

/// Adds each edge's rule to its class in `ecls` (crease rule from its end vertices' classes
/// `vcls`, linear in a boundary patch, else smooth) and returns the frame id of every edge
/// (empty without frames): the lowest frame of its faces' groups, for crease edges and
/// boundary-patch edges.
fn add_edge_rules(
    lvl: &Level,
    base: &Base,
    vcls: &[u8],
    ecls: &mut [u8],
    has_frames: bool,
) -> Vec<u16> {
    let ne = lvl.ne();
    let mut eframe = if has_frames {
        vec![0u16; ne]
    } else {
        Vec::new()
    };
    for e in 0..ne {
        let ef = lvl.edge_faces[e];
        let [a, b] = lvl.edges[e];
        let crease = ecls[e] & eclass::CREASE != 0;
        let in_bp = ef
            .iter()
            .any(|&f| f != NONE && base.boundary_patch[f as usize]);
        let rule = if crease {
            eclass::crease_rule(vcls[a as usize], vcls[b as usize])
        } else if in_bp {
            eclass::LINEAR
        } else {
            eclass::SMOOTH
        };
        ecls[e] |= rule;
        if has_frames && (crease || in_bp) {
            eframe[e] = ef
                .iter()
                .filter(|&&f| f != NONE)
                .map(|&f| base.group_frame[base.group[f as usize] as usize])
                .filter(|&id| id != 0)
                .min()
                .unwrap_or(0);
        }
    }
    eframe
}

/// Frame id of every vertex (the mesh has frames): for crease vertices, the lowest frame of
/// their crease edges.
fn vertex_frames(lvl: &Level, vcls: &[u8], ecls: &[u8], eframe: &[u16]) -> Vec<u16> {
    let mut vframe = vec![0u16; lvl.nv];
    for v in 0..lvl.nv {
        if vclass::is_crease(vcls[v]) {
            vframe[v] = lvl
                .ring(v)
                .iter()
                .filter(|&&e| ecls[e as usize] & eclass::CREASE != 0)
                .map(|&e| eframe[e as usize])
                .filter(|&id| id != 0)
                .min()
                .unwrap_or(0);
        }
    }
    vframe
}

/// Element counts `(V, E, F)` after one 1-to-4 step.
pub(crate) fn next_counts(v: u64, e: u64, f: u64) -> (u64, u64, u64) {
    (v + e, 2 * e + 3 * f, 4 * f)
}

/// Triangles of level j+1 from level j: the only part of the finest level that plain
/// uniform output needs.
pub(crate) fn refine_faces(l: &Level) -> Vec<u32> {
    let mut faces = vec![0u32; 12 * l.nf()];
    par::for_each_chunk_mut(&mut faces, 12, |f, out| {
        out.copy_from_slice(&child_faces(l, f));
    });
    faces
}

/// Level j+1 from level j (reference §1.2). `base` supplies per-base-face groups/frames for
/// the edges created inside faces.
pub(crate) fn refine_level(l: &Level, base: &Base, j: u32) -> Level {
    let nv = l.nv;
    let ne = l.ne();
    let nf = l.nf();
    let nv2 = nv + ne;
    let ne2 = 2 * ne + 3 * nf;
    let has_frames = !l.eframe.is_empty();
    let base_of = |f: usize| f >> (2 * j);

    // Faces and face edges: 4 children per face.
    let faces = refine_faces(l);
    let mut face_edges = vec![0u32; 12 * nf];
    par::for_each_chunk_mut(&mut face_edges, 12, |f, out| {
        out.copy_from_slice(&child_face_edges(l, f));
    });

    // Edges and edge faces.
    let mut edges = vec![[0u32; 2]; ne2];
    let mut edge_faces = vec![[0u32; 2]; ne2];
    // child face of face f at its corner holding vertex x
    let corner_child = |f: u32, x: u32| -> u32 {
        if f == NONE {
            return NONE;
        }
        let c = &l.faces[3 * f as usize..3 * f as usize + 3];
        let k = if c[0] == x {
            0
        } else if c[1] == x {
            1
        } else {
            2
        };
        4 * f + k
    };
    {
        let (old_e, new_e) = edges.split_at_mut(2 * ne);
        par::for_each_chunk_mut(old_e, 2, |e, out| {
            let [a, b] = l.edges[e];
            let m = (nv + e) as u32;
            out[0] = [a, m];
            out[1] = [m, b];
        });
        par::for_each_chunk_mut(new_e, 3, |f, out| {
            let m0 = nv as u32 + l.face_edges[3 * f];
            let m1 = nv as u32 + l.face_edges[3 * f + 1];
            let m2 = nv as u32 + l.face_edges[3 * f + 2];
            out[0] = [m0, m2];
            out[1] = [m1, m0];
            out[2] = [m2, m1];
        });
        let (old_ef, new_ef) = edge_faces.split_at_mut(2 * ne);
        par::for_each_chunk_mut(old_ef, 2, |e, out| {
            let [a, b] = l.edges[e];
            let [fl, fr] = l.edge_faces[e];
            out[0] = [corner_child(fl, a), corner_child(fr, a)];
            out[1] = [corner_child(fl, b), corner_child(fr, b)];
        });
        par::for_each_chunk_mut(new_ef, 3, |f, out| {
            let f = f as u32;
            out[0] = [4 * f, 4 * f + 3];
            out[1] = [4 * f + 1, 4 * f + 3];
            out[2] = [4 * f + 2, 4 * f + 3];
        });
    }

    // Classes.
    let mut vcls = Vec::with_capacity(nv2);
    vcls.extend_from_slice(&l.vclass);
    vcls.extend(l.eclass.iter().map(|&c| edge_vertex_class(c)));
    let mut ecls = vec![0u8; ne2];
    {
        let (old_c, new_c) = ecls.split_at_mut(2 * ne);
        par::for_each_chunk_mut(old_c, 2, |e, out| {
            let c = l.eclass[e];
            let flags = c & !eclass::RULE_MASK;
            let [a, b] = l.edges[e];
            if c & eclass::CREASE != 0 {
                let cm = vclass::CREASE_REGULAR;
                out[0] = flags | eclass::crease_rule(l.vclass[a as usize], cm);
                out[1] = flags | eclass::crease_rule(cm, l.vclass[b as usize]);
            } else {
                out[0] = c;
                out[1] = c;
            }
        });
        par::for_each_chunk_mut(new_c, 3, |f, out| {
            let r = if base.boundary_patch[base_of(f)] {
                eclass::LINEAR
            } else {
                eclass::SMOOTH
            };
            out.fill(r);
        });
    }
    let (vframe, eframe) = if has_frames {
        let mut vframe = Vec::with_capacity(nv2);
        vframe.extend_from_slice(&l.vframe);
        vframe.extend((0..ne).map(|e| {
            if l.eclass[e] & eclass::CREASE != 0 {
                l.eframe[e]
            } else {
                0
            }
        }));
        let mut eframe = vec![0u16; ne2];
        for e in 0..ne {
            eframe[2 * e] = l.eframe[e];
            eframe[2 * e + 1] = l.eframe[e];
        }
        for f in 0..nf {
            let b = base_of(f);
            let id = if base.boundary_patch[b] {
                base.group_frame[base.group[b] as usize]
            } else {
                0
            };
            eframe[2 * ne + 3 * f..2 * ne + 3 * f + 3].fill(id);
        }
        (vframe, eframe)
    } else {
        (Vec::new(), Vec::new())
    };

    Level {
        nv: nv2,
        faces,
        face_edges,
        edges,
        edge_faces,
        rings: OnceLock::new(),
        vclass: vcls,
        eclass: ecls,
        vframe,
        eframe,
    }
}

/// Rings of level j+1 from level j.
pub(crate) fn build_rings(l: &Level) -> Rings {
    let nv = l.nv;
    let ne = l.ne();
    let nv2 = nv + ne;
    let half = |e: u32, x: u32| -> u32 {
        if l.edges[e as usize][0] == x {
            2 * e
        } else {
            2 * e + 1
        }
    };
    // Rings: old vertices map their edges to the halves at themselves; a new vertex on e
    // gets [toward b, two interior edges of the left face, toward a, two of the right face].
    let lr = l
        .rings
        .get()
        .expect("rings of the coarser level are built first");
    let old_ring_len = lr.edges.len();
    let mut ring_offsets = Vec::with_capacity(nv2 + 1);
    ring_offsets.extend_from_slice(&lr.offsets);
    let mut acc = old_ring_len as u32;
    for e in 0..ne {
        acc += if l.edge_faces[e][1] == NONE { 4 } else { 6 };
        ring_offsets.push(acc);
    }
    let mut ring_edges = vec![0u32; acc as usize];
    {
        let (old_r, new_r) = ring_edges.split_at_mut(old_ring_len);
        // old part: position i belongs to vertex v; do it per vertex chunk via offsets
        par::for_each_segment_mut(old_r, &lr.offsets, |v, out| {
            for (o, &e) in out.iter_mut().zip(l.ring(v)) {
                *o = half(e, v as u32);
            }
        });
        let new_offsets: Vec<u32> = ring_offsets[nv..]
            .iter()
            .map(|&o| o - old_ring_len as u32)
            .collect();
        par::for_each_segment_mut(new_r, &new_offsets, |e, out| {
            let [fl, fr] = l.edge_faces[e];
            let e32 = e as u32;
            let interior = |f: u32| -> (u32, u32) {
                let s = l.slot(f as usize, e32) as u32;
                let i0 = 2 * ne as u32 + 3 * f;
                (i0 + (s + 1) % 3, i0 + s)
            };
            let (l1, l2) = interior(fl);
            if fr == NONE {
                out.copy_from_slice(&[2 * e32 + 1, l1, l2, 2 * e32]);
            } else {
                let (r1, r2) = interior(fr);
                out.copy_from_slice(&[2 * e32 + 1, l1, l2, 2 * e32, r1, r2]);
            }
        });
    }

    Rings {
        offsets: ring_offsets,
        edges: ring_edges,
    }
}

/// The class of the vertex a level inserts on an edge of class `c`: a regular crease vertex
/// on a crease, fixed on a linear (boundary-patch) edge, smooth elsewhere.
#[inline]
pub(crate) fn edge_vertex_class(c: u8) -> u8 {
    if c & eclass::CREASE != 0 {
        vclass::CREASE_REGULAR
    } else if c & eclass::RULE_MASK == eclass::LINEAR {
        vclass::FIXED
    } else {
        vclass::SMOOTH
    }
}
