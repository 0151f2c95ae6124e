//! Subdivision engine: Loop subdivision with Hoppe's piecewise-smooth rules, S-CODE's nested
//! index numbering, limit positions and normals, boundary patches (planes, cylinders, cones)
//! and crack-free level-of-detail extraction.
//!
//! The exact rules are the format's decoding rules and are written down in
//! `spec/subdivision.md`.
//!
//! Usage: build a [`Refinement`] once per control-mesh connectivity (the topology of every
//! level 0..=n), then evaluate positions for any set of control points with
//! [`Refinement::positions`] / [`Refinement::positions_into`] (a pure function of topology
//! and control points; the encoder calls it many times with reused buffers), or get the
//! linear map itself with [`Refinement::stencils`]. Limit points and normals:
//! [`Refinement::limit_positions`], [`Refinement::limit_normals`]. Level of detail:
//! [`Refinement::extract_lod`] with one level per base triangle. [`subdivide`] is the
//! one-call convenience (and `subdivide_adaptive`, with one level per control face, the
//! tests').
//!
//! Layout: `topology` (level 0 build, classification, one refinement step as index
//! arithmetic), `masks` (weights), `eval` (mask producers shared by positions, limits,
//! normals and stencils), `frame` (cylindrical coordinates of cylinder/cone patches), `lod`
//! (extraction, gap filling, stitching), `sparse` (S-CODE's output of boundary patches:
//! only split edges subdivided, belts along the rulings; `spec/subdivision.md` §8), `par` (rayon-or-sequential loops; every output
//! element is written by exactly one closure call, so results do not depend on the thread
//! count). Parallelism is over vertices / edges / faces of a level, which balances better
//! than over base faces and needs no stitching of per-face results.

mod accuracy;
mod charge;
mod eval;
mod flips;
mod frame;
mod lazy;
mod lod;
mod masks;
mod max_edge;
mod next_level;
pub(crate) mod par;
#[cfg(feature = "remesh")]
mod plane_refine;
mod sparse;
// What the encoder's measurement reads to subdivide only the groups that changed.
#[cfg(feature = "encoder")]
pub(crate) mod support;
mod topology;
#[cfg(any(feature = "encoder", feature = "internals"))]
mod uniform;

#[cfg(test)]
pub(crate) mod test_support;
#[cfg(test)]
mod tests;

use std::sync::OnceLock;

use glam::DVec3;

use crate::error::{Error, Result};
use crate::mesh::ControlMesh;

#[cfg(any(test, feature = "internals"))]
pub use accuracy::subdivide_to_tolerance;
#[cfg(feature = "internals")]
pub use accuracy::AccurateSurface;
pub use accuracy::{subdivide_to_tolerance_within, AccuracyOptions};
#[cfg(feature = "encoder")]
pub(crate) use charge::default_decode_bytes;
pub(crate) use charge::default_top_level;
#[cfg(test)]
pub use lod::lod_corner_face;
#[cfg(feature = "internals")]
pub use lod::AdaptiveMesh;
#[cfg(feature = "internals")]
pub use masks::{loop_beta, loop_omega};
pub use max_edge::split_to_max_edge;
#[cfg(feature = "remesh")]
pub use plane_refine::refine_planes;
#[cfg(all(feature = "remesh", feature = "internals"))]
pub use plane_refine::PlaneRefinement;
pub use sparse::BoundaryPatchOutput;
#[cfg(any(feature = "encoder", feature = "internals"))]
pub use uniform::UniformSurface;

use masks::{eclass, ValenceTables};
use next_level::NextLevel;
use topology::{Base, Level};

/// Default cap on the number of finest-level triangles (`Error::LimitsExceeded` above it):
/// 64 Mi triangles need about 4 GB for topology and positions.
pub const DEFAULT_MAX_FACES: u64 = 1 << 26;

/// Memory a uniform subdivision takes per finest-level triangle, output included (the
/// topology of every level, positions, limit positions and normals, the output mesh; dense
/// boundary output, the larger one): what a decoder charges against its memory budget
/// before subdividing.
pub const MEMORY_PER_TRIANGLE: u64 = 200;

/// Largest accepted refinement level.
pub const MAX_LEVEL: u32 = 12;

/// Options of the one-call helpers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubdivOptions {
    /// Project the output vertices to the limit surface and return limit normals.
    pub limit: bool,
    /// With `limit`: also compute the limit normals (default true; callers that only need
    /// the surface, such as the encoder's error measurement, save their cost).
    pub normals: bool,
    /// Refuse to produce more than this many triangles.
    pub max_faces: u64,
    /// Sparse (S-CODE, default) or dense output of boundary patches.
    pub boundary_patches: BoundaryPatchOutput,
}

impl Default for SubdivOptions {
    fn default() -> Self {
        SubdivOptions {
            limit: false,
            normals: true,
            max_faces: DEFAULT_MAX_FACES,
            boundary_patches: BoundaryPatchOutput::Sparse,
        }
    }
}

/// Topology of all levels 0..=n with S-CODE's nested numbering: vertex ids of level j are
/// the prefix `[0, V_j)` of every finer level, the children of face k are `4k..4k+3`, the
/// descendants of base edge e at level m are `[e 2^m, (e+1) 2^m)`. Built once per control
/// mesh connectivity; positions are evaluated separately.
///
/// Level 0 is the control mesh with every polygon fan-triangulated `(v0, vi, vi+1)`;
/// "base faces" are these level-0 triangles.
#[derive(Clone, Debug)]
pub struct Refinement {
    /// `levels[j]`: connectivity and classification of level j < n (level 0 when n = 0).
    levels: Vec<Level>,
    /// Triangles of the finest level n, built on first use: uniform output needs only these
    /// of the finest level, and output made face by face (see [`UniformSurface`]) not even
    /// these.
    finest_faces: OnceLock<Vec<u32>>,
    finest_nv: usize,
    /// Full connectivity of level n, built on first use (edges, LOD, limit, normals), so
    /// that positions + triangles cost no more than they need.
    finest: OnceLock<Level>,
    max_level: u32,
    base: Base,
    tables: ValenceTables,
}

/// A read-only view of one level's connectivity. Triangles are always available; edge
/// queries on the finest level build its full connectivity on first use.
#[derive(Clone, Copy, Debug)]
pub struct LevelView<'a> {
    level: u32,
    r: &'a Refinement,
}

impl<'a> LevelView<'a> {
    #[cfg(any(feature = "encoder", feature = "internals"))]
    fn full(&self) -> &'a Level {
        self.r.full(self.level)
    }
    #[cfg(feature = "internals")]
    pub fn level(&self) -> u32 {
        self.level
    }
    pub fn vertex_count(&self) -> usize {
        if self.level == self.r.max_level {
            self.r.finest_nv
        } else {
            self.r.levels[self.level as usize].nv
        }
    }
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn face_count(&self) -> usize {
        self.triangles().len() / 3
    }
    #[cfg(feature = "internals")]
    pub fn edge_count(&self) -> usize {
        self.full().ne()
    }
    /// Triangle corners, 3 per face, counter-clockwise.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn triangles(&self) -> &'a [u32] {
        if self.level == self.r.max_level {
            self.r.finest_faces()
        } else {
            &self.r.levels[self.level as usize].faces
        }
    }
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn triangle(&self, f: usize) -> [u32; 3] {
        let t = self.triangles();
        [t[3 * f], t[3 * f + 1], t[3 * f + 2]]
    }
    /// Edge ids of face f: `(c0c1, c1c2, c2c0)`.
    #[cfg(feature = "internals")]
    pub fn face_edges(&self, f: usize) -> [u32; 3] {
        let fe = &self.full().face_edges[3 * f..3 * f + 3];
        [fe[0], fe[1], fe[2]]
    }
    /// Edges in their stored orientation.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn edges(&self) -> &'a [[u32; 2]] {
        &self.full().edges
    }
    /// Base (level-0) triangle of face f.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn base_face(&self, f: usize) -> usize {
        f >> (2 * self.level)
    }
    /// Group (CAD face) of face f.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn face_group(&self, f: usize) -> u32 {
        self.r.base.group[self.base_face(f)]
    }
    /// The edge descends from an edge flagged sharp in the control mesh.
    #[cfg(feature = "internals")]
    pub fn edge_is_sharp(&self, e: usize) -> bool {
        self.full().eclass[e] & eclass::SHARP != 0
    }
    /// The edge is a crease (sharp or mesh boundary).
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn edge_is_crease(&self, e: usize) -> bool {
        self.full().eclass[e] & eclass::CREASE != 0
    }
    /// The edge lies on the mesh boundary.
    #[cfg(feature = "internals")]
    pub fn edge_is_boundary(&self, e: usize) -> bool {
        self.full().eclass[e] & eclass::BOUNDARY != 0
    }
}

/// The linear map from control points to the points of one level: row i is
/// `sum_k weights[k] * control[indices[k]]` over `offsets[i]..offsets[i + 1]`.
///
/// Rows whose derivation used a cylinder/cone frame are not linear in the control points
/// (the masks act on cylindrical coordinates there); for them `exact[i]` is false and the
/// row holds the Cartesian mask composition (a linearisation that is exact for control points
/// evenly spaced in angle). All other rows reproduce [`Refinement::positions`] exactly.
#[cfg(any(feature = "encoder", feature = "internals"))]
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SparseStencils {
    pub offsets: Vec<u32>,
    pub indices: Vec<u32>,
    pub weights: Vec<f64>,
    pub exact: Vec<bool>,
}

#[cfg(any(feature = "encoder", feature = "internals"))]
impl SparseStencils {
    #[cfg(test)]
    pub fn row_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }
    /// `(indices, weights)` of row i.
    pub fn row(&self, i: usize) -> (&[u32], &[f64]) {
        let (a, b) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
        (&self.indices[a..b], &self.weights[a..b])
    }
    /// Applies the map to control points.
    #[cfg(test)]
    pub fn apply(&self, control: &[DVec3]) -> Vec<DVec3> {
        (0..self.row_count())
            .map(|i| {
                let (ix, w) = self.row(i);
                ix.iter()
                    .zip(w)
                    .fold(DVec3::ZERO, |acc, (&k, &w)| acc + control[k as usize] * w)
            })
            .collect()
    }
}

impl Refinement {
    /// Builds the topology of levels 0..=`max_level` with the default face cap.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn new(mesh: &ControlMesh, max_level: u32) -> Result<Refinement> {
        Self::with_max_faces(mesh, max_level, DEFAULT_MAX_FACES)
    }

    /// Builds the topology of levels 0..=`max_level`; `Error::LimitsExceeded` when the
    /// finest level would have more than `max_faces` triangles. `Error::Mesh` for
    /// non-manifold or inconsistently oriented meshes, unknown sharp edges, bad axes.
    pub fn with_max_faces(
        mesh: &ControlMesh,
        max_level: u32,
        max_faces: u64,
    ) -> Result<Refinement> {
        if max_level > MAX_LEVEL {
            return Err(Error::Parameter(format!(
                "subdivision level {max_level} exceeds the maximum {MAX_LEVEL}"
            )));
        }
        // Check counts before building anything.
        let tri: u64 = mesh.faces().map(|f| f.len().saturating_sub(2) as u64).sum();
        let ftot = tri.saturating_mul(1u64 << (2 * max_level));
        if ftot > max_faces {
            return Err(Error::LimitsExceeded {
                what: "subdivided triangles",
                value: ftot,
                limit: max_faces,
            });
        }
        let (l0, base) = topology::build_level0(mesh)?;
        let (mut v, mut e, mut f) = (l0.nv as u64, l0.ne() as u64, l0.nf() as u64);
        for _ in 0..max_level {
            (v, e, f) = topology::next_counts(v, e, f);
        }
        if v.max(e).max(3 * f).max(2 * e) >= u32::MAX as u64 {
            return Err(Error::LimitsExceeded {
                what: "subdivided elements (32-bit indices)",
                value: v.max(e).max(3 * f),
                limit: u32::MAX as u64,
            });
        }
        let max_k = (0..l0.nv).map(|v| l0.ring(v).len()).max().unwrap_or(6);
        let mut levels = Vec::with_capacity(max_level as usize + 1);
        levels.push(l0);
        for j in 1..max_level {
            let prev = &levels[j as usize - 1];
            let next = topology::refine_level(prev, &base, j - 1);
            let _ = next.rings.set(topology::build_rings(prev));
            levels.push(next);
        }
        let (finest, finest_faces) = (OnceLock::new(), OnceLock::new());
        let finest_nv = if max_level == 0 {
            let l0 = &levels[0];
            let _ = finest.set(l0.clone());
            let _ = finest_faces.set(l0.faces.clone());
            l0.nv
        } else {
            let prev = &levels[max_level as usize - 1];
            prev.nv + prev.ne()
        };
        Ok(Refinement {
            levels,
            finest_faces,
            finest_nv,
            finest,
            max_level,
            base,
            tables: ValenceTables::new(max_k),
        })
    }

    /// The finest triangles (built on first use).
    fn finest_faces(&self) -> &[u32] {
        self.finest_faces.get_or_init(|| {
            let prev = &self.levels[self.max_level as usize - 1];
            topology::refine_faces(prev)
        })
    }

    /// The finest triangles, consuming the refinement (uniform output without a copy).
    fn into_finest_faces(self) -> Vec<u32> {
        self.finest_faces();
        self.finest_faces.into_inner().unwrap_or_default()
    }

    /// Vertex count of every level below the finest.
    fn level_nv(&self) -> Vec<usize> {
        self.levels[..self.max_level as usize]
            .iter()
            .map(|l| l.nv)
            .collect()
    }

    /// What uniform output reads of this refinement (see [`sparse::UniformFaces`]).
    fn uniform_faces<'a>(
        &'a self,
        level_nv: &'a [usize],
        plan: Option<&'a sparse::SparsePlan>,
    ) -> sparse::UniformFaces<'a> {
        let n = self.max_level;
        sparse::UniformFaces {
            l0: &self.levels[0],
            base: &self.base,
            last: (n > 0).then(|| &self.levels[n as usize - 1]),
            level_nv,
            n,
            plan,
        }
    }

    /// Sharp edges of the finest level (the descendants of the control mesh's sharp edges),
    /// without building the finest level's edge arrays.
    fn finest_sharp_edges(&self) -> std::collections::BTreeSet<(u32, u32)> {
        let l0 = &self.levels[0];
        let mut keys = Vec::new();
        let mut chain = Vec::new();
        let level_nv = self.level_nv();
        for e in 0..l0.ne() {
            if l0.eclass[e] & eclass::SHARP != 0 {
                sparse::base_edge_chain(l0, &level_nv, self.max_level, e, &mut chain);
                keys.extend(chain.windows(2).map(|w| crate::mesh::edge_key(w[0], w[1])));
            }
        }
        keys.sort_unstable();
        keys.dedup();
        keys.into_iter().collect()
    }

    pub fn max_level(&self) -> u32 {
        self.max_level
    }

    /// Full connectivity of level `m` (the finest is built on first use).
    fn full(&self, m: u32) -> &Level {
        if m < self.max_level || (m == 0 && self.max_level == 0) {
            return &self.levels[m as usize];
        }
        self.finest.get_or_init(|| {
            let prev = &self.levels[m as usize - 1];
            topology::refine_level(prev, &self.base, m - 1)
        })
    }

    /// Number of base (level-0) triangles.
    #[cfg(feature = "internals")]
    pub fn base_face_count(&self) -> usize {
        self.levels[0].nf()
    }

    /// Control-mesh face of base triangle k (polygons are fan-triangulated).
    #[cfg(feature = "internals")]
    pub fn base_control_face(&self, k: usize) -> usize {
        self.base.control_face[k] as usize
    }

    /// Expands per-control-face levels to per-base-triangle levels (every triangle of a
    /// fan-triangulated polygon gets its polygon's level).
    #[cfg(feature = "internals")]
    pub fn base_levels_from_control(&self, per_control_face: &[u8]) -> Result<Vec<u8>> {
        self.base
            .control_face
            .iter()
            .map(|&f| {
                per_control_face.get(f as usize).copied().ok_or_else(|| {
                    Error::Parameter(format!(
                        "{} per-face levels given, control face {f} has none",
                        per_control_face.len()
                    ))
                })
            })
            .collect()
    }

    /// Level-of-detail mesh: base triangle k shown at level `per_face_levels[k]`, from the
    /// finest-level positions `finest` (subdivided or limit) and optional normals, with gap
    /// filling and stitching (`spec/subdivision.md` §7), boundary patches sparse (§8; both
    /// faces of a belt quad are shown at the finer of their two levels). Reuse one
    /// `Refinement` for many extractions (a viewer changing levels per frame).
    #[cfg(feature = "internals")]
    pub fn extract_lod(
        &self,
        finest: &[DVec3],
        normals: Option<&[DVec3]>,
        per_face_levels: &[u8],
    ) -> Result<AdaptiveMesh> {
        self.extract_lod_with(
            finest,
            normals,
            per_face_levels,
            BoundaryPatchOutput::Sparse,
        )
    }

    /// [`Refinement::extract_lod`] with a choice of boundary-patch output (the default is
    /// [`BoundaryPatchOutput::Sparse`]; both faces of a belt quad are shown at the finer of
    /// their two levels).
    #[cfg(feature = "internals")]
    pub fn extract_lod_with(
        &self,
        finest: &[DVec3],
        normals: Option<&[DVec3]>,
        per_face_levels: &[u8],
        boundary_patches: BoundaryPatchOutput,
    ) -> Result<AdaptiveMesh> {
        if let Some(nn) = normals {
            if nn.len() != finest.len() {
                return Err(Error::Parameter(format!(
                    "{} normals for {} positions",
                    nn.len(),
                    finest.len()
                )));
            }
        }
        lod::extract(self, finest, normals, per_face_levels, boundary_patches)
    }

    /// Number of control points expected by [`Refinement::positions`].
    pub fn control_count(&self) -> usize {
        self.levels[0].nv
    }

    /// Connectivity of level `m` (panics if `m > max_level()`).
    pub fn level(&self, m: u32) -> LevelView<'_> {
        assert!(
            m <= self.max_level,
            "level {m} > max level {}",
            self.max_level
        );
        LevelView { level: m, r: self }
    }

    /// Level `m` with its vertex rings built.
    fn level_with_rings(&self, m: usize) -> &Level {
        let l = self.full(m as u32);
        if m > 0 {
            l.rings
                .get_or_init(|| topology::build_rings(self.full(m as u32 - 1)));
        }
        l
    }

    fn check_control(&self, control: &[DVec3]) -> Result<()> {
        if control.len() != self.control_count() {
            return Err(Error::Parameter(format!(
                "{} control points given, the mesh has {}",
                control.len(),
                self.control_count()
            )));
        }
        Ok(())
    }

    /// Positions of all vertices of level `m` (subdivided, not limit).
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn positions_at(&self, control: &[DVec3], m: u32) -> Result<Vec<DVec3>> {
        let (mut out, mut scratch) = (Vec::new(), Vec::new());
        self.positions_into(control, m, &mut out, &mut scratch)?;
        Ok(out)
    }

    /// [`Refinement::positions_at`] into caller-owned buffers (`out` receives the level-`m`
    /// positions, `scratch` is working space of a quarter of that size), so repeated
    /// evaluations allocate nothing.
    pub fn positions_into(
        &self,
        control: &[DVec3],
        m: u32,
        out: &mut Vec<DVec3>,
        scratch: &mut Vec<DVec3>,
    ) -> Result<()> {
        self.check_control(control)?;
        if m > self.max_level() {
            return Err(Error::Parameter(format!(
                "level {m} requested, refinement built to {}",
                self.max_level()
            )));
        }
        let n_out = self.level(m).vertex_count();
        // Two buffers alternate between levels (level j+1 is written while level j is read),
        // chosen so that the last step writes into `out`: `out` holds levels m, m-2, ..,
        // `scratch` levels m-1, m-3, ..; both are reserved once with exact capacity and
        // written by appending, so nothing is zero-filled or copied back.
        out.clear();
        scratch.clear();
        if m == 0 {
            out.extend_from_slice(control);
            return Ok(());
        }
        out.reserve_exact(n_out);
        scratch.reserve_exact(self.level(m - 1).vertex_count());
        let (t, b) = (&self.tables, &self.base);
        for j in 0..m as usize {
            let l = &self.levels[j];
            let into_out = (m as usize - 1 - j) % 2 == 0;
            let (src, dst): (&[DVec3], &mut Vec<DVec3>) = match (j, into_out) {
                (0, true) => (control, &mut *out),
                (0, false) => (control, &mut *scratch),
                (_, true) => (&scratch[..], &mut *out),
                (_, false) => (&out[..], &mut *scratch),
            };
            dst.clear();
            par::extend_mapped(dst, l.nv, |v| eval::eval_vertex(l, t, b, src, v));
            par::extend_mapped(dst, l.ne(), |e| eval::eval_edge(l, b, src, e));
        }
        Ok(())
    }

    /// Positions of the finest level.
    #[cfg(feature = "internals")]
    pub fn positions(&self, control: &[DVec3]) -> Result<Vec<DVec3>> {
        self.positions_at(control, self.max_level())
    }

    /// Limit positions of the level-`m` vertices given their level-`m` positions. Unless it
    /// is built already, the finest level's connectivity is read through the level before
    /// ([`NextLevel`]): limit positions alone never build it.
    pub fn limit_positions(&self, level_positions: &[DVec3], m: u32) -> Result<Vec<DVec3>> {
        let (t, b) = (&self.tables, &self.base);
        if m > 0 && m == self.max_level && self.finest.get().is_none() {
            let next = NextLevel {
                l: &self.levels[m as usize - 1],
                base: b,
                j: m - 1,
            };
            check_count(level_positions.len(), next.vertex_count(), m)?;
            return Ok(limit_positions_of(&next, t, b, level_positions));
        }
        let l = self.checked_level(level_positions, m)?;
        Ok(limit_positions_of(l, t, b, level_positions))
    }

    /// Unit limit normals of the level-`m` vertices given their level-`m` positions (crease
    /// and corner vertices: normalised mean of the normals of their smooth sectors).
    pub fn limit_normals(&self, level_positions: &[DVec3], m: u32) -> Result<Vec<DVec3>> {
        let l = self.checked_level(level_positions, m)?;
        let mut out = vec![DVec3::ZERO; l.nv];
        let (t, b) = (&self.tables, &self.base);
        par::for_each_mut(&mut out, |v, o| {
            *o = eval::eval_normal(l, t, b, m, level_positions, v, None)
        });
        Ok(out)
    }

    /// Per-corner limit normals of the level-`m` triangles (3 per face, in corner order):
    /// at crease and corner vertices each corner gets the normal of its own smooth sector,
    /// so sharp edges shade sharp; elsewhere the vertex normal.
    #[cfg(feature = "internals")]
    pub fn limit_corner_normals(&self, level_positions: &[DVec3], m: u32) -> Result<Vec<DVec3>> {
        let vertex_normals = self.limit_normals(level_positions, m)?;
        let l = self.checked_level(level_positions, m)?;
        let mut out = vec![DVec3::ZERO; l.faces.len()];
        let (t, b, p) = (&self.tables, &self.base, level_positions);
        par::for_each_chunk_mut(&mut out, 3, |f, o| {
            for (c, oc) in o.iter_mut().enumerate() {
                let v = l.faces[3 * f + c] as usize;
                let cls = l.vclass[v];
                *oc = vertex_normals[v];
                if masks::vclass::is_crease(cls) || cls == masks::vclass::CORNER {
                    // the wedge of face f at v starts with f's edge leaving v
                    let e_out = l.face_edges[3 * f + c];
                    if let Some(w) = l.ring(v).iter().position(|&e| e == e_out) {
                        *oc = eval::eval_normal(l, t, b, m, p, v, Some(w));
                    }
                }
            }
        });
        Ok(out)
    }

    /// Finest-level limit positions and normals from control points.
    #[cfg(feature = "internals")]
    pub fn limit_positions_and_normals(
        &self,
        control: &[DVec3],
    ) -> Result<(Vec<DVec3>, Vec<DVec3>)> {
        let n = self.max_level();
        let p = self.positions(control)?;
        Ok((self.limit_positions(&p, n)?, self.limit_normals(&p, n)?))
    }

    fn checked_level(&self, pos: &[DVec3], m: u32) -> Result<&Level> {
        if m > self.max_level() {
            return Err(Error::Parameter(format!(
                "level {m} requested, refinement built to {}",
                self.max_level()
            )));
        }
        let l = self.level_with_rings(m as usize);
        check_count(pos.len(), l.nv, m)?;
        Ok(l)
    }

    /// The linear map from control points to the level-`m` points (`limit`: to their limit
    /// points). See [`SparseStencils`] for rows that involve cylinder/cone frames.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn stencils(&self, m: u32, limit: bool) -> Result<SparseStencils> {
        if m > self.max_level() {
            return Err(Error::Parameter(format!(
                "level {m} requested, refinement built to {}",
                self.max_level()
            )));
        }
        let n0 = self.control_count();
        let mut cur = SparseStencils {
            offsets: (0..=n0 as u32).collect(),
            indices: (0..n0 as u32).collect(),
            weights: vec![1.0; n0],
            exact: vec![true; n0],
        };
        let mut scratch: Vec<(u32, f64)> = Vec::new();
        let mut exact_acc;
        for j in 0..=m as usize {
            let l = self.level_with_rings(j);
            let last = j == m as usize;
            if last && !limit {
                break;
            }
            let mut next = SparseStencils {
                offsets: vec![0],
                ..Default::default()
            };
            let push_row =
                |scratch: &mut Vec<(u32, f64)>, exact: bool, next: &mut SparseStencils| {
                    scratch.sort_unstable_by_key(|&(i, _)| i);
                    let mut k = 0;
                    while k < scratch.len() {
                        let (i, mut w) = scratch[k];
                        k += 1;
                        while k < scratch.len() && scratch[k].0 == i {
                            w += scratch[k].1;
                            k += 1;
                        }
                        if w != 0.0 {
                            next.indices.push(i);
                            next.weights.push(w);
                        }
                    }
                    next.offsets.push(next.indices.len() as u32);
                    next.exact.push(exact);
                    scratch.clear();
                };
            let gather = |i: u32, w: f64, scratch: &mut Vec<(u32, f64)>, ex: &mut bool| {
                let (ix, ws) = cur.row(i as usize);
                *ex &= cur.exact[i as usize];
                scratch.extend(ix.iter().zip(ws).map(|(&k, &x)| (k, x * w)));
            };
            if last {
                for v in 0..l.nv {
                    exact_acc = !(masks::vclass::is_crease(l.vclass[v]) && l.vframe(v) != 0);
                    eval::limit_mask(l, &self.tables, v, &mut |i, w| {
                        gather(i, w, &mut scratch, &mut exact_acc)
                    });
                    push_row(&mut scratch, exact_acc, &mut next);
                }
            } else {
                for v in 0..l.nv {
                    exact_acc = l.vframe(v) == 0;
                    eval::vertex_mask(l, &self.tables, v, &mut |i, w| {
                        gather(i, w, &mut scratch, &mut exact_acc)
                    });
                    push_row(&mut scratch, exact_acc, &mut next);
                }
                for e in 0..l.ne() {
                    exact_acc = l.eframe(e) == 0;
                    eval::edge_mask(l, e, &mut |i, w| gather(i, w, &mut scratch, &mut exact_acc));
                    push_row(&mut scratch, exact_acc, &mut next);
                }
            }
            cur = next;
        }
        Ok(cur)
    }
}

/// Limit positions of every vertex of level `l` from its positions `p` (one per vertex).
fn limit_positions_of(
    l: &(impl next_level::Connectivity + Sync),
    t: &ValenceTables,
    b: &topology::Base,
    p: &[DVec3],
) -> Vec<DVec3> {
    let mut out = vec![DVec3::ZERO; p.len()];
    par::for_each_mut(&mut out, |v, o| *o = eval::eval_limit(l, t, b, p, v));
    out
}

/// `Error::Parameter` unless `given` positions are the `nv` of level `m`.
fn check_count(given: usize, nv: usize, m: u32) -> Result<()> {
    if given != nv {
        return Err(Error::Parameter(format!(
            "{given} positions given, level {m} has {nv} vertices"
        )));
    }
    Ok(())
}

/// Subdivides uniformly to `level` and returns the triangle mesh (groups kept, descendants
/// of sharp edges flagged sharp, corner tags kept) plus limit normals when `opts.limit`
/// (then the positions are limit positions too). Boundary patches are emitted as
/// `opts.boundary_patches` says (sparse by default, `spec/subdivision.md` §8); the vertices
/// are then compacted (kept in level-`level` id order).
pub fn subdivide(
    mesh: &ControlMesh,
    level: u32,
    opts: &SubdivOptions,
) -> Result<(ControlMesh, Option<Vec<DVec3>>)> {
    let r = Refinement::with_max_faces(mesh, level, opts.max_faces)?;
    let mut p = Vec::new();
    {
        let mut scratch = Vec::new();
        r.positions_into(&mesh.positions, level, &mut p, &mut scratch)?;
    }
    let (positions, normals) = if opts.limit {
        let n = if opts.normals {
            Some(r.limit_normals(&p, level)?)
        } else {
            None
        };
        (r.limit_positions(&p, level)?, n)
    } else {
        (p, None)
    };
    let sharp_edges = r.finest_sharp_edges();
    let plan = match opts.boundary_patches {
        BoundaryPatchOutput::Sparse => sparse::SparsePlan::new(&r.levels[0], &r.base),
        #[cfg(feature = "internals")]
        BoundaryPatchOutput::Dense => None,
    };
    let groups = mesh.groups.clone();
    let corners = mesh.corners.clone();
    let Some(plan) = plan else {
        // Dense output: the finest triangles as they are (moved, not copied).
        let q = 1usize << (2 * level);
        let nf = r.finest_faces().len() / 3;
        let mut face_groups = Vec::with_capacity(nf);
        for &g in &r.base.group {
            face_groups.extend(std::iter::repeat_n(g, q));
        }
        let out = ControlMesh {
            positions,
            face_offsets: (0..=nf as u32).map(|i| 3 * i).collect(),
            face_vertices: r.into_finest_faces(),
            face_groups,
            groups,
            sharp_edges,
            corners,
        };
        return Ok((out, normals));
    };
    let level_nv = r.level_nv();
    let (tris, face_groups) = sparse::uniform(&r.uniform_faces(&level_nv, Some(&plan)));
    let (positions, normals, remap) = sparse::compact(&positions, normals.as_deref(), &tris);
    let nf = tris.len() / 3;
    let out = ControlMesh {
        positions,
        face_offsets: (0..=nf as u32).map(|i| 3 * i).collect(),
        face_vertices: tris.iter().map(|&v| remap[v as usize]).collect(),
        face_groups,
        groups,
        sharp_edges: sharp_edges
            .into_iter()
            .filter_map(|(a, b)| {
                let (ra, rb) = (remap[a as usize], remap[b as usize]);
                (ra != u32::MAX && rb != u32::MAX).then(|| crate::mesh::edge_key(ra, rb))
            })
            .collect(),
        corners: corners
            .into_iter()
            .filter_map(|c| remap.get(c as usize).copied().filter(|&x| x != u32::MAX))
            .collect(),
    };
    Ok((out, normals))
}

/// Level-of-detail extraction in one call: control face f is shown at level
/// `per_control_face_levels[f]` (all triangles of a polygon share its level), with S-CODE's
/// gap filling and a conforming stitch, so the output is watertight. Positions are the
/// finest-level (or, with `opts.limit`, limit) positions. A viewer that changes levels often
/// should build one [`Refinement`] and call [`Refinement::extract_lod`] with per-base-triangle
/// levels instead.
#[cfg(test)]
pub fn subdivide_adaptive(
    mesh: &ControlMesh,
    per_control_face_levels: &[u8],
    opts: &SubdivOptions,
) -> Result<AdaptiveMesh> {
    if per_control_face_levels.len() != mesh.face_count() {
        return Err(Error::Parameter(format!(
            "{} per-face levels given, the mesh has {} faces",
            per_control_face_levels.len(),
            mesh.face_count()
        )));
    }
    let max = per_control_face_levels.iter().copied().max().unwrap_or(0) as u32;
    let r = Refinement::with_max_faces(mesh, max, opts.max_faces)?;
    let levels = r.base_levels_from_control(per_control_face_levels)?;
    let p = r.positions(&mesh.positions)?;
    let (pos, normals) = if opts.limit {
        let n = if opts.normals {
            Some(r.limit_normals(&p, max)?)
        } else {
            None
        };
        (r.limit_positions(&p, max)?, n)
    } else {
        (p, None)
    };
    r.extract_lod_with(&pos, normals.as_deref(), &levels, opts.boundary_patches)
}
