//! A face's exact surface, when the input knows it (a STEP face's plane, cylinder, cone,
//! sphere or torus), so the error measurement can charge a decoded point for its distance to
//! the CAD surface itself and not only to the face's facets.
//!
//! Why it matters: the facets sag from the surface by up to their chord, on either side of a
//! decoded point, so no allowance on the distance to them is right on both sides (a point on
//! the concave side of a facet that sags by `a` is `a` farther from the surface than from the
//! facet, one on the convex side `a` nearer). Where the point's projection onto the exact
//! surface lies over the face, its distance to the surface is its distance to the face;
//! elsewhere only the facets bound it ([`super::allowance::OwnFaces`]).

use glam::DVec3;

use crate::mesh::AnalyticSurface;
use crate::mesh::Axis;

/// The untrimmed analytic surface under one input face (model units): a [`AnalyticSurface`] with
/// finite parameters and unit directions, whose cone has both nappes (a STEP cone face may
/// lie on either side of the apex; a fitted cone is the one nappe its points are on). A
/// face on any other surface has none and is measured against its facets alone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExactSurface(AnalyticSurface);

impl ExactSurface {
    /// The surface, with unit directions; `None` when a parameter is not finite, a radius
    /// is negative, a cone's half angle is not strictly between 0 and 90 degrees or a
    /// direction is zero (such a surface would measure nothing sensible).
    #[cfg(any(feature = "step", feature = "internals"))]
    pub fn new(surface: AnalyticSurface) -> Option<ExactSurface> {
        let unit = |a: Axis| -> Option<Axis> {
            let direction = a.direction.try_normalize()?;
            a.origin.is_finite().then_some(Axis {
                origin: a.origin,
                direction,
            })
        };
        let radius_ok = |r: f64| r.is_finite() && r >= 0.0;
        let s = match surface {
            AnalyticSurface::Plane { point, normal } => {
                let axis = unit(Axis {
                    origin: point,
                    direction: normal,
                })?;
                AnalyticSurface::Plane {
                    point: axis.origin,
                    normal: axis.direction,
                }
            }
            AnalyticSurface::Cylinder { axis, radius } if radius_ok(radius) => {
                AnalyticSurface::Cylinder {
                    axis: unit(axis)?,
                    radius,
                }
            }
            AnalyticSurface::Cone { axis, half_angle }
                if half_angle > 0.0 && half_angle < std::f64::consts::FRAC_PI_2 =>
            {
                AnalyticSurface::Cone {
                    axis: unit(axis)?,
                    half_angle,
                }
            }
            AnalyticSurface::Sphere { center, radius }
                if radius_ok(radius) && center.is_finite() =>
            {
                AnalyticSurface::Sphere { center, radius }
            }
            AnalyticSurface::Torus {
                axis,
                major_radius,
                minor_radius,
            } if radius_ok(major_radius) && radius_ok(minor_radius) => AnalyticSurface::Torus {
                axis: unit(axis)?,
                major_radius,
                minor_radius,
            },
            _ => return None,
        };
        Some(ExactSurface(s))
    }

    /// The surface itself, and for a cone its other nappe (a STEP cone face may lie on
    /// either side of the apex).
    fn nappes(&self) -> (AnalyticSurface, Option<AnalyticSurface>) {
        match self.0 {
            AnalyticSurface::Cone { axis, half_angle } => {
                let other = AnalyticSurface::Cone {
                    axis: Axis {
                        origin: axis.origin,
                        direction: -axis.direction,
                    },
                    half_angle,
                };
                (self.0, Some(other))
            }
            s => (s, None),
        }
    }

    /// Distance from `p` to the surface (a cone's nearer nappe).
    pub fn distance(&self, p: DVec3) -> f64 {
        match self.nappes() {
            (s, Some(other)) => s.distance(p).min(other.distance(p)),
            (s, None) => s.distance(p),
        }
    }

    /// The point of the surface nearest to `p` (a cone's nearer nappe): where the fit pulls
    /// a closed patch's limit points, so the patch lies on the CAD surface and not on its
    /// facets, which sag from it by up to their chord.
    pub fn project(&self, p: DVec3) -> DVec3 {
        match self.nappes() {
            (s, Some(other)) => {
                let (a, b) = (s.project(p), other.project(p));
                if b.distance(p) < a.distance(p) {
                    b
                } else {
                    a
                }
            }
            (s, None) => s.project(p),
        }
    }
}

/// A point on every surface of `surfaces` near `p` (where faces meet along a B-rep edge),
/// by alternating projections: `None` when they do not converge to a common point within
/// `1e-9` of `p`'s scale, or when the point found is more than four times as far from `p`
/// as `p` is from the farthest surface (nearly tangent surfaces let the iterates drift
/// along the edge instead of across it).
pub fn onto_all(surfaces: &[ExactSurface], p: DVec3) -> Option<DVec3> {
    let gap = |q: DVec3| surfaces.iter().map(|s| s.distance(q)).fold(0.0, f64::max);
    let start_gap = gap(p);
    let scale = p.abs().max_element().max(1.0);
    let mut q = p;
    for _ in 0..64 {
        for s in surfaces {
            q = s.project(q);
        }
        if gap(q) <= 1e-9 * scale {
            return (q.distance(p) <= 4.0 * start_gap + 1e-9 * scale).then_some(q);
        }
    }
    None
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
                AnalyticSurface::Plane {
                    point: a.origin,
                    normal: n,
                },
                a.origin + 0.3 * n + 5.0 * x,
                0.3,
            ),
            (
                AnalyticSurface::Cylinder {
                    axis: a,
                    radius: 2.0,
                },
                a.origin + 7.0 * n + 2.5 * x,
                0.5,
            ),
            (
                AnalyticSurface::Sphere {
                    center: a.origin,
                    radius: 2.0,
                },
                a.origin + 1.5 * x,
                0.5,
            ),
            (
                AnalyticSurface::Torus {
                    axis: a,
                    major_radius: 5.0,
                    minor_radius: 1.0,
                },
                a.origin + 5.0 * x + 0.25 * n,
                0.75,
            ),
            // A spindle torus: the point 2 from the axis at the centre's height is on the
            // tube circle about the opposite side's centre (v = pi: 1 + 3 cos v = -2).
            (
                AnalyticSurface::Torus {
                    axis: a,
                    major_radius: 1.0,
                    minor_radius: 3.0,
                },
                a.origin + 2.0 * x,
                0.0,
            ),
        ];
        for (s, p, want) in cases {
            let s = ExactSurface::new(s).unwrap();
            assert!(
                (s.distance(p) - want).abs() < 1e-12,
                "{s:?}: {}",
                s.distance(p)
            );
        }
    }

    #[test]
    fn projections_lie_on_the_surface_at_the_measured_distance() {
        let a = tilted();
        let (n, x) = (a.direction, across());
        let y = n.cross(x);
        let surfaces = [
            AnalyticSurface::Plane {
                point: a.origin,
                normal: n,
            },
            AnalyticSurface::Cylinder {
                axis: a,
                radius: 2.0,
            },
            AnalyticSurface::Cone {
                axis: a,
                half_angle: 0.4,
            },
            AnalyticSurface::Sphere {
                center: a.origin,
                radius: 2.0,
            },
            AnalyticSurface::Torus {
                axis: a,
                major_radius: 3.0,
                minor_radius: 1.0,
            },
            AnalyticSurface::Torus {
                axis: a,
                major_radius: 1.0,
                minor_radius: 3.0,
            },
        ];
        for s in surfaces {
            let e = ExactSurface::new(s).unwrap();
            for i in 0..50 {
                let t = f64::from(i);
                let p = a.origin
                    + (2.0 * (0.37 * t).sin() + 0.3) * n
                    + (3.0 * (0.71 * t).cos()) * x
                    + (2.5 * (1.13 * t).sin()) * y;
                let q = e.project(p);
                assert!(e.distance(q) < 1e-9, "{s:?}: {p} -> {q} is off the surface");
                assert!(
                    (q.distance(p) - e.distance(p)).abs() < 1e-9,
                    "{s:?}: {p} -> {q} at {} but the surface is {} away",
                    q.distance(p),
                    e.distance(p)
                );
            }
        }
    }

    #[test]
    fn a_point_near_a_circle_where_a_plane_cuts_a_sphere_goes_onto_it() {
        let a = tilted();
        let (n, x) = (a.direction, across());
        let plane = ExactSurface::new(AnalyticSurface::Plane {
            point: a.origin + n,
            normal: n,
        })
        .unwrap();
        let sphere = ExactSurface::new(AnalyticSurface::Sphere {
            center: a.origin,
            radius: 2.0,
        })
        .unwrap();
        // The circle: height 1, radius sqrt 3.
        let on = a.origin + n + 3f64.sqrt() * x;
        let p = on + 0.01 * n - 0.02 * x;
        let q = onto_all(&[plane, sphere], p).unwrap();
        assert!(q.distance(on) < 1e-6, "{q} is not {on}");
        // A plane and a sphere that do not meet: no common point.
        let far = ExactSurface::new(AnalyticSurface::Plane {
            point: a.origin + 3.0 * n,
            normal: n,
        })
        .unwrap();
        assert_eq!(onto_all(&[far, sphere], p), None);
    }

    #[test]
    fn cone_distance_beside_the_generator_and_behind_the_apex() {
        let a = tilted();
        let (n, x) = (a.direction, across());
        // 45 degrees: the generator through (h, r) = (1, 1).
        let s = ExactSurface::new(AnalyticSurface::Cone {
            axis: a,
            half_angle: std::f64::consts::FRAC_PI_4,
        })
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
            AnalyticSurface::Plane {
                point: zero.origin,
                normal: zero.direction,
            },
            AnalyticSurface::Cylinder {
                axis: a,
                radius: f64::NAN,
            },
            AnalyticSurface::Cone {
                axis: a,
                half_angle: 0.0,
            },
            AnalyticSurface::Sphere {
                center: DVec3::splat(f64::INFINITY),
                radius: 1.0,
            },
            AnalyticSurface::Torus {
                axis: a,
                major_radius: 2.0,
                minor_radius: -1.0,
            },
        ] {
            assert_eq!(ExactSurface::new(s), None, "{s:?}");
        }
        // A non-unit direction is normalised.
        let s = ExactSurface::new(AnalyticSurface::Plane {
            point: DVec3::ZERO,
            normal: DVec3::new(0.0, 0.0, 4.0),
        })
        .unwrap();
        assert!((s.distance(DVec3::new(3.0, 1.0, 2.0)) - 2.0).abs() < 1e-12);
    }
}
