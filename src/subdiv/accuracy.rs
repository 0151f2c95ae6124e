//! Subdivision to an accuracy: every base triangle is shown at the coarsest level whose
//! output lies within a tolerance of the limit surface, crack-free ([`super::lod`]).
//!
//! The rule. The refinement is built one level deeper than the finest level shown: `N = n +
//! 1` for output levels `0..=n`. The limit positions of the level-`N` vertices are samples of
//! the limit surface, `2^(N-m)` of them along every edge of a level-`m` triangle, so the
//! error of showing base triangle `k` at level `m` is *measured*, not guessed, both ways:
//!
//! * output densely (closed patches, dense cylinder/cone groups), from the surface to the
//!   output: the largest distance from the limit sample of a level-`N` vertex inside a
//!   level-`m` triangle (its edges included) to that triangle or, when nearer, to a
//!   triangle around its corners in the same CAD face (corners at their limit positions):
//!   a sample may lie beyond its own triangle along the surface, which is no distance, but
//!   not across a crease, where the neighbour is another surface. From the output to the
//!   surface: the largest distance from the points of the level-`m` triangles over their
//!   edges' midpoints and the level-(m+2) vertices inside them to the level-`N` triangles
//!   around those vertices (a triangle whose samples all lie nearer its neighbours can
//!   stand off the surface);
//! * output sparsely (plane patches, belts of cylinders and cones, `sparse`): the output
//!   uses only points on the split edges, and between them the patch is planar (a plane) or
//!   ruled along straight rulings (a belt), so the error is that of the split edges'
//!   chains: the largest distance from a level-`N` sample on the edge to the chords of the
//!   level-`m` chain over it.
//!
//! Between the samples the limit surface can stray further from the level-`N` mesh through
//! them; how far is bounded by the same measurement one level up: the distance between
//! level `N` and the limit shrinks by the factor `ρ` by which the measured error shrinks from
//! level `n - 1` to `n` (`h²` for smooth surfaces: `ρ = 1/4`; slower near extraordinary
//! vertices, which the measurement sees), so the tail beyond the samples is the geometric
//! series `e(n) ρ / (1 - ρ)`, `e` measured from the surface to the output (the other
//! direction searches around every point, so it is measured only at the levels a triangle
//! may be shown at). `ρ` is taken per base triangle from its own measurements,
//! clamped to `[1/4, 1/2]`: below 1/4 the ratio of two tiny errors is noise, above 1/2 the
//! triangle is not yet in the regime where the series applies, and a tail of at most `e(n)`
//! keeps the estimate safe. A base triangle gets the coarsest level `m` with `e(m) + tail <=
//! tolerance` (level `n` when none does: its bound is then reported above the tolerance).
//!
//! Each base triangle is measured as if its neighbours were at its level. Gap filling
//! (`spec/subdivision.md` §7) shows a base edge between two levels at the coarser side's
//! chords and moves the finer side's vertices onto them, so after the first choice every
//! base triangle next to a coarser one is measured again as the output shows it (moved
//! vertices, the coarser neighbour's triangles, and the moved vertices to the surface along
//! the edge); where that exceeds the tolerance the coarser neighbour is raised a level,
//! until nothing changes (levels only rise, so this ends).
//!
//! Last, the edges inside plane patches are flipped toward well-shaped triangles
//! ([`super::flips`]), which moves the surface by at most [`FLIP_SHARE`] of the tolerance,
//! kept free when the levels are chosen.

use glam::DVec3;

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

/// Memory [`subdivide_to_tolerance`] takes per triangle of level `max_level`, the finest it
/// can show: the connectivity of levels 0 to `max_level` (about 68 bytes per triangle of a
/// level, so 90 for all of them), the positions of level `max_level + 1` and their limit
/// positions (two vertices per triangle of `max_level`, 24 bytes each: 96), and the
/// positions of level `max_level`, their limit normals and the gap-filled copy the extraction
/// makes (half a vertex per triangle each: 36). The output is a fraction of a uniform
/// level's. A decoder charges this before refining, as it charges
/// [`super::MEMORY_PER_TRIANGLE`] for a uniform level.
pub const MEMORY_PER_TRIANGLE: u64 = 220;

/// Subdivides `mesh` so that every base triangle is shown at the coarsest level (at most
/// `opts.max_level`) whose output is within the tolerance of the limit surface (the rule is
/// the module's documentation), crack-free, at limit positions.
pub fn subdivide_to_tolerance(
    mesh: &ControlMesh,
    opts: &AccuracyOptions,
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
    // Level n + 1 is only evaluated (positions and limit positions), never triangulated.
    let r = Refinement::with_max_faces(mesh, n + 1, opts.max_faces.saturating_mul(4))?;
    let (mut fine, mut at_n) = (Vec::new(), Vec::new());
    r.positions_into(&mesh.positions, n + 1, &mut fine, &mut at_n)?;
    // `positions_into` leaves level n in its scratch buffer, except for level 0, which it
    // reads from the control points.
    if n == 0 {
        at_n = mesh.positions.clone();
    }
    let limit = r.limit_positions(&fine, n + 1)?;
    drop(fine);
    let tolerance = resolve_tolerance(&limit, opts)?;
    let plan = match opts.boundary_patches {
        BoundaryPatchOutput::Sparse => SparsePlan::new(r.full(0), &r.base),
        BoundaryPatchOutput::Dense => None,
    };
    let m = Measure {
        r: &r,
        limit: &limit,
        fine: n + 1,
        plan: plan.as_ref(),
        floor: tolerance * 1e-6,
    };
    // The flips of plane patches afterwards may move the surface by a small share of the
    // tolerance: the levels are chosen for the rest.
    let (levels, bound) = m.choose_levels(tolerance * (1.0 - FLIP_SHARE));
    let normals = if opts.normals {
        Some(r.limit_normals(&at_n, n)?)
    } else {
        None
    };
    drop(at_n);
    let nv_n = r.level(n).vertex_count();
    let (out, remap) = lod::extract_at(
        &r,
        n,
        &limit[..nv_n],
        normals.as_deref(),
        &levels,
        opts.boundary_patches,
    )?;
    let mut mesh_out = out.to_control_mesh(&mesh.groups);
    mesh_out.sharp_edges = m.sharp_edges(&levels, n, &remap);
    mesh_out.corners = mesh
        .corners
        .iter()
        .filter_map(|&c| remap.get(c as usize).copied().filter(|&x| x != u32::MAX))
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

/// What the measurement reads: the refinement (built to level `fine`) and the limit
/// positions of the level-`fine` vertices.
struct Measure<'a> {
    r: &'a Refinement,
    limit: &'a [DVec3],
    fine: u32,
    plan: Option<&'a SparsePlan>,
    /// Distances below this are not told apart (a millionth of the tolerance): a flat
    /// face's points lie on its triangles up to rounding, and measuring each of them to the
    /// triangles around would cost a flat face as much as a curved one.
    floor: f64,
}

impl Measure<'_> {
    fn l0(&self) -> &Level {
        self.r.full(0)
    }

    /// Per base triangle the coarsest level within `tolerance` (belt quads at the finer of
    /// their two), then raised where gap filling takes a finer neighbour beyond it; and the
    /// largest estimated error of the output.
    fn choose_levels(&self, tolerance: f64) -> (Vec<u8>, f64) {
        let nf = self.l0().nf();
        let edge_errors = self.edge_errors();
        let mut errors = vec![FaceErrors::default(); nf];
        par::for_each_heavy(&mut errors, |k, e| {
            *e = self.face_errors(k, &edge_errors, tolerance);
        });
        let mut levels: Vec<u8> = errors.iter().map(|e| e.first_within(tolerance)).collect();
        self.pair_belts(&mut levels);
        let bound = self.settle_gap_filling(&mut levels, &edge_errors, &mut errors, tolerance);
        (levels, bound)
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
                let [a, b] = l0.edge_faces[e as usize];
                let o = if a as usize == k { b } else { a };
                (o != NONE).then_some(o as usize)
            })
    }

    /// Raises the coarser neighbours of every base triangle that gap filling takes beyond
    /// the tolerance (or beyond its own bound, where not even level n meets the tolerance)
    /// until none is, and returns the largest bound of the output. Levels only rise and are
    /// at most n, so this ends; each round checks only the triangles next to a raised one.
    fn settle_gap_filling(
        &self,
        levels: &mut [u8],
        edge_errors: &[f64],
        errors: &mut [FaceErrors],
        tolerance: f64,
    ) -> f64 {
        let nf = levels.len();
        let top = (self.fine - 1) as u8;
        let mut bounds = vec![0.0f64; nf];
        let mut check: Vec<usize> = (0..nf).collect();
        let partner = |f: usize| match self.plan.map_or(DENSE, |p| p.unit[f]) {
            DENSE => f,
            u => u as usize,
        };
        while !check.is_empty() {
            self.measure_missing(&check, levels, errors);
            let mut shown = vec![0.0f64; check.len()];
            {
                let (lv, errs): (&[u8], &[FaceErrors]) = (levels, errors);
                par::for_each_heavy(&mut shown, |i, out| {
                    let k = check[i];
                    *out = self.shown_error(k, lv, edge_errors, &errs[k]) + errs[k].tail;
                });
            }
            let mut raise = Vec::new();
            for (&k, &b) in check.iter().zip(&shown) {
                let own = errors[k].bound(levels[k]);
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

    /// Measures the base triangles of `faces` at their `levels` where that is not measured
    /// yet (levels above the first one within the tolerance are measured when a triangle is
    /// raised to them).
    fn measure_missing(&self, faces: &[usize], levels: &[u8], errors: &mut [FaceErrors]) {
        let missing: Vec<usize> = faces
            .iter()
            .copied()
            .filter(|&k| errors[k].error[levels[k] as usize].is_nan())
            .collect();
        let mut values = vec![0.0f64; missing.len()];
        par::for_each_heavy(&mut values, |i, v| {
            let k = missing[i];
            *v = self.dense_error(k, u32::from(levels[k]));
        });
        for (&k, v) in missing.iter().zip(values) {
            errors[k].error[levels[k] as usize] = v;
        }
    }

    /// The measured error of base triangle `k` as the output shows it at `levels`: a base
    /// edge next to a coarser triangle shows that triangle's chords, and the vertices of `k`
    /// on it are moved onto them (gap filling).
    fn shown_error(&self, k: usize, levels: &[u8], edge_errors: &[f64], own: &FaceErrors) -> f64 {
        let m = levels[k];
        let l0 = self.l0();
        let per = self.fine as usize;
        let unit = self.plan.map_or(DENSE, |p| p.unit[k]);
        if unit != DENSE {
            // A sparse face shows every split edge at the coarser of its two sides' chords.
            let mut err = 0.0f64;
            let faces = if unit as usize == k {
                [k, k]
            } else {
                [k, unit as usize]
            };
            for f in faces {
                for &be in &l0.face_edges[3 * f..3 * f + 3] {
                    let be = be as usize;
                    let [a, b] = l0.edge_faces[be];
                    let o = if a as usize == f { b } else { a };
                    let shown = if o == NONE {
                        m
                    } else {
                        m.min(levels[o as usize])
                    };
                    if let Some(ee) = edge_errors.get(be * per..(be + 1) * per) {
                        err = err.max(ee[shown as usize]);
                    }
                    if shown < m {
                        err = err.max(self.chord_to_surface(be, m.into(), shown.into()));
                    }
                }
            }
            return err;
        }
        let mut moved: Vec<(u32, DVec3)> = Vec::new();
        let mut skip = Vec::new();
        for &be in &l0.face_edges[3 * k..3 * k + 3] {
            let be = be as usize;
            let [a, b] = l0.edge_faces[be];
            let o = if a as usize == k { b } else { a };
            if o != NONE && levels[o as usize] < m {
                self.gap_filled(be, m as u32, levels[o as usize] as u32, &mut moved);
                skip.push(be);
            }
        }
        if moved.is_empty() {
            return own.error[m as usize];
        }
        let mut chords = 0.0f64;
        for &be in &skip {
            let [a, b] = l0.edge_faces[be];
            let o = if a as usize == k { b } else { a };
            chords = chords.max(self.chord_to_surface(be, m.into(), levels[o as usize].into()));
        }
        moved.sort_unstable_by_key(|&(v, _)| v);
        let at = |v: u32| match moved.binary_search_by_key(&v, |&(x, _)| x) {
            Ok(i) => moved[i].1,
            Err(_) => self.limit[v as usize],
        };
        let m = m as u32;
        let lm = self.r.full(m);
        let shown = |g: usize| {
            let base = g >> (2 * m);
            let lo = u32::from(levels[base]);
            let (l, g) = if base == k || lo >= m {
                (lm, g)
            } else {
                (self.r.full(lo), g >> (2 * (m - lo)))
            };
            let c = &l.faces[3 * g..3 * g + 3];
            if base == k {
                [at(c[0]), at(c[1]), at(c[2])]
            } else {
                [
                    self.limit[c[0] as usize],
                    self.limit[c[1] as usize],
                    self.limit[c[2] as usize],
                ]
            }
        };
        // Moving vertices along the edge slides the triangles next to it along the surface,
        // so a sample is measured to the nearest of the triangles shown around its own (the
        // coarser neighbour's across the edge).
        self.max_nearest(k, m, &skip, &shown, f64::INFINITY)
            .max(chords)
            .max(self.output_error(k, m, &shown, f64::INFINITY))
    }

    /// The largest distance from the vertices gap filling moves onto the coarser side's
    /// chords of base edge `e` (shown at `fine` and `coarse`) to the limit surface next to
    /// the edge. The samples on either side are measured to the output, not the output to
    /// them, and a chord can leave the surface where neither side's samples see it: on a
    /// curved face an edge whose limit curve bends sideways within the surface has its
    /// chord inside the solid. The surface next to the edge is the level-`fine` strip of
    /// triangles along it, with their corners at their limit positions; a nearest point
    /// beyond the strip only makes the distance larger.
    fn chord_to_surface(&self, e: usize, fine: u32, coarse: u32) -> f64 {
        let mut moved = Vec::new();
        self.gap_filled(e, fine, coarse, &mut moved);
        let last = self.r.full(self.fine - 1);
        let span = 1usize << (self.fine - 1);
        let mut strip = Vec::with_capacity(8 * span);
        for d in e * span..(e + 1) * span {
            for f in last.edge_faces[d] {
                if f == NONE {
                    continue;
                }
                let c = super::next_level::child_faces(last, f as usize);
                strip.extend(c.chunks_exact(3).map(|t| {
                    [
                        self.limit[t[0] as usize],
                        self.limit[t[1] as usize],
                        self.limit[t[2] as usize],
                    ]
                }));
            }
        }
        let mut err = 0.0f64;
        for (_, q) in moved {
            err = err.max(nearest(q, &strip, err).sqrt());
        }
        err
    }

    /// The largest distance from the limit samples inside base triangle `k` (but those on
    /// the base edges `skip`) to the nearest of the triangles around the level-`m` face
    /// holding each (its own and those around its corners in the same CAD face, as `tri`
    /// gives them); stops as soon as it exceeds `stop_above`. Distances below
    /// `self.floor` are not told apart.
    ///
    /// Every sample's distance to its own triangle is an upper bound on its distance; only
    /// samples whose own distance exceeds the largest distance found so far can raise it,
    /// and they are few once the sample with the largest own distance sets it, so a first
    /// pass over a coarser grid of samples finds such a sample and a second measures it
    /// first and then only those to the triangles around. The samples are visited, not stored: a base triangle at a deep
    /// level has millions.
    fn max_nearest(
        &self,
        k: usize,
        m: u32,
        skip: &[usize],
        tri: &impl Fn(usize) -> [DVec3; 3],
        stop_above: f64,
    ) -> f64 {
        let lm = self.r.full(m);
        let q = 1usize << (2 * m);
        // The largest distance to its own triangle among the samples two levels down: the
        // error varies smoothly, so that sample sets a threshold near the final one.
        let mut first = (0.0f64, DVec3::ZERO, u32::MAX);
        let upto = (m + 2).min(self.fine);
        for f in k * q..(k + 1) * q {
            let t = tri(f);
            self.for_samples(m, f, skip, upto, &mut |p| {
                let own = point_triangle_distance_squared(p, &t);
                if own > first.0 {
                    first = (own, p, f as u32);
                }
            });
        }
        let group = self.r.base.group[k];
        let (mut around, mut tris) = (Vec::new(), Vec::new());
        let mut ring_of = u32::MAX;
        let mut err2 = self.floor * self.floor;
        let mut measure = |p: DVec3, f: u32, own: f64, err2: &mut f64| {
            if own <= *err2 {
                return;
            }
            if ring_of != f {
                faces_around(lm, f as usize, &mut around);
                tris.clear();
                tris.push(tri(f as usize));
                // Only within the CAD face: across a crease the neighbour is another surface,
                // and a sample near it is no nearer the output of its own.
                tris.extend(
                    around
                        .iter()
                        .filter(|&&g| self.r.base.group[g as usize >> (2 * m)] == group)
                        .map(|&g| tri(g as usize)),
                );
                ring_of = f;
            }
            *err2 = err2.max(nearest(p, &tris, err2.sqrt()));
        };
        if first.2 != u32::MAX {
            measure(first.1, first.2, first.0, &mut err2);
        }
        for f in k * q..(k + 1) * q {
            if err2 > stop_above * stop_above {
                break;
            }
            let t = tri(f);
            self.for_samples(m, f, skip, self.fine, &mut |p| {
                let own = point_triangle_distance_squared(p, &t);
                measure(p, f as u32, own, &mut err2);
            });
        }
        err2.sqrt()
    }

    /// Calls `visit` with the limit samples of the vertices that levels m+1..=upto add inside
    /// face `f` of level `m` and on its edges, but those on the base edges `skip`: each once
    /// (the edges' shared with the neighbouring face too), by the nested numbering (the
    /// descendants of a level-j edge e at level t are `[e 2^(t-j), (e+1) 2^(t-j))`, and face
    /// g of level i has the interior edges `2 ne_i + 3g + s` at level i+1).
    fn for_samples(
        &self,
        m: u32,
        f: usize,
        skip: &[usize],
        upto: u32,
        visit: &mut impl FnMut(DVec3),
    ) {
        let lm = self.r.full(m);
        let on_base = self.l0().ne() << m;
        for &e in &lm.face_edges[3 * f..3 * f + 3] {
            let e = e as usize;
            if !(e < on_base && skip.contains(&(e >> m))) {
                self.edge_samples(m, e, upto, visit);
            }
        }
        for i in m..upto.saturating_sub(1) {
            let li = self.r.full(i);
            let span = 1usize << (2 * (i - m));
            for g in f * span..(f + 1) * span {
                for s in 0..3 {
                    self.edge_samples(i + 1, 2 * li.ne() + 3 * g + s, upto, visit);
                }
            }
        }
    }

    /// Calls `visit` with the limit samples of the vertices that levels j+1..=upto add on
    /// edge `e` of level `j`.
    fn edge_samples(&self, j: u32, e: usize, upto: u32, visit: &mut impl FnMut(DVec3)) {
        for t in j..upto {
            let nv = self.r.full(t).nv;
            let d0 = e << (t - j);
            for &p in &self.limit[nv + d0..nv + d0 + (1 << (t - j))] {
                visit(p);
            }
        }
    }

    /// Appends the vertices that gap filling moves on base edge `e` shown at level `fine`
    /// on one side and `coarse` on the other, with their moved positions (the spec's
    /// `(1 - t) x_j0 + t x_j0+s`, the same arithmetic as the extraction).
    fn gap_filled(&self, e: usize, fine: u32, coarse: u32, out: &mut Vec<(u32, DVec3)>) {
        let l0 = self.l0();
        let level_nv: Vec<usize> = (0..fine).map(|j| self.r.full(j).nv).collect();
        let s = 1usize << (fine - coarse);
        let x = |j: usize| lod::edge_vertex(l0, &level_nv, fine, e, j);
        for j in 1..1usize << fine {
            if j % s != 0 {
                let j0 = j / s * s;
                let t = (j - j0) as f64 / s as f64;
                let (a, b) = (self.limit[x(j0) as usize], self.limit[x(j0 + s) as usize]);
                out.push((x(j), a * (1.0 - t) + b * t));
            }
        }
    }

    /// Per base edge that sparse output uses as a chain (split edges of sparse faces): the
    /// error of its level-m chain for m = 0..fine (`fine` entries per edge; zeros for other
    /// edges).
    fn edge_errors(&self) -> Vec<f64> {
        let per = self.fine as usize;
        let Some(plan) = self.plan else {
            return Vec::new();
        };
        let l0 = self.l0();
        let level_nv: Vec<usize> = (0..self.fine).map(|j| self.r.full(j).nv).collect();
        let mut out = vec![0.0; l0.ne() * per];
        par::for_each_chunk_mut(&mut out, per, |e, errs| {
            let [fl, fr] = l0.edge_faces[e];
            let sparse = |f: u32| f != NONE && plan.unit[f as usize] != DENSE;
            if !plan.split[e] || !(sparse(fl) || sparse(fr)) {
                return;
            }
            let mut chain = Vec::new();
            base_edge_chain(l0, &level_nv, self.fine, e, &mut chain);
            for (m, err) in errs.iter_mut().enumerate() {
                *err = chain_error(&chain, self.limit, self.fine - m as u32);
            }
        });
        out
    }

    /// The measurements of base triangle `k`: a sparse face's at every level (its chains'
    /// errors, measured once per edge); a dense face's from the surface to the output at its
    /// two finest levels (its tail: the ratio of the two), and both ways from level 0 up to
    /// the first within `tolerance`, the levels that fail stopping at their first sample
    /// beyond it (the others are measured if the face is raised to them).
    fn face_errors(&self, k: usize, edge_errors: &[f64], tolerance: f64) -> FaceErrors {
        let per = self.fine as usize;
        let n = per - 1;
        let mut out = FaceErrors::default();
        let unit = self.plan.map_or(DENSE, |p| p.unit[k]);
        if unit != DENSE {
            let e = &mut out.error[..per];
            let l0 = self.l0();
            e.fill(0.0);
            let faces = if unit as usize == k {
                [k, k]
            } else {
                [k, unit as usize]
            };
            for f in faces {
                for &be in &l0.face_edges[3 * f..3 * f + 3] {
                    let be = be as usize;
                    if let Some(ee) = edge_errors.get(be * per..(be + 1) * per) {
                        for (x, &y) in e.iter_mut().zip(ee) {
                            *x = x.max(y);
                        }
                    }
                }
            }
            out.tail = tail_beyond_samples(&out.error[..per]);
            return out;
        }
        let mut to_output = [f64::NAN; super::MAX_LEVEL as usize];
        let finest = n.saturating_sub(1)..=n;
        for m in finest.clone() {
            to_output[m] = self.surface_to_output(k, m as u32, f64::INFINITY);
        }
        out.tail = tail_beyond_samples(&to_output[..per]);
        let within = tolerance - out.tail;
        for (m, &known) in to_output.iter().enumerate().take(per) {
            let mut x = known;
            if !finest.contains(&m) {
                x = self.surface_to_output(k, m as u32, within);
            }
            if x <= within {
                x = x.max(self.output_to_surface(k, m as u32, within));
            }
            out.error[m] = x;
            if x <= within {
                break;
            }
        }
        out
    }

    /// The error of showing base triangle `k` at level `m`: both ways, [`Self::surface_to_output`]
    /// and [`Self::output_to_surface`].
    fn dense_error(&self, k: usize, m: u32) -> f64 {
        self.surface_to_output(k, m, f64::INFINITY)
            .max(self.output_to_surface(k, m, f64::INFINITY))
    }

    /// Triangle `f` of level `m`, corners at their limit positions.
    fn level_triangle(&self, m: u32, f: usize) -> [DVec3; 3] {
        let c = &self.r.full(m).faces[3 * f..3 * f + 3];
        [
            self.limit[c[0] as usize],
            self.limit[c[1] as usize],
            self.limit[c[2] as usize],
        ]
    }

    /// The largest distance from a level-`fine` limit sample inside base triangle `k` to the
    /// level-`m` surface near it: the level-`m` triangle holding the sample (corners at their
    /// limit positions) and, when that is further, the triangles around its corners. The
    /// samples of a triangle are parametrically inside it but may lie beyond its edges along
    /// the surface (the limit parametrisation is not the triangles' own); that sliding is no
    /// distance from the output, which continues in the neighbouring triangles.
    ///
    /// Stops as soon as the error exceeds `stop_above` (a level that fails needs no more).
    fn surface_to_output(&self, k: usize, m: u32, stop_above: f64) -> f64 {
        if m >= self.fine {
            return 0.0;
        }
        self.max_nearest(k, m, &[], &|f| self.level_triangle(m, f), stop_above)
    }

    /// [`Self::output_error`] of the level-`m` triangles of base triangle `k`.
    fn output_to_surface(&self, k: usize, m: u32, stop_above: f64) -> f64 {
        if m >= self.fine {
            return 0.0;
        }
        self.output_error(k, m, &|f| self.level_triangle(m, f), stop_above)
    }

    /// The other direction: the largest distance from the output to the limit surface,
    /// measured at the points of the level-`m` triangles of base triangle `k` (as `tri`
    /// gives them) that lie over their edges' midpoints and the level-(m+2) vertices inside
    /// them, each to the
    /// limit surface around that vertex (the level-`fine` triangles of the level-(fine-1)
    /// faces at it, corners at their limit positions; a nearest point beyond them only makes
    /// the distance larger). Samples near the output do not make the output near them: a
    /// triangle whose samples all lie nearer its neighbours can stand off the surface.
    fn output_error(
        &self,
        k: usize,
        m: u32,
        tri: &impl Fn(usize) -> [DVec3; 3],
        stop_above: f64,
    ) -> f64 {
        let q = 1usize << (2 * m);
        let depth = (self.fine - m).min(2);
        let (mut points, mut around, mut near) = (Vec::new(), Vec::new(), Vec::new());
        let mut err2 = self.floor * self.floor;
        for f in k * q..(k + 1) * q {
            let t = tri(f);
            points.clear();
            self.points_over(m, f, depth, &mut points);
            for &(x, b) in &points {
                let p = t[0] * b[0] + t[1] * b[1] + t[2] * b[2];
                // The limit point of the vertex is on the surface: an upper bound at once.
                if (p - self.limit[x as usize]).length_squared() <= err2 {
                    continue;
                }
                self.surface_around(x, &mut around, &mut near);
                err2 = err2.max(nearest(p, &near, err2.sqrt()));
                if err2 > stop_above * stop_above {
                    return err2.sqrt();
                }
            }
        }
        err2.sqrt()
    }

    /// Points of face `f` of level `m` with their barycentric coordinates in it: the level-m+1
    /// vertices (its edges' midpoints) and, with `depth` 2, the level-m+2 vertices inside it
    /// (midpoints in the parameter domain, by the children layout of
    /// [`super::next_level::child_faces`]).
    fn points_over(&self, m: u32, f: usize, depth: u32, out: &mut Vec<(u32, [f64; 3])>) {
        let lm = self.r.full(m);
        let e = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mid = |a: [f64; 3], b: [f64; 3]| {
            [
                (a[0] + b[0]) / 2.0,
                (a[1] + b[1]) / 2.0,
                (a[2] + b[2]) / 2.0,
            ]
        };
        let fe = &lm.face_edges[3 * f..3 * f + 3];
        let mids = [mid(e[0], e[1]), mid(e[1], e[2]), mid(e[2], e[0])];
        for s in 0..3 {
            out.push((lm.nv as u32 + fe[s], mids[s]));
        }
        if depth < 2 {
            return;
        }
        // The middle child (`child_faces` order: the three corner children, then the middle
        // one, m0 m1 m2): the midpoints of its edges are the level-(m+2) vertices inside the
        // face, the others lie on its edges between the points above and its corners.
        let l1 = self.r.full(m + 1);
        let g = 4 * f + 3;
        let fe = &l1.face_edges[3 * g..3 * g + 3];
        for s in 0..3 {
            out.push((l1.nv as u32 + fe[s], mid(mids[s], mids[(s + 1) % 3])));
        }
    }

    /// Into `near`: the level-`fine` triangles (corners at their limit positions) of the
    /// level-(fine-1) faces at vertex `x` (a vertex of any level up to `fine`).
    fn surface_around(&self, x: u32, faces: &mut Vec<u32>, near: &mut Vec<[DVec3; 3]>) {
        let last = self.r.full(self.fine - 1);
        faces.clear();
        if (x as usize) < last.nv {
            for &e in last.ring(x as usize) {
                faces.extend(last.edge_faces[e as usize].iter().filter(|&&g| g != NONE));
            }
            faces.sort_unstable();
            faces.dedup();
        } else {
            let d = x as usize - last.nv;
            faces.extend(last.edge_faces[d].iter().filter(|&&g| g != NONE));
        }
        near.clear();
        for &g in faces.iter() {
            let c = super::next_level::child_faces(last, g as usize);
            near.extend(c.chunks_exact(3).map(|t| {
                [
                    self.limit[t[0] as usize],
                    self.limit[t[1] as usize],
                    self.limit[t[2] as usize],
                ]
            }));
        }
    }

    /// The sharp edges of the output: along every sharp base edge, the chain of the finer of
    /// its two faces' levels (the coarser side is fanned through it), through `remap`.
    fn sharp_edges(
        &self,
        levels: &[u8],
        top: u32,
        remap: &[u32],
    ) -> std::collections::BTreeSet<(u32, u32)> {
        let l0 = self.l0();
        let level_nv: Vec<usize> = (0..top).map(|j| self.r.full(j).nv).collect();
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
                    .get(lod::edge_vertex(l0, &level_nv, top, e, j) as usize)
                    .copied()
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

/// The measurements of one base triangle.
#[derive(Clone, Copy, Debug)]
struct FaceErrors {
    /// Measured error at each level shown (`0..=n`); NaN where not measured, a lower bound
    /// where the measurement stopped beyond the tolerance.
    error: [f64; super::MAX_LEVEL as usize],
    /// How far beyond the samples the limit surface may stray (see
    /// [`tail_beyond_samples`]).
    tail: f64,
}

impl Default for FaceErrors {
    fn default() -> Self {
        FaceErrors {
            error: [f64::NAN; super::MAX_LEVEL as usize],
            tail: 0.0,
        }
    }
}

impl FaceErrors {
    /// The estimated error of showing the triangle at level `m`.
    fn bound(&self, m: u8) -> f64 {
        self.error[m as usize] + self.tail
    }

    /// The first level measured within `tolerance`, else the finest measured.
    fn first_within(&self, tolerance: f64) -> u8 {
        let measured = self.error.iter().rposition(|e| !e.is_nan()).unwrap_or(0);
        let m = (0..=measured).find(|&m| self.bound(m as u8) <= tolerance);
        m.unwrap_or(measured) as u8
    }
}

/// How far the limit surface may stray from the mesh through the level-`n + 1` samples,
/// from the measured errors of levels `0..=n` (see the module documentation).
fn tail_beyond_samples(e: &[f64]) -> f64 {
    let n = e.len() - 1;
    let last = e[n];
    let rho = if n == 0 || e[n - 1].is_nan() || e[n - 1] <= 0.0 {
        0.25
    } else {
        (last / e[n - 1]).clamp(0.25, 0.5)
    };
    last * rho / (1.0 - rho)
}

/// The squared distance from `p` to the nearest of `tris`, or any value at most `below²`
/// once one is that near (the caller only needs to know it is no further).
fn nearest(p: DVec3, tris: &[[DVec3; 3]], below: f64) -> f64 {
    let mut best = f64::INFINITY;
    for t in tris {
        best = best.min(point_triangle_distance_squared(p, t));
        if best <= below * below {
            break;
        }
    }
    best
}

/// The faces of level `l` around the corners of face `f` (other than `f`), into `out`.
fn faces_around(l: &Level, f: usize, out: &mut Vec<u32>) {
    out.clear();
    for &v in &l.faces[3 * f..3 * f + 3] {
        for &e in l.ring(v as usize) {
            for g in l.edge_faces[e as usize] {
                if g != NONE && g as usize != f {
                    out.push(g);
                }
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
fn chain_error(chain: &[u32], limit: &[DVec3], shift: u32) -> f64 {
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
