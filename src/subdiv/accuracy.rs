//! Subdivision to an accuracy: every base triangle is shown at the coarsest level whose
//! output lies within a tolerance of the limit surface, crack-free ([`super::lod`]).
//!
//! The rule. Showing base triangle `k` at level `m` is measured against the limit points of
//! the vertices of level `s = m + 2` over it (`s = m + 1` for the level before the finest
//! shown, whose next-but-one level the refinement does not have), its *samples*, both ways:
//! `E(m)` is the largest of
//!
//! * output densely (closed patches, dense cylinder/cone groups): the distances from the
//!   samples to the level-`m` triangles (corners at their limit points) holding them or,
//!   when nearer, to a triangle around their corners in the same CAD face (a sample may lie
//!   beyond its own triangle along the surface, which is no distance, but not across a
//!   crease, where the neighbour is another surface); and from the output to the samples'
//!   mesh: the distances from the points of the level-`m` triangles over the samples to the
//!   level-`s` triangles at them (a triangle whose samples lie nearer its neighbours can
//!   stand off the surface);
//! * output sparsely (plane patches, belts of cylinders and cones, `sparse`): the output
//!   uses only points on the split edges, and between them the patch is planar (a plane) or
//!   ruled along straight rulings (a belt), so the error is that of the split edges' chains:
//!   the largest distance from a level-`s` sample on the edge to the chords of the level-`m`
//!   chain over it.
//!
//! Between the samples the limit surface strays from the samples' mesh by the error of level
//! `s`, which is `ρ^(s-m)` times that of level `m`: `ρ = 1/4` on smooth surfaces (the error
//! shrinks with the triangles' size squared), slower near extraordinary vertices. So the
//! error `e(m)` of level `m` is at most `E(m) + ρ^(s-m) e(m)`, i.e. `e(m) <= E(m) / (1 -
//! ρ^(s-m))`, the estimate used, with `ρ` taken per base triangle (per chain) as the ratio
//! `E(m) / E(m-1)`, clamped to `[1/4, 1/2]`: below 1/4 the ratio of two tiny errors is noise,
//! above 1/2 the triangle is not yet in the regime where the series applies, and 1/2 keeps
//! the estimate safe; level 0, which has no level before, takes `1/2`. The finest level shown,
//! `n`, is not measured (that would take the level after it): its estimate is `ρ e(n - 1)`
//! with the ratio of level `n - 1`. A base triangle gets the coarsest level `m` with `e(m) <=
//! tolerance` (level `n` when none does: its estimate is then reported above the tolerance).
//!
//! The samples are few: a triangle shown at level `m` needs the limit points of its
//! level-`s` vertices and what they depend on, which [`LazyLimits`] evaluates on demand, level
//! by level, from the positions those depend on. Most base triangles of a CAD model stop at
//! level 0 or 1, so the decode evaluates a small share of the finest level's vertices and
//! never builds that level's connectivity.
//!
//! Each base triangle is measured as if its neighbours were at its level. Gap filling
//! (`spec/subdivision.md` §7) shows a base edge between two levels at the coarser side's
//! chords and moves the finer side's vertices onto them. Next to a corner or a crease the
//! limit points along an edge are spaced unevenly, so a moved vertex can travel far along
//! the chord (many times the tolerance on dense tessellations with a corner at most
//! vertices) while the triangles it moves stay on the surface: what counts is where the
//! moved triangles lie, not how far their corners travel. A point of a moved triangle is
//! within the triangle's estimate plus its distance from the unmoved triangles, or within the
//! coarser side's estimate plus its distance from the coarser side's triangles, of the limit
//! surface; a point of an unmoved triangle is within its distance from the moved triangles
//! or the coarser side's ones of the output. So a base triangle next to a coarser one is
//! within its estimate plus the largest of these distances over the points of its triangles
//! at the moved edges ([`Measure::moved_deviation`]), and never more than plus the largest
//! distance a moved vertex travels; where that exceeds the tolerance (or, where not even
//! level `top` meets it, the triangle's own estimate) the coarser neighbour is raised a
//! level, until nothing changes (levels only rise, so this ends).
//!
//! Last, the edges inside plane patches are flipped toward well-shaped triangles
//! ([`super::flips`]), which moves the surface by at most [`FLIP_SHARE`] of the tolerance,
//! kept free when the levels are chosen.

use glam::DVec3;

use super::eval::wedge_face;
use super::lazy::{LazyLimits, Paged, Prefix};
use super::next_level::child_faces;
use super::sparse::{base_edge_chain, SparsePlan, DENSE};
use super::topology::{Level, NONE};
use super::{flips, lod, masks::eclass, par, BoundaryPatchOutput, Refinement};
use crate::error::{Error, Result};
use crate::mesh::{edge_key, BoundarySurface, ControlMesh, PatchKind, Tolerance};

/// Options of [`subdivide_to_tolerance`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccuracyOptions {
    /// Largest distance between the output and the limit surface; a relative tolerance is
    /// a fraction of the bounding-box diagonal of the limit surface.
    pub tolerance: Tolerance,
    /// Upper bound on the tolerance in model units, whatever `tolerance` resolves to
    /// (`f64::INFINITY`: none).
    pub max_tolerance: f64,
    /// Finest level a base triangle may be shown at. The refinement is built one level
    /// deeper, to measure this one.
    pub max_level: u32,
    /// Also compute the limit normals of the output vertices.
    pub normals: bool,
    /// Refuse to refine when level `max_level` has more than this many triangles.
    pub max_faces: u64,
    /// Sparse (S-CODE, default) or dense output of boundary patches.
    pub boundary_patches: BoundaryPatchOutput,
}

impl Default for AccuracyOptions {
    fn default() -> Self {
        AccuracyOptions {
            tolerance: Tolerance::DEFAULT,
            max_tolerance: f64::INFINITY,
            max_level: 4,
            normals: true,
            max_faces: super::DEFAULT_MAX_FACES,
            boundary_patches: BoundaryPatchOutput::Sparse,
        }
    }
}

/// The output of [`subdivide_to_tolerance`].
#[derive(Clone, Debug, PartialEq)]
pub struct AccurateSurface {
    /// Triangles at limit positions; groups kept, sharp edges (the descendants of the
    /// control mesh's sharp edges) and corners carried.
    pub mesh: ControlMesh,
    /// Limit normals of the output vertices (with `AccuracyOptions::normals`).
    pub normals: Option<Vec<DVec3>>,
    /// Level of every base triangle (control faces fan-triangulated).
    pub levels: Vec<u8>,
    /// The tolerance in model units.
    pub tolerance: f64,
    /// The largest estimated distance of any base triangle's output from the limit surface
    /// (measured error plus the tail beyond the samples); above `tolerance` only when some
    /// triangle needs a level beyond `max_level`.
    pub bound: f64,
}

/// Subdivides `mesh` so that every base triangle is shown at the coarsest level (at most
/// `opts.max_level`) whose output is within the tolerance of the limit surface (the rule is
/// the module's documentation), crack-free, at limit positions.
#[cfg(any(test, feature = "internals"))]
pub fn subdivide_to_tolerance(
    mesh: &ControlMesh,
    opts: &AccuracyOptions,
) -> Result<AccurateSurface> {
    subdivide_to_tolerance_within(mesh, opts, &mut |_, _| Ok(()))
}

/// [`subdivide_to_tolerance`], charging the memory it allocates to `charge` (what for, bytes)
/// before allocating it, as a decoder charges its budget ([`super::charge`]): the
/// measurement before the refinement is built, then the output once the levels are chosen.
/// An error from `charge` is returned at once.
pub fn subdivide_to_tolerance_within(
    mesh: &ControlMesh,
    opts: &AccuracyOptions,
    charge: &mut dyn FnMut(&'static str, u64) -> Result<()>,
) -> Result<AccurateSurface> {
    let n = opts.max_level;
    let tri: u64 = mesh.faces().map(|f| f.len().saturating_sub(2) as u64).sum();
    let shown = tri.saturating_mul(1u64.checked_shl(n.saturating_mul(2)).unwrap_or(u64::MAX));
    if shown > opts.max_faces {
        return Err(Error::LimitsExceeded {
            what: "subdivided triangles",
            value: shown,
            limit: opts.max_faces,
        });
    }
    if n >= super::MAX_LEVEL {
        return Err(Error::Parameter(format!(
            "subdivision to a tolerance shows at most level {}, {n} asked",
            super::MAX_LEVEL - 1
        )));
    }
    if tri == 0 {
        return Ok(AccurateSurface {
            mesh: ControlMesh {
                groups: mesh.groups.clone(),
                ..Default::default()
            },
            normals: opts.normals.then(Vec::new),
            levels: Vec::new(),
            tolerance: 0.0,
            bound: 0.0,
        });
    }
    // Level n's connectivity is read through level n - 1, never built; level 0 is measured
    // against level 1.
    let counts = super::charge::level_counts(mesh, n.max(1));
    charge(
        "decode memory with subdivision to a tolerance: refinement and measurement (bytes)",
        super::charge::measurement_bytes(&counts, n.max(1)),
    )?;
    let r = Refinement::with_max_faces(mesh, n.max(1), opts.max_faces.saturating_mul(4))?;
    let mut lazy = LazyLimits::new(&r, &mesh.positions, charge);
    let nv0 = mesh.positions.len() as u32;
    lazy.evaluate(&(0..nv0).collect::<Vec<u32>>(), false);
    lazy.check()?;
    let base_limits: Vec<DVec3> = (0..nv0 as usize).map(|i| lazy.limit()[i]).collect();
    let tolerance = resolve_tolerance(&base_limits, opts)?;
    let plan = match opts.boundary_patches {
        BoundaryPatchOutput::Sparse => SparsePlan::new(r.full(0), &r.base),
        #[cfg(feature = "internals")]
        BoundaryPatchOutput::Dense => None,
    };
    let m = Measure {
        r: &r,
        top: n,
        plan: plan.as_ref(),
        floor: tolerance * 1e-6,
        level_nv: (0..=r.max_level())
            .map(|j| r.level(j).vertex_count())
            .collect(),
    };
    // The flips of plane patches afterwards may move the surface by a small share of the
    // tolerance: the levels are chosen for the rest.
    let (levels, bound) = m.choose_levels(&mut lazy, tolerance * (1.0 - FLIP_SHARE));
    lazy.check()?;
    lazy.charge(
        "decode memory with subdivision to a tolerance: output (bytes)",
        super::charge::output_bytes(r.full(0), &levels, m.level_nv[n as usize]),
    )?;
    let (out, remap) = m.extract(&mut lazy, &levels, opts)?;
    let mut mesh_out = out.to_control_mesh(&mesh.groups);
    mesh_out.sharp_edges = m.sharp_edges(&levels, n, &remap);
    mesh_out.corners = mesh
        .corners
        .iter()
        .filter_map(|&c| remap.get(c as usize))
        .collect();
    let flipped = well_shaped_planes(&mut mesh_out, FLIP_SHARE * tolerance);
    Ok(AccurateSurface {
        mesh: mesh_out,
        normals: out.normals,
        levels,
        tolerance,
        bound: if flipped > 0 {
            bound + FLIP_SHARE * tolerance
        } else {
            bound
        },
    })
}

/// The share of the tolerance that the edge flips of plane patches may move the surface:
/// a flip exchanges the two triangles of a quad whose corners lie within this distance of
/// one plane, which moves no point further. Plane patches are planar up to the rounding of
/// their quantised control points and their crease curves computed in a neighbouring
/// cylinder's frame; a thousandth of the tolerance admits the first and not the second.
const FLIP_SHARE: f64 = 1e-3;

/// Flips the edges inside the plane patches of `mesh` toward well-shaped triangles
/// ([`flips`]), keeping sharp edges and patch outlines; returns how many it flipped.
fn well_shaped_planes(mesh: &mut ControlMesh, max_deviation: f64) -> usize {
    let flippable: Vec<bool> = mesh
        .groups
        .iter()
        .map(|g| matches!(g.patch, PatchKind::Boundary(BoundarySurface::Plane)))
        .collect();
    if !flippable.iter().any(|&p| p) {
        return 0;
    }
    let mut tris: Vec<[u32; 3]> = mesh
        .face_vertices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    let flipped = flips::flip_to_well_shaped(
        &mesh.positions,
        &mut tris,
        &mesh.face_groups,
        &flippable,
        &mesh.sharp_edges,
        max_deviation,
    );
    mesh.face_vertices = tris.into_iter().flatten().collect();
    flipped
}

/// The tolerance in model units: a relative one against the diagonal of the limit samples'
/// bounding box (the surface the output approximates), capped by `max_tolerance`.
fn resolve_tolerance(limit: &[DVec3], opts: &AccuracyOptions) -> Result<f64> {
    let (lo, hi) = limit.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    let diagonal = if limit.is_empty() {
        0.0
    } else {
        (hi - lo).length()
    };
    let t = opts.tolerance.resolve(diagonal).min(opts.max_tolerance);
    // Zero is allowed (a model collapsed to a point has a zero relative tolerance): then
    // only triangles whose measured error is zero stay coarse.
    if t >= 0.0 && t.is_finite() {
        Ok(t)
    } else {
        Err(Error::Parameter(format!(
            "the tolerance must be finite and not negative, got {} (limit surface diagonal {diagonal})",
            opts.tolerance
        )))
    }
}

/// What the measurement reads: the refinement (built to level `max(top, 1)`), the sparse
/// plan and the vertex counts of its levels.
struct Measure<'a> {
    r: &'a Refinement,
    /// The finest level shown.
    top: u32,
    plan: Option<&'a SparsePlan>,
    /// Distances below this are not told apart (a millionth of the tolerance): a flat
    /// face's points lie on its triangles up to rounding, and measuring each of them to the
    /// triangles around would cost a flat face as much as a curved one.
    floor: f64,
    /// Vertex count of every level of the refinement.
    level_nv: Vec<usize>,
}

/// The measurements of one base triangle at each level (NaN: not measured; a lower bound
/// where the measurement stopped beyond the tolerance).
#[derive(Clone, Copy)]
struct Errors {
    /// `E(m)`, measured against the samples.
    raw: [f64; super::MAX_LEVEL as usize],
    /// `e(m)`, the estimated error.
    est: [f64; super::MAX_LEVEL as usize],
}

impl Errors {
    const NONE: Errors = Errors {
        raw: [f64::NAN; super::MAX_LEVEL as usize],
        est: [f64::NAN; super::MAX_LEVEL as usize],
    };
}

/// `ρ` at level `m` from the measurements `raw` (module documentation): `E(m) / E(m - 1)`
/// clamped to `[1/4, 1/2]`, or `1/2` without a level before. Where `E(m - 1)` stopped early
/// it is a lower bound, which only makes the ratio larger.
fn ratio(raw: &[f64], m: usize) -> f64 {
    if m == 0 || raw[m - 1].is_nan() || raw[m - 1] <= 0.0 || raw[m].is_nan() {
        return 0.5;
    }
    (raw[m] / raw[m - 1]).clamp(0.25, 0.5)
}

/// `e(m) = E(m) / (1 - ρ^d)` for samples `d` levels finer.
fn estimate(raw: &[f64], m: usize, d: u32) -> f64 {
    raw[m] / (1.0 - ratio(raw, m).powi(d as i32))
}

/// The estimated errors of the base edges that sparse output shows as chains, `top + 1`
/// levels per edge (NaN: not measured).
struct EdgeErrors {
    per: usize,
    /// `e(m)` and `E(m)` of every edge.
    e: Vec<f64>,
    raw: Vec<f64>,
}

impl EdgeErrors {
    fn get(&self, e: usize, m: u32) -> f64 {
        self.e[e * self.per + m as usize]
    }
}

impl Measure<'_> {
    fn l0(&self) -> &Level {
        self.r.full(0)
    }

    /// The faces of the sparse unit of base triangle `k` (itself twice for a plane face),
    /// `None` for a dense face.
    fn unit(&self, k: usize) -> Option<[usize; 2]> {
        match self.plan.map_or(DENSE, |p| p.unit[k]) {
            DENSE => None,
            u => Some([k, u as usize]),
        }
    }

    /// The base edges of a sparse unit that its output shows as chains (its split edges).
    fn chain_edges(&self, unit: [usize; 2], out: &mut Vec<usize>) {
        let (l0, plan) = (self.l0(), self.plan.expect("a sparse unit has a plan"));
        for f in unit {
            for &e in &l0.face_edges[3 * f..3 * f + 3] {
                if plan.split[e as usize] && !out.contains(&(e as usize)) {
                    out.push(e as usize);
                }
            }
        }
    }

    /// The base triangle across base edge `e` from `k` (`NONE` on a boundary).
    fn across(&self, e: usize, k: usize) -> u32 {
        let [a, b] = self.l0().edge_faces[e];
        if a as usize == k {
            b
        } else {
            a
        }
    }

    /// Per base triangle the coarsest level within `tolerance` (belt quads at the finer of
    /// their two), then raised where gap filling takes a finer neighbour beyond it; and the
    /// largest estimated error of the output.
    fn choose_levels(&self, lazy: &mut LazyLimits, tolerance: f64) -> (Vec<u8>, f64) {
        let nf = self.l0().nf();
        let top = self.top;
        let mut errors = vec![Errors::NONE; nf];
        let per = top as usize + 1;
        let mut edges = EdgeErrors {
            per,
            e: vec![f64::NAN; self.l0().ne() * per],
            raw: vec![f64::NAN; self.l0().ne() * per],
        };
        let mut levels = vec![top as u8; nf];
        let mut open: Vec<usize> = (0..nf).collect();
        for m in 0..=top {
            // Level top derives from level top - 1, so that one is measured in full.
            let stop = if m + 1 >= top {
                f64::INFINITY
            } else {
                tolerance
            };
            self.measure(lazy, &open, m, stop, &mut errors, &mut edges);
            open.retain(|&k| {
                let within = errors[k].est[m as usize] <= tolerance;
                if within {
                    levels[k] = m as u8;
                }
                !within
            });
            if open.is_empty() {
                break;
            }
        }
        self.pair_belts(&mut levels);
        let bound = self.settle_gap_filling(lazy, &mut levels, &mut errors, &mut edges, tolerance);
        (levels, bound)
    }

    /// Measures base triangles `faces` at level `m` where not measured yet; a dense face's
    /// measurement stops once its `E(m)` exceeds `stop`.
    fn measure(
        &self,
        lazy: &mut LazyLimits,
        faces: &[usize],
        m: u32,
        stop: f64,
        errors: &mut [Errors],
        edges: &mut EdgeErrors,
    ) {
        let mi = m as usize;
        let (mut dense, mut chains, mut sparse) = (Vec::new(), Vec::new(), Vec::new());
        for &k in faces.iter().filter(|&&k| errors[k].est[mi].is_nan()) {
            match self.unit(k) {
                Some(u) => {
                    self.chain_edges(u, &mut chains);
                    sparse.push(k);
                }
                None => dense.push(k),
            }
        }
        self.measure_edges(lazy, &chains, m, edges);
        let mut on_unit = Vec::new();
        for &k in &sparse {
            on_unit.clear();
            self.chain_edges(self.unit(k).expect("sparse"), &mut on_unit);
            errors[k].est[mi] = on_unit.iter().fold(0.0, |a, &e| a.max(edges.get(e, m)));
        }
        if dense.is_empty() {
            return;
        }
        if m > 0 && m == self.top {
            let unmeasured: Vec<usize> = dense
                .iter()
                .copied()
                .filter(|&k| errors[k].raw[mi - 1].is_nan())
                .collect();
            self.measure(lazy, &unmeasured, m - 1, f64::INFINITY, errors, edges);
            for &k in &dense {
                let e = &mut errors[k];
                e.est[mi] = ratio(&e.raw, mi - 1) * e.est[mi - 1];
            }
            return;
        }
        // Neighbouring triangles share most of their samples: asked for triangle by
        // triangle, the repeats are dropped as they come, and a triangle asks for the samples
        // of the triangles around it only where those are not measured here themselves.
        let mut asked = vec![false; self.l0().nf()];
        for &k in &dense {
            asked[k] = true;
        }
        let (mut want, mut scratch) = (Vec::new(), SampleScratch::default());
        for &k in &dense {
            want.clear();
            self.sample_vertices(k, m, &asked, &mut scratch, &mut want);
            lazy.ask(&want, false);
        }
        lazy.run();
        let limit = lazy.limit();
        let mut values = vec![0.0f64; dense.len()];
        par::for_each_heavy(&mut values, |i, v| {
            // e(m) >= E(m): a level whose E(m) exceeds the limit fails whatever its ratio.
            *v = self.dense_error(limit, dense[i], m, stop);
        });
        for (&k, v) in dense.iter().zip(values) {
            let e = &mut errors[k];
            e.raw[mi] = v;
            e.est[mi] = estimate(&e.raw, mi, self.sample_level(m) - m);
        }
    }

    /// The estimated errors of the chains of base edges `chains` at level `m` where not
    /// measured yet.
    fn measure_edges(
        &self,
        lazy: &mut LazyLimits,
        chains: &[usize],
        m: u32,
        edges: &mut EdgeErrors,
    ) {
        let todo: Vec<usize> = chains
            .iter()
            .copied()
            .filter(|&e| edges.get(e, m).is_nan())
            .collect();
        if todo.is_empty() {
            return;
        }
        if m > 0 && m == self.top {
            self.measure_edges(lazy, &todo, m - 1, edges);
            for &e in &todo {
                let i = e * edges.per + m as usize;
                edges.e[i] = ratio(&edges.raw[i - m as usize..i], m as usize - 1) * edges.e[i - 1];
            }
            return;
        }
        let l0 = self.l0();
        let sl = self.sample_level(m);
        let mut chain = Vec::new();
        let mut want = Vec::new();
        for &e in &todo {
            base_edge_chain(l0, &self.level_nv, sl, e, &mut chain);
            want.extend_from_slice(&chain);
        }
        lazy.evaluate(&want, false);
        for &e in &todo {
            base_edge_chain(l0, &self.level_nv, sl, e, &mut chain);
            let (i, at) = (e * edges.per, m as usize);
            edges.raw[i + at] = chain_error(&chain, lazy.limit(), sl - m);
            edges.e[i + at] = estimate(&edges.raw[i..i + at + 1], at, sl - m);
        }
    }

    /// The level whose limit points sample level `m`: two levels finer where the
    /// refinement has that level's vertices, else one.
    fn sample_level(&self, m: u32) -> u32 {
        (m + 2).min(self.r.max_level())
    }

    /// The vertices of level `s` (`m + 1` or `m + 2`) on face `g` of level `m`, each once:
    /// its corners and the vertices [`Self::points_over`] it.
    fn vertices_over(
        &self,
        g: usize,
        m: u32,
        s: u32,
        scratch: &mut SampleScratch,
        out: &mut Vec<u32>,
    ) {
        out.extend_from_slice(&self.r.full(m).faces[3 * g..3 * g + 3]);
        scratch.points.clear();
        self.points_over(m, g, s - m, &mut scratch.points);
        out.extend(scratch.points.iter().map(|&(x, _)| x));
    }

    /// The vertices whose limit points the measurement of dense base triangle `k` at level
    /// `m` reads: those of the sample level over its level-`m` faces and over the faces
    /// around them, leaving out the faces of the base triangles `asked` marks (which ask for
    /// their own).
    fn sample_vertices(
        &self,
        k: usize,
        m: u32,
        asked: &[bool],
        scratch: &mut SampleScratch,
        out: &mut Vec<u32>,
    ) {
        let lm = self.r.full(m);
        let s = self.sample_level(m);
        let q = 1usize << (2 * m);
        for f in k * q..(k + 1) * q {
            self.vertices_over(f, m, s, scratch, out);
            // Most faces around belong to base triangles asked for themselves: only the
            // others are gathered.
            let other = |g: u32| g as usize >> (2 * m) != k && !asked[g as usize >> (2 * m)];
            faces_around(lm, f, other, &mut scratch.around);
            for i in 0..scratch.around.len() {
                self.vertices_over(scratch.around[i] as usize, m, s, scratch, out);
            }
        }
    }

    /// The vertices of the output of base triangle `k` at level `m`: the corners of its
    /// level-`m` faces, or for a sparse face the chains along its edges.
    fn output_vertices(&self, k: usize, m: u32, out: &mut Vec<u32>) {
        if let Some(u) = self.unit(k) {
            let mut chain = Vec::new();
            for f in u {
                for &e in &self.l0().face_edges[3 * f..3 * f + 3] {
                    base_edge_chain(self.l0(), &self.level_nv, m, e as usize, &mut chain);
                    out.extend_from_slice(&chain);
                }
            }
            return;
        }
        if m == 0 {
            out.extend_from_slice(&self.l0().faces[3 * k..3 * k + 3]);
        } else if m < self.r.max_level() {
            let q = 1usize << (2 * m);
            out.extend_from_slice(&self.r.full(m).faces[3 * k * q..3 * (k + 1) * q]);
        } else {
            let prev = self.r.full(m - 1);
            let q = 1usize << (2 * (m - 1));
            for g in k * q..(k + 1) * q {
                out.extend_from_slice(&child_faces(prev, g));
            }
        }
    }

    /// `E(m)` of dense base triangle `k` (the module's documentation), from the limit points
    /// `limit` of the sample level `s`; stops as soon as it exceeds `stop_above`. Distances
    /// below `self.floor` are not told apart.
    fn dense_error(&self, limit: &Paged, k: usize, m: u32, stop_above: f64) -> f64 {
        let lm = self.r.full(m);
        let tri = |g: usize| {
            let c = &lm.faces[3 * g..3 * g + 3];
            [
                limit[c[0] as usize],
                limit[c[1] as usize],
                limit[c[2] as usize],
            ]
        };
        self.dense_error_of(limit, k, m, stop_above, &tri)
    }

    /// [`Self::dense_error`] of the output whose level-`m` faces (of `k` and around it) are
    /// the triangles `tri` gives.
    fn dense_error_of(
        &self,
        limit: &Paged,
        k: usize,
        m: u32,
        stop_above: f64,
        tri: &impl Fn(usize) -> [DVec3; 3],
    ) -> f64 {
        let lm = self.r.full(m);
        let s = self.sample_level(m);
        let q = 1usize << (2 * m);
        let group = self.r.base.group[k];
        let (mut around, mut ring) = (Vec::new(), Vec::new());
        let mut points = Vec::new();
        let mut err2 = self.floor * self.floor;
        for f in k * q..(k + 1) * q {
            let t = tri(f);
            ring.clear();
            points.clear();
            self.points_over(m, f, s - m, &mut points);
            for &(x, b) in &points {
                let p = limit[x as usize];
                // The output's point over the sample lies on t, so both distances below are
                // at most its distance from the sample: when that is within err2 neither can
                // raise it (most samples, once err2 has grown to the triangle's error).
                let o = t[0] * b[0] + t[1] * b[1] + t[2] * b[2];
                let op2 = (o - p).length_squared();
                if op2 <= err2 {
                    continue;
                }
                // From the surface to the output: the sample to its own triangle, or to the
                // nearest around it in the same CAD face.
                let own = point_triangle_distance_squared(p, &t);
                if own > err2 {
                    if ring.is_empty() {
                        faces_around(lm, f, |_| true, &mut around);
                        ring.extend(
                            around
                                .iter()
                                .filter(|&&g| self.r.base.group[g as usize >> (2 * m)] == group)
                                .map(|&g| tri(g as usize)),
                        );
                    }
                    err2 = err2.max(nearest(p, own, &ring, err2.sqrt()));
                }
                // From the output to the samples' mesh: the output's point over the sample
                // to the sample level's triangles at the sample.
                if op2 > err2 {
                    err2 = err2.max(self.nearest_sample_triangle(o, x, s, limit, err2));
                }
            }
            if err2 > stop_above * stop_above {
                break;
            }
        }
        err2.sqrt()
    }

    /// The vertices of levels `m + 1 ..= m + depth` (`depth` 1 or 2) on face `f` of level
    /// `m` and inside it, with their barycentric coordinates in it (midpoints in the
    /// parameter domain, by the children layout of [`child_faces`]): the midpoints of its
    /// edges, then the quarter points of its edges and the midpoints of its middle child's
    /// edges.
    fn points_over(&self, m: u32, f: usize, depth: u32, out: &mut Vec<(u32, [f64; 3])>) {
        let lm = self.r.full(m);
        let corner = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mid = |a: [f64; 3], b: [f64; 3]| {
            [
                (a[0] + b[0]) / 2.0,
                (a[1] + b[1]) / 2.0,
                (a[2] + b[2]) / 2.0,
            ]
        };
        let c = &lm.faces[3 * f..3 * f + 3];
        let fe = &lm.face_edges[3 * f..3 * f + 3];
        let mids = [
            mid(corner[0], corner[1]),
            mid(corner[1], corner[2]),
            mid(corner[2], corner[0]),
        ];
        let nv = lm.nv as u32;
        for side in 0..3 {
            out.push((nv + fe[side], mids[side]));
        }
        if depth < 2 {
            return;
        }
        let l1 = self.r.full(m + 1);
        let nv1 = l1.nv as u32;
        for side in 0..3 {
            // The halves of edge e are the level-(m+1) edges 2e and 2e + 1; each has one end
            // at a corner of f, and its midpoint lies a quarter of the way from that corner.
            let e = fe[side] as usize;
            for h in [2 * e, 2 * e + 1] {
                let [a, b] = l1.edges[h];
                let end = if a < nv { a } else { b };
                let at = if end == c[side] { side } else { (side + 1) % 3 };
                out.push((nv1 + h as u32, mid(corner[at], mids[side])));
            }
        }
        // The middle child (`child_faces` order: the three corner children, then the middle
        // one, m0 m1 m2): the midpoints of its edges are the level-(m+2) vertices inside f.
        let g = 4 * f + 3;
        let ge = &l1.face_edges[3 * g..3 * g + 3];
        for side in 0..3 {
            out.push((nv1 + ge[side], mid(mids[side], mids[(side + 1) % 3])));
        }
    }

    /// The squared distance from `p` to the nearest of the level-`s` triangles (corners at
    /// their limit points) at vertex `x` of level `s - 1` or `s`, the children of the
    /// level-`(s - 1)` faces at it; or any value at most `within2` once one is that near (the
    /// caller only needs to know it is no further). `p` lies near the limit point of `x`, so
    /// the children with `x` as a corner are tried first, and the others only when none of
    /// those is that near: the search usually stops at one of the first.
    fn nearest_sample_triangle(
        &self,
        p: DVec3,
        x: u32,
        s: u32,
        limit: &Paged,
        within2: f64,
    ) -> f64 {
        let last = self.r.full(s - 1);
        // The faces at x: at an old vertex each face once, the one on the counter-clockwise
        // side of each ring edge (none after the last edge of a boundary vertex's ring); at
        // a new vertex the faces of its edge.
        let (ring, edge): (&[u32], [u32; 2]) = if (x as usize) < last.nv {
            (last.ring(x as usize), [NONE; 2])
        } else {
            (&[], last.edge_faces[x as usize - last.nv])
        };
        let faces = ring
            .iter()
            .map(|&e| wedge_face(last, x as usize, e))
            .chain(edge)
            .filter(|&g| g != NONE);
        let mut best = f64::INFINITY;
        for with_x in [true, false] {
            for g in faces.clone() {
                for t in child_faces(last, g as usize).chunks_exact(3) {
                    if t.contains(&x) != with_x {
                        continue;
                    }
                    let tri = [
                        limit[t[0] as usize],
                        limit[t[1] as usize],
                        limit[t[2] as usize],
                    ];
                    best = best.min(point_triangle_distance_squared(p, &tri));
                    if best <= within2 {
                        return best;
                    }
                }
            }
        }
        best
    }

    /// Both faces of a belt quad at the finer of their levels (the extraction shows them so).
    fn pair_belts(&self, levels: &mut [u8]) {
        let Some(plan) = self.plan else { return };
        for k in 0..levels.len() {
            let u = plan.unit[k];
            if u != DENSE && u as usize != k {
                let m = levels[k].max(levels[u as usize]);
                levels[k] = m;
                levels[u as usize] = m;
            }
        }
    }

    /// The base triangles across the edges of base triangle `k`.
    fn neighbours(&self, k: usize) -> impl Iterator<Item = usize> + '_ {
        let l0 = self.l0();
        l0.face_edges[3 * k..3 * k + 3]
            .iter()
            .filter_map(move |&e| {
                let o = self.across(e as usize, k);
                (o != NONE).then_some(o as usize)
            })
    }

    /// Raises the coarser neighbours of every base triangle that gap filling takes beyond
    /// the tolerance (or beyond its own estimate, where not even level `top` meets the
    /// tolerance) until none is, and returns the largest estimate of the output. Levels only
    /// rise and are at most `top`, so this ends; each round checks only the triangles next
    /// to a raised one.
    fn settle_gap_filling(
        &self,
        lazy: &mut LazyLimits,
        levels: &mut [u8],
        errors: &mut [Errors],
        edges: &mut EdgeErrors,
        tolerance: f64,
    ) -> f64 {
        let nf = levels.len();
        let top = self.top as u8;
        let mut bounds = vec![0.0f64; nf];
        let mut check: Vec<usize> = (0..nf).collect();
        let partner = |f: usize| self.unit(f).map_or(f, |u| u[1]);
        while !check.is_empty() {
            self.prepare_shown(lazy, &check, levels, errors, edges);
            let mut shown = vec![0.0f64; check.len()];
            {
                let (lv, errs, eds, limit): (&[u8], &[Errors], &EdgeErrors, &Paged) =
                    (levels, errors, edges, lazy.limit());
                par::for_each_heavy(&mut shown, |i, out| {
                    *out = self.shown_error(check[i], lv, errs, eds, limit);
                });
            }
            let mut raise = Vec::new();
            for (&k, &b) in check.iter().zip(&shown) {
                let own = errors[k].est[levels[k] as usize];
                if b > tolerance.max(own) {
                    // A belt quad shows the edges of both its faces.
                    let unit = [k, partner(k)];
                    raise.extend(
                        unit.iter()
                            .flat_map(|&f| self.neighbours(f))
                            .filter(|&o| levels[o] < levels[k] && levels[o] < top),
                    );
                }
                bounds[k] = own.max(b);
            }
            if raise.is_empty() {
                break;
            }
            let before = levels.to_vec();
            raise.sort_unstable();
            raise.dedup();
            for &o in &raise {
                levels[o] += 1;
            }
            self.pair_belts(levels);
            // The triangles next to a raised one show it, and so does the belt partner of
            // each (a belt quad is measured with the edges of both its faces).
            let mut next: Vec<usize> = (0..nf)
                .filter(|&o| levels[o] != before[o])
                .flat_map(|o| self.neighbours(o).chain([o]))
                .flat_map(|f| [f, partner(f)])
                .collect();
            next.sort_unstable();
            next.dedup();
            check = next;
        }
        bounds.iter().fold(0.0f64, |a, &b| a.max(b))
    }

    /// Measures what [`Self::shown_error`] reads of base triangles `faces` at `levels`:
    /// each at its level, the chains of sparse faces at the levels they are shown at, and
    /// the limit points of the vertices gap filling moves.
    fn prepare_shown(
        &self,
        lazy: &mut LazyLimits,
        faces: &[usize],
        levels: &[u8],
        errors: &mut [Errors],
        edges: &mut EdgeErrors,
    ) {
        for m in 0..=self.top {
            let at: Vec<usize> = faces
                .iter()
                .copied()
                .filter(|&k| u32::from(levels[k]) == m)
                .collect();
            self.measure(lazy, &at, m, f64::INFINITY, errors, edges);
            let mut chains = Vec::new();
            for &k in &at {
                let Some(u) = self.unit(k) else { continue };
                let mut own = Vec::new();
                self.chain_edges(u, &mut own);
                for f in u {
                    for &e in &self.l0().face_edges[3 * f..3 * f + 3] {
                        let o = self.across(e as usize, f);
                        if own.contains(&(e as usize))
                            && o != NONE
                            && u32::from(levels[o as usize]) < m
                        {
                            chains.push((e as usize, levels[o as usize]));
                        }
                    }
                }
            }
            for j in 0..m {
                let on: Vec<usize> = chains
                    .iter()
                    .filter(|&&(_, l)| u32::from(l) == j)
                    .map(|&(e, _)| e)
                    .collect();
                self.measure_edges(lazy, &on, j, edges);
            }
            let mut want = Vec::new();
            for &k in at.iter().filter(|&&k| self.unit(k).is_none()) {
                want.clear();
                self.output_vertices(k, m, &mut want);
                lazy.ask(&want, false);
            }
            lazy.run();
        }
    }

    /// The estimated error of base triangle `k` as the output shows it at `levels`: a base
    /// edge next to a coarser triangle shows that triangle's chords, and the vertices of `k`
    /// on it are moved onto them (gap filling).
    fn shown_error(
        &self,
        k: usize,
        levels: &[u8],
        errors: &[Errors],
        edges: &EdgeErrors,
        limit: &Paged,
    ) -> f64 {
        let m = levels[k];
        let l0 = self.l0();
        if let Some(u) = self.unit(k) {
            // A sparse face shows every split edge at the coarser of its two sides' chains.
            let mut own = Vec::new();
            self.chain_edges(u, &mut own);
            let mut err = 0.0f64;
            for f in u {
                for &e in &l0.face_edges[3 * f..3 * f + 3] {
                    let e = e as usize;
                    if !own.contains(&e) {
                        continue;
                    }
                    let o = self.across(e, f);
                    let shown = if o == NONE {
                        m
                    } else {
                        m.min(levels[o as usize])
                    };
                    err = err.max(edges.get(e, shown.into()));
                }
            }
            return err;
        }
        let (mut moved, mut chains) = (Vec::new(), Vec::new());
        let mut beyond = Beyond::default();
        for &e in &l0.face_edges[3 * k..3 * k + 3] {
            let o = self.across(e as usize, k);
            if o != NONE && levels[o as usize] < m {
                chains.extend(
                    (0..=1usize << m)
                        .map(|j| lod::edge_vertex(l0, &self.level_nv, m.into(), e as usize, j)),
                );
                self.shown_at_edge(o as usize, e as usize, levels, errors, limit, &mut beyond);
                self.gap_filled(
                    limit,
                    e as usize,
                    m.into(),
                    levels[o as usize].into(),
                    &mut moved,
                );
            }
        }
        let own = errors[k].est[m as usize];
        if moved.is_empty() {
            return own;
        }
        let far = moved
            .iter()
            .fold(0.0f64, |a, &(v, p)| {
                a.max((p - limit[v as usize]).length_squared())
            })
            .sqrt();
        moved.sort_unstable_by_key(|&(v, _)| v);
        // Every point of a triangle moves by at most the largest move of its corners, but a
        // move along the coarser side's chord (the spacing of an edge's limit points is
        // uneven next to corners and creases) slides the triangles within the surface they
        // already show: what counts is how far the moved triangles lie from the unmoved ones.
        chains.sort_unstable();
        let slid = self
            .moved_deviation(k, m.into(), limit, &moved, &chains, own, &beyond)
            .min(far);
        if u32::from(m) == self.top && self.top > 0 {
            // Not measured: the level after the finest shown is not in the refinement.
            return own + slid;
        }
        // Measured as shown: k's triangles with the moved corners, the coarser neighbours'
        // own triangles.
        let at = |v: u32| match moved.binary_search_by_key(&v, |&(x, _)| x) {
            Ok(i) => moved[i].1,
            Err(_) => limit[v as usize],
        };
        let m = u32::from(m);
        let lm = self.r.full(m);
        let shown = |g: usize| {
            let base = g >> (2 * m);
            let lo = u32::from(levels[base]);
            if base == k {
                let c = &lm.faces[3 * g..3 * g + 3];
                return [at(c[0]), at(c[1]), at(c[2])];
            }
            let (l, g) = if lo >= m {
                (lm, g)
            } else {
                (self.r.full(lo), g >> (2 * (m - lo)))
            };
            let c = &l.faces[3 * g..3 * g + 3];
            [
                limit[c[0] as usize],
                limit[c[1] as usize],
                limit[c[2] as usize],
            ]
        };
        let raw = self.dense_error_of(limit, k, m, f64::INFINITY, &shown);
        let d = self.sample_level(m) - m;
        let rho = ratio(&errors[k].raw, m as usize).powi(d as i32);
        (raw / (1.0 - rho)).min(own + slid)
    }

    /// How far gap filling takes the level-`m` triangles of dense base triangle `k` beyond
    /// `k`'s own estimate `own` (`moved`: the moved vertices, sorted, with their positions on
    /// the coarser sides' chords; `chains`: the vertices of `k`'s gap-filled base edges,
    /// sorted; `beyond`: the coarser sides' triangles at those edges). A point of a moved
    /// triangle is within `own` plus its distance of the unmoved triangles, or within the
    /// coarser side's estimate plus its distance of that side's triangles, of the limit
    /// surface; a point of an unmoved triangle (within `own` of the surface) is within its
    /// distance of the moved triangles or of the coarser side's. The largest excess over
    /// `own`, at the points over each triangle two levels down; below `self.floor`, 0.
    #[allow(clippy::too_many_arguments)]
    fn moved_deviation(
        &self,
        k: usize,
        m: u32,
        limit: &Paged,
        moved: &[(u32, DVec3)],
        chains: &[u32],
        own: f64,
        beyond: &Beyond,
    ) -> f64 {
        let is_moved = |v: &u32| moved.binary_search_by_key(v, |&(x, _)| x).is_ok();
        let at = |v: u32| match moved.binary_search_by_key(&v, |&(x, _)| x) {
            Ok(i) => moved[i].1,
            Err(_) => limit[v as usize],
        };
        let mut corners = Vec::new();
        self.output_vertices(k, m, &mut corners);
        // A moved vertex slides along its base edge between the same coarse chain vertices,
        // so the triangles compared with are those at the gap-filled edges; only those with
        // a moved corner differ.
        let (mut still, mut shifted, mut differ) = (Vec::new(), Vec::new(), Vec::new());
        for c in corners.chunks_exact(3) {
            if !c.iter().any(|v| chains.binary_search(v).is_ok()) {
                continue;
            }
            if c.iter().any(is_moved) {
                differ.push(still.len());
            }
            still.push([
                limit[c[0] as usize],
                limit[c[1] as usize],
                limit[c[2] as usize],
            ]);
            shifted.push([at(c[0]), at(c[1]), at(c[2])]);
        }
        // The coarser side's estimate counts where it exceeds k's own.
        let extra = (beyond.err - own).max(0.0);
        let mut worst = self.floor;
        for (from, to, d_beyond) in [(&shifted, &still, extra), (&still, &shifted, 0.0)] {
            for &i in &differ {
                let t = &from[i];
                for b in DEVIATION_POINTS {
                    let p = t[0] * b[0] + t[1] * b[1] + t[2] * b[2];
                    let first = point_triangle_distance_squared(p, &to[i]);
                    let near = nearest(p, first, to, worst).sqrt();
                    if near <= worst {
                        continue;
                    }
                    let below = (worst - d_beyond).max(0.0);
                    let across = nearest(p, f64::INFINITY, &beyond.tris, below).sqrt() + d_beyond;
                    worst = worst.max(near.min(across));
                }
            }
        }
        if worst > self.floor {
            worst
        } else {
            0.0
        }
    }

    /// Appends to `beyond` the level-`lo` triangles of dense base triangle `o`, shown at its
    /// level `lo`, that touch base edge `e` (at their limit points), and raises its error to
    /// `o`'s estimate; a sparse `o` adds nothing.
    fn shown_at_edge(
        &self,
        o: usize,
        e: usize,
        levels: &[u8],
        errors: &[Errors],
        limit: &Paged,
        beyond: &mut Beyond,
    ) {
        if self.unit(o).is_some() {
            return;
        }
        let lo = u32::from(levels[o]);
        let l0 = self.l0();
        let mut chain: Vec<u32> = (0..=1usize << lo)
            .map(|j| lod::edge_vertex(l0, &self.level_nv, lo, e, j))
            .collect();
        chain.sort_unstable();
        let mut corners = Vec::new();
        self.output_vertices(o, lo, &mut corners);
        for c in corners.chunks_exact(3) {
            if c.iter().any(|v| chain.binary_search(v).is_ok()) {
                beyond.tris.push([
                    limit[c[0] as usize],
                    limit[c[1] as usize],
                    limit[c[2] as usize],
                ]);
            }
        }
        beyond.err = beyond.err.max(errors[o].est[lo as usize]);
    }

    /// Appends the vertices gap filling moves on base edge `e` shown at level `fine` on one
    /// side and `coarse` on the other, with their moved positions on the chords of the
    /// coarser side (the spec's `(1 - t) x_j0 + t x_j0+s`, as the extraction computes them).
    fn gap_filled(
        &self,
        limit: &Paged,
        e: usize,
        fine: u32,
        coarse: u32,
        out: &mut Vec<(u32, DVec3)>,
    ) {
        let l0 = self.l0();
        let s = 1usize << (fine - coarse);
        let x = |j: usize| lod::edge_vertex(l0, &self.level_nv, fine, e, j);
        for j in 1..1usize << fine {
            if j % s != 0 {
                let j0 = j / s * s;
                let t = (j - j0) as f64 / s as f64;
                let (a, b) = (limit[x(j0) as usize], limit[x(j0 + s) as usize]);
                out.push((x(j), a * (1.0 - t) + b * t));
            }
        }
    }

    /// The output: every base triangle at its level, gap-filled and stitched, at limit
    /// points (with their normals when asked); and the map from level-`top` vertex ids to
    /// output vertices.
    fn extract(
        &self,
        lazy: &mut LazyLimits,
        levels: &[u8],
        opts: &AccuracyOptions,
    ) -> Result<(lod::AdaptiveMesh, lod::Remap)> {
        let mut want = Vec::new();
        for (k, &m) in levels.iter().enumerate() {
            want.clear();
            self.output_vertices(k, m.into(), &mut want);
            lazy.ask(&want, opts.normals);
        }
        lazy.run();
        lazy.check()?;
        let nv = self.level_nv[self.top as usize];
        loop {
            let normals = opts.normals.then(|| Prefix(lazy.normals(), nv));
            let (out, remap) = lod::extract_at(
                self.r,
                self.top,
                &Prefix(lazy.limit(), nv),
                normals.as_ref(),
                levels,
                opts.boundary_patches,
            )?;
            // The output's vertices are those asked for above; should the extraction read
            // one more, it is evaluated and the output made again.
            let missing: Vec<u32> = remap
                .used()
                .iter()
                .copied()
                .filter(|&v| !lazy.has(v, opts.normals))
                .collect();
            if missing.is_empty() {
                return Ok((out, remap));
            }
            debug_assert!(false, "the output reads {} more vertices", missing.len());
            lazy.evaluate(&missing, opts.normals);
            lazy.check()?;
        }
    }

    /// The sharp edges of the output: along every sharp base edge, the chain of the finer of
    /// its two faces' levels (the coarser side is fanned through it), through `remap`.
    fn sharp_edges(
        &self,
        levels: &[u8],
        top: u32,
        remap: &lod::Remap,
    ) -> std::collections::BTreeSet<(u32, u32)> {
        let l0 = self.l0();
        let mut out = std::collections::BTreeSet::new();
        for e in 0..l0.ne() {
            if l0.eclass[e] & eclass::SHARP == 0 {
                continue;
            }
            let [fl, fr] = l0.edge_faces[e];
            let mut m = levels[fl as usize];
            if fr != NONE {
                m = m.max(levels[fr as usize]);
            }
            let step = 1usize << (top - u32::from(m));
            let mut prev = u32::MAX;
            let mut j = 0;
            while j <= 1usize << top {
                let v = remap
                    .get(lod::edge_vertex(l0, &self.level_nv, top, e, j) as usize)
                    .unwrap_or(u32::MAX);
                if prev != u32::MAX && v != u32::MAX {
                    out.insert(edge_key(prev, v));
                }
                prev = v;
                j += step;
            }
        }
        out
    }
}

/// The squared distance from `p` to the nearest of a triangle at squared distance `first`
/// and `tris`, or any value at most `below²` once one is that near (the caller only needs to
/// know it is no further).
fn nearest(p: DVec3, first: f64, tris: &[[DVec3; 3]], below: f64) -> f64 {
    let mut best = first;
    if best <= below * below {
        return best;
    }
    for t in tris {
        best = best.min(point_triangle_distance_squared(p, t));
        if best <= below * below {
            break;
        }
    }
    best
}

/// The coarser neighbours' triangles along a base triangle's gap-filled edges, as shown,
/// and the largest of those neighbours' estimates ([`Measure::moved_deviation`]).
#[derive(Default)]
struct Beyond {
    tris: Vec<[DVec3; 3]>,
    err: f64,
}

/// Barycentric coordinates of the points over a triangle two levels down (its corners, the
/// midpoints and quarter points of its edges and the three points inside), where
/// [`Measure::moved_deviation`] compares triangles.
const DEVIATION_POINTS: [[f64; 3]; 15] = [
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.5, 0.5, 0.0],
    [0.0, 0.5, 0.5],
    [0.5, 0.0, 0.5],
    [0.75, 0.25, 0.0],
    [0.25, 0.75, 0.0],
    [0.0, 0.75, 0.25],
    [0.0, 0.25, 0.75],
    [0.25, 0.0, 0.75],
    [0.75, 0.0, 0.25],
    [0.5, 0.25, 0.25],
    [0.25, 0.5, 0.25],
    [0.25, 0.25, 0.5],
];

/// Buffers [`Measure::sample_vertices`] reuses from one triangle to the next.
#[derive(Default)]
struct SampleScratch {
    around: Vec<u32>,
    points: Vec<(u32, [f64; 3])>,
}

/// The faces of level `l` around the corners of face `f` that `keep` keeps (`f` never), each
/// once, into `out` in id order. Each corner's ring gives each face at it once (the face on
/// one side of each ring edge).
fn faces_around(l: &Level, f: usize, keep: impl Fn(u32) -> bool, out: &mut Vec<u32>) {
    out.clear();
    for &v in &l.faces[3 * f..3 * f + 3] {
        for &e in l.ring(v as usize) {
            let g = wedge_face(l, v as usize, e);
            if g != NONE && g as usize != f && keep(g) {
                out.push(g);
            }
        }
    }
    out.sort_unstable();
    out.dedup();
}

/// Chord error of the level-`m` chain over a level-`fine` chain, `shift = fine - m`: the
/// largest distance from a sample to the chord between the level-`m` points on either side,
/// or to the chord before or after it when that is nearer (the samples slide along the curve
/// as they do along a surface, see [`Measure::dense_error`]).
fn chain_error(chain: &[u32], limit: &Paged, shift: u32) -> f64 {
    let step = 1usize << shift;
    let segments = (chain.len() - 1) / step;
    let seg = |i: usize| {
        (
            limit[chain[i * step] as usize],
            limit[chain[(i + 1) * step] as usize],
        )
    };
    let mut d2 = 0.0f64;
    for i in 0..segments {
        let (a, b) = seg(i);
        for &v in &chain[i * step + 1..(i + 1) * step] {
            let p = limit[v as usize];
            let mut best = point_segment_distance_squared(p, a, b);
            for j in [i.wrapping_sub(1), i + 1] {
                if j < segments && best > d2 {
                    let (a, b) = seg(j);
                    best = best.min(point_segment_distance_squared(p, a, b));
                }
            }
            d2 = d2.max(best);
        }
    }
    d2.sqrt()
}

fn point_segment_distance_squared(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let l2 = ab.length_squared();
    let t = if l2 > 0.0 {
        ((p - a).dot(ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).length_squared()
}

/// Squared distance from `p` to triangle `t` (Ericson's Voronoi regions, Real-Time Collision
/// Detection §5.1.5; a degenerate triangle falls back to its edges).
pub(super) fn point_triangle_distance_squared(p: DVec3, t: &[DVec3; 3]) -> f64 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.length_squared();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.length_squared();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return point_segment_distance_squared(p, a, b);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.length_squared();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return point_segment_distance_squared(p, a, c);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return point_segment_distance_squared(p, b, c);
    }
    let sum = va + vb + vc;
    if sum.abs() < f64::MIN_POSITIVE || !sum.is_finite() {
        return point_segment_distance_squared(p, a, b)
            .min(point_segment_distance_squared(p, b, c))
            .min(point_segment_distance_squared(p, a, c));
    }
    let (v, w) = (vb / sum, vc / sum);
    (p - (a + ab * v + ac * w)).length_squared()
}
