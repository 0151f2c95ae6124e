//! Coordinate frames of the curved boundary patches: cylinder, cone, sphere and torus.
//!
//! Every mask is an affine combination. Applied to coordinates in which the surface is a
//! constant (or linear) third coordinate, instead of to Cartesian coordinates, any affine
//! combination keeps that coordinate: `r = R` on a cylinder and a sphere, `r = k h` about a
//! cone's apex, the tube radius `rho = r` on a torus. Points computed from control points on
//! the analytic surface stay exactly on it. See `spec/subdivision.md` §5.

use glam::DVec3;

use crate::mesh::BoundarySurface;

/// Which surface a frame's coordinates describe (see [`Frame::coords`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum FrameKind {
    Cylinder,
    Cone,
    Sphere,
    Torus { major_radius: f64 },
}

/// A coordinate system about an axis. Stored once per framed group and referenced by a small
/// id from vertices and edges, because only a few groups have one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Frame {
    pub origin: DVec3,
    /// Unit axis direction.
    pub axis: DVec3,
    pub e1: DVec3,
    pub e2: DVec3,
    /// An angle about the axis (or about a torus's spine circle) is undefined for points
    /// closer than this to the axis (the circle): a cone's apex, a sphere's poles.
    pub eps: f64,
    pub kind: FrameKind,
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

/// A point's frame coordinates: `c[i]` for `i` in 0..3, and for the angular ones
/// ([`Frame::angular`]) whether the point defines that angle.
struct Coords {
    c: [f64; 3],
    defined: [bool; 2],
}

impl Frame {
    /// Frame of a boundary surface; `None` for planes. `scale` is the mesh size (sets `eps`).
    pub fn of_surface(s: &BoundarySurface, scale: f64) -> Option<Result<Frame, String>> {
        let axis = s.axis()?;
        let kind = match *s {
            BoundarySurface::Plane => return None,
            BoundarySurface::Cylinder { .. } => FrameKind::Cylinder,
            BoundarySurface::Cone { .. } => FrameKind::Cone,
            BoundarySurface::Sphere { .. } => FrameKind::Sphere,
            BoundarySurface::Torus { major_radius, .. } => {
                if !(major_radius.is_finite() && major_radius >= 0.0) {
                    // No float in the message: formatting one would add a float printer to
                    // the WebAssembly decoder.
                    return Some(Err(
                        "torus major radius is not a finite non-negative number".into(),
                    ));
                }
                FrameKind::Torus { major_radius }
            }
        };
        let len = axis.direction.length();
        if !(len.is_finite() && len > 1e-300 && axis.origin.is_finite()) {
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
            kind,
        }))
    }

    /// Which coordinates are angles, combined after unwrapping: the angle about the axis
    /// always, the angle about a torus's spine circle too.
    fn angular(&self) -> [bool; 2] {
        [true, matches!(self.kind, FrameKind::Torus { .. })]
    }

    /// Coordinates of a point: cylinder and cone `(theta, h, r)`; sphere `(longitude,
    /// latitude, r)`; torus `(u, v, rho)` (angle about the axis, angle about the spine
    /// circle, distance from it).
    #[inline]
    fn coords(&self, p: DVec3) -> Coords {
        let d = p - self.origin;
        let h = d.dot(self.axis);
        let x = d.dot(self.e1);
        let y = d.dot(self.e2);
        let s = (x * x + y * y).sqrt();
        let theta = y.atan2(x);
        match self.kind {
            FrameKind::Cylinder | FrameKind::Cone => Coords {
                c: [theta, h, s],
                defined: [s > self.eps, false],
            },
            FrameKind::Sphere => Coords {
                c: [theta, h.atan2(s), (s * s + h * h).sqrt()],
                defined: [s > self.eps, false],
            },
            FrameKind::Torus { major_radius } => {
                let w = s - major_radius;
                let rho = (w * w + h * h).sqrt();
                Coords {
                    c: [theta, h.atan2(w), rho],
                    defined: [s > self.eps, rho > self.eps],
                }
            }
        }
    }

    /// How far apart `p` and `q` lie in the angle about the axis, in `[0, pi]` (0 when one of
    /// them is on the axis, where the angle is undefined). A straight edge on a cylinder or
    /// cone lies on the surface only at 0 (a ruling).
    pub fn turn(&self, p: DVec3, q: DVec3) -> f64 {
        let (a, b) = (self.coords(p), self.coords(q));
        if a.defined[0] && b.defined[0] {
            wrap(a.c[0] - b.c[0]).abs()
        } else {
            0.0
        }
    }

    /// The point with coordinates `c` ([`Frame::coords`]).
    #[inline]
    fn point(&self, c: [f64; 3]) -> DVec3 {
        let (sin, cos) = c[0].sin_cos();
        let around = self.e1 * cos + self.e2 * sin;
        match self.kind {
            FrameKind::Cylinder | FrameKind::Cone => self.origin + self.axis * c[1] + around * c[2],
            FrameKind::Sphere => {
                let (sin_lat, cos_lat) = c[1].sin_cos();
                self.origin + around * (c[2] * cos_lat) + self.axis * (c[2] * sin_lat)
            }
            FrameKind::Torus { major_radius } => {
                let (sin_v, cos_v) = c[1].sin_cos();
                self.origin + around * (major_radius + c[2] * cos_v) + self.axis * (c[2] * sin_v)
            }
        }
    }

    /// Affine combination `sum w_i p_i` carried out on the frame's coordinates: angles are
    /// unwrapped against the first point that defines them, points that do not (on the axis,
    /// on a torus's spine circle) do not vote for them.
    pub fn combine(&self, pts: &[(DVec3, f64)]) -> DVec3 {
        let angular = self.angular();
        let mut sum = [0.0; 3];
        let mut first: [Option<f64>; 2] = [None; 2];
        let mut votes = [0.0; 2];
        for &(p, w) in pts {
            let Coords { c, defined } = self.coords(p);
            for i in 0..3 {
                if i < 2 && angular[i] {
                    if defined[i] {
                        let t0 = *first[i].get_or_insert(c[i]);
                        sum[i] += w * wrap(c[i] - t0);
                        votes[i] += w;
                    }
                } else {
                    sum[i] += w * c[i];
                }
            }
        }
        for i in 0..2 {
            if angular[i] {
                sum[i] = match first[i] {
                    Some(t0) if votes[i].abs() > 1e-300 => t0 + sum[i] / votes[i],
                    _ => 0.0,
                };
            }
        }
        self.point(sum)
    }

    /// Unit surface normal at `p` (away from the axis, the centre or the spine circle; for a
    /// cone tilted by the half-angle); zero where it is undefined.
    pub fn surface_normal(&self, p: DVec3) -> DVec3 {
        let d = p - self.origin;
        let h = d.dot(self.axis);
        let radial = d - self.axis * h;
        let r = radial.length();
        match self.kind {
            FrameKind::Sphere => return super::masks::normalize_or_zero(d),
            FrameKind::Torus { major_radius } => {
                if r <= self.eps {
                    return DVec3::ZERO;
                }
                let spine = self.origin + radial * (major_radius / r);
                return super::masks::normalize_or_zero(p - spine);
            }
            FrameKind::Cylinder | FrameKind::Cone => {}
        }
        if r <= self.eps {
            return DVec3::ZERO;
        }
        let u = radial / r;
        if self.kind == FrameKind::Cone && h.abs() > self.eps {
            // surface r - (r/h) h = 0: gradient u - (r/h) axis
            super::masks::normalize_or_zero(u - self.axis * (r / h))
        } else {
            u
        }
    }

    /// A number that tells the kinds apart, and a torus's major radius, for fingerprints.
    #[cfg(feature = "encoder")]
    pub fn kind_bits(&self) -> (u64, u64) {
        match self.kind {
            FrameKind::Cylinder => (0, 0),
            FrameKind::Cone => (1, 0),
            FrameKind::Sphere => (2, 0),
            FrameKind::Torus { major_radius } => (3, major_radius.to_bits()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Axis;

    fn frame(s: BoundarySurface) -> Frame {
        Frame::of_surface(&s, 1.0).unwrap().unwrap()
    }

    fn axis(origin: DVec3, direction: DVec3) -> Axis {
        Axis { origin, direction }
    }

    #[test]
    fn combine_keeps_radius_and_wraps() {
        let f = frame(BoundarySurface::Cylinder {
            axis: axis(DVec3::new(1.0, 2.0, 3.0), DVec3::new(0.0, 0.0, 2.0)),
        });
        let a = f.point([3.0, 0.0, 2.0]);
        let b = f.point([-3.0, 1.0, 2.0]); // across the +-pi seam
        let m = f.combine(&[(a, 0.5), (b, 0.5)]);
        let c = f.coords(m).c;
        assert!((c[2] - 2.0).abs() < 1e-12);
        assert!((c[1] - 0.5).abs() < 1e-12);
        assert!((wrap(c[0] - std::f64::consts::PI)).abs() < 1e-12);
    }

    #[test]
    fn sphere_combinations_stay_on_the_sphere_and_poles_do_not_vote() {
        let centre = DVec3::new(-1.0, 0.5, 2.0);
        let f = frame(BoundarySurface::Sphere {
            axis: axis(centre, DVec3::new(1.0, 1.0, 0.0)),
        });
        let on = |lon: f64, lat: f64| f.point([lon, lat, 3.0]);
        // A Loop edge mask across the longitude seam, with negative weights elsewhere.
        let pts = [
            (on(3.0, 0.2), 0.375),
            (on(-3.0, -0.4), 0.375),
            (on(2.5, 0.9), 0.125),
            (on(-2.6, -1.1), 0.125),
        ];
        let m = f.combine(&pts);
        assert!(((m - centre).length() - 3.0).abs() < 1e-12);
        let c = f.coords(m).c;
        assert!(wrap(c[0] - std::f64::consts::PI).abs() < 0.3, "{c:?}");
        let w = [(on(0.3, -0.2), 1.25), (on(0.1, 0.4), -0.25)];
        assert!(((f.combine(&w) - centre).length() - 3.0).abs() < 1e-12);
        // The pole has no longitude: the midpoint of the pole and a point at longitude 1 is
        // at longitude 1.
        let pole = centre + f.axis * 3.0;
        let c = f.coords(f.combine(&[(pole, 0.5), (on(1.0, 0.0), 0.5)])).c;
        assert!((c[0] - 1.0).abs() < 1e-12 && (c[1] - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        let n = f.surface_normal(on(0.7, 0.3));
        assert!((n - (on(0.7, 0.3) - centre) / 3.0).length() < 1e-12);
    }

    #[test]
    fn torus_combinations_stay_on_the_torus_across_both_seams() {
        let centre = DVec3::new(0.0, 0.0, 1.0);
        let (major, minor) = (5.0, 1.5);
        let f = frame(BoundarySurface::Torus {
            axis: axis(centre, DVec3::Z),
            major_radius: major,
        });
        let on = |u: f64, v: f64| f.point([u, v, minor]);
        let dist_to_spine = |p: DVec3| {
            let d = p - centre;
            let s = (d.x * d.x + d.y * d.y).sqrt();
            ((s - major).powi(2) + d.z * d.z).sqrt()
        };
        let pts = [
            (on(3.1, 3.0), 0.625),
            (on(-3.1, -3.1), 0.125),
            (on(3.0, -3.0), 0.125),
            (on(-3.0, 2.9), 0.125),
        ];
        let m = f.combine(&pts);
        assert!((dist_to_spine(m) - minor).abs() < 1e-12);
        let c = f.coords(m).c;
        assert!(wrap(c[0] - std::f64::consts::PI).abs() < 0.2, "{c:?}");
        assert!(wrap(c[1] - std::f64::consts::PI).abs() < 0.2, "{c:?}");
        // Affine with a negative weight: still on the torus.
        let w = [(on(0.2, 1.0), 1.5), (on(0.4, 1.2), -0.5)];
        assert!((dist_to_spine(f.combine(&w)) - minor).abs() < 1e-12);
        let p = on(0.7, 2.0);
        let n = f.surface_normal(p);
        let spine = centre + DVec3::new(0.7f64.cos(), 0.7f64.sin(), 0.0) * major;
        assert!((n - (p - spine) / minor).length() < 1e-12);
    }

    #[test]
    fn a_torus_needs_a_finite_major_radius() {
        let s = BoundarySurface::Torus {
            axis: axis(DVec3::ZERO, DVec3::Z),
            major_radius: f64::NAN,
        };
        assert!(Frame::of_surface(&s, 1.0).unwrap().is_err());
    }
}
