//! The fitting encoder: from a face-grouped triangle mesh (a tessellated B-rep) to a coarse
//! control mesh whose subdivision surface stays within a tolerance of the input.
//!
//! Pipeline (each step is deterministic):
//! 1. **Faces.** Use the input's groups (one per CAD face) with their surface types when the
//!    caller knows them, classify the rest by least-squares primitive fits; an ungrouped mesh
//!    is segmented first ([`super::segment`]).
//! 2. **Curve network.** Corners and boundary chains between them ([`super::curves`]).
//! 3. **Control points on chains.** Each chain keeps a few of its vertices (Douglas-Peucker
//!    within the chain's tolerance; on cylinders and cones at most 60 degrees apart about the
//!    axis). Both adjacent faces share them.
//! 4. **Topology.** One constrained decimation of the whole mesh ([`super::decimate`]): chain
//!    vertices that are not control points slide away along their chain, boundary patches
//!    (planes, cylinders, cones) lose every interior vertex, closed patches are simplified
//!    while their quadric error allows. Sharp edges are the group boundaries, corners the
//!    B-rep vertices: watertight by construction.
//! 5. **Geometry.** Control points are fitted so the *limit* surface computed by
//!    [`crate::subdiv`] (the decoder's own rules) matches the input: first the Cartesian
//!    crease curves against their chain polylines, then the interiors of closed patches
//!    against their faces, by linearised least squares with re-projected targets (moved on
//!    to the faces' exact surfaces where the input knows them: a STEP face's facets and
//!    edge polylines sag from the CAD surface, which the error is measured against). Curves on
//!    cylinders and cones keep their on-surface positions: the decoder's cylindrical rule
//!    keeps them exactly on the surface.
//! 6. **Error control.** The caller's `reconstruct` callback quantises the control mesh the
//!    way the bitstream will; the decoded surface at the default level is measured against
//!    the input both ways ([`crate::metrics`]). Faces and chains that exceed the tolerance get
//!    more control points and the model is rebuilt, until the tolerance holds. Then closed
//!    patches that ended far within it are coarsened again once ([`Relaxation`]), and the
//!    smaller file of the two models, each at the coarsest quantisation that still holds the
//!    tolerance, is kept.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::DVec3;

use super::allowance::{add_analytic_surface_allowance, OwnFaces};
use super::curves::{build_curve_network, CurveNetwork, CurveOptions};
use super::decimate::{decimate, DecimateInput, GroupRule, SurfaceRef, VertexRole};
use super::domain::PlaneDomain;
use super::exact::onto_all;
pub use super::exact::ExactSurface;
use super::measure::ErrorMeter;
use super::primitives::{fit_cone, fit_cylinder, fit_plane, Primitive};
use super::segment::{segment, SegmentOptions};
use crate::error::{Error, Result};
use crate::mesh::{edge_key, Axis, BoundarySurface, ControlMesh, PatchKind};
use crate::metrics::TriangleSurface;
use crate::subdiv::Refinement;

/// What the input says a group's surface is (a STEP face type or a sidecar entry).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SurfaceHint {
    Plane,
    Cylinder,
    Cone,
    /// Sphere, torus, B-spline, revolution, ...: a closed patch.
    Freeform,
    /// Unknown: classify from the geometry.
    Unknown,
}

/// Options of [`fit_model`].
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    /// Largest allowed distance between input and decoded surface, model units; default
    /// `1e-3` of the bounding-box diagonal.
    pub tolerance: Option<f64>,
    /// Largest allowed mean distance (the larger of the two directions' means), model units;
    /// `None`: unbounded. The fit's rounds are driven by `tolerance`; this bound keeps the
    /// quantisation search from trading mean error for bytes (at a loose `tolerance` a
    /// coarser grid step can keep the max within it while the mean grows). A fit whose mean
    /// is over it even at the default step is reported out of tolerance.
    pub mean_tolerance: Option<f64>,
    /// Decode level the tolerance is checked at; default: 4, raised to 5 when that is what
    /// it takes.
    pub default_level: Option<u8>,
    /// Segmentation of ungrouped meshes: dihedral angle of sharp edges.
    pub sharp_angle_deg: f64,
    /// Rebuild rounds with more control points before giving up on the tolerance.
    pub max_rounds: usize,
    /// Surface samples per direction for the error measurement.
    pub error_samples: usize,
    /// After the fit, try up to this many bits coarser quantisation than the default, and keep
    /// the coarsest that still meets the tolerance (0: keep the default); then (with
    /// `quarter_bit_steps`) up to 3/4 bit more in quarter bits, each kept only if it also
    /// makes the file smaller and keeps the RMS error within a quarter of the tolerance (a
    /// fractional step trades RMS error for bytes, and the RMS bound keeps the surface as
    /// close to the reference on average as the whole-bit steps do).
    pub max_coarser_bits: u8,
    /// Whether the quantisation search goes on in quarter bits after whole bits (see
    /// `max_coarser_bits`): two more measurements for a few percent on most models.
    pub quarter_bit_steps: bool,
    /// Refine a failing closed patch only near where it fails (its decimation threshold
    /// lowered within two control edges of the samples out of tolerance) instead of
    /// everywhere. That is all it changes: a fit without failing closed patches is the same
    /// either way. Off by default: it makes smaller files on some models and larger ones on
    /// others; `Effort::Max` tries both.
    pub local_refinement: bool,
    /// Plane patches keep the control points their faces need: the decimation refuses a
    /// collapse that would make an interior edge leave the face (across a hole or a concave
    /// notch; a plane's interior edges decode straight), and a failing group refines only the
    /// boundary chains near where it fails, not all of them: fewer control points on plates
    /// with many holes. On by default, for face groups from the input; a segmented mesh's
    /// planes are decimated freely (its regions' outlines are the segmenter's guesses, and
    /// keeping them costs control points for no gain in accuracy). `Effort::Max` tries both.
    pub keep_planes_on_faces: bool,
    /// Once the model is within tolerance, coarsen the refined closed patches that ended far
    /// within it by half a refinement step, restore those that then fail, and keep whichever
    /// model (converged or relaxed, each at its coarsest quantisation) makes the smaller file
    /// (see `Relaxation`). Costs one or two more rounds.
    pub relax: bool,
    /// By input group: the face's exact surface where the input knows it (a STEP face's
    /// plane, cylinder, cone, sphere or torus), else `None`; empty for none at all. The
    /// decoded surface of a group is then held within the tolerance of that surface too,
    /// not only of its facets (see [`ExactSurface`]), and a closed patch is fitted onto it
    /// (as are creases whose faces all have one).
    pub exact_surfaces: Vec<Option<ExactSurface>>,
    /// A finer tessellation of the same faces (the same groups, by name, in the same order)
    /// to measure the decoded surface against instead of the input; the fit still starts
    /// from and fits to the input's triangles. `None`: measured against the input.
    pub reference: Option<ControlMesh>,
}

/// When a round's worst excess stays above this fraction of the previous round's, adding
/// control points has stopped paying and the fit moves to decode level 5 (once). A lower
/// ratio moves models to level 5 that level 4 fits as well, at four times the triangles to
/// measure.
const STALL_RATIO: f64 = 0.85;

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            tolerance: None,
            mean_tolerance: None,
            default_level: None,
            sharp_angle_deg: 30.0,
            max_rounds: 8,
            error_samples: 60_000,
            max_coarser_bits: 3,
            quarter_bit_steps: true,
            local_refinement: false,
            keep_planes_on_faces: true,
            relax: true,
            exact_surfaces: Vec::new(),
            reference: None,
        }
    }
}

/// Measured distances between the input and the decoded surface (model units).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FitError {
    pub max: f64,
    pub rms: f64,
    pub mean: f64,
    /// Largest distance beyond the input's own chord error (see [`chord_allowance`]): the
    /// quantity the tolerance bounds.
    pub max_beyond_chord: f64,
}

/// What the encoder did, for `--verbose` and the report.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FitReport {
    pub tolerance: f64,
    /// [`FitOptions::mean_tolerance`], model units.
    pub mean_tolerance: Option<f64>,
    pub diagonal: f64,
    /// The input had no groups and was segmented.
    pub segmented: bool,
    /// Patch kinds of the output groups ("closed", "plane", "cylinder", "cone").
    pub patch_kinds: BTreeMap<&'static str, usize>,
    pub control_vertices: usize,
    pub control_faces: usize,
    pub rounds: usize,
    pub default_level: u8,
    /// Error of the decoded surface (quantised, default level, limit positions).
    pub error: FitError,
    pub within_tolerance: bool,
    /// How many times a failing closed patch was refined (over all rounds and groups). When
    /// it is 0, [`FitOptions::local_refinement`] would not have changed the fit.
    pub closed_refinements: usize,
    /// Stage name and seconds.
    pub timings: Vec<(&'static str, f64)>,
    pub notes: Vec<String>,
}

/// The result of [`fit_model`].
pub struct FitOutcome {
    /// The control mesh to store (before quantisation).
    pub control: ControlMesh,
    /// How many quarter bits coarser than the caller's default quantisation still meets
    /// the tolerance (the `reconstruct` argument that was measured last within it): the grid
    /// step is the default's times `2^(coarser_quarter_bits / 4)`.
    pub coarser_quarter_bits: u8,
    pub default_level: u8,
    pub report: FitReport,
}

/// Per-group state that the rounds refine.
#[derive(Clone, Copy, Debug)]
struct GroupPlan {
    kind: PatchKind,
    /// Closed patches: decimation threshold as a multiple of the tolerance.
    cost_factor: f64,
    failures: u32,
}

/// The chain's frame: cylinder/cone axis of the lowest-index framed group next to it.
fn chain_frame(chain_groups: &[u32], plans: &[GroupPlan]) -> Option<Axis> {
    chain_frame_owner(chain_groups, plans).and_then(|g| match plans[g as usize].kind {
        PatchKind::Boundary(BoundarySurface::Cylinder { axis })
        | PatchKind::Boundary(BoundarySurface::Cone { axis }) => Some(axis),
        _ => None,
    })
}

/// The group whose frame the decoder applies to the chain's crease (the lowest-index
/// cylinder or cone boundary patch next to it), if any.
fn chain_frame_owner(chain_groups: &[u32], plans: &[GroupPlan]) -> Option<u32> {
    chain_groups.iter().copied().find(|&g| {
        matches!(
            plans[g as usize].kind,
            PatchKind::Boundary(BoundarySurface::Cylinder { .. })
                | PatchKind::Boundary(BoundarySurface::Cone { .. })
        )
    })
}

fn kind_name(k: &PatchKind) -> &'static str {
    match k {
        PatchKind::Closed => "closed",
        PatchKind::Boundary(BoundarySurface::Plane) => "plane",
        PatchKind::Boundary(BoundarySurface::Cylinder { .. }) => "cylinder",
        PatchKind::Boundary(BoundarySurface::Cone { .. }) => "cone",
    }
}

/// Area-weighted vertex normals over the faces of one group.
fn group_points_normals(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group: u32,
) -> (Vec<DVec3>, Vec<DVec3>) {
    let mut normal: BTreeMap<u32, DVec3> = BTreeMap::new();
    for (f, t) in tris.iter().enumerate() {
        if mesh.face_groups[f] != group {
            continue;
        }
        let p = t.map(|i| mesh.positions[i as usize]);
        let n = (p[1] - p[0]).cross(p[2] - p[0]);
        for &i in t {
            *normal.entry(i).or_insert(DVec3::ZERO) += n;
        }
    }
    let points = normal.keys().map(|&i| mesh.positions[i as usize]).collect();
    let normals = normal.values().map(|n| n.normalize_or_zero()).collect();
    (points, normals)
}

/// Chooses a group's patch kind from its hint and its geometry: a boundary patch only when
/// the analytic surface fits the group's vertices within a fraction of the tolerance.
fn classify_group(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group: u32,
    hint: SurfaceHint,
    tol: f64,
) -> PatchKind {
    let (points, normals) = group_points_normals(mesh, tris, group);
    if points.len() < 3 {
        return PatchKind::Closed;
    }
    let within = |r: &super::primitives::PrimitiveFit| r.residuals.max <= 0.25 * tol;
    let try_plane = || {
        fit_plane(&points)
            .filter(within)
            .map(|_| PatchKind::Boundary(BoundarySurface::Plane))
    };
    let try_cyl = || {
        fit_cylinder(&points, &normals)
            .filter(within)
            .and_then(|f| match f.primitive {
                Primitive::Cylinder { axis, .. } => {
                    Some(PatchKind::Boundary(BoundarySurface::Cylinder { axis }))
                }
                _ => None,
            })
    };
    let try_cone = || {
        fit_cone(&points, &normals)
            .filter(within)
            .and_then(|f| match f.primitive {
                Primitive::Cone { axis, .. } => {
                    Some(PatchKind::Boundary(BoundarySurface::Cone { axis }))
                }
                _ => None,
            })
    };
    let kind = match hint {
        SurfaceHint::Plane => try_plane(),
        SurfaceHint::Cylinder => try_cyl(),
        SurfaceHint::Cone => try_cone(),
        SurfaceHint::Freeform => None,
        SurfaceHint::Unknown => try_plane().or_else(try_cyl).or_else(try_cone),
    };
    kind.unwrap_or(PatchKind::Closed)
}

/// The input's own cylinder or cone for a group (a STEP face's exact axis and apex), when
/// the group's vertices lie on it within a quarter of the tolerance; `None` otherwise (and
/// for planes, whose exact description adds nothing to the plane fitted to the vertices).
/// Taking it instead of a fitted axis keeps a fit error out of the patch's shape.
fn exact_surface_kind(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group: u32,
    tol: f64,
) -> Option<PatchKind> {
    let kind = mesh.groups.get(group as usize)?.patch;
    let PatchKind::Boundary(surface) = kind else {
        return None;
    };
    let (points, _) = group_points_normals(mesh, tris, group);
    if points.len() < 3 {
        return None;
    }
    let radial = |axis: &crate::mesh::Axis, p: DVec3| {
        let d = p - axis.origin;
        let h = d.dot(axis.direction);
        (h, (d - h * axis.direction).length())
    };
    let fits = match surface {
        BoundarySurface::Plane => false,
        BoundarySurface::Cylinder { axis } => {
            let r: Vec<f64> = points.iter().map(|&p| radial(&axis, p).1).collect();
            let mean = r.iter().sum::<f64>() / r.len() as f64;
            r.iter().all(|x| (x - mean).abs() <= 0.25 * tol)
        }
        BoundarySurface::Cone { axis } => {
            let hr: Vec<(f64, f64)> = points.iter().map(|&p| radial(&axis, p)).collect();
            let (num, den) = hr
                .iter()
                .fold((0.0, 0.0), |a, &(h, r)| (a.0 + r * h, a.1 + h * h));
            let slope = if den > 0.0 { num / den } else { return None };
            let scale = 1.0 / (1.0 + slope * slope).sqrt();
            hr.iter()
                .all(|&(h, r)| ((r - slope * h) * scale).abs() <= 0.25 * tol)
        }
    };
    fits.then_some(kind)
}

/// The surface a group's collapses must keep facing: the analytic one for boundary patches
/// (a plane's normal fitted to the group's vertices), none for closed patches.
fn collapse_surface(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group: u32,
    kind: &PatchKind,
) -> SurfaceRef {
    match *kind {
        PatchKind::Closed => SurfaceRef::Free,
        PatchKind::Boundary(BoundarySurface::Plane) => {
            let (pts, _) = group_points_normals(mesh, tris, group);
            let normal = fit_plane(&pts)
                .and_then(|f| match f.primitive {
                    Primitive::Plane { normal, .. } => Some(normal),
                    _ => None,
                })
                .unwrap_or(DVec3::Z);
            SurfaceRef::Plane { normal }
        }
        PatchKind::Boundary(BoundarySurface::Cylinder { axis }) => SurfaceRef::Cylinder { axis },
        PatchKind::Boundary(BoundarySurface::Cone { axis }) => SurfaceRef::Cone { axis },
    }
}

/// Cylindrical coordinates about an axis: (theta, h, r).
fn cyl_coords(axis: &Axis, p: DVec3) -> (f64, f64, f64) {
    let (e1, e2) = axis.direction.any_orthonormal_pair();
    let d = p - axis.origin;
    let h = d.dot(axis.direction);
    let q = d - axis.direction * h;
    (q.dot(e2).atan2(q.dot(e1)), h, q.length())
}

/// Douglas-Peucker on a polyline given as points; returns kept indices (ends included).
fn douglas_peucker(points: &[DVec3], tol: f64) -> Vec<usize> {
    let n = points.len();
    if n <= 2 {
        return (0..n).collect();
    }
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0usize, n - 1)];
    while let Some((a, b)) = stack.pop() {
        if b <= a + 1 {
            continue;
        }
        let (pa, pb) = (points[a], points[b]);
        let ab = pb - pa;
        let len2 = ab.length_squared();
        let (mut worst, mut at) = (-1.0, a);
        for (i, &p) in points.iter().enumerate().take(b).skip(a + 1) {
            let t = if len2 > 0.0 {
                ((p - pa).dot(ab) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let d = (p - (pa + ab * t)).length();
            if d > worst {
                worst = d;
                at = i;
            }
        }
        if worst > tol {
            keep[at] = true;
            stack.push((a, at));
            stack.push((at, b));
        }
    }
    (0..n).filter(|&i| keep[i]).collect()
}

/// Control points (indices into `chain.vertices`) of one chain.
fn chain_controls(
    points: &[DVec3],
    frame: Option<Axis>,
    tol: f64,
    max_step: f64,
    min_interior: usize,
) -> Vec<usize> {
    let n = points.len();
    let mut keep: Vec<usize> = match frame {
        None => douglas_peucker(points, tol),
        Some(axis) => {
            // Unwrapped cylindrical coordinates, scaled to lengths, then DP in that space,
            // plus at most `max_step` radians between consecutive control points (a plane's
            // straight interior edges leave an arc's end at up to half that angle from its
            // chord, so coarse arcs let plane triangles cut across a hole).
            let mut prev = None;
            let mut unwrapped = 0.0;
            let param: Vec<DVec3> = points
                .iter()
                .map(|&p| {
                    let (th, h, r) = cyl_coords(&axis, p);
                    if let Some(pt) = prev {
                        let mut d: f64 = th - pt;
                        while d > std::f64::consts::PI {
                            d -= std::f64::consts::TAU;
                        }
                        while d <= -std::f64::consts::PI {
                            d += std::f64::consts::TAU;
                        }
                        unwrapped += d;
                    }
                    prev = Some(th);
                    DVec3::new(unwrapped, h, r)
                })
                .collect();
            let rmax = param.iter().map(|q| q.z).fold(0.0, f64::max);
            let scaled: Vec<DVec3> = param
                .iter()
                .map(|q| DVec3::new(q.x * rmax, q.y, q.z))
                .collect();
            let mut k = douglas_peucker(&scaled, tol);
            let mut out = vec![0];
            for w in k.windows(2) {
                let (a, b) = (w[0], w[1]);
                let span = (param[b].x - param[a].x).abs();
                let pieces = (span / max_step).ceil().max(1.0) as usize;
                // Insert evenly spaced (in angle) chain vertices between a and b.
                for s in 1..pieces {
                    let target = param[a].x + (param[b].x - param[a].x) * s as f64 / pieces as f64;
                    let best = (a + 1..b)
                        .min_by(|&i, &j| {
                            (param[i].x - target)
                                .abs()
                                .total_cmp(&(param[j].x - target).abs())
                        })
                        .unwrap_or(a);
                    if best > *out.last().unwrap_or(&0) {
                        out.push(best);
                    }
                }
                out.push(b);
            }
            k = out;
            k.dedup();
            k
        }
    };
    // Short loops need interior points or the decimation would collapse them to a digon.
    let interior = keep.len().saturating_sub(2);
    if interior < min_interior && n > 2 {
        let want = min_interior.min(n - 2);
        keep = (0..want + 2).map(|i| i * (n - 1) / (want + 1)).collect();
        keep.dedup();
    }
    keep
}

/// Closest point to `p` on a polyline.
fn closest_on_polyline(p: DVec3, line: &[DVec3]) -> DVec3 {
    let mut best = (f64::INFINITY, line[0]);
    for w in line.windows(2) {
        let ab = w[1] - w[0];
        let len2 = ab.length_squared();
        let t = if len2 > 0.0 {
            ((p - w[0]).dot(ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let q = w[0] + ab * t;
        let d = (p - q).length_squared();
        if d < best.0 {
            best = (d, q);
        }
    }
    best.1
}

/// Linearised least squares: find `delta` for the `unknowns` (control ids) minimising
/// `sum_r |sum_k w_rk delta_k - residual_r|^2 + mu |delta|^2`, by conjugate gradients on the
/// normal equations (three right-hand sides, one matrix, Jacobi-preconditioned).
fn solve_increment(rows: &[(Vec<(usize, f64)>, DVec3)], n_unknowns: usize, mu: f64) -> Vec<DVec3> {
    let mut diag = vec![mu; n_unknowns];
    for (row, _) in rows {
        for &(k, w) in row {
            diag[k] += w * w;
        }
    }
    let apply = |x: &[DVec3], out: &mut Vec<DVec3>| {
        out.clear();
        out.extend(x.iter().map(|&v| v * mu));
        for (row, _) in rows {
            let s: DVec3 = row.iter().map(|&(k, w)| x[k] * w).sum();
            for &(k, w) in row {
                out[k] += s * w;
            }
        }
    };
    let mut b = vec![DVec3::ZERO; n_unknowns];
    for (row, r) in rows {
        for &(k, w) in row {
            b[k] += *r * w;
        }
    }
    // Componentwise CG (the three coordinates share the matrix but not the step sizes).
    let mut x = vec![DVec3::ZERO; n_unknowns];
    let mut r = b.clone();
    let mut z: Vec<DVec3> = r.iter().zip(&diag).map(|(v, d)| *v / *d).collect();
    let mut p = z.clone();
    let dot = |a: &[DVec3], b: &[DVec3]| -> DVec3 { a.iter().zip(b).map(|(u, v)| *u * *v).sum() };
    let mut rz = dot(&r, &z);
    let b_norm = dot(&b, &b);
    let mut ap = Vec::with_capacity(n_unknowns);
    for _ in 0..(4 * n_unknowns + 50).min(2000) {
        apply(&p, &mut ap);
        let pap = dot(&p, &ap);
        let alpha = DVec3::select(pap.cmpgt(DVec3::splat(1e-300)), rz / pap, DVec3::ZERO);
        for i in 0..n_unknowns {
            x[i] += p[i] * alpha;
            r[i] -= ap[i] * alpha;
        }
        let rr = dot(&r, &r);
        if rr.cmple(b_norm * 1e-20 + DVec3::splat(1e-300)).all() {
            break;
        }
        for i in 0..n_unknowns {
            z[i] = r[i] / diag[i];
        }
        let rz_new = dot(&r, &z);
        let beta = DVec3::select(rz.cmpgt(DVec3::splat(1e-300)), rz_new / rz, DVec3::ZERO);
        rz = rz_new;
        for i in 0..n_unknowns {
            p[i] = z[i] + p[i] * beta;
        }
    }
    x
}

/// Per input triangle, how far its flat facet may be from the CAD surface it tessellates:
/// the largest arc sagitta `L/2 tan(theta/4)` over its edges, where `theta` is the angle
/// between the edge's two vertex normals within the triangle's group (planar facets get 0).
/// A decoded surface that follows the CAD surface is this far from the facets, and the
/// tolerance should not charge the codec for the input's own discretisation.
pub fn chord_allowance(mesh: &ControlMesh, tris: &[[u32; 3]]) -> Vec<f64> {
    let mut normals: BTreeMap<(u32, u32), DVec3> = BTreeMap::new();
    for (f, t) in tris.iter().enumerate() {
        let g = mesh.face_groups[f];
        let p = t.map(|i| mesh.positions[i as usize]);
        let n = (p[1] - p[0]).cross(p[2] - p[0]);
        for &i in t {
            *normals.entry((g, i)).or_insert(DVec3::ZERO) += n;
        }
    }
    tris.iter()
        .enumerate()
        .map(|(f, t)| {
            let g = mesh.face_groups[f];
            (0..3)
                .map(|k| {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    let (na, nb) = (normals[&(g, a)], normals[&(g, b)]);
                    let theta = na.angle_between(nb);
                    let len = (mesh.positions[a as usize] - mesh.positions[b as usize]).length();
                    if theta.is_finite() {
                        0.5 * len * (0.25 * theta).tan()
                    } else {
                        0.0
                    }
                })
                .fold(0.0, f64::max)
        })
        .collect()
}

/// Facets along a curved CAD edge end at the edge's chord while the decoded patch follows
/// the curve: give every triangle on a chain edge at least that edge's sagitta
/// `L/2 tan(theta/4)`, `theta` the mean turning angle of the chain at the edge's ends.
fn add_curved_edge_allowance(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    net: &CurveNetwork,
    chord: &mut [f64],
) {
    let mut edge_sag: BTreeMap<(u32, u32), f64> = BTreeMap::new();
    for chain in &net.chains {
        let p: Vec<DVec3> = chain
            .vertices
            .iter()
            .map(|&v| mesh.positions[v as usize])
            .collect();
        let n = p.len();
        let turn = |i: usize| -> f64 {
            if i == 0 || i + 1 >= n {
                return 0.0;
            }
            let a = (p[i] - p[i - 1]).angle_between(p[i + 1] - p[i]);
            if a.is_finite() {
                a
            } else {
                0.0
            }
        };
        for i in 0..n.saturating_sub(1) {
            let (ta, tb) = (turn(i), turn(i + 1));
            let theta = match (i == 0, i + 2 >= n) {
                (true, true) => 0.0,
                (true, false) => tb,
                (false, true) => ta,
                _ => 0.5 * (ta + tb),
            };
            let sag = 0.5 * (p[i + 1] - p[i]).length() * (0.25 * theta).tan();
            edge_sag.insert(edge_key(chain.vertices[i], chain.vertices[i + 1]), sag);
        }
    }
    for (f, t) in tris.iter().enumerate() {
        for k in 0..3 {
            if let Some(&s) = edge_sag.get(&edge_key(t[k], t[(k + 1) % 3])) {
                chord[f] = chord[f].max(s);
            }
        }
    }
}

/// A Cartesian chain whose tolerance has been halved down to this fraction of the
/// tolerance (its groups failed about four times) and which already keeps every vertex
/// cannot be refined any further: its interior control points become corners, so the
/// decoded crease is the chain polyline itself. A smooth crease through few control points
/// cannot follow a chain that turns by tens of degrees at a vertex (e.g. a three-vertex
/// chain between a blade and a hub, 49 degrees at the middle vertex); least squares then
/// cuts the turn and the blade's patch sags behind its facets near that vertex.
const STUCK_CHAIN_TOL: f64 = 0.125;

/// A closed patch's first decimation threshold, in tolerances.
const INITIAL_CLOSED_COST: f64 = 8.0;

/// How much a failing closed patch's decimation threshold shrinks per round.
const CLOSED_COST_STEP: f64 = 0.35;

/// A converged closed patch whose worst excess is below this fraction of the tolerance was
/// refined further than it needed: its last refinement step divided its threshold by
/// 1/[`CLOSED_COST_STEP`] (about 2.9x its control faces) when it may have been a few
/// percent over.
const RELAX_BELOW: f64 = 0.6;

/// How much a relaxed patch's decimation thresholds grow: half a refinement step back.
const RELAX_STEP: f64 = 1.690_308_509_457_033; // 1 / sqrt(CLOSED_COST_STEP)

/// The state a relaxation round starts from, to restore the groups it breaks.
///
/// Refinement only ever adds control points, in steps sized for convergence, so a patch
/// a little over the tolerance in one round often ends far within it (a sphere patch 1.1-1.5
/// tol off can end with more than twice the control faces it needs). Once the
/// model is within tolerance, one round coarsens such patches again; where that fails, the
/// converged thresholds come back and the model is measured again; the smaller model within
/// tolerance is kept.
struct Relaxation {
    /// Relaxed groups, ascending.
    groups: Vec<usize>,
    /// Plans and per-vertex cost factors before relaxing.
    plans: Vec<GroupPlan>,
    vertex_cost: Vec<f64>,
    /// By group: the input vertices whose cost factor was raised.
    vertices: Vec<Vec<u32>>,
    /// Whether this is the round after a failed relaxation.
    verifying: bool,
}

/// Raises the decimation thresholds of refined closed patches whose excess is below
/// [`RELAX_BELOW`] tolerances (see [`Relaxation`]).
fn relax_refined_groups(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group_excess: &[(f64, DVec3, &str)],
    tol: f64,
    plans: &mut [GroupPlan],
    vertex_cost: &mut [f64],
) -> Relaxation {
    let saved_plans = plans.to_vec();
    let saved_cost = vertex_cost.to_vec();
    let mut vertices = vec![Vec::new(); plans.len()];
    for (t, &g) in tris.iter().zip(&mesh.face_groups) {
        vertices[g as usize].extend(t.iter().copied());
    }
    let mut groups = Vec::new();
    for (g, plan) in plans.iter_mut().enumerate() {
        let vs = &mut vertices[g];
        if !matches!(plan.kind, PatchKind::Closed)
            || plan.failures == 0
            || group_excess.get(g).is_none_or(|e| e.0 >= RELAX_BELOW * tol)
        {
            vs.clear();
            continue;
        }
        vs.sort_unstable();
        vs.dedup();
        vs.retain(|&v| vertex_cost[v as usize] < 1.0);
        let lowered_locally = !vs.is_empty();
        for &v in vs.iter() {
            vertex_cost[v as usize] = (vertex_cost[v as usize] * RELAX_STEP).min(1.0);
        }
        if plan.cost_factor < INITIAL_CLOSED_COST {
            plan.cost_factor = (plan.cost_factor * RELAX_STEP).min(INITIAL_CLOSED_COST);
        } else if !lowered_locally {
            continue;
        }
        groups.push(g);
    }
    Relaxation {
        groups,
        plans: saved_plans,
        vertex_cost: saved_cost,
        vertices,
        verifying: false,
    }
}

/// Mean length of the edges of group `g`'s faces in a control mesh (0 without faces).
fn mean_group_edge(control: &ControlMesh, g: u32) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for f in 0..control.face_count() {
        if control.face_groups[f] != g {
            continue;
        }
        let face = control.face(f);
        for k in 0..face.len() {
            let (a, b) = (face[k], face[(k + 1) % face.len()]);
            sum += (control.positions[a as usize] - control.positions[b as usize]).length();
            n += 1;
        }
    }
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

/// Multiplies by `step` the decimation factor of group `g`'s input vertices within `radius`
/// of a point where its decoded surface was out of tolerance; returns how many. Refining a
/// closed patch only there, not everywhere, keeps the rest as coarse as it was fine
/// (a sphere corner patch that fails only at its three corners would otherwise triple its
/// control vertices in one round).
fn lower_cost_near(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    g: u32,
    points: &[DVec3],
    radius: f64,
    step: f64,
    vertex_cost: &mut [f64],
) -> usize {
    if points.is_empty() || !(radius > 0.0 && radius.is_finite()) {
        return 0;
    }
    // Points hashed into cells of side `radius` (thinned to a quarter radius apart), so a
    // vertex looks at its 27 neighbouring cells only.
    let cell = |p: DVec3| -> (i64, i64, i64) {
        let c = (p / radius).floor();
        (c.x as i64, c.y as i64, c.z as i64)
    };
    let mut grid: BTreeMap<(i64, i64, i64), Vec<DVec3>> = BTreeMap::new();
    for &p in points {
        let list = grid.entry(cell(p)).or_default();
        if list.iter().all(|q| (*q - p).length() > 0.25 * radius) {
            list.push(p);
        }
    }
    let mut seen = std::collections::BTreeSet::new();
    for (t, &fg) in tris.iter().zip(&mesh.face_groups) {
        if fg == g {
            seen.extend(t.iter().copied());
        }
    }
    let mut lowered = 0;
    for v in seen {
        let p = mesh.positions[v as usize];
        let (cx, cy, cz) = cell(p);
        let near = (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dz| {
                    grid.get(&(cx + dx, cy + dy, cz + dz))
                        .is_some_and(|l| l.iter().any(|q| (*q - p).length() <= radius))
                })
            })
        });
        if near {
            vertex_cost[v as usize] *= step;
            lowered += 1;
        }
    }
    lowered
}

/// Points thinned to at most one per cell of side `cell` (first come first kept).
fn thin_points(points: &[DVec3], cell: f64) -> Vec<DVec3> {
    if !(cell > 0.0 && cell.is_finite()) {
        return points.to_vec();
    }
    let mut seen = std::collections::BTreeSet::new();
    points
        .iter()
        .copied()
        .filter(|p| {
            let c = (*p / cell).floor();
            seen.insert((c.x as i64, c.y as i64, c.z as i64))
        })
        .collect()
}

/// Which chains of the failing groups to refine: for each point where a group is out of
/// tolerance (thinned to one per 2 tol), the group's chains at most 1.5 times as far from it
/// as the nearest one, plus 2 tol (the nearest chain is what shapes a boundary patch's error
/// there), and for closed patches only chains within `reach[g]` of the point (farther, the
/// patch's interior is what is off).
#[allow(clippy::too_many_arguments)]
fn chains_near_failures(
    mesh: &ControlMesh,
    net: &CurveNetwork,
    group_chains: &[Vec<usize>],
    bad_group: &[bool],
    bad_points: &[Vec<DVec3>],
    plans: &[GroupPlan],
    reach: &[f64],
    tol: f64,
) -> Vec<bool> {
    let mut refine = vec![false; net.chains.len()];
    for (g, &bad) in bad_group.iter().enumerate() {
        if !bad || group_chains[g].is_empty() {
            continue;
        }
        let closed = matches!(plans[g].kind, PatchKind::Closed);
        let pts = thin_points(&bad_points[g], 2.0 * tol);
        if pts.is_empty() {
            // No located failure: refine them all.
            for &c in &group_chains[g] {
                refine[c] = true;
            }
            continue;
        }
        let lines: Vec<Vec<DVec3>> = group_chains[g]
            .iter()
            .map(|&c| {
                net.chains[c]
                    .vertices
                    .iter()
                    .map(|&v| mesh.positions[v as usize])
                    .collect()
            })
            .collect();
        for p in pts {
            let d: Vec<f64> = lines
                .iter()
                .map(|line| (closest_on_polyline(p, line) - p).length())
                .collect();
            let dmin = d.iter().copied().fold(f64::INFINITY, f64::min);
            for (k, &c) in group_chains[g].iter().enumerate() {
                let near = d[k] <= 1.5 * dmin + 2.0 * tol;
                if near && (!closed || d[k] <= reach[g]) {
                    refine[c] = true;
                }
            }
        }
    }
    refine
}

/// Everything one build round produces.
struct Built {
    control: ControlMesh,
    /// Control edge -> chain index, for sharp edges.
    edge_chain: BTreeMap<(u32, u32), usize>,
}

/// Steps 3 and 4: control points on chains, then the constrained decimation.
#[allow(clippy::too_many_arguments)]
fn build_topology(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    net: &CurveNetwork,
    plans: &[GroupPlan],
    surfaces: &[SurfaceRef],
    chain_tol: &[f64],
    chain_step: &[f64],
    tol: f64,
    chain_loop_len: &[usize],
    vertex_cost: &[f64],
    plane_domains: &[Option<PlaneDomain>],
) -> Built {
    let nv = mesh.vertex_count();
    let mut roles = vec![VertexRole::Interior; nv];
    // Interior vertices of stuck Cartesian chains, made control corners below: a crease
    // through corners only is the chain's polyline itself (see [`STUCK_CHAIN_TOL`]).
    let mut pinned: Vec<u32> = Vec::new();
    for c in &net.corners {
        roles[c.vertex as usize] = VertexRole::Keep;
    }
    for (ci, chain) in net.chains.iter().enumerate() {
        let points: Vec<DVec3> = chain
            .vertices
            .iter()
            .map(|&v| mesh.positions[v as usize])
            .collect();
        let frame = chain_frame(&chain.groups, plans);
        let min_interior = if chain_loop_len[ci] < 3 { 2 } else { 0 };
        let keep = chain_controls(&points, frame, chain_tol[ci], chain_step[ci], min_interior);
        if frame.is_none()
            && points.len() >= 3
            && keep.len() == points.len()
            && chain_tol[ci] <= STUCK_CHAIN_TOL * tol
        {
            pinned.extend_from_slice(&chain.vertices[1..points.len() - 1]);
        }
        for (i, &v) in chain.vertices.iter().enumerate() {
            if roles[v as usize] == VertexRole::Keep {
                continue;
            }
            roles[v as usize] = if keep.binary_search(&i).is_ok() {
                VertexRole::Keep
            } else {
                VertexRole::ChainDrop
            };
        }
    }
    let rules: Vec<GroupRule> = plans
        .iter()
        .zip(surfaces)
        .map(|(plan, &surface)| {
            let closed = matches!(plan.kind, PatchKind::Closed);
            GroupRule {
                remove_all_interior: !closed,
                max_cost: (plan.cost_factor * tol).powi(2),
                // A boundary patch turned closed is checked like any freeform face.
                surface: if closed { SurfaceRef::Free } else { surface },
                max_edge_angle: 80f64.to_radians(),
            }
        })
        .collect();
    let dec = decimate(&DecimateInput {
        positions: &mesh.positions,
        triangles: tris,
        face_groups: &mesh.face_groups,
        roles: &roles,
        rules: &rules,
        // Distance factors to the squared-distance units of `max_cost`.
        cost_scale: Some(&vertex_cost.iter().map(|f| f * f).collect::<Vec<f64>>()),
        domain: (!plane_domains.is_empty()).then_some(plane_domains),
    });
    // Compact into a control mesh.
    let mut index = vec![u32::MAX; nv];
    let mut control = ControlMesh::new();
    let mut origin = Vec::new();
    for &v in &dec.vertices {
        index[v as usize] = control.push_vertex(mesh.positions[v as usize]);
        origin.push(v);
    }
    for g in &mesh.groups {
        control.groups.push(g.clone());
    }
    for (g, plan) in plans.iter().enumerate() {
        control.groups[g].patch = plan.kind;
    }
    for (t, &g) in dec.triangles.iter().zip(&dec.face_groups) {
        control.push_face(&t.map(|v| index[v as usize]), g);
    }
    // Sharp edges: every edge between two groups; mesh-boundary edges are creases anyway.
    let mut edge_faces: BTreeMap<(u32, u32), Vec<u32>> = BTreeMap::new();
    for f in 0..control.face_count() {
        let face = control.face(f);
        for k in 0..face.len() {
            let e = edge_key(face[k], face[(k + 1) % face.len()]);
            edge_faces
                .entry(e)
                .or_default()
                .push(control.face_groups[f]);
        }
    }
    for (&(a, b), groups) in &edge_faces {
        if groups.len() == 2 && groups[0] != groups[1] {
            control.set_sharp(a, b);
        }
    }
    for v in net.corners.iter().map(|c| c.vertex).chain(pinned) {
        let i = index[v as usize];
        if i != u32::MAX {
            control.corners.insert(i);
        }
    }
    // Which chain each control edge on a chain belongs to.
    let mut vertex_chain: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (ci, chain) in net.chains.iter().enumerate() {
        for &v in &chain.vertices {
            vertex_chain.entry(v).or_default().push(ci);
        }
    }
    let mut edge_chain = BTreeMap::new();
    for &(a, b) in edge_faces.keys() {
        let (oa, ob) = (origin[a as usize], origin[b as usize]);
        if let (Some(ca), Some(cb)) = (vertex_chain.get(&oa), vertex_chain.get(&ob)) {
            if let Some(&c) = ca.iter().find(|c| cb.contains(c)) {
                let boundary = edge_faces[&(a, b)].len() == 1
                    || edge_faces[&(a, b)].first() != edge_faces[&(a, b)].last();
                if boundary {
                    edge_chain.insert((a, b), c);
                }
            }
        }
    }
    Built {
        control,
        edge_chain,
    }
}

/// Step 5: least-squares fit of the Cartesian crease curves, then of closed-patch interiors.
fn fit_geometry(
    built: &mut Built,
    mesh: &ControlMesh,
    net: &CurveNetwork,
    plans: &[GroupPlan],
    group_surfaces: &[Option<TriangleSurface>],
    exact: &[Option<ExactSurface>],
) -> Result<()> {
    const LEVEL: u32 = 2;
    let control = &mut built.control;
    let refinement = Refinement::new(control, LEVEL)?;
    let stencils = refinement.stencils(LEVEL, true)?;
    let view = refinement.level(LEVEL);
    let nv_l = view.vertex_count();
    let base = refinement.level(0);
    let base_edges = base.edges();
    // Per level-LEVEL vertex: chain it lies on (crease samples) and group (interior samples).
    let mut sample_chain: Vec<Option<usize>> = vec![None; nv_l];
    let mut multi_chain = vec![false; nv_l];
    let e0 = base_edges.len();
    for (e, ends) in view.edges().iter().enumerate() {
        if !view.edge_is_crease(e) || e >= e0 << LEVEL {
            continue;
        }
        let be = base_edges[e >> LEVEL];
        let Some(&c) = built.edge_chain.get(&edge_key(be[0], be[1])) else {
            continue;
        };
        for &v in ends {
            match sample_chain[v as usize] {
                Some(old) if old != c => multi_chain[v as usize] = true,
                _ => sample_chain[v as usize] = Some(c),
            }
        }
    }
    let mut sample_group: Vec<Option<u32>> = vec![None; nv_l];
    let mut mixed = vec![false; nv_l];
    for f in 0..view.face_count() {
        let g = view.face_group(f);
        for v in view.triangle(f) {
            match sample_group[v as usize] {
                Some(old) if old != g => mixed[v as usize] = true,
                _ => sample_group[v as usize] = Some(g),
            }
        }
    }
    // Unknowns.
    let nc = control.vertex_count();
    let mut on_sharp = vec![false; nc];
    for &(a, b) in &control.sharp_edges {
        on_sharp[a as usize] = true;
        on_sharp[b as usize] = true;
    }
    let chain_frame_of = |c: usize| chain_frame(&net.chains[c].groups, plans);
    // Per chain: the exact surfaces of its faces, when every one of them has one.
    let chain_exact: Vec<Option<Vec<ExactSurface>>> = net
        .chains
        .iter()
        .map(|c| {
            let mut groups = c.groups.clone();
            groups.dedup();
            groups
                .iter()
                .map(|&g| exact.get(g as usize).copied().flatten())
                .collect()
        })
        .collect();
    // Stage 1: Cartesian chains. Stage 2: closed interiors.
    for stage in 0..2 {
        let mut col = vec![usize::MAX; nc];
        let mut unknowns = Vec::new();
        for v in 0..nc {
            let movable = if stage == 0 {
                // Interior control point of a Cartesian chain.
                !control.corners.contains(&(v as u32))
                    && on_sharp[v]
                    && sample_chain
                        .get(v)
                        .copied()
                        .flatten()
                        .is_some_and(|c| chain_frame_of(c).is_none())
                    && !multi_chain[v]
            } else {
                !on_sharp[v]
                    && !mixed[v]
                    && sample_group[v]
                        .is_some_and(|g| matches!(plans[g as usize].kind, PatchKind::Closed))
            };
            if movable {
                col[v] = unknowns.len();
                unknowns.push(v);
            }
        }
        if unknowns.is_empty() {
            continue;
        }
        let chain_points: BTreeMap<usize, Vec<DVec3>> = if stage == 0 {
            net.chains
                .iter()
                .enumerate()
                .map(|(i, c)| {
                    (
                        i,
                        c.vertices
                            .iter()
                            .map(|&v| mesh.positions[v as usize])
                            .collect(),
                    )
                })
                .collect()
        } else {
            BTreeMap::new()
        };
        for _iteration in 0..4 {
            let level = refinement.positions_at(&control.positions, LEVEL)?;
            let limit = refinement.limit_positions(&level, LEVEL)?;
            let mut rows = Vec::new();
            for s in 0..nv_l {
                let target = if stage == 0 {
                    match sample_chain[s] {
                        Some(c) if !multi_chain[s] && chain_frame_of(c).is_none() => {
                            // On the edge's polyline, then onto the exact surfaces of
                            // its faces where the input knows them all: the polyline
                            // sags from the CAD edge by up to its chord.
                            let on_line = closest_on_polyline(limit[s], &chain_points[&c]);
                            chain_exact[c]
                                .as_deref()
                                .and_then(|surfaces| onto_all(surfaces, on_line))
                                .unwrap_or(on_line)
                        }
                        _ => continue,
                    }
                } else {
                    match sample_group[s] {
                        Some(g) if !mixed[s] && sample_chain[s].is_none() => {
                            match &group_surfaces[g as usize] {
                                Some(surface)
                                    if matches!(plans[g as usize].kind, PatchKind::Closed) =>
                                {
                                    // On the face's facets, then onto its exact surface
                                    // where the input knows it: the facets sag from the
                                    // CAD surface by up to their chord, and the error is
                                    // measured against the CAD surface too.
                                    let on_facets = surface.closest_point(limit[s]).point;
                                    match exact.get(g as usize).copied().flatten() {
                                        Some(e) => e.project(on_facets),
                                        None => on_facets,
                                    }
                                }
                                _ => continue,
                            }
                        }
                        _ => continue,
                    }
                };
                let (idx, w) = stencils.row(s);
                let row: Vec<(usize, f64)> = idx
                    .iter()
                    .zip(w)
                    .filter(|(&k, _)| col[k as usize] != usize::MAX)
                    .map(|(&k, &w)| (col[k as usize], w))
                    .collect();
                if !row.is_empty() {
                    rows.push((row, target - limit[s]));
                }
            }
            let mean_diag = rows
                .iter()
                .map(|(r, _)| r.iter().map(|(_, w)| w * w).sum::<f64>())
                .sum::<f64>()
                / unknowns.len() as f64;
            let delta = solve_increment(&rows, unknowns.len(), 1e-3 * mean_diag.max(1e-12));
            for (k, &v) in unknowns.iter().enumerate() {
                if delta[k].is_finite() {
                    control.positions[v] += delta[k];
                }
            }
        }
    }
    Ok(())
}

/// Adds to a mesh error the CAD faces (groups) whose control faces break the control mesh's
/// topology (a side used twice in one direction, or by more than two faces; else the faces
/// around a vertex with more than two open sides, where holes touch), so a failing
/// fit names the B-rep faces to look at instead of only vertex numbers.
pub(crate) fn with_faces_involved(e: Error, control: &ControlMesh) -> Error {
    let Error::Mesh(msg) = e else { return e };
    let mut uses: std::collections::BTreeMap<(u32, u32), Vec<(usize, bool)>> = Default::default();
    for f in 0..control.face_count() {
        let face = control.face(f);
        for k in 0..face.len() {
            let (a, b) = (face[k], face[(k + 1) % face.len()]);
            uses.entry(crate::mesh::edge_key(a, b))
                .or_default()
                .push((f, a < b));
        }
    }
    let mut groups = std::collections::BTreeSet::new();
    for faces in uses.values() {
        let forward = faces.iter().filter(|u| u.1).count();
        if faces.len() > 2 || forward > 1 || faces.len() - forward > 1 {
            for &(f, _) in faces {
                if let Some(&g) = control.face_groups.get(f) {
                    groups.insert(g);
                }
            }
        }
    }
    if groups.is_empty() {
        // A vertex where two holes touch (more than two open sides): the faces around it.
        let mut open_sides: BTreeMap<u32, usize> = BTreeMap::new();
        for (&(a, b), faces) in &uses {
            if faces.len() == 1 {
                *open_sides.entry(a).or_default() += 1;
                *open_sides.entry(b).or_default() += 1;
            }
        }
        for f in 0..control.face_count() {
            if control
                .face(f)
                .iter()
                .any(|v| open_sides.get(v).is_some_and(|&n| n > 2))
            {
                if let Some(&g) = control.face_groups.get(f) {
                    groups.insert(g);
                }
            }
        }
    }
    if groups.is_empty() {
        return Error::Mesh(msg);
    }
    let names: Vec<String> = groups
        .iter()
        .take(8)
        .map(|&g| {
            control
                .groups
                .get(g as usize)
                .map_or_else(|| format!("group {g}"), |gr| format!("'{}'", gr.name))
        })
        .collect();
    Error::Mesh(format!(
        "{msg} (CAD faces involved: {}{})",
        names.join(", "),
        if groups.len() > 8 { ", ..." } else { "" }
    ))
}

/// A closest-point structure per group over the group's own triangles (`None` for a group
/// without any). Each holds the group's own vertices only (in first-use order): the same
/// triangles in the same order, so the same closest points, without a copy of every
/// position per group (hundreds of groups times tens of thousands of vertices).
fn group_surfaces_of(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group_triangles: &[Vec<u32>],
) -> Vec<Option<TriangleSurface>> {
    let mut local = vec![u32::MAX; mesh.vertex_count()];
    group_triangles
        .iter()
        .map(|ids| {
            let t: Vec<[u32; 3]> = ids.iter().map(|&t| tris[t as usize]).collect();
            if t.is_empty() {
                return None;
            }
            let mut positions = Vec::new();
            let mut used = Vec::new();
            let t: Vec<[u32; 3]> = t
                .iter()
                .map(|tri| {
                    tri.map(|v| {
                        if local[v as usize] == u32::MAX {
                            local[v as usize] = positions.len() as u32;
                            positions.push(mesh.positions[v as usize]);
                            used.push(v);
                        }
                        local[v as usize]
                    })
                })
                .collect();
            for v in used {
                local[v as usize] = u32::MAX;
            }
            TriangleSurface::new(positions, t).ok()
        })
        .collect()
}

/// `m` with its polygons fan-split into triangles (same vertices, groups and face groups).
fn triangulated(m: &ControlMesh) -> ControlMesh {
    let mut t = ControlMesh::new();
    t.positions = m.positions.clone();
    t.groups = m.groups.clone();
    for f in 0..m.face_count() {
        let face = m.face(f);
        for i in 1..face.len().saturating_sub(1) {
            t.push_face(&[face[0], face[i], face[i + 1]], m.face_groups[f]);
        }
    }
    t
}

/// Per group of a triangle mesh, the indices of its triangles (faces).
fn triangles_by_group(m: &ControlMesh) -> Vec<Vec<u32>> {
    let mut by_group: Vec<Vec<u32>> = vec![Vec::new(); m.groups.len()];
    for (t, &g) in m.face_groups.iter().enumerate() {
        if let Some(b) = by_group.get_mut(g as usize) {
            b.push(t as u32);
        }
    }
    by_group
}

/// The quantise-encode-decode callback of [`fit_model`]: `(control, level, coarser)` to the
/// decoded control mesh and the size of its file in bytes; `coarser` counts quarter bits.
pub type Reconstruct<'a> = dyn FnMut(&ControlMesh, u8, u8) -> Result<(ControlMesh, usize)> + 'a;

/// A fitted model within reach of the output: its error, control mesh, decode level and
/// file size at the default quantisation.
struct Candidate {
    err: FitError,
    control: ControlMesh,
    level: u8,
    bytes: usize,
}

/// Fits a control mesh to `input` (a triangle or polygon mesh; polygons are fan-split).
/// `hints[g]` is what the input says group g's surface is (or `Unknown`). `reconstruct`
/// must return the control mesh exactly as the decoder will see it (quantised with a grid
/// step `2^(coarser / 4)` times the caller's default, stored for decode level `level`), with the
/// input's group numbering, and the size of the file it was decoded from:
/// `reconstruct(control, level, coarser) -> (decoded, bytes)`. The sizes decide between
/// candidate control meshes that all meet the tolerance (see [`Relaxation`]).
pub fn fit_model(
    input: &ControlMesh,
    hints: &[SurfaceHint],
    opts: &FitOptions,
    reconstruct: &mut Reconstruct<'_>,
) -> Result<FitOutcome> {
    let t_start = Instant::now();
    let mut report = FitReport::default();
    input.validate()?;
    if input.face_count() == 0 {
        return Err(Error::Mesh("the input has no faces".into()));
    }
    // Fan-split polygons: the fit works on the input's triangles.
    let mut mesh = triangulated(input);
    let diag = mesh.diagonal();
    let tol = opts.tolerance.unwrap_or(1e-3 * diag);
    if !(tol > 0.0 && tol.is_finite()) {
        return Err(Error::Parameter(format!(
            "tolerance must be positive, got {tol}"
        )));
    }
    if let Some(mt) = opts.mean_tolerance {
        if !(mt > 0.0 && mt.is_finite()) {
            return Err(Error::Parameter(format!(
                "mean tolerance must be positive, got {mt}"
            )));
        }
    }
    let mean_ok = |e: &FitError| opts.mean_tolerance.is_none_or(|mt| e.mean <= mt);
    report.tolerance = tol;
    report.mean_tolerance = opts.mean_tolerance;
    report.diagonal = diag;
    let mut hints: Vec<SurfaceHint> = hints.to_vec();
    hints.resize(mesh.groups.len(), SurfaceHint::Unknown);
    // 1. Faces.
    let mut t = Instant::now();
    let segmented = mesh.groups.len() <= 1;
    let keep_planes_on_faces = opts.keep_planes_on_faces && !segmented;
    if segmented {
        let seg_opts = SegmentOptions {
            sharp_angle_deg: opts.sharp_angle_deg,
            // Region growing merges more with a looser tolerance, and merged regions hide
            // features a patch cannot follow: cap it.
            tolerance: Some(0.25 * tol.min(2e-3 * diag)),
            ..Default::default()
        };
        let (seg, seg_report) = segment(&mesh, &seg_opts)?;
        report.notes.push(format!(
            "segmented into {} faces: {}",
            seg.groups.len(),
            seg_report.summary()
        ));
        mesh = seg;
        report.segmented = true;
    }
    let tris: Vec<[u32; 3]> = mesh.faces().map(|f| [f[0], f[1], f[2]]).collect();
    let mut plans: Vec<GroupPlan> = (0..mesh.groups.len() as u32)
        .map(|g| {
            let kind = if segmented {
                mesh.groups[g as usize].patch
            } else {
                exact_surface_kind(&mesh, &tris, g, tol)
                    .unwrap_or_else(|| classify_group(&mesh, &tris, g, hints[g as usize], tol))
            };
            GroupPlan {
                kind,
                cost_factor: INITIAL_CLOSED_COST,
                failures: 0,
            }
        })
        .collect();
    // What collapses must respect per group (plane normals are fitted once here).
    let surfaces: Vec<SurfaceRef> = plans
        .iter()
        .enumerate()
        .map(|(g, plan)| collapse_surface(&mesh, &tris, g as u32, &plan.kind))
        .collect();
    report.timings.push(("faces", t.elapsed().as_secs_f64()));
    // 2. Curve network.
    t = Instant::now();
    let net = build_curve_network(
        &mesh,
        &CurveOptions {
            simplify_tolerance: Some(tol),
            ..Default::default()
        },
    )?;
    let mut chain_loop_len = vec![usize::MAX; net.chains.len()];
    for gl in &net.group_loops {
        for lp in &gl.loops {
            for lc in lp {
                let c = lc.chain as usize;
                chain_loop_len[c] = chain_loop_len[c].min(lp.len());
            }
        }
    }
    // Input triangles of each group (global indices), for the per-face surfaces below.
    let group_triangles = triangles_by_group(&mesh);
    // Where each plane face lies in its plane, for the decimation's domain test.
    let plane_domains: Vec<Option<PlaneDomain>> = if keep_planes_on_faces {
        group_triangles
            .iter()
            .zip(&surfaces)
            .map(|(ids, surface)| match *surface {
                SurfaceRef::Plane { normal } => {
                    let t: Vec<[DVec3; 3]> = ids
                        .iter()
                        .map(|&t| tris[t as usize].map(|v| mesh.positions[v as usize]))
                        .collect();
                    PlaneDomain::new(&t, normal, tol)
                }
                _ => None,
            })
            .collect()
    } else {
        Vec::new()
    };
    let group_surfaces = group_surfaces_of(&mesh, &tris, &group_triangles);
    let input_surface = TriangleSurface::new(mesh.positions.clone(), tris.clone())?;
    let mut chord = chord_allowance(&mesh, &tris);
    add_curved_edge_allowance(&mesh, &tris, &net, &mut chord);
    let kinds: Vec<PatchKind> = plans.iter().map(|p| p.kind).collect();
    add_analytic_surface_allowance(
        &mesh.positions,
        &tris,
        &mesh.face_groups,
        &kinds,
        &mut chord,
    );
    report.timings.push(("curves", t.elapsed().as_secs_f64()));
    let mut chain_tol = vec![2.0 * tol; net.chains.len()];
    let mut chain_step = vec![60f64.to_radians(); net.chains.len()];
    // Chains of each group, for refinement.
    let mut group_chains: Vec<Vec<usize>> = vec![Vec::new(); mesh.groups.len()];
    for (ci, c) in net.chains.iter().enumerate() {
        for &g in &c.groups {
            group_chains[g as usize].push(ci);
        }
    }
    // What the decoded surface is measured against: the input, or the finer tessellation of
    // the same faces the caller gave (`FitOptions::reference`).
    let reference = opts.reference.as_ref().filter(|r| {
        !segmented
            && r.groups.len() == mesh.groups.len()
            && r.groups
                .iter()
                .zip(&mesh.groups)
                .all(|(a, b)| a.name == b.name)
            // Indices in range and finite positions (it is the caller's mesh, not checked
            // like the input).
            && r.face_groups.len() == r.face_count()
            && r.face_groups.iter().all(|&g| (g as usize) < r.groups.len())
            && (0..r.face_count()).all(|f| {
                r.face(f)
                    .iter()
                    .all(|&v| (v as usize) < r.positions.len())
            })
            && r.positions.iter().all(|p| p.is_finite())
    });
    if opts.reference.is_some() && reference.is_none() {
        report.notes.push(
            "the reference tessellation does not hold the input's faces (or has invalid indices or \
             positions): measured against the input"
                .into(),
        );
    }
    let ref_parts = match reference {
        Some(r) => {
            let r_mesh = triangulated(r);
            let r_tris: Vec<[u32; 3]> = r_mesh.faces().map(|f| [f[0], f[1], f[2]]).collect();
            let r_group_tris = triangles_by_group(&r_mesh);
            let r_surface = TriangleSurface::new(r_mesh.positions.clone(), r_tris.clone())?;
            let mut r_chord = chord_allowance(&r_mesh, &r_tris);
            add_analytic_surface_allowance(
                &r_mesh.positions,
                &r_tris,
                &r_mesh.face_groups,
                &kinds,
                &mut r_chord,
            );
            let r_group_surfaces = group_surfaces_of(&r_mesh, &r_tris, &r_group_tris);
            report.notes.push(format!(
                "measured against a reference tessellation of {} triangles (input: {})",
                r_tris.len(),
                tris.len()
            ));
            Some((
                r_mesh,
                r_tris,
                r_group_tris,
                r_surface,
                r_chord,
                r_group_surfaces,
            ))
        }
        None => None,
    };
    let (m_mesh, m_tris, m_group_tris, m_surface, m_chord, m_group_surfaces) = match &ref_parts {
        Some((a, b, c, d, e, f)) => (a, b, c, d, e, f),
        None => (
            &mesh,
            &tris,
            &group_triangles,
            &input_surface,
            &chord,
            &group_surfaces,
        ),
    };
    let group_max_chord: Vec<f64> = m_group_tris
        .iter()
        .map(|ids| ids.iter().fold(0.0f64, |m, &t| m.max(m_chord[t as usize])))
        .collect();
    let exact_faces = if segmented {
        0
    } else {
        opts.exact_surfaces.iter().flatten().count()
    };
    if exact_faces > 0 {
        report.notes.push(format!(
            "{exact_faces} of {} faces measured against their exact surfaces too",
            mesh.groups.len()
        ));
    }
    // A segmented input's groups are not the input's: no exact surfaces then.
    let exact_surfaces: &[Option<ExactSurface>] =
        if segmented { &[] } else { &opts.exact_surfaces };
    let meter = ErrorMeter::new(
        m_mesh,
        m_tris,
        m_surface,
        m_chord,
        OwnFaces {
            surfaces: m_group_surfaces,
            triangles: m_group_tris,
            max_allowance: &group_max_chord,
            exact: exact_surfaces,
        },
        opts.error_samples,
        tol,
    );
    // Per input vertex, a factor on its closed patch's decimation threshold, lowered round by
    // round where the patch's decoded surface is off (see `lower_cost_near`).
    let mut vertex_cost = vec![1.0f64; mesh.vertex_count()];
    // The best converged model, and the relaxed one when relaxing it stayed within tolerance.
    let mut best: Option<Candidate> = None;
    let mut relaxed_best: Option<Candidate> = None;
    let mut levels_tried = opts.default_level;
    let mut prev_worst: Option<f64> = None;
    // Set once the model is within tolerance and refined patches are being coarsened again.
    let mut relaxing: Option<Relaxation> = None;
    for round in 0..opts.max_rounds.max(1) {
        report.rounds = round + 1;
        t = Instant::now();
        let mut built = build_topology(
            &mesh,
            &tris,
            &net,
            &plans,
            &surfaces,
            &chain_tol,
            &chain_step,
            tol,
            &chain_loop_len,
            &vertex_cost,
            &plane_domains,
        );
        let t_top = t.elapsed().as_secs_f64();
        t = Instant::now();
        fit_geometry(
            &mut built,
            &mesh,
            &net,
            &plans,
            &group_surfaces,
            exact_surfaces,
        )
        .map_err(|e| with_faces_involved(e, &built.control))?;
        let t_fit = t.elapsed().as_secs_f64();
        // 6. Error of the decoded surface.
        t = Instant::now();
        let level = levels_tried.unwrap_or(4);
        let (decoded, round_bytes) = reconstruct(&built.control, level, 0)
            .map_err(|e| with_faces_involved(e, &built.control))?;
        let measured = meter
            .measure(&decoded, level)
            .map_err(|e| with_faces_involved(e, &decoded))?;
        let err = measured.error;
        let worst = err.max_beyond_chord;
        report.timings.push(("topology", t_top));
        report.timings.push(("fit", t_fit));
        report.timings.push(("measure", t.elapsed().as_secs_f64()));
        report.notes.push(format!(
            "round {}: {} control vertices, level {level}, max error {:.3e} ({:.2} tol; {:.2} tol beyond the input's chord error), rms {:.3e}; {} of {} faces measured anew",
            round + 1,
            built.control.vertex_count(),
            err.max,
            err.max / tol,
            err.max_beyond_chord / tol,
            err.rms,
            measured.changed_groups,
            mesh.groups.len()
        ));
        let ok = err.max_beyond_chord <= tol;
        let better = best.as_ref().is_none_or(|b| {
            let e = &b.err;
            let e_ok = e.max_beyond_chord <= tol;
            (ok && !e_ok) || (ok == e_ok && err.max_beyond_chord < e.max_beyond_chord)
        });
        let candidate = || Candidate {
            err,
            control: built.control.clone(),
            level,
            bytes: round_bytes,
        };
        if relaxing.is_none() && (better || ok) {
            best = Some(candidate());
        } else if relaxing.is_some() && ok {
            relaxed_best = Some(candidate());
        }
        match relaxing.take() {
            None if ok && (!opts.relax || round + 1 >= opts.max_rounds) => break,
            None if ok => {
                let relaxed = relax_refined_groups(
                    &mesh,
                    &tris,
                    &measured.group_excess,
                    tol,
                    &mut plans,
                    &mut vertex_cost,
                );
                if relaxed.groups.is_empty() {
                    break;
                }
                report.notes.push(format!(
                    "  within tolerance; {} refined closed patches far within it get a coarser threshold",
                    relaxed.groups.len()
                ));
                relaxing = Some(relaxed);
                continue;
            }
            None => {}
            Some(r) if ok || r.verifying => break,
            Some(mut r) => {
                // Relaxing broke the tolerance somewhere: the relaxed groups that fail get
                // their converged thresholds back and the model is measured once more. When
                // a group that was not relaxed fails (relaxed patches moved vertices it
                // shares), that would be the converged model again: keep it.
                let failing: Vec<usize> = (0..mesh.groups.len())
                    .filter(|&g| measured.group_excess[g].0 > tol)
                    .collect();
                if failing.iter().any(|g| r.groups.binary_search(g).is_err())
                    || round + 1 >= opts.max_rounds
                {
                    break;
                }
                for &g in &r.groups {
                    if failing.binary_search(&g).is_ok() {
                        plans[g] = r.plans[g];
                        for &v in &r.vertices[g] {
                            vertex_cost[v as usize] = r.vertex_cost[v as usize];
                        }
                    }
                }
                report.notes.push(format!(
                    "  relaxing failed in {} groups: their thresholds restored",
                    failing.len()
                ));
                r.verifying = true;
                relaxing = Some(r);
                continue;
            }
        }
        // Where is the error?
        let group_excess = &measured.group_excess;
        let bad_group: Vec<bool> = group_excess.iter().map(|e| e.0 > tol).collect();
        let mut worst_groups: Vec<usize> =
            (0..mesh.groups.len()).filter(|&g| bad_group[g]).collect();
        worst_groups.sort_by(|&a, &b| group_excess[b].0.total_cmp(&group_excess[a].0));
        let listed: Vec<String> = worst_groups
            .iter()
            .take(4)
            .map(|&g| {
                let (d, p, dir) = group_excess[g];
                format!(
                    "group {g} '{}' ({}) {:.2} tol {dir} at ({:.4}, {:.4}, {:.4})",
                    mesh.groups[g].name,
                    kind_name(&plans[g].kind),
                    d / tol,
                    p.x,
                    p.y,
                    p.z
                )
            })
            .collect();
        report.notes.push(format!(
            "  {} groups beyond tolerance; worst: {}",
            worst_groups.len(),
            listed.join("; ")
        ));
        // When adding control points stops paying, the rest may be the piecewise-linear
        // chord error of level 4: go to level 5 (4x the triangles) once.
        if opts.default_level.is_none()
            && levels_tried.is_none()
            && prev_worst.is_some_and(|p| worst > STALL_RATIO * p)
        {
            levels_tried = Some(5);
        }
        prev_worst = Some(worst);
        // Chains are refined only near where their groups fail (a plane with a hundred
        // holes failing at one of them keeps the other holes coarse); the last rounds, and
        // every round once the worst excess is within 1.5 tol, refine every chain of a
        // failing group: convergence first (near the tolerance, refining only near the
        // failures takes more rounds than it saves control points).
        let chain_refine =
            if round + 4 >= opts.max_rounds || !keep_planes_on_faces || worst < 1.5 * tol {
                let mut all = vec![false; net.chains.len()];
                for g in (0..mesh.groups.len()).filter(|&g| bad_group[g]) {
                    for &c in &group_chains[g] {
                        all[c] = true;
                    }
                }
                all
            } else {
                let reach: Vec<f64> = (0..mesh.groups.len())
                    .map(|g| {
                        if bad_group[g] && matches!(plans[g].kind, PatchKind::Closed) {
                            0.5 * mean_group_edge(&built.control, g as u32)
                        } else {
                            0.0
                        }
                    })
                    .collect();
                chains_near_failures(
                    &mesh,
                    &net,
                    &group_chains,
                    &bad_group,
                    &measured.bad_points,
                    &plans,
                    &reach,
                    tol,
                )
            };
        let mut refitted_closed = Vec::new();
        for (g, bad) in bad_group.iter().enumerate() {
            if !bad {
                continue;
            }
            let plan = &mut plans[g];
            plan.failures += 1;
            if matches!(plan.kind, PatchKind::Closed) {
                report.closed_refinements += 1;
                let radius = 2.0 * mean_group_edge(&built.control, g as u32);
                let lowered = if !opts.local_refinement {
                    0
                } else {
                    lower_cost_near(
                        &mesh,
                        &tris,
                        g as u32,
                        &measured.bad_points[g],
                        radius,
                        CLOSED_COST_STEP,
                        &mut vertex_cost,
                    )
                };
                if lowered == 0 {
                    plan.cost_factor *= CLOSED_COST_STEP;
                }
            } else if plan.failures >= 4 {
                report.notes.push(format!(
                    "group {g} ({}) refitted as a closed patch",
                    kind_name(&plan.kind)
                ));
                plan.kind = PatchKind::Closed;
                plan.cost_factor = 2.0;
                refitted_closed.push(g);
            }
        }
        for (c, &r) in chain_refine.iter().enumerate() {
            if r {
                chain_tol[c] *= 0.5;
                chain_step[c] = (chain_step[c] * 0.6).max(5f64.to_radians());
            }
        }
        // A crease next to a cylinder or cone is interpolated in that patch's frame: on its
        // surface, but between control points off any other surface it bounds (a slanted
        // plane cuts a cone in a hyperbola, not in a curve affine in (theta, h, r)). A group
        // that failed as a boundary patch may fail because of such creases, and making it
        // closed does not change them: make the frame's owner closed too, so the crease
        // becomes Cartesian and is fitted to its polyline (e.g. a hexagon's sides next to
        // its chamfer cones).
        for g in refitted_closed {
            for &c in &group_chains[g] {
                let Some(h) = chain_frame_owner(&net.chains[c].groups, &plans) else {
                    continue;
                };
                let plan = &mut plans[h as usize];
                report.notes.push(format!(
                    "group {h} ({}) refitted as a closed patch: its frame shapes a crease of group {g}",
                    kind_name(&plan.kind)
                ));
                plan.kind = PatchKind::Closed;
                plan.cost_factor = 2.0;
            }
        }
    }
    let Some(converged) = best else {
        return Err(Error::Mesh("fitting produced no control mesh".into()));
    };
    let mut candidates = vec![converged];
    candidates.extend(relaxed_best);
    let compared = candidates.len() > 1;
    // The quantisation step was chosen for a quarter of the tolerance; the limit surface
    // averages control points, so coarser steps often still fit. Keep the coarsest that does,
    // for each candidate, then the candidate whose file is smaller.
    t = Instant::now();
    // (error, control mesh, decode level, coarser quarter bits, bytes) of the smallest file so far.
    let mut chosen: Option<(FitError, ControlMesh, u8, u8, usize)> = None;
    let mut sizes = Vec::new();
    for Candidate {
        mut err,
        mut control,
        level,
        mut bytes,
    } in candidates
    {
        if segmented {
            // The segmenter's region names ("face_i") are made up here, not the input's: do
            // not spend bytes on them (they can be a sixth of a small file). Groups and patch
            // kinds stay.
            for g in &mut control.groups {
                g.name.clear();
            }
            if compared {
                // The sizes decide between the candidates: measure them without the names.
                bytes = reconstruct(&control, level, 0)
                    .map_err(|e| with_faces_involved(e, &control))?
                    .1;
            }
        }
        let mut coarser_bits = 0;
        if err.max_beyond_chord <= tol {
            // Binary search over whole bits 0..=max (the error grows with the step, though
            // not strictly: it also depends on how the grid falls on the control points), at
            // most two or three measurements; then quarter bits beyond the whole count found,
            // halving (+1/2, then +1/4 or +3/4): a whole bit doubles the step, and the
            // tolerance often still holds at 1.2 to 1.7 times the step where it fails at 2.
            // A fraction must also shrink the file and keep the RMS error within a quarter
            // of the tolerance (see `FitOptions::max_coarser_bits`). `coarser` counts
            // quarter bits.
            // The chord allowance is for the input's facets, not for quantisation noise: the
            // plain max error may not grow beyond max(tolerance, the unquantised fit's).
            let max_cap = tol.max(err.max);
            let (mut lo, mut hi) = (0u8, opts.max_coarser_bits);
            // The quarter bit to try beyond `lo` whole bits once the search has settled (2,
            // then 1 or 3; 0 when done, or when the caller fixed the precision
            // (`max_coarser_bits` 0) or asked for whole bits only).
            let mut quarter = if opts.max_coarser_bits > 0 && opts.quarter_bit_steps {
                2u8
            } else {
                0
            };
            loop {
                let coarser = if lo < hi {
                    4 * (lo + hi).div_ceil(2)
                } else if quarter > 0 {
                    4 * lo + quarter
                } else {
                    break;
                };
                let (decoded, coarser_bytes) = reconstruct(&control, level, coarser)
                    .map_err(|e| with_faces_involved(e, &control))?;
                // A failing step usually fails where the finer one was worst: probing those
                // samples first decides it without a full measurement (same decision).
                let m = meter
                    .measure_unless_over(&decoded, level, Some(max_cap))
                    .map_err(|e| with_faces_involved(e, &decoded))?;
                let whole = coarser % 4 == 0;
                let within = m.filter(|m| {
                    m.error.max_beyond_chord <= tol
                        && m.error.max <= max_cap
                        && mean_ok(&m.error)
                        && (whole || (coarser_bytes < bytes && m.error.rms <= 0.25 * tol))
                });
                let held = within.is_some();
                if let Some(m) = within {
                    coarser_bits = coarser;
                    err = m.error;
                    bytes = coarser_bytes;
                }
                if whole {
                    if held {
                        lo = coarser / 4;
                    } else {
                        hi = coarser / 4 - 1;
                    }
                } else if quarter == 2 {
                    quarter = if held { 3 } else { 1 };
                } else {
                    quarter = 0;
                }
            }
        }
        sizes.push((control.vertex_count(), coarser_bits, bytes));
        if chosen.as_ref().is_none_or(|c| bytes < c.4) {
            chosen = Some((err, control, level, coarser_bits, bytes));
        }
    }
    report
        .timings
        .push(("quantisation", t.elapsed().as_secs_f64()));
    let Some((err, control, level, coarser_bits, _)) = chosen else {
        return Err(Error::Mesh("fitting produced no control mesh".into()));
    };
    if let [(cv, cb, cbytes), (rv, rb, rbytes)] = sizes[..] {
        report.notes.push(format!(
            "relaxed: {rv} control vertices, {} bits coarser, {rbytes} bytes; converged: \
             {cv}, {} bits coarser, {cbytes} bytes; kept the {}",
            f64::from(rb) / 4.0,
            f64::from(cb) / 4.0,
            if rbytes < cbytes {
                "relaxed"
            } else {
                "converged"
            }
        ));
    }
    if coarser_bits > 0 {
        report.notes.push(format!(
            "quantisation: {} bits coarser than the default still meets the tolerance \
             (max error {:.3e}, {:.2} tol beyond the input's chord error)",
            f64::from(coarser_bits) / 4.0,
            err.max,
            err.max_beyond_chord / tol
        ));
    }
    report.error = err;
    report.within_tolerance = err.max_beyond_chord <= tol && mean_ok(&err);
    if !mean_ok(&err) {
        report.notes.push(format!(
            "mean error {:.3e} is over the mean tolerance {:.3e}: lower the tolerance",
            err.mean,
            opts.mean_tolerance.unwrap_or(f64::INFINITY)
        ));
    }
    report.default_level = level;
    report.control_vertices = control.vertex_count();
    report.control_faces = control.face_count();
    for g in &control.groups {
        *report.patch_kinds.entry(kind_name(&g.patch)).or_insert(0) += 1;
    }
    report
        .timings
        .push(("total", t_start.elapsed().as_secs_f64()));
    Ok(FitOutcome {
        control,
        coarser_quarter_bits: coarser_bits,
        default_level: level,
        report,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles of groups `a` and `b` touching at vertex 0 only, and a third group
    /// elsewhere: the error names the two faces around the pinch, not the third.
    #[test]
    fn faces_around_a_pinched_vertex_are_named() {
        let mut m = ControlMesh::new();
        for p in [
            DVec3::ZERO,
            DVec3::X,
            DVec3::Y,
            -DVec3::X,
            -DVec3::Y,
            DVec3::new(5.0, 0.0, 0.0),
            DVec3::new(6.0, 0.0, 0.0),
            DVec3::new(5.0, 1.0, 0.0),
        ] {
            m.push_vertex(p);
        }
        for name in ["a", "b", "c"] {
            m.push_group(name, PatchKind::Closed);
        }
        m.push_face(&[0, 1, 2], 0);
        m.push_face(&[0, 3, 4], 1);
        m.push_face(&[5, 6, 7], 2);
        let e = with_faces_involved(Error::Mesh("vertex 0 is pinched".into()), &m).to_string();
        assert!(e.contains("'a'") && e.contains("'b'"), "{e}");
        assert!(!e.contains("'c'"), "{e}");
        // Other errors pass through as they are.
        let e = with_faces_involved(Error::Parameter("p".into()), &m);
        assert!(matches!(e, Error::Parameter(_)));
    }

    /// A side used twice in one direction names the faces using it.
    #[test]
    fn faces_sharing_a_side_in_one_direction_are_named() {
        let mut m = ControlMesh::new();
        for p in [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::NEG_Y] {
            m.push_vertex(p);
        }
        m.push_group("a", PatchKind::Closed);
        m.push_group("b", PatchKind::Closed);
        m.push_face(&[0, 1, 2], 0);
        m.push_face(&[0, 1, 3], 1);
        let e = with_faces_involved(Error::Mesh("edge".into()), &m).to_string();
        assert!(e.contains("CAD faces involved: 'a', 'b'"), "{e}");
    }
}
