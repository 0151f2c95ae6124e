//! Subdivision engine: Loop subdivision with Hoppe's piecewise-smooth rules, S-CODE's nested
//! index numbering, limit positions and normals, boundary patches (planes, cylinders, cones)
//! and crack-free level-of-detail extraction.
//!
//! The exact rules are the format's decoding rules and are written down in
//! `spec/subdivision.md`; the numbers were checked against
//! `../shared/reference/loop-subdivision.md`.
//!
//! Usage: build a [`Refinement`] once per control-mesh connectivity (the topology of every
//! level 0..=n), then evaluate positions for any set of control points with
//! [`Refinement::positions`] (a pure function of topology and control points; the encoder
//! calls it many times), or get the linear map itself with [`Refinement::stencils`].
//! [`subdivide`] and [`subdivide_adaptive`] are the one-call conveniences.

mod eval;
mod frame;
mod lod;
mod masks;
mod par;
mod topology;

#[cfg(test)]
pub(crate) mod test_support;
#[cfg(test)]
mod tests;

use glam::DVec3;

use crate::error::{Error, Result};
use crate::mesh::ControlMesh;

pub use lod::{lod_corner_face, AdaptiveMesh};
pub use masks::{loop_beta, loop_omega};

use masks::{eclass, ValenceTables};
use topology::{Base, Level};

/// Default cap on the number of finest-level triangles (`Error::LimitsExceeded` above it).
pub const DEFAULT_MAX_FACES: u64 = 1 << 28;

/// Largest accepted refinement level.
pub const MAX_LEVEL: u32 = 12;

/// Options of the one-call helpers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubdivOptions {
    /// Project the output vertices to the limit surface and return limit normals.
    pub limit: bool,
    /// Refuse to produce more than this many triangles.
    pub max_faces: u64,
}

impl Default for SubdivOptions {
    fn default() -> Self {
        SubdivOptions {
            limit: false,
            max_faces: DEFAULT_MAX_FACES,
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
    /// `levels[j]`: connectivity and classification of level j.
    levels: Vec<Level>,
    base: Base,
    tables: ValenceTables,
}

/// A read-only view of one level's connectivity.
#[derive(Clone, Copy, Debug)]
pub struct LevelView<'a> {
    level: u32,
    l: &'a Level,
    base: &'a Base,
}

impl<'a> LevelView<'a> {
    pub fn level(&self) -> u32 {
        self.level
    }
    pub fn vertex_count(&self) -> usize {
        self.l.nv
    }
    pub fn face_count(&self) -> usize {
        self.l.nf()
    }
    pub fn edge_count(&self) -> usize {
        self.l.ne()
    }
    /// Triangle corners, 3 per face, counter-clockwise.
    pub fn triangles(&self) -> &'a [u32] {
        &self.l.faces
    }
    pub fn triangle(&self, f: usize) -> [u32; 3] {
        [self.l.faces[3 * f], self.l.faces[3 * f + 1], self.l.faces[3 * f + 2]]
    }
    /// Edge ids of face f: `(c0c1, c1c2, c2c0)`.
    pub fn face_edges(&self, f: usize) -> [u32; 3] {
        let fe = &self.l.face_edges[3 * f..3 * f + 3];
        [fe[0], fe[1], fe[2]]
    }
    /// Edges in their stored orientation.
    pub fn edges(&self) -> &'a [[u32; 2]] {
        &self.l.edges
    }
    /// Base (level-0) triangle of face f.
    pub fn base_face(&self, f: usize) -> usize {
        f >> (2 * self.level)
    }
    /// Group (CAD face) of face f.
    pub fn face_group(&self, f: usize) -> u32 {
        self.base.group[self.base_face(f)]
    }
    /// The edge descends from an edge flagged sharp in the control mesh.
    pub fn edge_is_sharp(&self, e: usize) -> bool {
        self.l.eclass[e] & eclass::SHARP != 0
    }
    /// The edge is a crease (sharp or mesh boundary).
    pub fn edge_is_crease(&self, e: usize) -> bool {
        self.l.eclass[e] & eclass::CREASE != 0
    }
    /// The edge lies on the mesh boundary.
    pub fn edge_is_boundary(&self, e: usize) -> bool {
        self.l.eclass[e] & eclass::BOUNDARY != 0
    }
}

/// The linear map from control points to the points of one level: row i is
/// `sum_k weights[k] * control[indices[k]]` over `offsets[i]..offsets[i + 1]`.
///
/// Rows whose derivation used a cylinder/cone frame are not linear in the control points
/// (the masks act on cylindrical coordinates there); for them `exact[i]` is false and the
/// row holds the Cartesian mask composition (a linearisation that is exact for control points
/// evenly spaced in angle). All other rows reproduce [`Refinement::positions`] exactly.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SparseStencils {
    pub offsets: Vec<u32>,
    pub indices: Vec<u32>,
    pub weights: Vec<f64>,
    pub exact: Vec<bool>,
}

impl SparseStencils {
    pub fn row_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }
    /// `(indices, weights)` of row i.
    pub fn row(&self, i: usize) -> (&[u32], &[f64]) {
        let (a, b) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
        (&self.indices[a..b], &self.weights[a..b])
    }
    /// Applies the map to control points.
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
    pub fn new(mesh: &ControlMesh, max_level: u32) -> Result<Refinement> {
        Self::with_max_faces(mesh, max_level, DEFAULT_MAX_FACES)
    }

    /// Builds the topology of levels 0..=`max_level`; `Error::LimitsExceeded` when the
    /// finest level would have more than `max_faces` triangles. `Error::Mesh` for
    /// non-manifold or inconsistently oriented meshes, unknown sharp edges, bad axes.
    pub fn with_max_faces(mesh: &ControlMesh, max_level: u32, max_faces: u64) -> Result<Refinement> {
        if max_level > MAX_LEVEL {
            return Err(Error::Parameter(format!(
                "subdivision level {max_level} exceeds the maximum {MAX_LEVEL}"
            )));
        }
        // Check counts before building anything.
        let tri: u64 = mesh
            .faces()
            .map(|f| f.len().saturating_sub(2) as u64)
            .sum();
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
        let max_k = (0..l0.nv)
            .map(|v| l0.ring(v).len())
            .max()
            .unwrap_or(6);
        let mut levels = Vec::with_capacity(max_level as usize + 1);
        levels.push(l0);
        for j in 0..max_level {
            let next = topology::refine_level(&levels[j as usize], &base, j);
            if j + 1 < max_level {
                // coarser levels need rings for position evaluation; the finest builds
                // them on demand (limit positions, normals)
                let _ = next.rings.set(topology::build_rings(&levels[j as usize]));
            }
            levels.push(next);
        }
        Ok(Refinement {
            levels,
            base,
            tables: ValenceTables::new(max_k),
        })
    }

    pub fn max_level(&self) -> u32 {
        (self.levels.len() - 1) as u32
    }

    /// Number of base (level-0) triangles.
    pub fn base_face_count(&self) -> usize {
        self.levels[0].nf()
    }

    /// Control-mesh face of base triangle k (polygons are fan-triangulated).
    pub fn base_control_face(&self, k: usize) -> usize {
        self.base.control_face[k] as usize
    }

    /// Number of control points expected by [`Refinement::positions`].
    pub fn control_count(&self) -> usize {
        self.levels[0].nv
    }

    /// Connectivity of level `m` (panics if `m > max_level()`).
    pub fn level(&self, m: u32) -> LevelView<'_> {
        LevelView {
            level: m,
            l: &self.levels[m as usize],
            base: &self.base,
        }
    }

    /// Level `m` with its vertex rings built.
    fn level_with_rings(&self, m: usize) -> &Level {
        let l = &self.levels[m];
        if m > 0 {
            l.rings
                .get_or_init(|| topology::build_rings(&self.levels[m - 1]));
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
    pub fn positions_at(&self, control: &[DVec3], m: u32) -> Result<Vec<DVec3>> {
        let (mut out, mut scratch) = (Vec::new(), Vec::new());
        self.positions_into(control, m, &mut out, &mut scratch)?;
        Ok(out)
    }

    /// [`Refinement::positions_at`] into caller-owned buffers (`out` receives the level-`m`
    /// positions, `scratch` is working space), so repeated evaluations allocate nothing.
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
        let n_out = self.levels[m as usize].nv;
        // ping-pong so that the last step writes into `out`
        let (mut cur, mut next) = if m % 2 == 0 {
            (out, scratch)
        } else {
            (scratch, out)
        };
        cur.clear();
        cur.reserve(n_out);
        next.clear();
        next.reserve(n_out);
        cur.extend_from_slice(control);
        for j in 0..m as usize {
            let l = &self.levels[j];
            next.clear();
            let (t, b, p) = (&self.tables, &self.base, &cur[..]);
            par::extend_mapped(next, l.nv, |v| eval::eval_vertex(l, t, b, p, v));
            par::extend_mapped(next, l.ne(), |e| eval::eval_edge(l, b, p, e));
            std::mem::swap(&mut cur, &mut next);
        }
        Ok(())
    }

    /// Positions of the finest level.
    pub fn positions(&self, control: &[DVec3]) -> Result<Vec<DVec3>> {
        self.positions_at(control, self.max_level())
    }

    /// Limit positions of the level-`m` vertices given their level-`m` positions.
    pub fn limit_positions(&self, level_positions: &[DVec3], m: u32) -> Result<Vec<DVec3>> {
        let l = self.checked_level(level_positions, m)?;
        let mut out = vec![DVec3::ZERO; l.nv];
        let (t, b) = (&self.tables, &self.base);
        par::for_each_mut(&mut out, |v, o| *o = eval::eval_limit(l, t, b, level_positions, v));
        Ok(out)
    }

    /// Unit limit normals of the level-`m` vertices given their level-`m` positions (crease
    /// and corner vertices: normalised mean of the normals of their smooth sectors).
    pub fn limit_normals(&self, level_positions: &[DVec3], m: u32) -> Result<Vec<DVec3>> {
        let l = self.checked_level(level_positions, m)?;
        let mut out = vec![DVec3::ZERO; l.nv];
        let (t, b) = (&self.tables, &self.base);
        par::for_each_mut(&mut out, |v, o| {
            *o = eval::eval_normal(l, t, b, m, level_positions, v)
        });
        Ok(out)
    }

    /// Finest-level limit positions and normals from control points.
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
        if pos.len() != l.nv {
            return Err(Error::Parameter(format!(
                "{} positions given, level {m} has {} vertices",
                pos.len(),
                l.nv
            )));
        }
        Ok(l)
    }

    /// The linear map from control points to the level-`m` points (`limit`: to their limit
    /// points). See [`SparseStencils`] for rows that involve cylinder/cone frames.
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
            let push_row = |scratch: &mut Vec<(u32, f64)>, exact: bool, next: &mut SparseStencils| {
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

/// Subdivides uniformly to `level` and returns the triangle mesh (groups kept, descendants
/// of sharp edges flagged sharp, corner tags kept) plus limit normals when `opts.limit`
/// (then the positions are limit positions too).
pub fn subdivide(
    mesh: &ControlMesh,
    level: u32,
    opts: &SubdivOptions,
) -> Result<(ControlMesh, Option<Vec<DVec3>>)> {
    let r = Refinement::with_max_faces(mesh, level, opts.max_faces)?;
    let p = r.positions(&mesh.positions)?;
    let (positions, normals) = if opts.limit {
        (r.limit_positions(&p, level)?, Some(r.limit_normals(&p, level)?))
    } else {
        (p, None)
    };
    let lv = r.level(level);
    let nf = lv.face_count();
    let mut out = ControlMesh {
        positions,
        face_offsets: (0..=nf as u32).map(|i| 3 * i).collect(),
        face_vertices: lv.triangles().to_vec(),
        face_groups: (0..nf).map(|f| lv.face_group(f)).collect(),
        groups: mesh.groups.clone(),
        corners: mesh.corners.clone(),
        ..Default::default()
    };
    out.sharp_edges = (0..lv.edge_count())
        .filter(|&e| lv.edge_is_sharp(e))
        .map(|e| {
            let [a, b] = lv.edges()[e];
            crate::mesh::edge_key(a, b)
        })
        .collect();
    Ok((out, normals))
}

/// Level-of-detail extraction: base triangle k is shown at level `per_face_levels[k]`
/// (at most `max_level`), with S-CODE's gap filling and a conforming stitch so the output
/// is watertight (see [`lod`](AdaptiveMesh)). Positions are the finest-level (or limit)
/// positions.
pub fn subdivide_adaptive(
    mesh: &ControlMesh,
    per_face_levels: &[u8],
    opts: &SubdivOptions,
) -> Result<AdaptiveMesh> {
    let max = per_face_levels.iter().copied().max().unwrap_or(0) as u32;
    let r = Refinement::with_max_faces(mesh, max, opts.max_faces)?;
    let p = r.positions(&mesh.positions)?;
    let (pos, normals) = if opts.limit {
        (r.limit_positions(&p, max)?, Some(r.limit_normals(&p, max)?))
    } else {
        (p, None)
    };
    lod::extract(&r, &pos, normals.as_deref(), per_face_levels)
}
