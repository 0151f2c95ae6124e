//! Exact elementary surfaces (plane, cylinder, cone, sphere, torus) built from the STEP
//! record itself, with closed-form evaluation and inversion (point -> (u, v)).
//!
//! truck-stepio converts these surfaces into its own revolved-curve forms, and on some files
//! the result does not pass through the face's own edges (cones, spindle tori with a minor
//! radius larger than the major one, ...): the conforming tessellation could then not
//! project the boundary. The STEP definition (ISO 10303-42) is simple enough to evaluate
//! here, in the record's own parametrisation:
//!
//! * plane: `C + u x + v y`
//! * cylinder: `C + r (cos u x + sin u y) + v z`
//! * cone: `C + (r + v tan a) (cos u x + sin u y) + v z` (apex at `v = -r / tan a`)
//! * sphere: `C + r cos v (cos u x + sin u y) + r sin v z`, `v` in `[-pi/2, pi/2]`
//! * torus: `C + (R + r cos v) (cos u x + sin u y) + r sin v z`
//!
//! with `(C, x, y, z)` the AXIS2_PLACEMENT_3D. `u` (and the torus's `v`) is periodic with
//! period 2 pi. The normal `d/du x d/dv` points away from the axis (plane: along `z`), as in
//! STEP; a face's `same_sense` is applied by the caller.

use glam::{DMat4, DVec3};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

use super::text::Records;
use crate::io::faces_json::SurfaceType;
use crate::mesh::{AnalyticSurface, Axis};

/// Which elementary surface, with its sizes (file units; angle in radians).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Kind {
    Plane,
    Cylinder {
        radius: f64,
    },
    /// `radius` at the placement (`v = 0`), `semi_angle` in radians, in `(0, pi/2)`.
    Cone {
        radius: f64,
        semi_angle: f64,
    },
    Sphere {
        radius: f64,
    },
    Torus {
        major: f64,
        minor: f64,
    },
}

/// An elementary surface in its STEP placement. Kept as the frame plus the sizes (not as a
/// matrix) because evaluation and inversion both work in the local frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Analytic {
    pub origin: DVec3,
    /// Orthonormal, right-handed: `x` is the placement's ref_direction made perpendicular to
    /// `z` (the axis), `y = z x x`.
    pub x: DVec3,
    pub y: DVec3,
    pub z: DVec3,
    pub kind: Kind,
}

impl Analytic {
    /// The exact surface of record `#surface_id` if it is one of the five elementary
    /// surfaces; `Ok(None)` for other surfaces, `Err` when the record is one but cannot be
    /// read (the message names the field). `radians_per_unit` converts the cone's semi-angle.
    pub fn from_record(
        records: &Records,
        surface_id: u64,
        radians_per_unit: f64,
    ) -> Result<Option<Analytic>, String> {
        let Some(r) = records.get(surface_id) else {
            return Ok(None);
        };
        if r.names.len() != 1 {
            return Ok(None);
        }
        let name = r.names[0].as_str();
        let count = match name {
            "PLANE" => 2,
            "CYLINDRICAL_SURFACE" | "SPHERICAL_SURFACE" => 3,
            "CONICAL_SURFACE" | "TOROIDAL_SURFACE" => 4,
            _ => return Ok(None),
        };
        let here = format!("{name} #{surface_id}");
        let args = records
            .args(surface_id)
            .ok_or_else(|| format!("{here}: its parameters cannot be read"))?;
        if args.len() != count {
            return Err(format!(
                "{here}: {} parameters where {count} were expected",
                args.len()
            ));
        }
        let placement_id = args[1]
            .trim()
            .strip_prefix('#')
            .and_then(|s| s.parse::<u64>().ok())
            .ok_or_else(|| format!("{here}: the position is not a reference"))?;
        let m: DMat4 = records
            .placement(placement_id)
            .ok_or_else(|| format!("{here}: AXIS2_PLACEMENT_3D #{placement_id} is unreadable"))?;
        let number = |k: usize, what: &str| -> Result<f64, String> {
            let s = args[k].trim();
            // A typed measure `LENGTH_MEASURE(2.)` or a plain number.
            let s = s
                .find('(')
                .and_then(|o| s.rfind(')').map(|c| &s[o + 1..c]))
                .unwrap_or(s);
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("{here}: the {what} `{}` is not a number", args[k]))
        };
        let positive = |x: f64, what: &str| {
            if x > 0.0 {
                Ok(x)
            } else {
                Err(format!("{here}: the {what} {x} is not positive"))
            }
        };
        let kind = match name {
            "PLANE" => Kind::Plane,
            "CYLINDRICAL_SURFACE" => Kind::Cylinder {
                radius: positive(number(2, "radius")?, "radius")?,
            },
            "SPHERICAL_SURFACE" => Kind::Sphere {
                radius: positive(number(2, "radius")?, "radius")?,
            },
            "CONICAL_SURFACE" => {
                let radius = number(2, "radius")?;
                let semi_angle = number(3, "semi-angle")? * radians_per_unit;
                if radius < 0.0 || !(semi_angle > 0.0 && semi_angle < FRAC_PI_2) {
                    return Err(format!(
                        "{here}: radius {radius} / semi-angle {semi_angle} rad out of range"
                    ));
                }
                Kind::Cone { radius, semi_angle }
            }
            _ => Kind::Torus {
                major: positive(number(2, "major radius")?, "major radius")?,
                minor: positive(number(3, "minor radius")?, "minor radius")?,
            },
        };
        Ok(Some(Analytic {
            origin: m.w_axis.truncate(),
            x: m.x_axis.truncate(),
            y: m.y_axis.truncate(),
            z: m.z_axis.truncate(),
            kind,
        }))
    }

    fn radial_dir(&self, u: f64) -> DVec3 {
        u.cos() * self.x + u.sin() * self.y
    }

    /// The point at `(u, v)`.
    pub fn point(&self, u: f64, v: f64) -> DVec3 {
        let c = self.origin;
        match self.kind {
            Kind::Plane => c + u * self.x + v * self.y,
            Kind::Cylinder { radius } => c + radius * self.radial_dir(u) + v * self.z,
            Kind::Cone { radius, semi_angle } => {
                c + (radius + v * semi_angle.tan()) * self.radial_dir(u) + v * self.z
            }
            Kind::Sphere { radius } => {
                c + radius * v.cos() * self.radial_dir(u) + radius * v.sin() * self.z
            }
            Kind::Torus { major, minor } => {
                c + (major + minor * v.cos()) * self.radial_dir(u) + minor * v.sin() * self.z
            }
        }
    }

    /// Periods of `u` and `v`.
    pub fn periods(&self) -> [Option<f64>; 2] {
        match self.kind {
            Kind::Plane => [None, None],
            Kind::Cylinder { .. } | Kind::Cone { .. } | Kind::Sphere { .. } => [Some(TAU), None],
            Kind::Torus { .. } => [Some(TAU), Some(TAU)],
        }
    }

    /// The domain edge a face bounded by one loop around the axis is closed against: the
    /// sphere's poles (`v` in `[-pi/2, pi/2]`) and the cone's apex (both ends at the apex's
    /// `v`, whichever side the face lies on). `None` where the parameter is unbounded.
    pub fn ranges(&self) -> [Option<(f64, f64)>; 2] {
        match self.kind {
            Kind::Sphere { .. } => [None, Some((-FRAC_PI_2, FRAC_PI_2))],
            Kind::Cone { radius, semi_angle } => {
                let apex = -radius / semi_angle.tan();
                [None, Some((apex, apex))]
            }
            _ => [None, None],
        }
    }

    /// Parameters of the point of the surface nearest to `p` (exact, closed form). Where
    /// `u` is undefined (on the axis: sphere poles, cone apex) it is taken from `hint`.
    /// Periodic parameters are the representatives nearest to `hint` (else in `[-pi, pi]`).
    pub fn project(&self, p: DVec3, hint: Option<[f64; 2]>) -> [f64; 2] {
        let d = p - self.origin;
        let (lx, ly, lz) = (d.dot(self.x), d.dot(self.y), d.dot(self.z));
        let rho = lx.hypot(ly);
        // On the axis the angle is undefined: keep the hint's.
        let scale = match self.kind {
            Kind::Plane => 1.0,
            Kind::Cylinder { radius } | Kind::Sphere { radius } => radius,
            Kind::Cone { radius, .. } => radius.max(lz.abs()),
            Kind::Torus { major, minor } => major.max(minor),
        };
        let on_axis = rho <= 1e-12 * scale.max(1e-300);
        let angle = if on_axis {
            hint.map_or(0.0, |h| h[0])
        } else {
            ly.atan2(lx)
        };
        let uv = match self.kind {
            Kind::Plane => [lx, ly],
            Kind::Cylinder { .. } => [angle, lz],
            Kind::Sphere { .. } => [angle, lz.atan2(rho)],
            Kind::Cone { radius, semi_angle } => {
                let (s, c) = semi_angle.sin_cos();
                // Foot on the generator through (radius, 0) along (sin a, cos a) in the
                // (rho, z) half-plane at `angle`, and on the one at `angle + pi` (the other
                // nappe, reached when the cone's radius is negative there).
                let foot = |rho: f64| {
                    let t = (rho - radius) * s + lz * c;
                    let q = (radius + t * s, t * c);
                    (t * c, (q.0 - rho).hypot(q.1 - lz))
                };
                let (v1, d1) = foot(rho);
                let (v2, d2) = foot(-rho);
                let r1 = radius + v1 * semi_angle.tan();
                if on_axis || (r1 >= 0.0 && d1 <= d2) {
                    [angle, v1]
                } else {
                    [angle + PI, v2]
                }
            }
            Kind::Torus { major, minor } => {
                // The meridian circle at `angle` (centre at +major) or at `angle + pi`
                // (centre at -major in this half-plane): the nearer one.
                let d1 = ((rho - major).hypot(lz) - minor).abs();
                let d2 = ((-rho - major).hypot(lz) - minor).abs();
                if on_axis || d1 <= d2 {
                    [angle, lz.atan2(rho - major)]
                } else {
                    [angle + PI, lz.atan2(-rho - major)]
                }
            }
        };
        let periods = self.periods();
        let mut out = uv;
        for k in 0..2 {
            if let Some(t) = periods[k] {
                let reference = hint.map_or(0.0, |h| h[k]);
                out[k] = uv[k] + ((reference - uv[k]) / t).round() * t;
            }
        }
        out
    }

    /// Parameter values over `range` such that a grid of them is within `tol` of the
    /// surface (chordal error of arcs; straight directions need only their ends).
    pub fn division(&self, range: ((f64, f64), (f64, f64)), tol: f64) -> (Vec<f64>, Vec<f64>) {
        let ((u0, u1), (v0, v1)) = range;
        // Angle step of a circle of radius r with sagitta tol.
        let step = |r: f64| {
            if r <= tol {
                PI / 2.0
            } else {
                (2.0 * (1.0 - tol / r).acos()).min(PI / 2.0)
            }
        };
        let split = |a: f64, b: f64, h: f64| {
            let n = (((b - a).abs() / h).ceil() as usize).clamp(1, 1 << 20);
            (0..=n)
                .map(|i| a + (b - a) * i as f64 / n as f64)
                .collect::<Vec<f64>>()
        };
        match self.kind {
            Kind::Plane => (vec![u0, u1], vec![v0, v1]),
            Kind::Cylinder { radius } => (split(u0, u1, step(radius)), vec![v0, v1]),
            Kind::Cone { radius, semi_angle } => {
                let t = semi_angle.tan();
                let r = (radius + v0 * t).abs().max((radius + v1 * t).abs());
                (split(u0, u1, step(r)), vec![v0, v1])
            }
            Kind::Sphere { radius } => (split(u0, u1, step(radius)), split(v0, v1, step(radius))),
            Kind::Torus { major, minor } => (
                split(u0, u1, step(major + minor)),
                split(v0, v1, step(minor)),
            ),
        }
    }

    /// The surface type and the exact surface in model coordinates (file units).
    pub fn describe(&self) -> (SurfaceType, AnalyticSurface) {
        let axis = Axis {
            origin: self.origin,
            direction: self.z,
        };
        match self.kind {
            Kind::Plane => (
                SurfaceType::Plane,
                AnalyticSurface::Plane {
                    point: self.origin,
                    normal: self.z,
                },
            ),
            Kind::Cylinder { radius } => (
                SurfaceType::Cylinder,
                AnalyticSurface::Cylinder { axis, radius },
            ),
            Kind::Sphere { radius } => (
                SurfaceType::Sphere,
                AnalyticSurface::Sphere {
                    center: self.origin,
                    radius,
                },
            ),
            Kind::Torus { major, minor } => (
                SurfaceType::Torus,
                AnalyticSurface::Torus {
                    axis,
                    major_radius: major,
                    minor_radius: minor,
                },
            ),
            Kind::Cone { radius, semi_angle } => (
                SurfaceType::Cone,
                AnalyticSurface::Cone {
                    axis: Axis {
                        origin: self.origin - radius / semi_angle.tan() * self.z,
                        direction: self.z,
                    },
                    half_angle: semi_angle,
                },
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(kind: Kind) -> Analytic {
        // A tilted frame so no test passes by coinciding with the world axes.
        let z = DVec3::new(1.0, 2.0, 2.0) / 3.0;
        let x = DVec3::new(2.0, -2.0, 1.0) / 3.0;
        Analytic {
            origin: DVec3::new(3.0, -1.0, 0.5),
            x,
            y: z.cross(x),
            z,
            kind,
        }
    }

    fn all() -> Vec<Analytic> {
        vec![
            frame(Kind::Plane),
            frame(Kind::Cylinder { radius: 2.0 }),
            frame(Kind::Cone {
                radius: 1.5,
                semi_angle: 0.4,
            }),
            frame(Kind::Sphere { radius: 2.5 }),
            frame(Kind::Torus {
                major: 4.0,
                minor: 1.0,
            }),
            // A spindle torus (minor > major), as in screw.step.
            frame(Kind::Torus {
                major: 1.0,
                minor: 6.5,
            }),
        ]
    }

    #[test]
    fn project_inverts_point() {
        for s in all() {
            for i in 0..7 {
                for j in 0..7 {
                    let u = -3.0 + 0.9 * f64::from(i);
                    let v = match s.kind {
                        Kind::Sphere { .. } => -1.4 + 0.45 * f64::from(j),
                        Kind::Torus { .. } => -3.0 + 0.9 * f64::from(j),
                        _ => -1.0 + 0.7 * f64::from(j),
                    };
                    // Stay on the spindle torus's outer sheet (R + r cos v > 0) and the
                    // cone's nappe (radius + v tan a > 0), where (u, v) is unique.
                    if let Kind::Torus { major, minor } = s.kind {
                        if major + minor * v.cos() <= 0.1 {
                            continue;
                        }
                    }
                    let p = s.point(u, v);
                    let q = s.project(p, Some([u + 0.1, v - 0.1]));
                    assert!(
                        (q[0] - u).abs() < 1e-9 && (q[1] - v).abs() < 1e-9,
                        "{:?}: ({u}, {v}) -> {q:?}",
                        s.kind
                    );
                    assert!(s.point(q[0], q[1]).distance(p) < 1e-12);
                    // Off the surface along the normal: the same parameters.
                    let du = (s.point(u + 1e-6, v) - s.point(u - 1e-6, v)) / 2e-6;
                    let dv = (s.point(u, v + 1e-6) - s.point(u, v - 1e-6)) / 2e-6;
                    let n = du.cross(dv).normalize();
                    let q = s.project(p + 0.05 * n, Some([u, v]));
                    assert!(s.point(q[0], q[1]).distance(p) < 1e-6, "{:?}", s.kind);
                }
            }
        }
    }

    #[test]
    fn known_points() {
        let cyl = frame(Kind::Cylinder { radius: 2.0 });
        assert!(cyl
            .point(0.0, 1.0)
            .abs_diff_eq(cyl.origin + 2.0 * cyl.x + cyl.z, 1e-12));
        let cone = frame(Kind::Cone {
            radius: 1.0,
            semi_angle: std::f64::consts::FRAC_PI_4,
        });
        // The apex, one unit below the placement, with any u.
        let apex = cone.origin - cone.z;
        assert!(cone.point(1.3, -1.0).distance(apex) < 1e-12);
        let AnalyticSurface::Cone { axis, .. } = cone.describe().1 else {
            panic!("not a cone")
        };
        assert!(axis.origin.distance(apex) < 1e-12);
        let q = cone.project(apex, Some([0.7, 0.0]));
        assert!((q[0] - 0.7).abs() < 1e-12 && (q[1] + 1.0).abs() < 1e-12);
        // Sphere poles and equator.
        let sph = frame(Kind::Sphere { radius: 2.0 });
        assert!(sph
            .point(0.3, FRAC_PI_2)
            .abs_diff_eq(sph.origin + 2.0 * sph.z, 1e-12));
        assert!(sph
            .point(FRAC_PI_2, 0.0)
            .abs_diff_eq(sph.origin + 2.0 * sph.y, 1e-12));
        let q = sph.project(sph.origin - 2.0 * sph.z, Some([0.4, -1.0]));
        assert!((q[0] - 0.4).abs() < 1e-12 && (q[1] + FRAC_PI_2).abs() < 1e-12);
        // Torus: outer equator and top.
        let tor = frame(Kind::Torus {
            major: 4.0,
            minor: 1.0,
        });
        assert!(tor
            .point(0.0, 0.0)
            .abs_diff_eq(tor.origin + 5.0 * tor.x, 1e-12));
        assert!(tor
            .point(PI, FRAC_PI_2)
            .abs_diff_eq(tor.origin - 4.0 * tor.x + tor.z, 1e-12));
        // Periodic parameters follow the hint.
        let q = cyl.project(cyl.point(0.1, 0.0), Some([TAU, 0.0]));
        assert!((q[0] - (TAU + 0.1)).abs() < 1e-12);
    }

    #[test]
    fn division_meets_the_chordal_tolerance() {
        let tol = 1e-3;
        for s in all() {
            let (u, v) = s.division(((0.0, 2.0), (-0.5, 0.5)), tol);
            assert!(u.len() >= 2 && v.len() >= 2);
            for w in u.windows(2) {
                for vv in &v {
                    let a = s.point(w[0], *vv);
                    let b = s.point(w[1], *vv);
                    let mid = s.point(0.5 * (w[0] + w[1]), *vv);
                    assert!(mid.distance(0.5 * (a + b)) <= tol * 1.0001, "{:?}", s.kind);
                }
            }
            for w in v.windows(2) {
                for uu in &u {
                    let a = s.point(*uu, w[0]);
                    let b = s.point(*uu, w[1]);
                    let mid = s.point(*uu, 0.5 * (w[0] + w[1]));
                    assert!(mid.distance(0.5 * (a + b)) <= tol * 1.0001, "{:?}", s.kind);
                }
            }
        }
    }

    #[test]
    fn reads_records_with_units() {
        let text = "ISO-10303-21;\nDATA;\n#1=CARTESIAN_POINT('',(1.,2.,3.));\n\
                    #2=DIRECTION('',(0.,0.,1.));\n#3=DIRECTION('',(1.,0.,0.));\n\
                    #4=AXIS2_PLACEMENT_3D('',#1,#2,#3);\n#5=CONICAL_SURFACE('',#4,2.,45.);\n\
                    #6=TOROIDAL_SURFACE('',#4,8.25,54.87);\n#7=PLANE('',#4);\n\
                    #8=CYLINDRICAL_SURFACE('',#4,-1.);\n#9=DIRECTION('',(1.,0.,0.));\n\
                    #10=AXIS2_PLACEMENT_3D('',#1,#9,$);\n#11=PLANE('',#10);\nENDSEC;\nEND-ISO-10303-21;\n";
        let records = super::super::text::scan(text);
        let cone = Analytic::from_record(&records, 5, PI / 180.0)
            .unwrap()
            .unwrap();
        assert_eq!(
            cone.kind,
            Kind::Cone {
                radius: 2.0,
                semi_angle: PI / 4.0
            }
        );
        assert!(cone.origin.abs_diff_eq(DVec3::new(1.0, 2.0, 3.0), 0.0));
        let tor = Analytic::from_record(&records, 6, 1.0).unwrap().unwrap();
        assert_eq!(
            tor.kind,
            Kind::Torus {
                major: 8.25,
                minor: 54.87
            }
        );
        assert_eq!(
            Analytic::from_record(&records, 7, 1.0)
                .unwrap()
                .unwrap()
                .kind,
            Kind::Plane
        );
        let err = Analytic::from_record(&records, 8, 1.0).unwrap_err();
        assert!(
            err.contains("CYLINDRICAL_SURFACE #8") && err.contains("radius"),
            "{err}"
        );
        assert_eq!(Analytic::from_record(&records, 1, 1.0), Ok(None));
        // No ref_direction and the axis along x (bug27693's planes): a frame all the same.
        let plane = Analytic::from_record(&records, 11, 1.0).unwrap().unwrap();
        assert!(plane.z.abs_diff_eq(DVec3::X, 1e-12));
        assert!(plane.x.dot(plane.z).abs() < 1e-12 && (plane.x.length() - 1.0).abs() < 1e-12);
    }
}
