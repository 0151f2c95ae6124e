//! The analytic surfaces a CAD face can lie on (plane, cylinder, cone, sphere, torus), in
//! model coordinates: what the STEP reader and the face sidecar read, what the fit fits and
//! classifies with, and what the error is measured against.

use std::fmt;

use glam::DVec3;

use super::Axis;

/// Maximum and root-mean-square distance of the fitted points to the surface.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Residuals {
    pub max: f64,
    pub rms: f64,
}

/// Surface types, in the order of preference used by classification (fewest parameters
/// first: a plane is also a cylinder of infinite radius, a cylinder a cone of zero angle).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum SurfaceKind {
    Plane,
    Cylinder,
    Cone,
    Sphere,
    Torus,
}

impl SurfaceKind {
    pub const ALL: [SurfaceKind; 5] = [
        SurfaceKind::Plane,
        SurfaceKind::Cylinder,
        SurfaceKind::Cone,
        SurfaceKind::Sphere,
        SurfaceKind::Torus,
    ];
}

/// An analytic surface in model coordinates. Directions are unit vectors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AnalyticSurface {
    Plane {
        point: DVec3,
        normal: DVec3,
    },
    Sphere {
        center: DVec3,
        radius: f64,
    },
    /// `axis.origin` is a point on the axis.
    Cylinder {
        axis: Axis,
        radius: f64,
    },
    /// `axis.origin` is the apex; the cone opens along `axis.direction`.
    Cone {
        axis: Axis,
        half_angle: f64,
    },
    /// `axis.origin` is the centre; `major_radius` is the spine circle's radius.
    Torus {
        axis: Axis,
        major_radius: f64,
        minor_radius: f64,
    },
}

/// Cylindrical coordinates of `p` about an axis: (height along it, distance from it, unit
/// radial direction or any perpendicular when on the axis).
fn axial(axis: &Axis, p: DVec3) -> (f64, f64, DVec3) {
    let v = p - axis.origin;
    let h = v.dot(axis.direction);
    let radial = v - h * axis.direction;
    let rho = radial.length();
    let dir = if rho > 0.0 {
        radial / rho
    } else {
        axis.direction.any_orthonormal_vector()
    };
    (h, rho, dir)
}

impl AnalyticSurface {
    /// The surface moved by a rigid placement: `point` maps positions, `vector` directions
    /// (renormalised); sizes are unchanged.
    #[cfg(any(feature = "step", feature = "internals"))]
    pub fn placed(self, point: impl Fn(DVec3) -> DVec3, vector: impl Fn(DVec3) -> DVec3) -> Self {
        self.mapped(point, |v| vector(v).normalize_or_zero(), 1.0)
    }

    /// The surface with every length times `s` (a change of unit about the origin).
    #[cfg(any(feature = "step", feature = "internals"))]
    pub fn scaled(self, s: f64) -> Self {
        self.mapped(|p| p * s, |d| d, s)
    }

    /// The surface with its points mapped by `point`, its unit directions by `direction`
    /// and its radii times `length`.
    #[cfg(any(feature = "step", feature = "internals"))]
    fn mapped(
        self,
        point: impl Fn(DVec3) -> DVec3,
        direction: impl Fn(DVec3) -> DVec3,
        length: f64,
    ) -> Self {
        let axis = |a: Axis| Axis {
            origin: point(a.origin),
            direction: direction(a.direction),
        };
        match self {
            AnalyticSurface::Plane { point: p, normal } => AnalyticSurface::Plane {
                point: point(p),
                normal: direction(normal),
            },
            AnalyticSurface::Sphere { center, radius } => AnalyticSurface::Sphere {
                center: point(center),
                radius: radius * length,
            },
            AnalyticSurface::Cylinder { axis: a, radius } => AnalyticSurface::Cylinder {
                axis: axis(a),
                radius: radius * length,
            },
            AnalyticSurface::Cone {
                axis: a,
                half_angle,
            } => AnalyticSurface::Cone {
                axis: axis(a),
                half_angle,
            },
            AnalyticSurface::Torus {
                axis: a,
                major_radius,
                minor_radius,
            } => AnalyticSurface::Torus {
                axis: axis(a),
                major_radius: major_radius * length,
                minor_radius: minor_radius * length,
            },
        }
    }

    pub fn kind(&self) -> SurfaceKind {
        match self {
            AnalyticSurface::Plane { .. } => SurfaceKind::Plane,
            AnalyticSurface::Sphere { .. } => SurfaceKind::Sphere,
            AnalyticSurface::Cylinder { .. } => SurfaceKind::Cylinder,
            AnalyticSurface::Cone { .. } => SurfaceKind::Cone,
            AnalyticSurface::Torus { .. } => SurfaceKind::Torus,
        }
    }

    /// Unsigned Euclidean distance from `p` to the surface (cones: the nappe that opens
    /// along the axis, including the apex).
    pub fn distance(&self, p: DVec3) -> f64 {
        match *self {
            AnalyticSurface::Plane { point, normal } => (p - point).dot(normal).abs(),
            AnalyticSurface::Sphere { center, radius } => ((p - center).length() - radius).abs(),
            AnalyticSurface::Cylinder { axis, radius } => (axial(&axis, p).1 - radius).abs(),
            AnalyticSurface::Cone { axis, half_angle } => {
                let (h, rho, _) = axial(&axis, p);
                let (s, c) = half_angle.sin_cos();
                if h * c + rho * s >= 0.0 {
                    (rho * c - h * s).abs()
                } else {
                    (h * h + rho * rho).sqrt()
                }
            }
            AnalyticSurface::Torus {
                axis,
                major_radius,
                minor_radius,
            } => {
                // The tube's section in p's plane through the axis is two circles, at
                // +major and -major from the axis; with the minor radius larger (a spindle
                // torus, as STEP allows) the far one may be nearer.
                let (h, rho, _) = axial(&axis, p);
                let near = ((rho - major_radius).hypot(h) - minor_radius).abs();
                let far = ((rho + major_radius).hypot(h) - minor_radius).abs();
                near.min(far)
            }
        }
    }

    /// The point of the surface nearest to `p` (cones: on the nappe that opens along the
    /// axis, the apex when `p` is behind it; a point on an axis or at a centre goes to any
    /// of its nearest points).
    pub fn project(&self, p: DVec3) -> DVec3 {
        match *self {
            AnalyticSurface::Plane { point, normal } => p - (p - point).dot(normal) * normal,
            AnalyticSurface::Sphere { center, radius } => {
                center + radius * (p - center).try_normalize().unwrap_or(DVec3::Z)
            }
            AnalyticSurface::Cylinder { axis, radius } => {
                let (h, _, r) = axial(&axis, p);
                axis.origin + h * axis.direction + radius * r
            }
            AnalyticSurface::Cone { axis, half_angle } => {
                let (h, rho, r) = axial(&axis, p);
                let (s, c) = half_angle.sin_cos();
                let t = (h * c + rho * s).max(0.0);
                axis.origin + t * (c * axis.direction + s * r)
            }
            AnalyticSurface::Torus {
                axis,
                major_radius,
                minor_radius,
            } => {
                // As in `distance`: the nearer of the two circles of p's axial section.
                let (_, _, r) = axial(&axis, p);
                let on_circle = |spine: DVec3| {
                    let foot = spine + minor_radius * (p - spine).try_normalize().unwrap_or(r);
                    (foot.distance(p), foot)
                };
                let near = on_circle(axis.origin + major_radius * r);
                let far = on_circle(axis.origin - major_radius * r);
                if far.0 < near.0 {
                    far.1
                } else {
                    near.1
                }
            }
        }
    }

    /// Unit surface normal at the foot point of `p` (orientation not meaningful).
    pub fn normal_at(&self, p: DVec3) -> DVec3 {
        match *self {
            AnalyticSurface::Plane { normal, .. } => normal,
            AnalyticSurface::Sphere { center, .. } => (p - center).normalize_or(DVec3::Z),
            AnalyticSurface::Cylinder { axis, .. } => axial(&axis, p).2,
            AnalyticSurface::Cone { axis, half_angle } => {
                let (_, _, r) = axial(&axis, p);
                let (s, c) = half_angle.sin_cos();
                (c * r - s * axis.direction).normalize_or(DVec3::Z)
            }
            AnalyticSurface::Torus {
                axis, major_radius, ..
            } => {
                let (_, _, r) = axial(&axis, p);
                let spine = axis.origin + major_radius * r;
                (p - spine).normalize_or(r)
            }
        }
    }

    /// Max and RMS of the distances of `points` to the surface.
    pub fn residuals(&self, points: &[DVec3]) -> Residuals {
        let mut r = Residuals::default();
        let mut s2 = 0.0;
        for &p in points {
            let d = self.distance(p);
            r.max = r.max.max(d);
            s2 += d * d;
        }
        if !points.is_empty() {
            r.rms = (s2 / points.len() as f64).sqrt();
        }
        r
    }
}

impl fmt::Display for AnalyticSurface {
    /// The kind and its parameters, for listings (`scode info --groups`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = |p: DVec3| format!("({:.4}, {:.4}, {:.4})", p.x, p.y, p.z);
        match *self {
            AnalyticSurface::Plane { point, normal } => {
                write!(f, "plane through {} normal {}", v(point), v(normal))
            }
            AnalyticSurface::Sphere { center, radius } => {
                write!(f, "sphere centre {} r {radius:.4}", v(center))
            }
            AnalyticSurface::Cylinder { axis, radius } => write!(
                f,
                "cylinder axis {} dir {} r {radius:.4}",
                v(axis.origin),
                v(axis.direction)
            ),
            AnalyticSurface::Cone { axis, half_angle } => write!(
                f,
                "cone apex {} dir {} half-angle {:.3} deg",
                v(axis.origin),
                v(axis.direction),
                half_angle.to_degrees()
            ),
            AnalyticSurface::Torus {
                axis,
                major_radius,
                minor_radius,
            } => write!(
                f,
                "torus centre {} dir {} r {major_radius:.4} / {minor_radius:.4}",
                v(axis.origin),
                v(axis.direction)
            ),
        }
    }
}
