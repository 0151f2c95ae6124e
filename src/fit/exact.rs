//! A face's exact surface, when the input knows it (a STEP face's plane, cylinder, cone,
//! sphere or torus), so the error measurement can charge a decoded point for its distance to
//! the CAD surface itself and not only to the face's facets.
//!
//! Why it matters: a decoded point is charged its distance to the nearest input facet minus
//! that facet's chord allowance (the facet's own distance from the CAD surface). That is
//! right on the convex side of a facet and too lenient on the other: a point on the
//! concave side of a facet that sags by `a` may be `tol + 2a` from the CAD surface and still
//! pass. With the exact surface known, the distance to it is a second lower bound of the
//! point's distance to the face, exact inside the face, and the larger of the two is kept.

use glam::DVec3;

use crate::mesh::Axis;

/// The untrimmed analytic surface under one input face (model units). Only the surfaces
/// whose distance is closed-form are here; a face on any other surface has none and is
/// measured against its facets alone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ExactSurface {
    /// Through `axis.origin`, normal `axis.direction`.
    Plane {
        axis: Axis,
    },
    Cylinder {
        axis: Axis,
        radius: f64,
    },
    /// Apex at `axis.origin`, axis along `axis.direction`; both nappes.
    Cone {
        axis: Axis,
        half_angle: f64,
    },
    Sphere {
        centre: DVec3,
        radius: f64,
    },
    /// Centre `axis.origin`, the tube's centre circle of radius `major` about the axis.
    Torus {
        axis: Axis,
        major: f64,
        minor: f64,
    },
}

/// Height along the axis and distance from it.
fn axial(axis: &Axis, p: DVec3) -> (f64, f64) {
    let d = p - axis.origin;
    let h = d.dot(axis.direction);
    (h, (d - h * axis.direction).length())
}

impl ExactSurface {
    /// The same surface with a unit axis direction, or `None` when a parameter is not finite,
    /// a radius is negative or the direction is zero (such a surface would measure nothing
    /// sensible; the face is then measured against its facets alone).
    pub fn normalized(self) -> Option<ExactSurface> {
        let unit = |a: Axis| -> Option<Axis> {
            let direction = a.direction.try_normalize()?;
            a.origin.is_finite().then_some(Axis {
                origin: a.origin,
                direction,
            })
        };
        let radius_ok = |r: f64| r.is_finite() && r >= 0.0;
        let s = match self {
            ExactSurface::Plane { axis } => ExactSurface::Plane { axis: unit(axis)? },
            ExactSurface::Cylinder { axis, radius } if radius_ok(radius) => {
                ExactSurface::Cylinder {
                    axis: unit(axis)?,
                    radius,
                }
            }
            ExactSurface::Cone { axis, half_angle }
                if half_angle > 0.0 && half_angle < std::f64::consts::FRAC_PI_2 =>
            {
                ExactSurface::Cone {
                    axis: unit(axis)?,
                    half_angle,
                }
            }
            ExactSurface::Sphere { centre, radius } if radius_ok(radius) && centre.is_finite() => {
                ExactSurface::Sphere { centre, radius }
            }
            ExactSurface::Torus { axis, major, minor } if radius_ok(major) && radius_ok(minor) => {
                ExactSurface::Torus {
                    axis: unit(axis)?,
                    major,
                    minor,
                }
            }
            _ => return None,
        };
        Some(s)
    }

    /// Distance from `p` to the surface (the axis direction must be a unit vector, as
    /// [`ExactSurface::normalized`] makes it).
    pub fn distance(&self, p: DVec3) -> f64 {
        match *self {
            ExactSurface::Plane { axis } => (p - axis.origin).dot(axis.direction).abs(),
            ExactSurface::Cylinder { axis, radius } => (axial(&axis, p).1 - radius).abs(),
            ExactSurface::Cone { axis, half_angle } => {
                // Both nappes (a STEP cone face may lie on either side of the apex): in p's
                // half-plane through the axis they are the rays (cos a, sin a) t and
                // (-cos a, sin a) t, t >= 0.
                let (h, r) = axial(&axis, p);
                let (s, c) = half_angle.sin_cos();
                let ray = |h: f64| {
                    if h * c + r * s >= 0.0 {
                        (r * c - h * s).abs()
                    } else {
                        h.hypot(r)
                    }
                };
                ray(h).min(ray(-h))
            }
            ExactSurface::Sphere { centre, radius } => ((p - centre).length() - radius).abs(),
            ExactSurface::Torus { axis, major, minor } => {
                // The tube's cross-section in p's plane through the axis is two circles, at
                // +major and -major from the axis; with minor > major (a spindle torus, as
                // STEP allows) the nearer part may be the far one.
                let (h, r) = axial(&axis, p);
                let near = ((r - major).hypot(h) - minor).abs();
                let far = ((r + major).hypot(h) - minor).abs();
                near.min(far)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tilted() -> Axis {
        Axis {
            origin: DVec3::new(1.0, -2.0, 0.5),
            direction: DVec3::new(1.0, 2.0, 2.0) / 3.0,
        }
    }

    /// A unit vector normal to the tilted axis.
    fn across() -> DVec3 {
        DVec3::new(2.0, -2.0, 1.0) / 3.0
    }

    #[test]
    fn distances_of_points_off_each_surface() {
        let a = tilted();
        let (n, x) = (a.direction, across());
        let cases = [
            (
                ExactSurface::Plane { axis: a },
                a.origin + 0.3 * n + 5.0 * x,
                0.3,
            ),
            (
                ExactSurface::Cylinder {
                    axis: a,
                    radius: 2.0,
                },
                a.origin + 7.0 * n + 2.5 * x,
                0.5,
            ),
            (
                ExactSurface::Sphere {
                    centre: a.origin,
                    radius: 2.0,
                },
                a.origin + 1.5 * x,
                0.5,
            ),
            (
                ExactSurface::Torus {
                    axis: a,
                    major: 5.0,
                    minor: 1.0,
                },
                a.origin + 5.0 * x + 0.25 * n,
                0.75,
            ),
            // A spindle torus: the point 2 from the axis at the centre's height is on the
            // tube circle about the opposite side's centre (v = pi: 1 + 3 cos v = -2).
            (
                ExactSurface::Torus {
                    axis: a,
                    major: 1.0,
                    minor: 3.0,
                },
                a.origin + 2.0 * x,
                0.0,
            ),
        ];
        for (s, p, want) in cases {
            let s = s.normalized().unwrap();
            assert!(
                (s.distance(p) - want).abs() < 1e-12,
                "{s:?}: {}",
                s.distance(p)
            );
        }
    }

    #[test]
    fn cone_distance_beside_the_generator_and_behind_the_apex() {
        let a = tilted();
        let (n, x) = (a.direction, across());
        // 45 degrees: the generator through (h, r) = (1, 1).
        let s = ExactSurface::Cone {
            axis: a,
            half_angle: std::f64::consts::FRAC_PI_4,
        }
        .normalized()
        .unwrap();
        // On the axis at height 2: sqrt(2) from the generator.
        assert!((s.distance(a.origin + 2.0 * n) - 2f64.sqrt()).abs() < 1e-12);
        // On the surface.
        assert!(s.distance(a.origin + 3.0 * n + 3.0 * x) < 1e-12);
        // Behind the apex: the other nappe.
        assert!(s.distance(a.origin - 3.0 * n + 3.0 * x) < 1e-12);
        assert!((s.distance(a.origin - 2.0 * n) - 2f64.sqrt()).abs() < 1e-12);
        // Level with the apex: sqrt 2 from both nappes.
        assert!((s.distance(a.origin + 2.0 * x) - 2f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn invalid_parameters_give_no_surface() {
        let a = tilted();
        let zero = Axis {
            origin: DVec3::ZERO,
            direction: DVec3::ZERO,
        };
        for s in [
            ExactSurface::Plane { axis: zero },
            ExactSurface::Cylinder {
                axis: a,
                radius: f64::NAN,
            },
            ExactSurface::Cone {
                axis: a,
                half_angle: 0.0,
            },
            ExactSurface::Sphere {
                centre: DVec3::splat(f64::INFINITY),
                radius: 1.0,
            },
            ExactSurface::Torus {
                axis: a,
                major: 2.0,
                minor: -1.0,
            },
        ] {
            assert_eq!(s.normalized(), None, "{s:?}");
        }
        // A non-unit direction is normalised.
        let s = ExactSurface::Plane {
            axis: Axis {
                origin: DVec3::ZERO,
                direction: DVec3::new(0.0, 0.0, 4.0),
            },
        }
        .normalized()
        .unwrap();
        assert!((s.distance(DVec3::new(3.0, 1.0, 2.0)) - 2.0).abs() < 1e-12);
    }
}
