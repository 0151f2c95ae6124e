//! Level-of-detail extraction with S-CODE gap filling (reference §1.3 and §6).
//!
//! Every base triangle is shown at its own level. Along a base edge shared by faces shown at
//! levels `lc < lf`, the finer side's extra vertices are moved onto the coarser side's chords
//! (S-CODE Figs. 7-8), and the coarser side's triangles that touch the edge are fanned through
//! those vertices, so the output is conforming (every interior edge has two faces) and has no
//! T-junction cracks.

use glam::DVec3;

use crate::error::{Error, Result};

use super::masks::normalize_or_zero;
use super::next_level::{child_face_edges, child_faces, Connectivity, NextLevel};
use super::sparse::{self, BoundaryPatchOutput, SparsePlan, DENSE};
use super::topology::NONE;
use super::Refinement;

/// Level-n face whose corner `c` is corner `c` of level-m face `g` (reference §1.3):
/// `g 4^(n-m) + c (4^(n-m) - 1) / 3` (the digit c appended n-m times).
#[cfg(test)]
pub fn lod_corner_face(g: usize, n: u32, m: u32, c: usize) -> usize {
    let q = 1usize << (2 * (n - m));
    g * q + c * (q - 1) / 3
}

/// An indexed triangle mesh produced by [`super::Refinement::extract_lod`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AdaptiveMesh {
    pub positions: Vec<DVec3>,
    /// Per-vertex unit normals (with `limit`).
    pub normals: Option<Vec<DVec3>>,
    /// Counter-clockwise triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Group (CAD face) of each triangle.
    pub face_groups: Vec<u32>,
}

impl AdaptiveMesh {
    /// The mesh as a triangle `ControlMesh` with the given groups (those of the input
    /// mesh; `face_groups` index them). Sharp flags and corner tags are not carried.
    pub fn to_control_mesh(&self, groups: &[crate::mesh::Group]) -> crate::mesh::ControlMesh {
        let nf = self.triangles.len() as u32;
        crate::mesh::ControlMesh {
            positions: self.positions.clone(),
            face_offsets: (0..=nf).map(|i| 3 * i).collect(),
            face_vertices: self.triangles.iter().flatten().copied().collect(),
            face_groups: self.face_groups.clone(),
            groups: groups.to_vec(),
            ..Default::default()
        }
    }
}

/// Extracts the LOD mesh from finest-level positions `pos` (and optional normals).
#[cfg(feature = "internals")]
pub(crate) fn extract(
    r: &Refinement,
    pos: &[DVec3],
    normals: Option<&[DVec3]>,
    levels: &[u8],
    mode: BoundaryPatchOutput,
) -> Result<AdaptiveMesh> {
    extract_at(r, r.max_level(), pos, normals, levels, mode).map(|(mesh, _)| mesh)
}

/// Level-`top` vertex `j` (`0..=2^top`) along base edge `e`, in its stored direction, by the
/// index arithmetic of [`sparse::base_edge_chain`] (no level-`top` edge array is read, so a
/// level below the refinement's finest needs nothing beyond the levels already built).
/// `level_nv[i]` is the vertex count of level i.
#[inline]
pub(crate) fn edge_vertex(
    l0: &super::topology::Level,
    level_nv: &[usize],
    top: u32,
    e: usize,
    j: usize,
) -> u32 {
    if j == 0 {
        return l0.edges[e][0];
    }
    if j == 1usize << top {
        return l0.edges[e][1];
    }
    let tz = j.trailing_zeros();
    let lev = top - 1 - tz;
    (level_nv[lev as usize] + (e << lev) + (j >> (tz + 1))) as u32
}

/// Points by vertex id: a slice, or the prefix of a store evaluated on demand
/// (`lazy::Prefix`), which [`extract_at`] reads.
pub(crate) trait Points: std::ops::Index<usize, Output = DVec3> {
    /// The number of vertices.
    fn count(&self) -> usize;
}

impl Points for [DVec3] {
    fn count(&self) -> usize {
        self.len()
    }
}

/// [`extract`] with level `top <= r.max_level()` as the finest level shown: `pos` holds the
/// positions of the level-`top` vertices (a prefix of every finer level's ids), so a
/// refinement built one level deeper than its output (to measure it) shows levels up to
/// `top` without building the connectivity of its finest level. Also returns the map from
/// level-`top` vertex ids to output vertex ids (`u32::MAX` for vertices not used).
pub(crate) fn extract_at<P: Points + ?Sized>(
    r: &Refinement,
    top: u32,
    pos: &P,
    normals: Option<&P>,
    levels: &[u8],
    mode: BoundaryPatchOutput,
) -> Result<(AdaptiveMesh, Remap)> {
    check_extract_input(r, top, pos, levels)?;
    let n = top;
    let l0 = r.full(0);
    let plan = match mode {
        BoundaryPatchOutput::Sparse => SparsePlan::new(l0, &r.base),
        #[cfg(feature = "internals")]
        BoundaryPatchOutput::Dense => None,
    };
    let levels = shown_levels(plan.as_ref(), levels);
    let ex = Extraction {
        r,
        l0,
        level_nv: (0..n).map(|m| r.full(m).nv).collect(),
        n,
        span: 1usize << n,
        levels,
    };
    let mut moved = ex.gap_fill(pos);

    // Triangles, with fans through the finer neighbour's vertices.
    let mut out = Emitted::new(pos.count());
    for k in 0..l0.nf() {
        if let Some(pl) = &plan {
            let u = pl.unit[k];
            if u != DENSE {
                if (u as usize) >= k {
                    ex.emit_unit(pl, k, &mut out);
                }
                // else: emitted with its belt partner
                continue;
            }
        }
        ex.emit_base_triangle(k, &mut out);
    }

    // A vertex on an edge between two levels moves once (the edge's coarser side decides).
    moved.sort_unstable_by_key(|&(v, _)| v);
    let disp = Displaced { pos, moved };
    let (mesh, mut remap) = compact(&disp, normals, &out.centroids, out.tris, out.groups);
    remap.truncate(pos.count());
    Ok((mesh, remap))
}

/// Checks the arguments of [`extract_at`]: `top` within the refinement, one level per base
/// triangle, none above `top`, and one position per level-`top` vertex.
fn check_extract_input<P: Points + ?Sized>(
    r: &Refinement,
    top: u32,
    pos: &P,
    levels: &[u8],
) -> Result<()> {
    if top > r.max_level() {
        return Err(Error::Parameter(format!(
            "level {top} shown, refinement built to {}",
            r.max_level()
        )));
    }
    let n = top;
    let l0 = r.full(0);
    if levels.len() != l0.nf() {
        return Err(Error::Parameter(format!(
            "{} per-face levels given, the mesh has {} base triangles",
            levels.len(),
            l0.nf()
        )));
    }
    if let Some(k) = levels.iter().position(|&m| m as u32 > n) {
        return Err(Error::Parameter(format!(
            "base triangle {k} asks for level {}, refinement built to {n}",
            levels[k]
        )));
    }
    if pos.count() != r.level(n).vertex_count() {
        return Err(Error::Parameter(format!(
            "positions do not match level {n}"
        )));
    }
    Ok(())
}

/// The level each base triangle is shown at: as asked, except that both faces of a belt
/// quad of the sparse `plan` are shown at the finer of their two levels.
fn shown_levels(plan: Option<&SparsePlan>, levels: &[u8]) -> Vec<u8> {
    match plan {
        Some(pl) => (0..levels.len())
            .map(|k| match pl.unit[k] {
                DENSE => levels[k],
                u => levels[k].max(levels[u as usize]),
            })
            .collect(),
        None => levels.to_vec(),
    }
}

/// What [`extract_at`] reads while it emits triangles.
struct Extraction<'a> {
    r: &'a Refinement,
    l0: &'a super::topology::Level,
    /// Vertex count of every level below `n`.
    level_nv: Vec<usize>,
    /// The finest level shown, and the number of its edges along a base edge.
    n: u32,
    span: usize,
    /// The level each base triangle is shown at.
    levels: Vec<u8>,
}

/// The triangles [`extract_at`] emits, and scratch lists reused from face to face.
struct Emitted {
    tris: Vec<[u32; 3]>,
    /// Group of every triangle.
    groups: Vec<u32>,
    /// Corners of the triangles fanned round their centroid, whose vertex ids follow the
    /// `first_centroid` positions.
    centroids: Vec<[u32; 3]>,
    first_centroid: usize,
    /// Outline of the current face: its corners with the finer neighbours' vertices between.
    poly: Vec<u32>,
    bufs: sparse::Chains,
    flat_tris: Vec<u32>,
}

impl Emitted {
    /// Nothing emitted yet; centroids are numbered from `first_centroid` on.
    fn new(first_centroid: usize) -> Self {
        Emitted {
            tris: Vec::new(),
            groups: Vec::new(),
            centroids: Vec::new(),
            first_centroid,
            poly: Vec::with_capacity(64),
            bufs: sparse::Chains::default(),
            flat_tris: Vec::new(),
        }
    }

    /// Triangulates the outline `poly` of the face with corners `c`, in group `g`: the face
    /// itself when no edge has extra vertices, a fan from the opposite corner when one edge
    /// (slot `extra_edge`) has, else a fan round a new centroid vertex.
    fn triangulate_outline(
        &mut self,
        c: [u32; 3],
        g: u32,
        edges_with_extras: usize,
        extra_edge: usize,
    ) {
        let poly = &self.poly;
        if edges_with_extras == 0 {
            self.tris.push([c[0], c[1], c[2]]);
            self.groups.push(g);
        } else if edges_with_extras == 1 {
            // fan from the corner opposite the edge with extras
            let apex = c[(extra_edge + 2) % 3];
            let ai = poly.iter().position(|&v| v == apex).unwrap_or(0);
            let len = poly.len();
            for i in 1..len - 1 {
                let (p1, p2) = (poly[(ai + i) % len], poly[(ai + i + 1) % len]);
                self.tris.push([apex, p1, p2]);
                self.groups.push(g);
            }
        } else {
            let centre = (self.first_centroid + self.centroids.len()) as u32;
            self.centroids.push([c[0], c[1], c[2]]);
            let len = poly.len();
            for i in 0..len {
                self.tris.push([centre, poly[i], poly[(i + 1) % len]]);
                self.groups.push(g);
            }
        }
    }
}

impl Extraction<'_> {
    /// Level-`n` vertex `j` (`0..=span`) along base edge `e`, in its stored direction.
    fn x(&self, e: usize, j: usize) -> u32 {
        edge_vertex(self.l0, &self.level_nv, self.n, e, j)
    }

    /// Gap filling: along every base edge between faces shown at two different levels, the
    /// finer side's extra vertices move onto the coarser side's chords. Returns the moved
    /// vertices with their new positions: few vertices move, so they are kept beside `pos`
    /// rather than in a copy of it (a refinement's finest level has many more vertices than
    /// an output to an accuracy uses).
    fn gap_fill<P: Points + ?Sized>(&self, pos: &P) -> Vec<(u32, DVec3)> {
        let (l0, n, span) = (self.l0, self.n, self.span);
        let levels = &self.levels;
        let mut moved: Vec<(u32, DVec3)> = Vec::new();
        for e in 0..l0.ne() {
            let [fl, fr] = l0.edge_faces[e];
            if fr == NONE {
                continue;
            }
            let (la, lb) = (levels[fl as usize] as u32, levels[fr as usize] as u32);
            let (lc, lf) = (la.min(lb), la.max(lb));
            if lf == lc {
                continue;
            }
            let step = 1usize << (n - lf);
            let s = 1usize << (n - lc);
            let mut j = step;
            while j < span {
                if j % s != 0 {
                    let j0 = j / s * s;
                    let t = (j - j0) as f64 / s as f64;
                    let (a, b) = (pos[self.x(e, j0) as usize], pos[self.x(e, j0 + s) as usize]);
                    moved.push((self.x(e, j), a * (1.0 - t) + b * t));
                }
                j += step;
            }
        }
        moved
    }

    /// Emits the sparse unit of base triangle `k` (with its belt partner, if any) as the
    /// plan `pl` triangulates it.
    fn emit_unit(&self, pl: &SparsePlan, k: usize, out: &mut Emitted) {
        let (l0, n, span) = (self.l0, self.n, self.span);
        let levels = &self.levels;
        // Chain along edge slot s of base face f: its split points at the finer
        // of the two levels meeting there (gap-filled positions), else its ends.
        let mut chain = |f: usize, s: usize, v: &mut Vec<u32>| {
            let c = &l0.faces[3 * f..3 * f + 3];
            let (a, b) = (c[s], c[(s + 1) % 3]);
            let be = l0.face_edges[3 * f + s] as usize;
            v.clear();
            if !pl.split[be] {
                v.extend_from_slice(&[a, b]);
                return;
            }
            let [bl, br] = l0.edge_faces[be];
            let other = if bl as usize == f { br } else { bl };
            let lo = if other == NONE {
                0
            } else {
                levels[other as usize]
            };
            let lf = levels[f].max(lo) as u32;
            let step = 1usize << (n - lf);
            let forward = l0.edges[be][0] == a;
            let mut j = 0;
            while j <= span {
                v.push(self.x(be, if forward { j } else { span - j }));
                j += step;
            }
        };
        out.flat_tris.clear();
        let t = sparse::emit_unit(l0, pl, k, &mut chain, &mut out.bufs, &mut out.flat_tris);
        out.tris
            .extend(out.flat_tris.chunks(3).map(|c| [c[0], c[1], c[2]]));
        out.groups
            .extend(std::iter::repeat_n(self.r.base.group[k], t));
    }

    /// Emits base triangle `k` at its level: every face of that level inside it, fanned
    /// through the vertices a finer neighbour has along its edges.
    fn emit_base_triangle(&self, k: usize, out: &mut Emitted) {
        let m = self.levels[k] as u32;
        let faces = LevelFaces::new(self.r, m);
        let g = self.r.base.group[k];
        let q = 1usize << (2 * m);
        for f in k * q..(k + 1) * q {
            let (c, fe) = faces.face(f);
            let (edges_with_extras, extra_edge) =
                self.face_outline(&faces, k, m, c, fe, &mut out.poly);
            out.triangulate_outline(c, g, edges_with_extras, extra_edge);
        }
    }

    /// Fills `poly` with the outline of level-`m` face (corners `c`, edges `fe`) of base
    /// triangle `k`: its corners, and along each edge on a base edge whose other side is
    /// shown finer, that side's vertices. Returns the number of such edges and the slot of
    /// the last one.
    fn face_outline(
        &self,
        faces: &LevelFaces,
        k: usize,
        m: u32,
        c: [u32; 3],
        fe: [u32; 3],
        poly: &mut Vec<u32>,
    ) -> (usize, usize) {
        let (l0, n) = (self.l0, self.n);
        let e0 = l0.ne();
        poly.clear();
        let mut edges_with_extras = 0;
        let mut extra_edge = 0;
        for (s, &cs) in c.iter().enumerate() {
            poly.push(cs);
            let eps = fe[s] as usize;
            if eps >= e0 << m {
                continue;
            }
            let be = eps >> m;
            let [bl, br] = l0.edge_faces[be];
            let other = if bl as usize == k { br } else { bl };
            if other == NONE {
                continue;
            }
            let lo = self.levels[other as usize] as u32;
            if lo <= m {
                continue;
            }
            edges_with_extras += 1;
            extra_edge = s;
            let seg = eps - (be << m);
            let per = 1usize << (n - m);
            let step = 1usize << (n - lo);
            let forward = faces.edge_start(eps) == cs;
            let cnt = per / step;
            for t in 1..cnt {
                let tt = if forward { t } else { cnt - t };
                poly.push(self.x(be, seg * per + tt * step));
            }
        }
        (edges_with_extras, extra_edge)
    }
}

/// The faces of one level as the extraction reads them: from the level's arrays, or for a
/// refinement's finest level (whose arrays a decode to an accuracy does not build) from the
/// level before, by the index arithmetic of its refinement.
enum LevelFaces<'a> {
    Built(&'a super::topology::Level),
    Next(NextLevel<'a>),
}

impl<'a> LevelFaces<'a> {
    fn new(r: &'a Refinement, m: u32) -> LevelFaces<'a> {
        if m > 0 && m == r.max_level() && r.finest.get().is_none() {
            LevelFaces::Next(NextLevel {
                l: r.full(m - 1),
                base: &r.base,
                j: m - 1,
            })
        } else {
            LevelFaces::Built(r.full(m))
        }
    }

    /// Corners and edges of face `f`.
    #[inline]
    fn face(&self, f: usize) -> ([u32; 3], [u32; 3]) {
        match self {
            LevelFaces::Built(l) => (
                [l.faces[3 * f], l.faces[3 * f + 1], l.faces[3 * f + 2]],
                [
                    l.face_edges[3 * f],
                    l.face_edges[3 * f + 1],
                    l.face_edges[3 * f + 2],
                ],
            ),
            LevelFaces::Next(nl) => {
                let (c, e) = (child_faces(nl.l, f / 4), child_face_edges(nl.l, f / 4));
                let i = 3 * (f % 4);
                ([c[i], c[i + 1], c[i + 2]], [e[i], e[i + 1], e[i + 2]])
            }
        }
    }

    /// The first end of edge `e` in its stored orientation.
    #[inline]
    fn edge_start(&self, e: usize) -> u32 {
        match self {
            LevelFaces::Built(l) => l.edges[e][0],
            LevelFaces::Next(nl) => nl.edge_ends(e)[0],
        }
    }
}

/// Positions after gap filling: `pos`, but the vertices in `moved` (sorted by id).
struct Displaced<'a, P: Points + ?Sized> {
    pos: &'a P,
    moved: Vec<(u32, DVec3)>,
}

impl<P: Points + ?Sized> Displaced<'_, P> {
    fn len(&self) -> usize {
        self.pos.count()
    }

    #[inline]
    fn at(&self, v: usize) -> DVec3 {
        match self.moved.binary_search_by_key(&(v as u32), |&(x, _)| x) {
            Ok(i) => self.moved[i].1,
            Err(_) => self.pos[v],
        }
    }
}

/// The map from vertex ids to output vertex ids that [`extract_at`] returns.
pub(crate) struct Remap {
    /// The output id + 1 of every used vertex, 0 for the others: allocated zeroed (`vec![0;
    /// n]` asks the allocator for zeroed memory rather than writing it), so that only the
    /// pages holding used vertices are ever written (a level's ids run to millions, an
    /// output to thousands).
    plus_one: Vec<u32>,
    /// The used vertices, in id order.
    used: Vec<u32>,
}

impl Remap {
    /// The output vertex of vertex `v`, if the output uses it.
    #[inline]
    pub fn get(&self, v: usize) -> Option<u32> {
        self.plus_one.get(v).and_then(|&x| x.checked_sub(1))
    }

    /// The vertices the output uses, in id order.
    pub fn used(&self) -> &[u32] {
        &self.used
    }

    /// Forgets the vertices from `n` on.
    fn truncate(&mut self, n: usize) {
        self.plus_one.truncate(n);
        let keep = self.used.partition_point(|&v| (v as usize) < n);
        self.used.truncate(keep);
    }
}

/// The output mesh of [`extract_at`]: keeps the used vertices of `disp` (gap-filled
/// positions) in index order, then the stitching centroids (vertex ids from `disp.len()` on,
/// the mean of their three corners), and renumbers `tris`. Returns the mesh and the map from
/// old to new vertex ids.
fn compact<P: Points + ?Sized>(
    disp: &Displaced<'_, P>,
    normals: Option<&P>,
    centroids: &[[u32; 3]],
    mut tris: Vec<[u32; 3]>,
    groups: Vec<u32>,
) -> (AdaptiveMesh, Remap) {
    let total = disp.len() + centroids.len();
    // The used vertices in id order, from a bit per id (a word covers 64 ids: the scan
    // reads a small fraction of what an array of ids would).
    let mut seen = vec![0u64; total.div_ceil(64)];
    for t in &tris {
        for &v in t {
            seen[v as usize / 64] |= 1 << (v % 64);
        }
    }
    let mut used = Vec::new();
    for (w, &word) in seen.iter().enumerate() {
        let mut bits = word;
        while bits != 0 {
            used.push((64 * w) as u32 + bits.trailing_zeros());
            bits &= bits - 1;
        }
    }
    let mut plus_one = vec![0u32; total];
    let mut positions = Vec::with_capacity(used.len());
    let mut out_normals = normals.map(|_| Vec::with_capacity(used.len()));
    for (next, &v) in used.iter().enumerate() {
        let v = v as usize;
        plus_one[v] = next as u32 + 1;
        if v < disp.len() {
            positions.push(disp.at(v));
            if let (Some(on), Some(nn)) = (out_normals.as_mut(), normals) {
                on.push(nn[v]);
            }
        } else {
            let cs = centroids[v - disp.len()];
            positions.push(cs.iter().map(|&i| disp.at(i as usize)).sum::<DVec3>() / 3.0);
            if let (Some(on), Some(nn)) = (out_normals.as_mut(), normals) {
                on.push(normalize_or_zero(cs.iter().map(|&i| nn[i as usize]).sum()));
            }
        }
    }
    for t in &mut tris {
        for v in t.iter_mut() {
            *v = plus_one[*v as usize] - 1;
        }
    }
    let mesh = AdaptiveMesh {
        positions,
        normals: out_normals,
        triangles: tris,
        face_groups: groups,
    };
    (mesh, Remap { plus_one, used })
}
