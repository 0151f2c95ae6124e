//! Cylindrical coordinate frames of cylinder and cone boundary patches.
//!
//! Every mask is an affine combination. Applied to the cylindrical coordinates
//! `(theta, h, r)` about a patch axis instead of to Cartesian coordinates, any affine
//! combination keeps `r = R` (cylinder) and `r = k h` about the apex (cone), so points
//! computed from control points on the analytic surface stay exactly on it. See
//! `spec/subdivision.md` §5.

use glam::DVec3;

use crate::mesh::BoundarySurface;

/// A cylindrical coordinate system about an axis. Stored once per Cylinder/Cone group and
/// referenced by a small id from vertices and edges, because only a few groups have one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Frame {
    pub origin: DVec3,
    /// Unit axis direction.
    pub axis: DVec3,
    pub e1: DVec3,
    pub e2: DVec3,
    /// Points closer than this to the axis have no angle (cone apex).
    pub eps: f64,
    pub is_cone: bool,
}

/// Angle difference wrapped into (-pi, pi].
#[inline]
fn wrap(d: f64) -> f64 {
    use std::f64::consts::PI;
    let mut d = d % (2.0 * PI);
    if d > PI {
        d -= 2.0 * PI;
    } else if d <= -PI {
        d += 2.0 * PI;
    }
    d
}

impl Frame {
    /// Frame of a boundary surface; `None` for planes. `scale` is the mesh size (sets `eps`).
    pub fn of_surface(s: &BoundarySurface, scale: f64) -> Option<Result<Frame, String>> {
        let (axis, is_cone) = match s {
            BoundarySurface::Plane => return None,
            BoundarySurface::Cylinder { axis } => (axis, false),
            BoundarySurface::Cone { axis } => (axis, true),
        };
        let len = axis.direction.length();
        if !(len.is_finite() && len > 1e-300) || !axis.origin.is_finite() {
            return Some(Err(format!(
                "axis origin {:?} / direction {:?} is not a finite non-zero vector",
                axis.origin, axis.direction
            )));
        }
        let dir = axis.direction / len;
        let (e1, e2) = dir.any_orthonormal_pair();
        Some(Ok(Frame {
            origin: axis.origin,
            axis: dir,
            e1,
            e2,
            eps: 1e-12 * scale.max(1e-300),
            is_cone,
        }))
    }

    /// `(theta, h, r)` of a point.
    #[inline]
    pub fn to_local(&self, p: DVec3) -> (f64, f64, f64) {
        let d = p - self.origin;
        let h = d.dot(self.axis);
        let x = d.dot(self.e1);
        let y = d.dot(self.e2);
        (y.atan2(x), h, (x * x + y * y).sqrt())
    }

    #[inline]
    pub fn from_local(&self, theta: f64, h: f64, r: f64) -> DVec3 {
        let (s, c) = theta.sin_cos();
        self.origin + self.axis * h + (self.e1 * c + self.e2 * s) * r
    }

    /// Affine combination `sum w_i p_i` carried out on `(theta, h, r)`: angles are unwrapped
    /// against the first point off the axis, points on the axis do not vote for the angle.
    pub fn combine(&self, pts: &[(DVec3, f64)]) -> DVec3 {
        let mut h = 0.0;
        let mut r = 0.0;
        let mut theta_ref = None;
        let mut dtheta = 0.0;
        let mut wtheta = 0.0;
        for &(p, w) in pts {
            let (t, hi, ri) = self.to_local(p);
            h += w * hi;
            r += w * ri;
            if ri > self.eps {
                let t0 = *theta_ref.get_or_insert(t);
                dtheta += w * wrap(t - t0);
                wtheta += w;
            }
        }
        let theta = match theta_ref {
            Some(t0) if wtheta.abs() > 1e-300 => t0 + dtheta / wtheta,
            _ => 0.0,
        };
        self.from_local(theta, h, r)
    }

    /// Unit surface normal at `p` (radially outward; for a cone tilted by the half-angle).
    pub fn surface_normal(&self, p: DVec3) -> DVec3 {
        let d = p - self.origin;
        let h = d.dot(self.axis);
        let radial = d - self.axis * h;
        let r = radial.length();
        if r <= self.eps {
            return DVec3::ZERO;
        }
        let u = radial / r;
        if self.is_cone && h.abs() > self.eps {
            // surface r - (r/h) h = 0: gradient u - (r/h) axis
            super::masks::normalize_or_zero(u - self.axis * (r / h))
        } else {
            u
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Axis;

    #[test]
    fn combine_keeps_radius_and_wraps() {
        let f = Frame::of_surface(
            &BoundarySurface::Cylinder {
                axis: Axis {
                    origin: DVec3::new(1.0, 2.0, 3.0),
                    direction: DVec3::new(0.0, 0.0, 2.0),
                },
            },
            1.0,
        )
        .unwrap()
        .unwrap();
        let a = f.from_local(3.0, 0.0, 2.0);
        let b = f.from_local(-3.0, 1.0, 2.0); // across the +-pi seam
        let m = f.combine(&[(a, 0.5), (b, 0.5)]);
        let (t, h, r) = f.to_local(m);
        assert!((r - 2.0).abs() < 1e-12);
        assert!((h - 0.5).abs() < 1e-12);
        assert!((wrap(t - std::f64::consts::PI)).abs() < 1e-12);
    }
}
