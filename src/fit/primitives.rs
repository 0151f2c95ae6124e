//! Least-squares fits of analytic surfaces (plane, sphere, cylinder, cone, torus) to point
//! sets, with max / RMS residuals.
//!
//! Every fit works in a normalised frame (centroid at the origin, RMS radius 1) so that the
//! Levenberg-Marquardt parameters are all of order one, and starts from a closed-form
//! initialisation:
//! * plane: smallest eigenvector of the covariance;
//! * sphere: algebraic (Kasa) fit `|p|^2 = 2 c.p + k`;
//! * cylinder: axis = direction most orthogonal to all normals (smallest eigenvector of
//!   `sum n n^T`), then a 2D circle fit across the axis;
//! * cone: normals make a constant angle with the axis, so the axis is the smallest
//!   eigenvector of the normals' covariance; every tangent plane contains the apex, which
//!   gives a 3 x 3 linear system for it;
//! * torus: every normal line meets the axis; in Plücker coordinates that is linear, so the
//!   axis is the smallest eigenvector of a 6 x 6 matrix; then a circle fit of the meridian.
//!
//! Then Levenberg-Marquardt on the geometric distances. Fits return `None` for inputs that
//! cannot determine the surface (too few points, missing normals, degenerate systems).

use glam::DVec3;

use super::linalg::{levenberg_marquardt, solve, sym_eigen, sym_eigen3};
use crate::mesh::{AnalyticSurface, Axis, Residuals, SurfaceKind};

/// A fitted surface with its residuals over the fitted points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceFit {
    pub surface: AnalyticSurface,
    pub residuals: Residuals,
}

/// Normalising similarity: `local = (world - center) / scale`.
struct Frame {
    center: DVec3,
    scale: f64,
}

impl Frame {
    fn new(points: &[DVec3]) -> Option<(Frame, Vec<DVec3>)> {
        if points.is_empty() || points.iter().any(|p| !p.is_finite()) {
            return None;
        }
        let center = points.iter().sum::<DVec3>() / points.len() as f64;
        let ms = points
            .iter()
            .map(|p| (*p - center).length_squared())
            .sum::<f64>()
            / points.len() as f64;
        let scale = ms.sqrt();
        if scale <= 0.0 || !scale.is_finite() {
            return None;
        }
        let local = points.iter().map(|p| (*p - center) / scale).collect();
        Some((Frame { center, scale }, local))
    }
    fn point(&self, q: DVec3) -> DVec3 {
        q * self.scale + self.center
    }
    fn len(&self, l: f64) -> f64 {
        l * self.scale
    }
}

fn finish(surface: AnalyticSurface, points: &[DVec3]) -> Option<SurfaceFit> {
    let ok = match surface {
        AnalyticSurface::Plane { point, normal } => point.is_finite() && normal.is_finite(),
        AnalyticSurface::Sphere { center, radius } => center.is_finite() && radius.is_finite(),
        AnalyticSurface::Cylinder { axis, radius }
        | AnalyticSurface::Torus {
            axis,
            major_radius: radius,
            ..
        } => axis.origin.is_finite() && axis.direction.is_finite() && radius.is_finite(),
        AnalyticSurface::Cone { axis, half_angle } => {
            axis.origin.is_finite() && axis.direction.is_finite() && half_angle.is_finite()
        }
    };
    ok.then(|| SurfaceFit {
        surface,
        residuals: surface.residuals(points),
    })
}

fn outer_sum(vs: impl Iterator<Item = DVec3>) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for v in vs {
        let a = v.to_array();
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += a[i] * a[j];
            }
        }
    }
    m
}

/// Unit direction from a base direction and two tangential offsets (LM parametrisation of
/// an axis: no constraint, no gimbal problem for rotations below 90 degrees).
fn perturbed(base: DVec3, e1: DVec3, e2: DVec3, u: f64, v: f64) -> DVec3 {
    (base + u * e1 + v * e2).normalize_or(base)
}

fn basis(d: DVec3) -> (DVec3, DVec3) {
    let e1 = d.any_orthonormal_vector();
    (e1, d.cross(e1))
}

/// Algebraic circle fit in 2D (`u^2 + v^2 = 2 a u + 2 b v + k`): centre and radius.
fn circle_2d(pts: &[(f64, f64)]) -> Option<((f64, f64), f64)> {
    if pts.len() < 3 {
        return None;
    }
    let mut ata = vec![0.0; 9];
    let mut atb = vec![0.0; 3];
    for &(u, v) in pts {
        let row = [2.0 * u, 2.0 * v, 1.0];
        let rhs = u * u + v * v;
        for i in 0..3 {
            atb[i] += row[i] * rhs;
            for j in 0..3 {
                ata[i * 3 + j] += row[i] * row[j];
            }
        }
    }
    let x = solve(ata, atb, 3)?;
    let r2 = x[2] + x[0] * x[0] + x[1] * x[1];
    (r2 > 0.0).then(|| ((x[0], x[1]), r2.sqrt()))
}

/// Best-fit plane through the centroid (total least squares). Needs 3 non-collinear points.
pub fn fit_plane(points: &[DVec3]) -> Option<SurfaceFit> {
    let (frame, q) = Frame::new(points)?;
    if q.len() < 3 {
        return None;
    }
    let (vals, vecs) = sym_eigen3(outer_sum(q.iter().copied()));
    if vals[1] <= 1e-12 * vals[2] {
        return None; // collinear
    }
    finish(
        AnalyticSurface::Plane {
            point: frame.center,
            normal: vecs[0],
        },
        points,
    )
}

/// Best-fit sphere (geometric distances). Needs 4 points not on one plane.
pub fn fit_sphere(points: &[DVec3]) -> Option<SurfaceFit> {
    fit_sphere_impl(points, f64::INFINITY)
}

fn fit_sphere_impl(points: &[DVec3], abandon_world: f64) -> Option<SurfaceFit> {
    let (frame, q) = Frame::new(points)?;
    let abandon = abandon_world / frame.scale;
    if q.len() < 4 {
        return None;
    }
    let mut ata = vec![0.0; 16];
    let mut atb = vec![0.0; 4];
    for p in &q {
        let row = [2.0 * p.x, 2.0 * p.y, 2.0 * p.z, 1.0];
        let rhs = p.length_squared();
        for i in 0..4 {
            atb[i] += row[i] * rhs;
            for j in 0..4 {
                ata[i * 4 + j] += row[i] * row[j];
            }
        }
    }
    let x = solve(ata, atb, 4)?;
    let c = DVec3::new(x[0], x[1], x[2]);
    let r2 = x[3] + c.length_squared();
    if r2 <= 0.0 {
        return None;
    }
    lm_sphere(&frame, &q, c, r2.sqrt(), points, abandon)
}

fn lm_sphere(
    frame: &Frame,
    q: &[DVec3],
    c: DVec3,
    r: f64,
    points: &[DVec3],
    abandon: f64,
) -> Option<SurfaceFit> {
    let mut p = [c.x, c.y, c.z, r];
    levenberg_marquardt(
        &mut p,
        q.len(),
        |p, out| {
            let c = DVec3::new(p[0], p[1], p[2]);
            for (o, x) in out.iter_mut().zip(q) {
                *o = (*x - c).length() - p[3];
            }
        },
        25,
        abandon,
    );
    finish(
        AnalyticSurface::Sphere {
            center: frame.point(DVec3::new(p[0], p[1], p[2])),
            radius: frame.len(p[3].abs()),
        },
        points,
    )
}

fn normals_ok(points: &[DVec3], normals: &[DVec3]) -> bool {
    normals.len() == points.len() && normals.iter().all(|n| n.is_finite())
}

/// Best-fit cylinder. `normals` (one per point, any orientation) initialise the axis.
pub fn fit_cylinder(points: &[DVec3], normals: &[DVec3]) -> Option<SurfaceFit> {
    fit_cylinder_impl(points, normals, f64::INFINITY)
}

fn fit_cylinder_impl(
    points: &[DVec3],
    normals: &[DVec3],
    abandon_world: f64,
) -> Option<SurfaceFit> {
    if !normals_ok(points, normals) || points.len() < 5 {
        return None;
    }
    let (frame, q) = Frame::new(points)?;
    let abandon = abandon_world / frame.scale;
    let (_, vecs) = sym_eigen3(outer_sum(normals.iter().map(|n| n.normalize_or_zero())));
    let a0 = vecs[0];
    let (e1, e2) = basis(a0);
    let uv: Vec<(f64, f64)> = q.iter().map(|p| (p.dot(e1), p.dot(e2))).collect();
    let ((cu, cv), r) = circle_2d(&uv)?;
    lm_cylinder(&frame, &q, a0, cu * e1 + cv * e2, r, points, abandon)
}

/// LM on a cylinder in local coordinates, starting from axis direction `a0`, axis point
/// `c0` and radius `r`.
fn lm_cylinder(
    frame: &Frame,
    q: &[DVec3],
    a0: DVec3,
    c0: DVec3,
    r: f64,
    points: &[DVec3],
    abandon: f64,
) -> Option<SurfaceFit> {
    if points.len() < 5 {
        return None;
    }
    let (e1, e2) = basis(a0);
    let c0 = c0 - c0.dot(a0) * a0;
    let mut p = [c0.dot(e1), c0.dot(e2), 0.0, 0.0, r];
    levenberg_marquardt(
        &mut p,
        q.len(),
        |p, out| {
            let a = perturbed(a0, e1, e2, p[2], p[3]);
            let c = p[0] * e1 + p[1] * e2;
            for (o, x) in out.iter_mut().zip(q) {
                *o = (*x - c).cross(a).length() - p[4];
            }
        },
        25,
        abandon,
    );
    let a = perturbed(a0, e1, e2, p[2], p[3]);
    let c = p[0] * e1 + p[1] * e2;
    // Report the axis point closest to the centroid of the points.
    let c = c - c.dot(a) * a;
    finish(
        AnalyticSurface::Cylinder {
            axis: Axis {
                origin: frame.point(c),
                direction: a,
            },
            radius: frame.len(p[4].abs()),
        },
        points,
    )
}

/// Best-fit cone (one nappe). `normals` initialise the axis and the apex.
pub fn fit_cone(points: &[DVec3], normals: &[DVec3]) -> Option<SurfaceFit> {
    fit_cone_impl(points, normals, f64::INFINITY, None)
}

/// `cylinder`: a cylinder fit of the same points if the caller has one (saves a fit).
fn fit_cone_impl(
    points: &[DVec3],
    normals: &[DVec3],
    abandon_world: f64,
    cylinder: Option<SurfaceFit>,
) -> Option<SurfaceFit> {
    if !normals_ok(points, normals) || points.len() < 6 {
        return None;
    }
    let (frame, q) = Frame::new(points)?;
    let abandon = abandon_world / frame.scale;
    let ns: Vec<DVec3> = normals.iter().map(|n| n.normalize_or_zero()).collect();
    let mean = ns.iter().sum::<DVec3>() / ns.len() as f64;
    let (_, vecs) = sym_eigen3(outer_sum(ns.iter().map(|n| *n - mean)));
    let mut a0 = vecs[0];
    // Apex: every tangent plane n.(x - p) = 0 contains it.
    let nn = outer_sum(ns.iter().copied());
    let mut rhs = [0.0; 3];
    for (n, p) in ns.iter().zip(&q) {
        let d = n.dot(*p);
        rhs[0] += n.x * d;
        rhs[1] += n.y * d;
        rhs[2] += n.z * d;
    }
    let apex = solve(nn.iter().flatten().copied().collect(), rhs.to_vec(), 3)?;
    let apex = DVec3::from_slice(&apex);
    if q.iter().map(|p| (*p - apex).dot(a0)).sum::<f64>() < 0.0 {
        a0 = -a0;
    }
    let angle = q
        .iter()
        .map(|p| {
            let v = *p - apex;
            let h = v.dot(a0);
            (v - h * a0).length().atan2(h)
        })
        .sum::<f64>()
        / q.len() as f64;
    let mut best = lm_cone(&frame, &q, apex, a0, angle, points, abandon);
    // Second start for narrow or nearly cylindrical cones, where the normals' cone is
    // too thin to give the axis: the best cylinder with a small opening either way.
    let good_enough = best.is_some_and(|b| b.residuals.rms <= 1e-7 * frame.scale);
    if good_enough {
        return best;
    }
    if let Some(SurfaceFit {
        surface: AnalyticSurface::Cylinder { axis, radius },
        ..
    }) = cylinder.or_else(|| fit_cylinder_impl(points, normals, abandon_world))
    {
        let a = axis.direction;
        let c = (axis.origin - frame.center) / frame.scale;
        let r = radius / frame.scale;
        let theta: f64 = 0.05;
        for sign in [1.0, -1.0] {
            let dir = a * sign;
            let apex = c - dir * (r / theta.tan());
            let cand = lm_cone(&frame, &q, apex, dir, theta, points, abandon);
            if let Some(c) = cand {
                if best.is_none_or(|b| c.residuals.rms < b.residuals.rms) {
                    best = Some(c);
                }
            }
        }
    }
    best
}

fn lm_cone(
    frame: &Frame,
    q: &[DVec3],
    apex: DVec3,
    a0: DVec3,
    angle: f64,
    points: &[DVec3],
    abandon: f64,
) -> Option<SurfaceFit> {
    if points.len() < 6 {
        return None;
    }
    let (e1, e2) = basis(a0);
    let mut p = [apex.x, apex.y, apex.z, 0.0, 0.0, angle];
    levenberg_marquardt(
        &mut p,
        q.len(),
        |p, out| {
            let apex = DVec3::new(p[0], p[1], p[2]);
            let a = perturbed(a0, e1, e2, p[3], p[4]);
            let (s, c) = p[5].sin_cos();
            for (o, x) in out.iter_mut().zip(q) {
                let v = *x - apex;
                let h = v.dot(a);
                let rho = (v - h * a).length();
                *o = rho * c - h * s;
            }
        },
        25,
        abandon,
    );
    let a = perturbed(a0, e1, e2, p[3], p[4]);
    // rho cos t - h sin t changes sign under t -> t + pi, so t is defined modulo pi; an
    // angle above pi/2 is the cone opening the other way.
    let (mut a, mut angle) = (a, p[5].rem_euclid(std::f64::consts::PI));
    if angle > std::f64::consts::FRAC_PI_2 {
        angle = std::f64::consts::PI - angle;
        a = -a;
    }
    finish(
        AnalyticSurface::Cone {
            axis: Axis {
                origin: frame.point(DVec3::new(p[0], p[1], p[2])),
                direction: a,
            },
            half_angle: angle,
        },
        points,
    )
}

/// Best-fit torus. `normals` initialise the axis (every normal line meets it).
pub fn fit_torus(points: &[DVec3], normals: &[DVec3]) -> Option<SurfaceFit> {
    fit_torus_impl(points, normals, f64::INFINITY)
}

fn fit_torus_impl(points: &[DVec3], normals: &[DVec3], abandon_world: f64) -> Option<SurfaceFit> {
    if !normals_ok(points, normals) || points.len() < 8 {
        return None;
    }
    let (frame, q) = Frame::new(points)?;
    let abandon = abandon_world / frame.scale;
    // Axis line (d, m) meets normal line (n, p x n) iff d.(p x n) + m.n = 0.
    let mut mat = vec![0.0; 36];
    for (p, n) in q.iter().zip(normals) {
        let n = n.normalize_or_zero();
        let w = p.cross(n);
        let row = [w.x, w.y, w.z, n.x, n.y, n.z];
        for i in 0..6 {
            for j in 0..6 {
                mat[i * 6 + j] += row[i] * row[j];
            }
        }
    }
    let (_, vecs) = sym_eigen(&mat, 6);
    let d = DVec3::new(vecs[0][0], vecs[0][1], vecs[0][2]);
    let m = DVec3::new(vecs[0][3], vecs[0][4], vecs[0][5]);
    if d.length() < 1e-6 {
        return None;
    }
    let x0 = d.cross(m) / d.length_squared();
    let a0 = d.normalize();
    // Meridian circle in (h, rho).
    let hr: Vec<(f64, f64)> = q
        .iter()
        .map(|p| {
            let v = *p - x0;
            let h = v.dot(a0);
            (h, (v - h * a0).length())
        })
        .collect();
    let ((h0, big_r), small_r) = circle_2d(&hr)?;
    lm_torus(
        &frame,
        &q,
        x0 + h0 * a0,
        a0,
        big_r,
        small_r,
        points,
        abandon,
    )
}

#[allow(clippy::too_many_arguments)] // the torus has seven parameters to start from
fn lm_torus(
    frame: &Frame,
    q: &[DVec3],
    c0: DVec3,
    a0: DVec3,
    big_r: f64,
    small_r: f64,
    points: &[DVec3],
    abandon: f64,
) -> Option<SurfaceFit> {
    if points.len() < 8 {
        return None;
    }
    let (e1, e2) = basis(a0);
    let mut p = [c0.x, c0.y, c0.z, 0.0, 0.0, big_r, small_r];
    levenberg_marquardt(
        &mut p,
        q.len(),
        |p, out| {
            let c = DVec3::new(p[0], p[1], p[2]);
            let a = perturbed(a0, e1, e2, p[3], p[4]);
            for (o, x) in out.iter_mut().zip(q) {
                let v = *x - c;
                let h = v.dot(a);
                let rho = (v - h * a).length();
                *o = ((rho - p[5]).powi(2) + h * h).sqrt() - p[6];
            }
        },
        25,
        abandon,
    );
    finish(
        AnalyticSurface::Torus {
            axis: Axis {
                origin: frame.point(DVec3::new(p[0], p[1], p[2])),
                direction: perturbed(a0, e1, e2, p[3], p[4]),
            },
            major_radius: frame.len(p[5]),
            minor_radius: frame.len(p[6].abs()),
        },
        points,
    )
}

/// Refits `start`'s kind to `points`, starting Levenberg-Marquardt from `start` (much more
/// robust than a fresh initialisation when a region grows: the old fit is already close).
/// Planes are refitted in closed form.
pub fn refine(start: &AnalyticSurface, points: &[DVec3]) -> Option<SurfaceFit> {
    let (frame, q) = Frame::new(points)?;
    let abandon = f64::INFINITY;
    let lp = |p: DVec3| (p - frame.center) / frame.scale;
    let ll = |l: f64| l / frame.scale;
    match *start {
        AnalyticSurface::Plane { .. } => fit_plane(points),
        AnalyticSurface::Sphere { center, radius } => {
            (q.len() >= 4).then_some(())?;
            lm_sphere(&frame, &q, lp(center), ll(radius), points, abandon)
        }
        AnalyticSurface::Cylinder { axis, radius } => lm_cylinder(
            &frame,
            &q,
            axis.direction,
            lp(axis.origin),
            ll(radius),
            points,
            abandon,
        ),
        AnalyticSurface::Cone { axis, half_angle } => lm_cone(
            &frame,
            &q,
            lp(axis.origin),
            axis.direction,
            half_angle,
            points,
            abandon,
        ),
        AnalyticSurface::Torus {
            axis,
            major_radius,
            minor_radius,
        } => lm_torus(
            &frame,
            &q,
            lp(axis.origin),
            axis.direction,
            ll(major_radius),
            ll(minor_radius),
            points,
            abandon,
        ),
    }
}

/// Fits `kind` to the points (normals are needed for cylinder, cone and torus).
#[cfg(test)]
pub fn fit_kind(kind: SurfaceKind, points: &[DVec3], normals: &[DVec3]) -> Option<SurfaceFit> {
    match kind {
        SurfaceKind::Plane => fit_plane(points),
        SurfaceKind::Sphere => fit_sphere(points),
        SurfaceKind::Cylinder => fit_cylinder(points, normals),
        SurfaceKind::Cone => fit_cone(points, normals),
        SurfaceKind::Torus => fit_torus(points, normals),
    }
}

/// Like [`fit_kind`], for callers that will reject fits whose max residual exceeds
/// `tolerance`: hopeless fits are abandoned early, and a cylinder fit of the same points
/// (if any) seeds the cone fit.
pub(crate) fn fit_kind_within(
    kind: SurfaceKind,
    points: &[DVec3],
    normals: &[DVec3],
    tolerance: f64,
    cylinder: Option<SurfaceFit>,
) -> Option<SurfaceFit> {
    // RMS <= max, and LM rarely gains a factor 4 after six iterations.
    let abandon = 4.0 * tolerance;
    match kind {
        SurfaceKind::Plane => fit_plane(points),
        SurfaceKind::Sphere => fit_sphere_impl(points, abandon),
        SurfaceKind::Cylinder => fit_cylinder_impl(points, normals, abandon),
        SurfaceKind::Cone => fit_cone_impl(points, normals, abandon, cylinder),
        SurfaceKind::Torus => fit_torus_impl(points, normals, abandon),
    }
}

/// The first kind of `kinds` (in order) whose fit has a max residual within `tolerance`.
#[cfg(test)]
pub fn fit_first_within(
    kinds: &[SurfaceKind],
    points: &[DVec3],
    normals: &[DVec3],
    tolerance: f64,
) -> Option<SurfaceFit> {
    kinds
        .iter()
        .filter_map(|&k| fit_kind(k, points, normals))
        .find(|f| f.residuals.max <= tolerance)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::SplitMixForTests as Rng;

    fn noisy(rng: &mut Rng, p: DVec3, n: DVec3, noise: f64) -> (DVec3, DVec3) {
        let e = (rng.f() - 0.5) * 2.0 * noise;
        let jitter = DVec3::new(rng.f() - 0.5, rng.f() - 0.5, rng.f() - 0.5) * 0.02;
        (p + e * n, (n + jitter).normalize())
    }

    fn frame(axis: DVec3) -> (DVec3, DVec3, DVec3) {
        let a = axis.normalize();
        let (e1, e2) = basis(a);
        (a, e1, e2)
    }

    fn unzip(v: Vec<(DVec3, DVec3)>) -> (Vec<DVec3>, Vec<DVec3>) {
        v.into_iter().unzip()
    }

    #[test]
    fn plane_recovered() {
        let mut rng = Rng::new(1);
        let (n, e1, e2) = frame(DVec3::new(1.0, 2.0, -0.5));
        let o = DVec3::new(3.0, -1.0, 7.0);
        let pts: Vec<DVec3> = (0..300)
            .map(|_| {
                let p = o + e1 * (rng.f() * 10.0) + e2 * (rng.f() * 4.0);
                noisy(&mut rng, p, n, 1e-4).0
            })
            .collect();
        let f = fit_plane(&pts).unwrap();
        let AnalyticSurface::Plane { point, normal } = f.surface else {
            panic!()
        };
        assert!(normal.dot(n).abs() > 1.0 - 1e-8);
        assert!((point - o).dot(n).abs() < 1e-4);
        assert!(f.residuals.max <= 1.1e-4 && f.residuals.rms < 1e-4);
        assert!(fit_plane(&[DVec3::ZERO, DVec3::X, DVec3::X * 2.0]).is_none());
    }

    #[test]
    fn sphere_recovered() {
        let mut rng = Rng::new(2);
        let c = DVec3::new(-2.0, 5.0, 1.0);
        let r = 3.5;
        // Only a cap of the sphere (harder than the full sphere).
        let pts: Vec<DVec3> = (0..400)
            .map(|_| {
                let th = rng.f() * 0.8;
                let ph = rng.f() * std::f64::consts::TAU;
                let n = DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
                noisy(&mut rng, c + r * n, n, 1e-4).0
            })
            .collect();
        let f = fit_sphere(&pts).unwrap();
        let AnalyticSurface::Sphere { center, radius } = f.surface else {
            panic!()
        };
        assert!((center - c).length() < 2e-3, "{center}");
        assert!((radius - r).abs() < 2e-3, "{radius}");
        assert!(f.residuals.max < 1.2e-4);
    }

    #[test]
    fn cylinder_recovered() {
        let mut rng = Rng::new(3);
        let (a, e1, e2) = frame(DVec3::new(0.3, -1.0, 0.2));
        let o = DVec3::new(10.0, 20.0, -5.0);
        let r = 0.75;
        // A 120-degree sector, like a fillet.
        let (pts, ns) = unzip(
            (0..400)
                .map(|_| {
                    let t = rng.f() * 2.1;
                    let n = e1 * t.cos() + e2 * t.sin();
                    let along = rng.f() * 5.0;
                    noisy(&mut rng, o + r * n + a * along, n, 1e-5)
                })
                .collect(),
        );
        let f = fit_cylinder(&pts, &ns).unwrap();
        let AnalyticSurface::Cylinder { axis, radius } = f.surface else {
            panic!()
        };
        assert!(axis.direction.dot(a).abs() > 1.0 - 1e-8);
        let off = (axis.origin - o) - (axis.origin - o).dot(a) * a;
        assert!(off.length() < 1e-4, "axis offset {off}");
        assert!((radius - r).abs() < 1e-4);
        assert!(f.residuals.max < 1.5e-5);
        // Normals are required.
        assert!(fit_cylinder(&pts, &[]).is_none());
        // Refining from a perturbed start recovers the same cylinder.
        let start = AnalyticSurface::Cylinder {
            axis: Axis {
                origin: o + DVec3::new(0.05, -0.03, 0.02),
                direction: (a + 0.05 * e1).normalize(),
            },
            radius: r * 1.1,
        };
        let g = refine(&start, &pts).unwrap();
        assert!(g.residuals.max < 1.5e-5, "{:?}", g.residuals);
    }

    #[test]
    fn cone_recovered() {
        let mut rng = Rng::new(4);
        let (a, e1, e2) = frame(DVec3::new(-0.2, 0.1, 1.0));
        let apex = DVec3::new(1.0, 2.0, 3.0);
        let half = 0.4f64;
        let (pts, ns) = unzip(
            (0..500)
                .map(|_| {
                    let t = rng.f() * std::f64::consts::TAU;
                    let h = 1.0 + rng.f() * 2.0;
                    let radial = e1 * t.cos() + e2 * t.sin();
                    let p = apex + h * a + h * half.tan() * radial;
                    let n = (half.cos() * radial - half.sin() * a).normalize();
                    noisy(&mut rng, p, n, 1e-5)
                })
                .collect(),
        );
        let f = fit_cone(&pts, &ns).unwrap();
        let AnalyticSurface::Cone { axis, half_angle } = f.surface else {
            panic!()
        };
        assert!(axis.direction.dot(a) > 1.0 - 1e-7, "{}", axis.direction);
        assert!((axis.origin - apex).length() < 1e-3, "{}", axis.origin);
        assert!((half_angle - half).abs() < 1e-4, "{half_angle}");
        assert!(f.residuals.max < 2e-5);
        // A cylinder's points are not a cone with a finite apex near them... but a plane
        // is never classified as a cone when the plane is tried first (see segment).
    }

    #[test]
    fn torus_recovered() {
        let mut rng = Rng::new(5);
        let (a, e1, e2) = frame(DVec3::new(1.0, 1.0, 0.0));
        let c = DVec3::new(0.0, -3.0, 2.0);
        let (big, small) = (2.0, 0.5);
        // Quarter of the tube over half the revolution (a fillet around a hole).
        let (pts, ns) = unzip(
            (0..600)
                .map(|_| {
                    let u = rng.f() * std::f64::consts::PI;
                    let v = rng.f() * std::f64::consts::FRAC_PI_2;
                    let radial = e1 * u.cos() + e2 * u.sin();
                    let n = radial * v.cos() + a * v.sin();
                    noisy(&mut rng, c + big * radial + small * n, n, 1e-5)
                })
                .collect(),
        );
        let f = fit_torus(&pts, &ns).unwrap();
        let AnalyticSurface::Torus {
            axis,
            major_radius,
            minor_radius,
        } = f.surface
        else {
            panic!()
        };
        assert!(axis.direction.dot(a).abs() > 1.0 - 1e-7);
        assert!((axis.origin - c).length() < 1e-3, "{}", axis.origin);
        assert!((major_radius - big).abs() < 1e-4 && (minor_radius - small).abs() < 1e-4);
        assert!(f.residuals.max < 2e-5);
    }

    #[test]
    fn classification_prefers_simplest() {
        let mut rng = Rng::new(6);
        let (a, e1, e2) = frame(DVec3::Z);
        let (pts, ns) = unzip(
            (0..200)
                .map(|_| {
                    let t = rng.f() * 3.0;
                    let n = e1 * t.cos() + e2 * t.sin();
                    (2.0 * n + a * rng.f(), n)
                })
                .collect(),
        );
        let f = fit_first_within(&SurfaceKind::ALL, &pts, &ns, 1e-6).unwrap();
        assert_eq!(f.surface.kind(), SurfaceKind::Cylinder);
        // Distances of the primitive agree with geometry.
        let p = DVec3::new(3.0, 0.0, 0.5);
        assert!((f.surface.distance(p) - 1.0).abs() < 1e-6);
        assert!(f.surface.normal_at(p).dot(DVec3::X) > 1.0 - 1e-6);
    }
}
