//! Conforming tessellation of one trimmed face: the face's triangles use exactly the points
//! of its edge polylines on its boundary, so neighbouring faces share their boundary
//! vertices by construction instead of by snapping.
//!
//! truck's own face tessellation (`robust_triangulation`) re-derives the boundary in the
//! surface's parameter plane and lets the constrained Delaunay triangulation drop or split
//! boundary constraints; on trimmed and periodic faces (tori, cones, spheres) it leaves
//! boundary vertices on no edge polyline, or tessellates the whole untrimmed surface, and the
//! welded model is then not a clean 2-manifold. Here the boundary is ours: every polyline
//! point is projected to (u, v) with truck's parameter search, periodic surfaces are cut
//! along a seam whose two copies share their vertices, the loops are inserted as constraints
//! of a spade CDT, interior points come from truck's `parameter_division` grid (kept away
//! from the boundary so no constraint is split), and triangles are kept by an even-odd test
//! against the loops. When any of this fails the caller falls back to truck's tessellation.

use std::collections::BTreeMap;

use glam::DVec3;
use spade::handles::FixedVertexHandle;
use spade::{ConstrainedDelaunayTriangulation, Point2 as SPoint2, Triangulation};
use truck_meshalgo::prelude::{
    ParameterDivision2D, ParametricSurface, Point3, SearchNearestParameter, SearchParameter, D2,
};
use truck_stepio::r#in::alias::Surface;

use super::analytic::Analytic;
use super::watch::Guarded;

/// A vertex of a conforming face mesh: a point of the shared pool (an edge polyline point),
/// or a point this face adds (interior grid points, points on a cut seam or at a pole).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum FaceVertex {
    Pool(u32),
    New(u32),
}

/// Triangles of one face over pool points and the face's own new points (body coordinates).
#[derive(Clone, Debug, Default)]
pub(super) struct ConformingMesh {
    pub new_points: Vec<DVec3>,
    /// Counter-clockwise in the surface's (u, v) plane, i.e. along the surface normal.
    pub triangles: Vec<[FaceVertex; 3]>,
}

/// A boundary point in the parameter plane with the vertex it stands for. The same vertex
/// may appear at several (u, v) (both sides of a seam, every point of a pole line).
#[derive(Clone, Copy, Debug, PartialEq)]
struct UvPoint {
    uv: [f64; 2],
    vertex: FaceVertex,
}

/// Most interior grid points accepted for one face (a runaway grid means a bad projection).
const MAX_GRID_POINTS: usize = 400_000;

fn p3(p: Point3) -> DVec3 {
    DVec3::new(p.x, p.y, p.z)
}

/// What the conforming tessellation needs of a surface: evaluation, inversion, periods,
/// domain edges and a parameter grid fine enough for the chordal tolerance. Implemented by
/// truck's converted surfaces (B-splines and the rest) and by our exact elementary surfaces
/// ([`Analytic`]), which follow the STEP record where truck's conversion can be wrong.
pub(super) trait UvSurface {
    /// For messages: how this surface was made (`" (as truck converts it)"` or empty).
    fn source(&self) -> &'static str;
    fn point(&self, u: f64, v: f64) -> DVec3;
    fn periods(&self) -> [Option<f64>; 2];
    /// Parameter ranges (a single open loop is closed against one of its ends).
    fn ranges(&self) -> [Option<(f64, f64)>; 2];
    /// Parameters of `p` (the nearest point of the surface), near `hint` if given.
    fn project(&self, p: DVec3, hint: Option<[f64; 2]>) -> Option<[f64; 2]>;
    /// A slower search for when [`UvSurface::project`] stopped in a local minimum: the
    /// parameters and the distance. `None` when there is nothing better to try.
    fn project_globally(&self, _p: DVec3) -> Option<([f64; 2], f64)> {
        None
    }
    /// Grid lines over `range` for the chordal tolerance `tol`.
    fn division(&self, range: ((f64, f64), (f64, f64)), tol: f64) -> (Vec<f64>, Vec<f64>);
}

impl UvSurface for Surface {
    fn source(&self) -> &'static str {
        " (as truck converts it)"
    }

    fn point(&self, u: f64, v: f64) -> DVec3 {
        p3(self.subs(u, v))
    }

    fn periods(&self) -> [Option<f64>; 2] {
        [self.u_period(), self.v_period()]
    }

    fn ranges(&self) -> [Option<(f64, f64)>; 2] {
        let (u, v) = self.try_range_tuple();
        [u, v]
    }

    fn project(&self, p: DVec3, hint: Option<[f64; 2]>) -> Option<[f64; 2]> {
        let pt = Point3::new(p.x, p.y, p.z);
        let h = hint.map(|h| (h[0], h[1]));
        SearchParameter::<D2>::search_parameter(self, pt, h, 100)
            .or_else(|| SearchParameter::<D2>::search_parameter(self, pt, None, 100))
            .or_else(|| SearchNearestParameter::<D2>::search_nearest_parameter(self, pt, h, 100))
            .or_else(|| SearchNearestParameter::<D2>::search_nearest_parameter(self, pt, None, 100))
            .map(|(u, v)| [u, v])
    }

    fn project_globally(&self, p: DVec3) -> Option<([f64; 2], f64)> {
        project_from_grid(self, p, self.periods())
    }

    fn division(&self, range: ((f64, f64), (f64, f64)), tol: f64) -> (Vec<f64>, Vec<f64>) {
        self.parameter_division(range, tol)
    }
}

impl UvSurface for Analytic {
    fn source(&self) -> &'static str {
        " (exact, from its STEP record)"
    }

    fn point(&self, u: f64, v: f64) -> DVec3 {
        Analytic::point(self, u, v)
    }

    fn periods(&self) -> [Option<f64>; 2] {
        Analytic::periods(self)
    }

    fn ranges(&self) -> [Option<(f64, f64)>; 2] {
        Analytic::ranges(self)
    }

    fn project(&self, p: DVec3, hint: Option<[f64; 2]>) -> Option<[f64; 2]> {
        Some(Analytic::project(self, p, hint))
    }

    fn division(&self, range: ((f64, f64), (f64, f64)), tol: f64) -> (Vec<f64>, Vec<f64>) {
        Analytic::division(self, range, tol)
    }
}

/// A surface whose evaluations stop the tessellation when its job is cancelled (see
/// `watch`): every loop of the tessellation evaluates or projects, so each polls.
impl<S: UvSurface> UvSurface for Guarded<S> {
    fn source(&self) -> &'static str {
        self.inner.source()
    }

    fn point(&self, u: f64, v: f64) -> DVec3 {
        self.get().point(u, v)
    }

    fn periods(&self) -> [Option<f64>; 2] {
        self.inner.periods()
    }

    fn ranges(&self) -> [Option<(f64, f64)>; 2] {
        self.inner.ranges()
    }

    fn project(&self, p: DVec3, hint: Option<[f64; 2]>) -> Option<[f64; 2]> {
        self.get().project(p, hint)
    }

    fn project_globally(&self, p: DVec3) -> Option<([f64; 2], f64)> {
        self.get().project_globally(p)
    }

    fn division(&self, range: ((f64, f64), (f64, f64)), tol: f64) -> (Vec<f64>, Vec<f64>) {
        self.get().division(range, tol)
    }
}

/// A surface over a parameter plane whose axes are stretched by `scale`: `(s_u u, s_v v)`.
///
/// Why: Delaunay triangles and the refinement's "next to the boundary" test are only as
/// good as the plane's distances, and parameters are often in incomparable units (a cone's
/// angle in radians against its height in millimetres). On a 500 mm cone strip 15 degrees
/// wide and 12 mm tall (corpus trj6) the raw plane is 500 times squashed along the angle:
/// there the triangulation joins boundary points 130 mm apart across the strip, facets sag
/// 4 mm from the cone against a 0.08 mm chordal tolerance, and every refinement point is
/// refused as "next to the boundary". Scaled by the surface's mean speed along each
/// parameter, plane distances are close to surface distances. The fitted bytes follow the
/// input triangles chaotically (the stretched plane makes some corpus files smaller by
/// 10-15% and others larger by as much), so the encoder also tries the raw plane.
struct Stretched<'a, S: UvSurface> {
    inner: &'a S,
    scale: [f64; 2],
}

impl<S: UvSurface> Stretched<'_, S> {
    fn plane_point(&self, uv: [f64; 2]) -> [f64; 2] {
        [uv[0] * self.scale[0], uv[1] * self.scale[1]]
    }

    fn parameters_of(&self, p: [f64; 2]) -> [f64; 2] {
        [p[0] / self.scale[0], p[1] / self.scale[1]]
    }
}

impl<S: UvSurface> UvSurface for Stretched<'_, S> {
    fn source(&self) -> &'static str {
        self.inner.source()
    }

    fn point(&self, u: f64, v: f64) -> DVec3 {
        let [u, v] = self.parameters_of([u, v]);
        self.inner.point(u, v)
    }

    fn periods(&self) -> [Option<f64>; 2] {
        let p = self.inner.periods();
        [0, 1].map(|k| p[k].map(|x| x * self.scale[k]))
    }

    fn ranges(&self) -> [Option<(f64, f64)>; 2] {
        let r = self.inner.ranges();
        [0, 1].map(|k| r[k].map(|(a, b)| (a * self.scale[k], b * self.scale[k])))
    }

    fn project(&self, p: DVec3, hint: Option<[f64; 2]>) -> Option<[f64; 2]> {
        let hint = hint.map(|h| self.parameters_of(h));
        self.inner.project(p, hint).map(|uv| self.plane_point(uv))
    }

    fn project_globally(&self, p: DVec3) -> Option<([f64; 2], f64)> {
        self.inner
            .project_globally(p)
            .map(|(uv, d)| (self.plane_point(uv), d))
    }

    fn division(&self, range: ((f64, f64), (f64, f64)), tol: f64) -> (Vec<f64>, Vec<f64>) {
        let [s, t] = self.scale;
        let ((u0, u1), (v0, v1)) = range;
        let (u, v) = self
            .inner
            .division(((u0 / s, u1 / s), (v0 / t, v1 / t)), tol);
        (
            u.into_iter().map(|x| x * s).collect(),
            v.into_iter().map(|x| x * t).collect(),
        )
    }
}

/// Lowest and highest (u, v) of all loops' points (infinite when there are none).
fn parameter_box(loops: &[Vec<UvPoint>]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in loops.iter().flatten() {
        for k in 0..2 {
            lo[k] = lo[k].min(p.uv[k]);
            hi[k] = hi[k].max(p.uv[k]);
        }
    }
    (lo, hi)
}

/// Mean speed of the surface along each parameter (surface length per parameter unit) over
/// a 5 x 5 grid of the loops' parameter box, by central differences; 1 where it is not a
/// positive finite number (a degenerate box, a surface that does not move).
fn metric_scale<S: UvSurface>(surface: &S, loops: &[Vec<UvPoint>]) -> [f64; 2] {
    let (lo, hi) = parameter_box(loops);
    const N: usize = 5;
    let mut scale = [1.0; 2];
    for (k, s) in scale.iter_mut().enumerate() {
        let h = 1e-4 * (hi[k] - lo[k]);
        if !(h.is_finite() && h > 0.0) {
            continue;
        }
        // Middle of cell `x` of the box along parameter `m`.
        let mid = |x: usize, m: usize| lo[m] + (hi[m] - lo[m]) * (x as f64 + 0.5) / N as f64;
        let (mut sum, mut n) = (0.0, 0usize);
        for i in 0..N {
            for j in 0..N {
                let c = [mid(i, 0), mid(j, 1)];
                let (mut a, mut b) = (c, c);
                a[k] -= h;
                b[k] += h;
                let speed = surface
                    .point(b[0], b[1])
                    .distance(surface.point(a[0], a[1]))
                    / (2.0 * h);
                if speed.is_finite() {
                    sum += speed;
                    n += 1;
                }
            }
        }
        let mean = sum / n.max(1) as f64;
        if mean.is_finite() && mean > 1e-12 {
            *s = mean;
        }
    }
    scale
}

/// Nearest-point search started from an 8 x 8 grid over one period (or the surface's
/// range) in each parameter; the best result with its distance.
fn project_from_grid(
    surface: &Surface,
    p: DVec3,
    periods: [Option<f64>; 2],
) -> Option<([f64; 2], f64)> {
    let (ur, vr) = surface.try_range_tuple();
    let span = |period: Option<f64>, range: Option<(f64, f64)>| match (period, range) {
        (Some(t), _) => Some((0.0, t)),
        (None, Some((a, b))) if a.is_finite() && b.is_finite() => Some((a, b)),
        _ => None,
    };
    let (u0, u1) = span(periods[0], ur)?;
    let (v0, v1) = span(periods[1], vr)?;
    let pt = Point3::new(p.x, p.y, p.z);
    let mut best: Option<([f64; 2], f64)> = None;
    for i in 0..8 {
        for j in 0..8 {
            let hint = (
                u0 + (u1 - u0) * (f64::from(i) + 0.5) / 8.0,
                v0 + (v1 - v0) * (f64::from(j) + 0.5) / 8.0,
            );
            let found =
                SearchNearestParameter::<D2>::search_nearest_parameter(surface, pt, hint, 100);
            if let Some((u, v)) = found {
                let d = surface.point(u, v).distance(p);
                if best.is_none_or(|b| d < b.1) {
                    best = Some(([u, v], d));
                }
            }
        }
    }
    best
}

/// The representative of `x` (modulo `period`) nearest to `reference`.
fn nearest_rep(x: f64, reference: f64, period: Option<f64>) -> f64 {
    match period {
        Some(p) if p > 0.0 => x + ((reference - x) / p).round() * p,
        _ => x,
    }
}

/// A boundary point farther than this fraction of the chordal tolerance from the surface at
/// its parameters is projected again (edge points lie on their faces' surfaces to the
/// file's precision, far closer than that).
const REPROJECT_OFF: f64 = 0.1;

/// Projects again, from between its nearest well-projected neighbours along the loop, each
/// point of a projected loop whose search stopped off the surface, and keeps the new
/// parameters when they are nearer; then unwraps periodic parameters along the loop again.
/// The search from the previous point's parameters can stop in a local minimum a few
/// tolerances off the surface (linkrods: a rational B-spline strip, three points in a row
/// up to 16 tolerances off, put next to the strip's far edge, so the loop crosses itself),
/// while a start between the neighbours on either side finds the point.
fn reproject_between_neighbours<S: UvSurface>(
    surface: &S,
    lp: &[(u32, DVec3)],
    pts: &mut [UvPoint],
    offs: &mut [f64],
    tol: f64,
) {
    let periods = surface.periods();
    let good = |o: f64| o <= REPROJECT_OFF * tol;
    let n = pts.len();
    if offs.iter().all(|&o| good(o)) || !offs.iter().any(|&o| good(o)) {
        return;
    }
    let mut changed = false;
    for i in 0..n {
        if good(offs[i]) {
            continue;
        }
        let before = (1..n).map(|k| (i + n - k) % n).find(|&j| good(offs[j]));
        let after = (1..n).map(|k| (i + k) % n).find(|&j| good(offs[j]));
        let (Some(b), Some(a)) = (before, after) else {
            continue;
        };
        let (db, da) = ((i + n - b) % n, (a + n - i) % n);
        let t = db as f64 / (db + da) as f64;
        let ub = pts[b].uv;
        let ua = [0, 1].map(|k| nearest_rep(pts[a].uv[k], ub[k], periods[k]));
        let hint = [0, 1].map(|k| ub[k] + t * (ua[k] - ub[k]));
        let p = lp[i].1;
        let Some(uv) = surface.project(p, Some(hint)) else {
            continue;
        };
        let off = surface.point(uv[0], uv[1]).distance(p);
        if off < offs[i] {
            pts[i].uv = [0, 1].map(|k| nearest_rep(uv[k], hint[k], periods[k]));
            offs[i] = off;
            changed = true;
        }
    }
    if changed {
        for i in 1..n {
            let q = pts[i - 1].uv;
            for k in 0..2 {
                pts[i].uv[k] = nearest_rep(pts[i].uv[k], q[k], periods[k]);
            }
        }
    }
}

/// Tessellates the face of `surface` bounded by `loops` (each a cyclic list of pool vertices
/// with their body-coordinate positions, in the face's wire order). `tol` is the chordal
/// tolerance in body units. With `stretch`, the parameter plane is stretched to the
/// surface's lengths first ([`Stretched`]). Errors say why the face cannot be done this way.
/// A face without loops is the whole of a closed surface ([`whole_surface`]).
pub(super) fn conforming_tessellation<S: UvSurface>(
    surface: &S,
    loops: &[Vec<(u32, DVec3)>],
    tol: f64,
    stretch: bool,
) -> Result<ConformingMesh, String> {
    if loops.is_empty() {
        return whole_surface(surface, tol);
    }
    let periods = surface.periods();
    let mut out = ConformingMesh::default();
    // 1. Project every loop, unwrapping periodic parameters along it.
    let mut closed: Vec<Vec<UvPoint>> = Vec::new();
    let mut open: Vec<OpenLoop> = Vec::new();
    for lp in loops {
        match project_loop(surface, lp, tol)? {
            ProjectedLoop::Closed(pts) => closed.push(pts),
            ProjectedLoop::Open(o) => open.push(o),
        }
    }
    // 2. Close open loops along a cut seam (two loops) or the domain's edge (one loop).
    let division = checked_division(surface, uv_range(&closed, &open), tol)?;
    close_open_loops(surface, &mut closed, open, &division, tol, &mut out)?;
    // 3. Loops of a periodic surface must lie in one period.
    bring_into_one_period(&mut closed, periods);
    // The inside test is even-odd, so loop orientation does not matter past this point
    // (some files' loops run clockwise in truck's parameters; the caller orients faces).
    let pool_xyz: BTreeMap<u32, DVec3> = loops.iter().flatten().copied().collect();
    // 4. Triangulate in a plane stretched to the surface's lengths (see `Stretched`).
    let scale = if stretch {
        metric_scale(surface, &closed)
    } else {
        [1.0, 1.0]
    };
    let stretched = Stretched {
        inner: surface,
        scale,
    };
    let mut plane_loops = closed.clone();
    for p in plane_loops.iter_mut().flatten() {
        p.uv = stretched.plane_point(p.uv);
    }
    triangulate(&stretched, &plane_loops, &pool_xyz, tol, out).map_err(|e| {
        format!(
            "{e} ({} loops: {}; periods {:?})",
            loops.len(),
            describe(&closed),
            periods
        )
    })
}

/// A boundary loop that is closed in 3D but not in (u, v): it goes once round a period.
#[derive(Default)]
struct OpenLoop {
    /// Its points, with the first repeated at the end, shifted by the period.
    points: Vec<UvPoint>,
    /// The parameter whose period it goes round.
    axis: usize,
    /// The sign of the shift.
    sign: f64,
}

/// A boundary loop in the parameter plane.
enum ProjectedLoop {
    Closed(Vec<UvPoint>),
    Open(OpenLoop),
}

/// Projects a loop of pool vertices into the parameter plane, unwrapping periodic
/// parameters along it, and tells whether it closes there. An error when a point cannot be
/// projected or the loop wraps round both periods.
fn project_loop<S: UvSurface>(
    surface: &S,
    lp: &[(u32, DVec3)],
    tol: f64,
) -> Result<ProjectedLoop, String> {
    if lp.len() < 2 {
        return Err(format!("a boundary loop has {} points", lp.len()));
    }
    let periods = surface.periods();
    let pts = project_points(surface, lp, tol)?;
    let (mut pts, poles) = split_singular(surface, pts);
    let first = pts[0].uv;
    let last = pts[pts.len() - 1].uv;
    let mut shift = [0.0; 2];
    for k in 0..2 {
        shift[k] = nearest_rep(first[k], last[k], periods[k]) - first[k];
    }
    let open_axes: Vec<usize> = (0..2).filter(|&k| shift[k].abs() > 1e-9).collect();
    // A loop that goes round the period and through a pole (a cap bounded by a circle and a
    // seam edge up to the pole and back): it is closed in (u, v) along the pole line, so
    // from the pole on its points lie one period back.
    if let [k] = open_axes.as_slice() {
        if let Some(&(i, _)) = poles.iter().find(|p| p.1 == *k) {
            let pole = pts[i];
            let second_copy = pts
                .get(i + 1)
                .is_some_and(|q| q.vertex == pole.vertex && q.uv[1 - k] == pole.uv[1 - k]);
            if !second_copy {
                pts.insert(i + 1, pole);
            }
            for p in &mut pts[i + 1..] {
                p.uv[*k] -= shift[*k];
            }
            return Ok(ProjectedLoop::Closed(pts));
        }
    }
    match open_axes.as_slice() {
        [] => Ok(ProjectedLoop::Closed(pts)),
        [k] => {
            let mut end = pts[0];
            end.uv[*k] += shift[*k];
            pts.push(end);
            Ok(ProjectedLoop::Open(OpenLoop {
                points: pts,
                axis: *k,
                sign: shift[*k].signum(),
            }))
        }
        _ => Err("a boundary loop wraps around both periods".into()),
    }
}

/// The parameters of each point of a loop, each searched from the previous point's and
/// unwrapped next to them. An error when a point cannot be projected or the surface passes
/// more than 10 tolerances from it.
fn project_points<S: UvSurface>(
    surface: &S,
    lp: &[(u32, DVec3)],
    tol: f64,
) -> Result<Vec<UvPoint>, String> {
    let periods = surface.periods();
    let mut pts: Vec<UvPoint> = Vec::with_capacity(lp.len() + 1);
    // Distance of each point from the surface at its parameters.
    let mut offs: Vec<f64> = Vec::with_capacity(lp.len());
    let mut prev: Option<[f64; 2]> = None;
    for &(id, p) in lp {
        let Some(mut uv) = surface.project(p, prev) else {
            return Err("a boundary point could not be projected onto the surface".into());
        };
        let mut off = surface.point(uv[0], uv[1]).distance(p);
        if off > 10.0 * tol {
            // The search can stop in a local minimum (tori): restart it from a grid.
            if let Some((best, d)) = surface.project_globally(p) {
                if d < off {
                    uv = best;
                    off = d;
                }
            }
        }
        if off > 10.0 * tol {
            return Err(format!(
                "the surface{} passes {off:.3e} from the face's edges",
                surface.source()
            ));
        }
        if let Some(q) = prev {
            for k in 0..2 {
                uv[k] = nearest_rep(uv[k], q[k], periods[k]);
            }
        }
        prev = Some(uv);
        offs.push(off);
        pts.push(UvPoint {
            uv,
            vertex: FaceVertex::Pool(id),
        });
    }
    reproject_between_neighbours(surface, lp, &mut pts, &mut offs, tol);
    Ok(pts)
}

/// The (u, v) range of all points of the closed and the open loops.
fn uv_range(closed: &[Vec<UvPoint>], open: &[OpenLoop]) -> ((f64, f64), (f64, f64)) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in closed
        .iter()
        .flatten()
        .chain(open.iter().flat_map(|o| o.points.iter()))
    {
        for k in 0..2 {
            lo[k] = lo[k].min(p.uv[k]);
            hi[k] = hi[k].max(p.uv[k]);
        }
    }
    ((lo[0], hi[0]), (lo[1], hi[1]))
}

/// Closes the open loops into `closed`: two that bound a band along a seam cut across it
/// ([`band_loop`]), one along the domain's edge ([`domain_edge_loop`]). Points on the seam
/// and the edge are new points of `out`. An error for open loops that cannot be closed so.
fn close_open_loops<S: UvSurface>(
    surface: &S,
    closed: &mut Vec<Vec<UvPoint>>,
    mut open: Vec<OpenLoop>,
    division: &(Vec<f64>, Vec<f64>),
    tol: f64,
    out: &mut ConformingMesh,
) -> Result<(), String> {
    match open.len() {
        0 => {}
        2 => {
            let o1 = open.pop().unwrap_or_default();
            let o0 = open.pop().unwrap_or_default();
            closed.push(band_loop(surface, o0, o1, division, out)?);
        }
        1 => {
            let o = open.pop().unwrap_or_default();
            closed.push(domain_edge_loop(surface, o, division, tol, out)?);
        }
        n => return Err(format!("{n} open boundary loops")),
    }
    Ok(())
}

/// Two open loops that bound a band round a period, as one closed loop: the one going the
/// positive way, a seam from its end to the other's start, the other, and the seam's other
/// copy (reversed, one period back).
fn band_loop<S: UvSurface>(
    surface: &S,
    o0: OpenLoop,
    o1: OpenLoop,
    division: &(Vec<f64>, Vec<f64>),
    out: &mut ConformingMesh,
) -> Result<Vec<UvPoint>, String> {
    if o0.axis != o1.axis || o0.sign == o1.sign {
        return Err("two open boundary loops that do not bound a band".into());
    }
    let (mut c0, mut c1) = if o0.sign > 0.0 {
        (o0.points, o1.points)
    } else {
        (o1.points, o0.points)
    };
    let k = o0.axis;
    let period = surface.periods()[k].unwrap_or(0.0);
    // Bring c1's start next to c0's end.
    let target = c0[c0.len() - 1].uv[k];
    let d = nearest_rep(c1[0].uv[k], target, Some(period)) - c1[0].uv[k];
    for p in &mut c1 {
        p.uv[k] += d;
    }
    let a = c0[c0.len() - 1].uv;
    let b = c1[0].uv;
    let seam = seam_points(surface, a, b, division, out);
    let mut lp: Vec<UvPoint> = Vec::new();
    lp.append(&mut c0);
    lp.extend(seam.iter().copied());
    lp.extend(c1.iter().copied());
    for p in seam.iter().rev() {
        let mut q = *p;
        q.uv[k] -= period;
        lp.push(q);
    }
    Ok(lp)
}

/// One open loop closed along the edge of the domain on the side where the face lies: the
/// loop, a seam from its end to that edge, the edge back to the seam, and the seam's other
/// copy. An error when the other parameter has no range to give the edge.
fn domain_edge_loop<S: UvSurface>(
    surface: &S,
    o: OpenLoop,
    division: &(Vec<f64>, Vec<f64>),
    tol: f64,
    out: &mut ConformingMesh,
) -> Result<Vec<UvPoint>, String> {
    let OpenLoop {
        points: mut c0,
        axis: k,
        sign: s,
    } = o;
    let other = 1 - k;
    let Some((b0, b1)) = surface.ranges()[other] else {
        return Err("an open boundary loop on a surface without a domain edge".into());
    };
    let period = surface.periods()[k].unwrap_or(0.0);
    // Counter-clockwise: going +u the face lies towards +v, going +v towards -u.
    let towards_max = (k == 0) == (s > 0.0);
    let edge = if towards_max { b1 } else { b0 };
    let start = c0[0].uv;
    let end = c0[c0.len() - 1].uv;
    let mut corner_end = end;
    corner_end[other] = edge;
    let mut corner_start = start;
    corner_start[other] = edge;
    // end -> corner_end (a seam), corner_end -> corner_start (the domain edge),
    // corner_start -> start (the seam's other copy).
    let seam = seam_points(surface, end, corner_end, division, out);
    let (along, corner_vertex) =
        edge_points(surface, corner_end, corner_start, division, k, tol, out);
    let mut lp: Vec<UvPoint> = Vec::new();
    lp.append(&mut c0);
    lp.extend(seam.iter().copied());
    lp.push(UvPoint {
        uv: corner_end,
        vertex: corner_vertex,
    });
    lp.extend(along.iter().copied());
    lp.push(UvPoint {
        uv: corner_start,
        vertex: corner_vertex,
    });
    for p in seam.iter().rev() {
        let mut q = *p;
        q.uv[k] -= s * period;
        lp.push(q);
    }
    Ok(lp)
}

/// Lowest and highest value of parameter `k` over a loop's points.
fn loop_extent(lp: &[UvPoint], k: usize) -> (f64, f64) {
    lp.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| {
        (a.0.min(p.uv[k]), a.1.max(p.uv[k]))
    })
}

/// Shifts each loop by whole periods so that all lie in the period of the widest one (the
/// outer loop on a periodic band).
fn bring_into_one_period(closed: &mut [Vec<UvPoint>], periods: [Option<f64>; 2]) {
    if closed.len() < 2 {
        return;
    }
    let centre = |lp: &[UvPoint], k: usize| {
        let (lo, hi) = loop_extent(lp, k);
        0.5 * (lo + hi)
    };
    let width = |lp: &[UvPoint]| {
        (0..2)
            .map(|k| {
                let (lo, hi) = loop_extent(lp, k);
                hi - lo
            })
            .sum::<f64>()
    };
    let widest = (0..closed.len())
        .max_by(|&a, &b| width(&closed[a]).total_cmp(&width(&closed[b])))
        .unwrap_or(0);
    for (k, period) in periods.iter().enumerate() {
        let Some(period) = *period else { continue };
        let reference = centre(&closed[widest], k);
        for lp in closed.iter_mut() {
            let c = centre(lp, k);
            let d = nearest_rep(c, reference, Some(period)) - c;
            if d != 0.0 {
                for p in lp.iter_mut() {
                    p.uv[k] += d;
                }
            }
        }
    }
}

/// The whole of a closed surface, for a face bounded only by a VERTEX_LOOP or by nothing (a
/// ball of a bearing in corpus trj4 is one SPHERICAL_SURFACE face whose only bound is the
/// vertex at its pole): the parameter grid over one period of a periodic parameter and
/// either one period of the other (a torus) or its range between two poles (a sphere),
/// each pole one vertex. Triangles are counter-clockwise in (u, v) like the trimmed ones.
fn whole_surface<S: UvSurface>(surface: &S, tol: f64) -> Result<ConformingMesh, String> {
    let not_closed = || {
        format!(
            "the face has no boundary, but its surface{} is not closed",
            surface.source()
        )
    };
    let [Some(pu), pv] = surface.periods() else {
        return Err(not_closed());
    };
    let (v0, v1, poles) = match (pv, surface.ranges()[1]) {
        (Some(p), _) => (0.0, p, false),
        (None, Some((a, b))) => {
            // Both ends of the range must be points (poles), else the surface is open there.
            let collapsed = |v: f64| {
                let p0 = surface.point(0.0, v);
                (1..4).all(|k| surface.point(pu * f64::from(k) / 4.0, v).distance(p0) <= tol)
            };
            if !(collapsed(a) && collapsed(b)) {
                return Err(not_closed());
            }
            (a, b, true)
        }
        (None, None) => return Err(not_closed()),
    };
    // The grid's lines meet the tolerance, but a cell's diagonal is about 1.4 times as long
    // as its sides and sags twice as much: half the tolerance for the lines.
    let (udiv, vdiv) = checked_division(surface, ((0.0, pu), (v0, v1)), 0.5 * tol)?;
    // As many steps as the grid, evenly spaced (the elementary surfaces' grids are).
    let steps = |d: &[f64], min: usize| d.len().saturating_sub(1).max(min);
    let (nu, nv) = (steps(&udiv, 3), steps(&vdiv, if poles { 2 } else { 3 }));
    let u = |i: usize| pu * (i % nu) as f64 / nu as f64;
    let v = |j: usize| v0 + (v1 - v0) * j as f64 / nv as f64;
    let mut out = ConformingMesh::default();
    // Rows of the grid, row by row: all rows of a torus (the last wraps to the first), the
    // rows strictly between the poles of a sphere.
    let first_row = usize::from(poles);
    for j in first_row..nv {
        for i in 0..nu {
            out.new_points.push(surface.point(u(i), v(j)));
        }
    }
    let at = |i: usize, j: usize| {
        let row = if poles { j } else { j % nv } - first_row;
        FaceVertex::New((row * nu + i % nu) as u32)
    };
    let quads = if poles { 1..nv - 1 } else { 0..nv };
    for j in quads {
        for i in 0..nu {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            out.triangles.push([a, b, c]);
            out.triangles.push([a, c, d]);
        }
    }
    if poles {
        let south = FaceVertex::New(out.new_points.len() as u32);
        out.new_points.push(surface.point(0.0, v0));
        let north = FaceVertex::New(out.new_points.len() as u32);
        out.new_points.push(surface.point(0.0, v1));
        for i in 0..nu {
            out.triangles.push([south, at(i + 1, 1), at(i, 1)]);
            out.triangles
                .push([at(i, nv - 1), at(i + 1, nv - 1), north]);
        }
    }
    Ok(out)
}

/// Replaces each boundary point at a singular point of the surface (a pole or apex, where
/// one parameter does not move the point) by two copies that continue the neighbours'
/// free parameter, as truck does, so the loop does not jump across the parameter plane.
///
/// Also returns, for each such point, the index of its first copy in the result and the
/// free parameter (the one that does not move the point).
fn split_singular<S: UvSurface>(
    surface: &S,
    pts: Vec<UvPoint>,
) -> (Vec<UvPoint>, Vec<(usize, usize)>) {
    let n = pts.len();
    let singular: Vec<Option<usize>> = pts
        .iter()
        .map(|p| {
            // Central differences in 3D (some inverted truck surfaces report derivatives
            // that do not match their points).
            let at = |du: f64, dv: f64| surface.point(p.uv[0] + du, p.uv[1] + dv);
            let h = 1e-4;
            let su = at(h, 0.0).distance(at(-h, 0.0));
            let sv = at(0.0, h).distance(at(0.0, -h));
            if su < 1e-9 * sv.max(1e-300) {
                Some(0)
            } else if sv < 1e-9 * su.max(1e-300) {
                Some(1)
            } else {
                None
            }
        })
        .collect();
    if singular.iter().all(Option::is_none) {
        return (pts, Vec::new());
    }
    let mut out = Vec::with_capacity(n + 4);
    let mut poles = Vec::new();
    for i in 0..n {
        let Some(k) = singular[i] else {
            out.push(pts[i]);
            continue;
        };
        let prev = pts[(i + n - 1) % n].uv[k];
        let next = pts[(i + 1) % n].uv[k];
        let mut a = pts[i];
        a.uv[k] = prev;
        poles.push((out.len(), k));
        out.push(a);
        if (next - prev).abs() > 1e-12 {
            let mut b = pts[i];
            b.uv[k] = next;
            out.push(b);
        }
    }
    (out, poles)
}

/// truck's parameter grid over `range`, refusing runaway sizes.
fn checked_division<S: UvSurface>(
    surface: &S,
    range: ((f64, f64), (f64, f64)),
    tol: f64,
) -> Result<(Vec<f64>, Vec<f64>), String> {
    let finite = [range.0 .0, range.0 .1, range.1 .0, range.1 .1]
        .iter()
        .all(|x| x.is_finite());
    if !finite {
        return Err("the boundary's parameter range is not finite".into());
    }
    let (u, v) = surface.division(range, tol);
    if u.len().saturating_mul(v.len()) > MAX_GRID_POINTS {
        return Err(format!(
            "the parameter grid would have {} x {} points",
            u.len(),
            v.len()
        ));
    }
    Ok((u, v))
}

/// Interior points of the seam segment `a -> b` in (u, v), one per grid line it crosses in
/// its main direction (at least none), as new vertices.
fn seam_points<S: UvSurface>(
    surface: &S,
    a: [f64; 2],
    b: [f64; 2],
    division: &(Vec<f64>, Vec<f64>),
    out: &mut ConformingMesh,
) -> Vec<UvPoint> {
    let n = segments_along(a, b, division);
    (1..n)
        .map(|i| {
            let t = i as f64 / n as f64;
            let uv = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            out.new_points.push(surface.point(uv[0], uv[1]));
            UvPoint {
                uv,
                vertex: FaceVertex::New(out.new_points.len() as u32 - 1),
            }
        })
        .collect()
}

/// Interior points of the domain-edge segment `a -> b` (along axis `k`) and the vertex of
/// its corners. A degenerate edge (a pole: every point at one position) is one vertex.
fn edge_points<S: UvSurface>(
    surface: &S,
    a: [f64; 2],
    b: [f64; 2],
    division: &(Vec<f64>, Vec<f64>),
    k: usize,
    tol: f64,
    out: &mut ConformingMesh,
) -> (Vec<UvPoint>, FaceVertex) {
    let _ = k;
    let n = segments_along(a, b, division).max(2);
    let pts: Vec<[f64; 2]> = (0..=n)
        .map(|i| {
            let t = i as f64 / n as f64;
            [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
        })
        .collect();
    let xyz: Vec<DVec3> = pts.iter().map(|uv| surface.point(uv[0], uv[1])).collect();
    let degenerate = xyz.iter().all(|p| p.distance(xyz[0]) <= 1e-3 * tol);
    if degenerate {
        out.new_points.push(xyz[0]);
        let v = FaceVertex::New(out.new_points.len() as u32 - 1);
        let along = pts[1..n]
            .iter()
            .map(|&uv| UvPoint { uv, vertex: v })
            .collect();
        return (along, v);
    }
    // A real edge of the domain (an open face boundary): its corners are the two copies of
    // one seam end, so they share one vertex.
    out.new_points.push(xyz[0]);
    let corner = FaceVertex::New(out.new_points.len() as u32 - 1);
    let along = (1..n)
        .map(|i| {
            out.new_points.push(xyz[i]);
            UvPoint {
                uv: pts[i],
                vertex: FaceVertex::New(out.new_points.len() as u32 - 1),
            }
        })
        .collect();
    (along, corner)
}

/// Number of segments for a straight (u, v) segment: the grid lines it crosses, at least 1.
fn segments_along(a: [f64; 2], b: [f64; 2], division: &(Vec<f64>, Vec<f64>)) -> usize {
    let count = |d: &[f64], x: f64, y: f64| {
        let (lo, hi) = (x.min(y), x.max(y));
        d.iter().filter(|&&t| t > lo && t < hi).count()
    };
    let n = count(&division.0, a[0], b[0]).max(count(&division.1, a[1], b[1]));
    (n + 1).min(4096)
}

/// spade refuses coordinates below its smallest allowed magnitude; those are zero.
fn spade_round(x: f64) -> f64 {
    if x.abs() < spade::MIN_ALLOWED_VALUE {
        0.0
    } else {
        x
    }
}

/// Short description of loops for messages: size, signed area and parameter box.
fn describe(loops: &[Vec<UvPoint>]) -> String {
    loops
        .iter()
        .map(|l| {
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for p in l {
                for k in 0..2 {
                    lo[k] = lo[k].min(p.uv[k]);
                    hi[k] = hi[k].max(p.uv[k]);
                }
            }
            format!(
                "[{} points, area {:.3e}, u {:.3}..{:.3}, v {:.3}..{:.3}]",
                l.len(),
                signed_area(l),
                lo[0],
                hi[0],
                lo[1],
                hi[1]
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

fn signed_area(lp: &[UvPoint]) -> f64 {
    let n = lp.len();
    (0..n)
        .map(|i| {
            let (p, q) = (lp[i].uv, lp[(i + 1) % n].uv);
            p[0] * q[1] - q[0] * p[1]
        })
        .sum::<f64>()
        * 0.5
}

/// Even-odd inside test against all loops.
fn inside(loops: &[Vec<UvPoint>], c: [f64; 2]) -> bool {
    let mut odd = false;
    for lp in loops {
        let n = lp.len();
        for i in 0..n {
            let (p, q) = (lp[i].uv, lp[(i + 1) % n].uv);
            if (p[1] > c[1]) != (q[1] > c[1]) {
                let x = p[0] + (c[1] - p[1]) / (q[1] - p[1]) * (q[0] - p[0]);
                if x > c[0] {
                    odd = !odd;
                }
            }
        }
    }
    odd
}

/// Squared distance from `c` to segment `p q`, after scaling the axes by `s`.
fn scaled_segment_distance2(c: [f64; 2], p: [f64; 2], q: [f64; 2], s: [f64; 2]) -> f64 {
    let (cx, cy) = (c[0] * s[0], c[1] * s[1]);
    let (px, py) = (p[0] * s[0], p[1] * s[1]);
    let (qx, qy) = (q[0] * s[0], q[1] * s[1]);
    let (dx, dy) = (qx - px, qy - py);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((cx - px) * dx + (cy - py) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (ex, ey) = (px + t * dx - cx, py + t * dy - cy);
    ex * ex + ey * ey
}

/// Triangulates the face bounded by `loops` (closed, in one period of the parameter plane)
/// into `out`: the loops are the constraints of a CDT, interior grid points and refinement
/// points bring its triangles within `tol` of the surface, and the triangles inside the
/// loops are kept. `pool_xyz` gives the boundary vertices' positions. Errors say why the
/// face cannot be done this way.
fn triangulate<S: UvSurface>(
    surface: &S,
    loops: &[Vec<UvPoint>],
    pool_xyz: &BTreeMap<u32, DVec3>,
    tol: f64,
    out: ConformingMesh,
) -> Result<ConformingMesh, String> {
    let mut face = FaceCdt::new(surface, loops, pool_xyz, tol, out);
    let handles = face.insert_boundary()?;
    face.constrain_loops(&handles)?;
    let constraints = face.cdt.num_constraints();
    face.insert_grid()?;
    face.refine(constraints)?;
    face.keep_inside_triangles()?;
    if face.out.triangles.is_empty() {
        return Err("no triangle inside the boundary".into());
    }
    Ok(face.out)
}

/// The constrained Delaunay triangulation of one face in its parameter plane, with the
/// face vertex each CDT vertex stands for and the mesh it becomes.
struct FaceCdt<'a, S: UvSurface> {
    surface: &'a S,
    loops: &'a [Vec<UvPoint>],
    /// Positions of the boundary's pool vertices.
    pool_xyz: &'a BTreeMap<u32, DVec3>,
    tol: f64,
    /// The loops' sides.
    segments: Vec<([f64; 2], [f64; 2])>,
    cdt: ConstrainedDelaunayTriangulation<SPoint2<f64>>,
    /// Vertex of each CDT vertex (by handle index).
    vertex_of: Vec<Option<FaceVertex>>,
    /// New vertices found to coincide with an edge point.
    alias: BTreeMap<u32, FaceVertex>,
    out: ConformingMesh,
}

impl<'a, S: UvSurface> FaceCdt<'a, S> {
    fn new(
        surface: &'a S,
        loops: &'a [Vec<UvPoint>],
        pool_xyz: &'a BTreeMap<u32, DVec3>,
        tol: f64,
        out: ConformingMesh,
    ) -> Self {
        let segments = loops
            .iter()
            .flat_map(|lp| (0..lp.len()).map(move |i| (lp[i].uv, lp[(i + 1) % lp.len()].uv)))
            .collect();
        FaceCdt {
            surface,
            loops,
            pool_xyz,
            tol,
            segments,
            cdt: ConstrainedDelaunayTriangulation::new(),
            vertex_of: Vec::new(),
            alias: BTreeMap::new(),
            out,
        }
    }

    /// The vertex slot of the CDT vertex with handle index `index`.
    fn vertex_slot(&mut self, index: usize) -> &mut Option<FaceVertex> {
        if self.vertex_of.len() <= index {
            self.vertex_of.resize(index + 1, None);
        }
        &mut self.vertex_of[index]
    }

    /// `v`, or the edge point it coincides with.
    fn resolved(&self, v: FaceVertex) -> FaceVertex {
        match v {
            FaceVertex::New(k) => self.alias.get(&k).copied().unwrap_or(v),
            _ => v,
        }
    }

    /// Position of a face vertex in body coordinates.
    fn position(&self, v: FaceVertex) -> Option<DVec3> {
        match v {
            FaceVertex::New(k) => match self.alias.get(&k) {
                Some(FaceVertex::Pool(i)) => self.pool_xyz.get(i).copied(),
                _ => self.out.new_points.get(k as usize).copied(),
            },
            FaceVertex::Pool(i) => self.pool_xyz.get(&i).copied(),
        }
    }

    /// Inserts every loop's points; the CDT handles of each loop's points.
    fn insert_boundary(&mut self) -> Result<Vec<Vec<FixedVertexHandle>>, String> {
        let loops = self.loops;
        let mut handles_of_loops = Vec::with_capacity(loops.len());
        for lp in loops {
            let mut handles = Vec::with_capacity(lp.len());
            for p in lp {
                handles.push(self.insert_boundary_point(p)?);
            }
            handles_of_loops.push(handles);
        }
        Ok(handles_of_loops)
    }

    /// Inserts one boundary point and records the vertex it stands for. Where it lands on
    /// a point already there, a point this face added (a pole or seam end) and an edge
    /// point are one vertex, the edge point; two other vertices there are an error.
    fn insert_boundary_point(&mut self, p: &UvPoint) -> Result<FixedVertexHandle, String> {
        if !(p.uv[0].is_finite() && p.uv[1].is_finite()) {
            return Err("a boundary point has no finite parameters".into());
        }
        let h = self
            .cdt
            .insert(SPoint2::new(spade_round(p.uv[0]), spade_round(p.uv[1])))
            .map_err(|e| format!("the CDT refused a boundary point: {e:?}"))?;
        let i = h.index();
        let there = *self.vertex_slot(i);
        match there.map(|v| (self.resolved(v), self.resolved(p.vertex))) {
            Some((FaceVertex::New(k), w @ FaceVertex::Pool(_)))
            | Some((w @ FaceVertex::Pool(_), FaceVertex::New(k))) => {
                self.alias.insert(k, w);
                self.vertex_of[i] = Some(w);
            }
            Some((v, w)) if v != w => {
                return Err(format!(
                    "two boundary vertices ({v:?}, {:?}) at one parameter point {:?}",
                    p.vertex, p.uv
                ))
            }
            _ => self.vertex_of[i] = Some(p.vertex),
        }
        Ok(h)
    }

    /// Makes each loop's sides constraints. An error when loops cross or the CDT split a
    /// side.
    fn constrain_loops(
        &mut self,
        handles_of_loops: &[Vec<FixedVertexHandle>],
    ) -> Result<(), String> {
        for handles in handles_of_loops {
            let n = handles.len();
            for i in 0..n {
                let (a, b) = (handles[i], handles[(i + 1) % n]);
                if a == b || self.cdt.exists_constraint(a, b) {
                    continue; // an edge used twice by its loop (a slit)
                }
                if !self.cdt.can_add_constraint(a, b) {
                    return Err("the boundary loops cross in the parameter plane".into());
                }
                self.cdt.add_constraint(a, b);
            }
        }
        if self.cdt.num_vertices() != self.vertex_of.iter().filter(|v| v.is_some()).count() {
            return Err("the CDT split a boundary segment".into());
        }
        Ok(())
    }

    /// Inserts the points of the surface's parameter grid that are inside the loops, away
    /// from the boundary so no constraint edge is split.
    fn insert_grid(&mut self) -> Result<(), String> {
        let (lo, hi) = parameter_box(self.loops);
        let (udiv, vdiv) =
            checked_division(self.surface, ((lo[0], hi[0]), (lo[1], hi[1])), self.tol)?;
        for (i, &u) in udiv.iter().enumerate() {
            let su = grid_spacing(&udiv, i);
            for (j, &v) in vdiv.iter().enumerate() {
                let c = [u, v];
                if !inside(self.loops, c) {
                    continue;
                }
                let sv = grid_spacing(&vdiv, j);
                if self.next_to_boundary(c, [su, sv]) {
                    continue;
                }
                self.insert_interior_point(c, "grid point")?;
            }
        }
        Ok(())
    }

    /// Whether grid point `c` is within 0.35 of the grid spacing (`spacing`, per
    /// parameter) of a side of the loops.
    fn next_to_boundary(&self, c: [f64; 2], spacing: [f64; 2]) -> bool {
        let ([u, v], [su, sv]) = (c, spacing);
        let s = [1.0 / su, 1.0 / sv];
        self.segments.iter().any(|&(p, q)| {
            // Cheap reject before the exact distance.
            let (ulo, uhi) = (p[0].min(q[0]) - 0.4 * su, p[0].max(q[0]) + 0.4 * su);
            let (vlo, vhi) = (p[1].min(q[1]) - 0.4 * sv, p[1].max(q[1]) + 0.4 * sv);
            u >= ulo
                && u <= uhi
                && v >= vlo
                && v <= vhi
                && scaled_segment_distance2(c, p, q, s) < 0.35 * 0.35
        })
    }

    /// Inserts an interior point (`what` names it in the error) as a new vertex of the
    /// face, unless it coincides with a point already there.
    fn insert_interior_point(&mut self, uv: [f64; 2], what: &str) -> Result<(), String> {
        let before = self.cdt.num_vertices();
        let h = self
            .cdt
            .insert(SPoint2::new(spade_round(uv[0]), spade_round(uv[1])))
            .map_err(|e| format!("the CDT refused a {what}: {e:?}"))?;
        if self.cdt.num_vertices() == before {
            return Ok(()); // coincides with an existing point
        }
        self.out.new_points.push(self.surface.point(uv[0], uv[1]));
        let vertex = FaceVertex::New(self.out.new_points.len() as u32 - 1);
        *self.vertex_slot(h.index()) = Some(vertex);
        Ok(())
    }

    /// Refines: a triangle whose middle (or the middle of an inner side) is more than `tol`
    /// from the surface gets a point at its centroid, until every triangle is within
    /// tolerance (the grid alone is not enough next to the boundary and on poles), for at
    /// most 24 rounds. `constraints` is the number of boundary constraints, which no
    /// refinement point may split.
    fn refine(&mut self, constraints: usize) -> Result<(), String> {
        for _round in 0..24 {
            let add = self.refinement_points()?;
            if add.is_empty() {
                break;
            }
            if self.cdt.num_vertices() + add.len() > MAX_GRID_POINTS {
                return Err("refining the face to the tolerance needs too many points".into());
            }
            for c in add {
                self.insert_interior_point(c, "refinement point")?;
            }
            if self.cdt.num_constraints() != constraints {
                return Err("refinement split a boundary segment".into());
            }
        }
        Ok(())
    }

    /// The centroids of the triangles inside the loops that are off the surface by more
    /// than the tolerance and clear of the boundary.
    fn refinement_points(&self) -> Result<Vec<[f64; 2]>, String> {
        let mut add: Vec<[f64; 2]> = Vec::new();
        for face in self.cdt.inner_faces() {
            let vs = face.vertices();
            let uv: [[f64; 2]; 3] = std::array::from_fn(|k| {
                let p = vs[k].position();
                [p.x, p.y]
            });
            let c = centroid(&uv);
            if !inside(self.loops, c) {
                continue;
            }
            let corners = self.corner_positions(vs.map(|v| v.fix().index()))?;
            // adjacent_edges()[k] runs from vertex k to vertex k + 1.
            let inner_sides = face.adjacent_edges().map(|e| !e.is_constraint_edge());
            if self.sags(&uv, &corners, inner_sides) && self.clear_of_boundary(&uv, c) {
                add.push(c);
            }
        }
        Ok(add)
    }

    /// Positions of the corners of a triangle, given its CDT vertices' handle indices.
    fn corner_positions(&self, handle_indices: [usize; 3]) -> Result<[DVec3; 3], String> {
        let mut corners = [DVec3::ZERO; 3];
        for k in 0..3 {
            let Some(Some(v)) = self.vertex_of.get(handle_indices[k]).copied() else {
                return Err("a triangle uses a point the CDT made up".into());
            };
            let Some(p) = self.position(v) else {
                return Err("a boundary vertex has no position".into());
            };
            corners[k] = p;
        }
        Ok(corners)
    }

    /// Whether the flat triangle with parameters `uv` and corners `corners` is more than
    /// the tolerance from the surface at its middle or at the middle of one of its
    /// `inner_sides` (side k runs from corner k to corner k + 1).
    fn sags(&self, uv: &[[f64; 2]; 3], corners: &[DVec3; 3], inner_sides: [bool; 3]) -> bool {
        let off = |w: [f64; 3]| {
            let u = w[0] * uv[0][0] + w[1] * uv[1][0] + w[2] * uv[2][0];
            let v = w[0] * uv[0][1] + w[1] * uv[1][1] + w[2] * uv[2][1];
            let flat = w[0] * corners[0] + w[1] * corners[1] + w[2] * corners[2];
            self.surface.point(u, v).distance(flat)
        };
        let third = 1.0 / 3.0;
        if off([third, third, third]) > self.tol {
            return true;
        }
        (0..3).filter(|&k| inner_sides[k]).any(|k| {
            let mut w = [0.0; 3];
            w[k] = 0.5;
            w[(k + 1) % 3] = 0.5;
            off(w) > self.tol
        })
    }

    /// Whether a refinement point at the centroid `c` of the triangle `uv` keeps clear of
    /// the boundary. Never a point on or next to it: spade would split a boundary segment
    /// (sliver triangles along the boundary have centroids almost on it).
    fn clear_of_boundary(&self, uv: &[[f64; 2]; 3], c: [f64; 2]) -> bool {
        let longest = (0..3)
            .map(|k| {
                let (p, q) = (uv[k], uv[(k + 1) % 3]);
                ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
            })
            .fold(0.0, f64::max);
        let area2 = ((uv[1][0] - uv[0][0]) * (uv[2][1] - uv[0][1])
            - (uv[2][0] - uv[0][0]) * (uv[1][1] - uv[0][1]))
            .abs();
        area2 > 1e-6 * longest * longest
            && !self.segments.iter().any(|&(p, q)| {
                scaled_segment_distance2(c, p, q, [1.0, 1.0]) < (0.05 * longest).powi(2)
            })
    }

    /// Adds the CDT's triangles inside the loops to the face's mesh, counter-clockwise in
    /// the plane, over the vertices they stand for; triangles of no area (relative to the
    /// loops' box) and triangles collapsed at a pole are left out.
    fn keep_inside_triangles(&mut self) -> Result<(), String> {
        let (lo, hi) = parameter_box(self.loops);
        let mut area_scale = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        if area_scale.is_nan() || area_scale <= 0.0 {
            area_scale = 1.0;
        }
        for face in self.cdt.inner_faces() {
            let vs = face.vertices();
            let uv: [[f64; 2]; 3] = std::array::from_fn(|k| {
                let p = vs[k].position();
                [p.x, p.y]
            });
            let area = 0.5
                * ((uv[1][0] - uv[0][0]) * (uv[2][1] - uv[0][1])
                    - (uv[2][0] - uv[0][0]) * (uv[1][1] - uv[0][1]));
            if area.abs() <= 1e-14 * area_scale {
                continue;
            }
            if !inside(self.loops, centroid(&uv)) {
                continue;
            }
            let mut t = [FaceVertex::Pool(0); 3];
            for k in 0..3 {
                let Some(Some(v)) = self.vertex_of.get(vs[k].fix().index()).copied() else {
                    return Err("a triangle uses a point the CDT made up".into());
                };
                t[k] = self.resolved(v);
            }
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                continue; // collapsed at a pole
            }
            if area < 0.0 {
                t.swap(1, 2);
            }
            self.out.triangles.push(t);
        }
        Ok(())
    }
}

/// Centroid of a triangle in the parameter plane.
fn centroid(uv: &[[f64; 2]; 3]) -> [f64; 2] {
    [
        (uv[0][0] + uv[1][0] + uv[2][0]) / 3.0,
        (uv[0][1] + uv[1][1] + uv[2][1]) / 3.0,
    ]
}

/// Spacing of grid line `i` of `d` from its nearer neighbour; the grid's whole span (or a
/// tiny positive number) for a single line.
fn grid_spacing(d: &[f64], i: usize) -> f64 {
    let a = if i > 0 {
        d[i] - d[i - 1]
    } else {
        f64::INFINITY
    };
    let b = if i + 1 < d.len() {
        d[i + 1] - d[i]
    } else {
        f64::INFINITY
    };
    let s = a.min(b);
    if s.is_finite() && s > 0.0 {
        s
    } else {
        (d[d.len() - 1] - d[0]).abs().max(1e-300)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;
    use truck_stepio::r#in::alias::{ElementarySurface, Line, Plane, Processor, RevolutedCurve};
    use truck_stepio::r#in::alias::{Point3 as P3, Vector3};

    /// The plane z = 0 whose projection finds a point only from a start within 0.3 of it
    /// (else it stays at the start: a local minimum).
    struct NearSighted;

    impl UvSurface for NearSighted {
        fn source(&self) -> &'static str {
            ""
        }
        fn point(&self, u: f64, v: f64) -> DVec3 {
            DVec3::new(u, v, 0.0)
        }
        fn periods(&self) -> [Option<f64>; 2] {
            [None, None]
        }
        fn ranges(&self) -> [Option<(f64, f64)>; 2] {
            [None, None]
        }
        fn project(&self, p: DVec3, hint: Option<[f64; 2]>) -> Option<[f64; 2]> {
            match hint {
                Some(h) if (h[0] - p.x).abs().max((h[1] - p.y).abs()) > 0.3 => Some(h),
                _ => Some([p.x, p.y]),
            }
        }
        fn division(&self, _: ((f64, f64), (f64, f64)), _: f64) -> (Vec<f64>, Vec<f64>) {
            (Vec::new(), Vec::new())
        }
    }

    #[test]
    fn points_stuck_off_the_surface_are_projected_from_between_their_neighbours() {
        // A unit square's boundary in steps of 0.25; points 5 and 6 were left where the
        // search stopped, 0.6 and 0.8 off the surface.
        let xy: Vec<[f64; 2]> = (0..4)
            .flat_map(|k| (0..4).map(move |i| (k, 0.25 * f64::from(i))))
            .map(|(k, t)| match k {
                0 => [t, 0.0],
                1 => [1.0, t],
                2 => [1.0 - t, 1.0],
                _ => [0.0, 1.0 - t],
            })
            .collect();
        let lp: Vec<(u32, DVec3)> = (0u32..)
            .zip(&xy)
            .map(|(i, q)| (i, DVec3::new(q[0], q[1], 0.0)))
            .collect();
        let mut pts: Vec<UvPoint> = lp
            .iter()
            .map(|&(i, p)| UvPoint {
                uv: [p.x, p.y],
                vertex: FaceVertex::Pool(i),
            })
            .collect();
        let mut offs = vec![0.0; pts.len()];
        let untouched = pts.clone();
        reproject_between_neighbours(&NearSighted, &lp, &mut pts, &mut offs, 0.01);
        assert_eq!(pts, untouched, "a loop on the surface is left as it is");
        for (i, wrong) in [(5, [0.4, 0.25]), (6, [0.2, 0.5])] {
            pts[i].uv = wrong;
            offs[i] = NearSighted.point(wrong[0], wrong[1]).distance(lp[i].1);
        }
        reproject_between_neighbours(&NearSighted, &lp, &mut pts, &mut offs, 0.01);
        assert_eq!(pts, untouched);
        assert!(offs.iter().all(|&o| o == 0.0), "{offs:?}");
    }

    fn circle(n: u32, z: f64, first_id: u32, forward: bool) -> Vec<(u32, DVec3)> {
        let mut pts: Vec<(u32, DVec3)> = (0..n)
            .map(|i| {
                let a = std::f64::consts::TAU * f64::from(i) / f64::from(n);
                (first_id + i, DVec3::new(a.cos(), a.sin(), z))
            })
            .collect();
        if !forward {
            pts[1..].reverse();
        }
        pts
    }

    fn area(mesh: &ConformingMesh, xyz: &BTreeMap<u32, DVec3>) -> f64 {
        let p = |v: FaceVertex| match v {
            FaceVertex::Pool(i) => xyz[&i],
            FaceVertex::New(k) => mesh.new_points[k as usize],
        };
        mesh.triangles
            .iter()
            .map(|t| 0.5 * (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).length())
            .sum()
    }

    fn segments(loops: &[Vec<(u32, DVec3)>]) -> BTreeSet<(u32, u32)> {
        let mut s = BTreeSet::new();
        for l in loops {
            for k in 0..l.len() {
                s.insert(crate::mesh::edge_key(l[k].0, l[(k + 1) % l.len()].0));
            }
        }
        s
    }

    /// A square with a square hole: only boundary points and no interior grid point are
    /// needed on a plane; the triangles cover exactly the square minus the hole.
    #[test]
    fn plane_with_hole_follows_its_loops() {
        let plane = Surface::ElementarySurface(Box::new(ElementarySurface::Plane(Plane::new(
            P3::new(0.0, 0.0, 0.0),
            P3::new(1.0, 0.0, 0.0),
            P3::new(0.0, 1.0, 0.0),
        ))));
        let sq = |ids: [u32; 4], lo: f64, hi: f64, ccw: bool| {
            let mut c = vec![(lo, lo), (hi, lo), (hi, hi), (lo, hi)];
            if !ccw {
                c.reverse();
            }
            ids.iter()
                .zip(c)
                .map(|(&i, (x, y))| (i, DVec3::new(x, y, 0.0)))
                .collect::<Vec<_>>()
        };
        let loops = vec![
            sq([0, 1, 2, 3], 0.0, 4.0, true),
            sq([4, 5, 6, 7], 1.0, 2.0, false),
        ];
        let mesh = conforming_tessellation(&plane, &loops, 1e-3, true).unwrap();
        assert!(super::super::tessellate::follows_edges(
            &mesh.triangles,
            &segments(&loops)
        ));
        let xyz: BTreeMap<u32, DVec3> = loops.iter().flatten().copied().collect();
        assert!((area(&mesh, &xyz) - 15.0).abs() < 1e-9);
    }

    /// Largest `off` over a barycentric grid (`n` steps a side) of every triangle.
    fn worst_facet_point(
        mesh: &ConformingMesh,
        xyz: &BTreeMap<u32, DVec3>,
        n: usize,
        off: impl Fn(DVec3) -> f64,
    ) -> f64 {
        let p = |v: FaceVertex| match v {
            FaceVertex::Pool(i) => xyz[&i],
            FaceVertex::New(k) => mesh.new_points[k as usize],
        };
        let mut worst = 0.0f64;
        for t in &mesh.triangles {
            let [a, b, c] = t.map(p);
            for i in 0..=n {
                for j in 0..=n - i {
                    let k = n - i - j;
                    let q = (a * i as f64 + b * j as f64 + c * k as f64) / n as f64;
                    worst = worst.max(off(q));
                }
            }
        }
        worst
    }

    /// A strip of a 500 mm cylinder, 15 degrees wide and 12 mm tall, bounded by two helical
    /// curves as truck polylines them (corpus trj6 has such strips on a 500 mm cone, bounded
    /// by parabolas): the angle is in radians and the height in millimetres, so the plain
    /// parameter plane is 500 times squashed along the strip. Every facet must still be
    /// within the chordal tolerance of the cylinder (in the plain parameter plane they sag
    /// by up to 4 mm against 0.08 mm).
    #[test]
    fn thin_strip_across_incomparable_parameters_meets_the_tolerance() {
        let r = 500.0;
        let line = Line(P3::new(r, 0.0, 0.0), P3::new(r, 0.0, 1.0));
        let revolved =
            RevolutedCurve::by_revolution(line, P3::new(0.0, 0.0, 0.0), Vector3::unit_z());
        let cylinder = Surface::ElementarySurface(Box::new(ElementarySurface::CylindricalSurface(
            Processor::new(revolved),
        )));
        let tol = 0.08;
        let span = 15f64.to_radians();
        // Polyline points of the curves: the angle step whose sagitta is the tolerance.
        let n = (span / (2.0 * (1.0 - tol / r).acos())).ceil() as u32;
        let at = |i: u32, top: bool| {
            let a = span * f64::from(i) / f64::from(n);
            let z = 40.0 * a + if top { 12.0 } else { 0.0 };
            DVec3::new(r * a.cos(), r * a.sin(), z)
        };
        let mut lp: Vec<(u32, DVec3)> = (0..=n).map(|i| (i, at(i, false))).collect();
        lp.extend((0..=n).rev().map(|i| (100 + i, at(i, true))));
        let loops = vec![lp];
        let mesh = conforming_tessellation(&cylinder, &loops, tol, true).unwrap();
        assert!(super::super::tessellate::follows_edges(
            &mesh.triangles,
            &segments(&loops)
        ));
        let xyz: BTreeMap<u32, DVec3> = loops.iter().flatten().copied().collect();
        let worst = worst_facet_point(&mesh, &xyz, 8, |q| (q.truncate().length() - r).abs());
        assert!(
            worst <= 1.05 * tol,
            "a facet is {worst:.3} mm off the cylinder ({} triangles)",
            mesh.triangles.len()
        );
    }

    /// A face with no boundary (a VERTEX_LOOP only, trj4's balls) is the whole closed
    /// surface: a sphere and a torus come out closed (every side used twice), with their
    /// vertices on the surface and their facets within the chordal tolerance; an open
    /// surface (a cylinder) is refused with a message.
    #[test]
    fn face_without_boundary_is_the_whole_closed_surface() {
        let text = "ISO-10303-21;\nDATA;\n#1=CARTESIAN_POINT('',(1.,2.,3.));\n\
                    #2=DIRECTION('',(0.,0.,1.));\n#3=DIRECTION('',(1.,0.,0.));\n\
                    #4=AXIS2_PLACEMENT_3D('',#1,#2,#3);\n#5=SPHERICAL_SURFACE('',#4,1.9);\n\
                    #6=TOROIDAL_SURFACE('',#4,5.,1.5);\n#7=CYLINDRICAL_SURFACE('',#4,2.);\n\
                    ENDSEC;\nEND-ISO-10303-21;\n";
        let records = super::super::text::scan(text);
        let surface = |id: u64| Analytic::from_record(&records, id, 1.0).unwrap().unwrap();
        let tol = 0.08;
        for id in [5, 6] {
            let s = surface(id);
            let mesh = conforming_tessellation(&s, &[], tol, true).unwrap();
            let mut uses: BTreeMap<(FaceVertex, FaceVertex), u32> = BTreeMap::new();
            for t in &mesh.triangles {
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
                }
            }
            assert!(uses.values().all(|&n| n == 2), "#{id} is closed");
            let off = |q: DVec3| {
                let uv = UvSurface::project(&s, q, None).unwrap();
                s.point(uv[0], uv[1]).distance(q)
            };
            for t in &mesh.triangles {
                assert!(
                    t.iter().all(|v| matches!(v, FaceVertex::New(_))),
                    "no pool vertex without a boundary"
                );
            }
            for &q in &mesh.new_points {
                assert!(off(q) < 1e-9, "#{id}: a vertex off the surface");
            }
            let worst = worst_facet_point(&mesh, &BTreeMap::new(), 6, off);
            assert!(
                worst <= 1.05 * tol,
                "#{id}: a facet is {worst} off the surface"
            );
        }
        let err = conforming_tessellation(&surface(7), &[], tol, true).unwrap_err();
        assert!(err.contains("not closed"), "{err}");
    }

    /// A cylinder band bounded by two circles and no seam edge: the loops are open in the
    /// periodic parameter, the band is cut along a seam whose two copies share vertices, so
    /// the result is a closed band whose only boundary is the two circles, within the
    /// chordal tolerance of the cylinder.
    #[test]
    fn cylinder_band_without_seam_edge_is_cut_and_closed() {
        let line = Line(P3::new(1.0, 0.0, 0.0), P3::new(1.0, 0.0, 1.0));
        let revolved =
            RevolutedCurve::by_revolution(line, P3::new(0.0, 0.0, 0.0), Vector3::unit_z());
        let cylinder = Surface::ElementarySurface(Box::new(ElementarySurface::CylindricalSurface(
            Processor::new(revolved),
        )));
        let loops = vec![circle(32, 0.0, 0, true), circle(32, 1.0, 100, false)];
        let tol = 2e-3;
        let mesh = conforming_tessellation(&cylinder, &loops, tol, true).unwrap();
        let mut uses: BTreeMap<(FaceVertex, FaceVertex), u32> = BTreeMap::new();
        for t in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let open: Vec<_> = uses
            .iter()
            .filter(|(_, &n)| n != 2)
            .map(|(k, n)| (*k, *n))
            .collect();
        assert!(
            super::super::tessellate::follows_edges(&mesh.triangles, &segments(&loops)),
            "{} triangles, {} new points; sides not used twice: {:?}",
            mesh.triangles.len(),
            mesh.new_points.len(),
            &open[..open.len().min(80)]
        );
        for p in &mesh.new_points {
            assert!((p.truncate().length() - 1.0).abs() < 1e-9, "{p}");
        }
        // Vertices on the cylinder, triangles within the tolerance: the area is the
        // cylinder's up to the chordal error (it may exceed it slightly: Schwarz lantern).
        let xyz: BTreeMap<u32, DVec3> = loops.iter().flatten().copied().collect();
        let a = area(&mesh, &xyz);
        assert!(
            (a - std::f64::consts::TAU).abs() < 0.01 * std::f64::consts::TAU,
            "{a}"
        );
    }
}
