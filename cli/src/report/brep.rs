//! The B-rep as the ruler (`scode report --reference brep`): a decoded surface's distance to
//! the part's exact surfaces, not to one tessellation of them.
//!
//! Each face of the reference is either measured **exactly** (a plane, cylinder, cone, sphere
//! or torus from the STEP record: a point's distance is its distance to that surface,
//! found by closed-form projection) or through **facets** (B-splines and the other surfaces
//! the reader cannot evaluate in closed form: the distance to a tessellation of the face
//! whose chordal tolerance is far below the accuracies measured). A point is charged to the
//! face of the nearest reference facet; the exact distance is used only where the point's
//! projection onto the exact surface lands on that face (within twice the chord of the
//! face's facets), since the untrimmed surface goes on beyond the face's edges (a point
//! past the end of a cylinder face is far from the face, not on its surface).
//!
//! The other direction samples the reference tessellation, moves every sample of an exact
//! face onto its surface, and measures the samples' distance to the decoded surface.

use std::collections::BTreeSet;

use glam::DVec3;

use scode::error::{Error, Result};
use scode::fit::encoder::ExactSurface;
use scode::mesh::{AnalyticSurface, ControlMesh};
use scode::metrics::{
    closest_points, one_sided_distances, sample_surface, DistanceOptions, DistanceReport, OneSided,
    TriangleSurface,
};

/// How one face of a [`BrepReference`] is measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaceRuler {
    /// Against its exact analytic surface (closed-form projection).
    Exact,
    /// Against the reference tessellation's facets (the surface cannot be evaluated here).
    Facets,
}

/// The exact surfaces of a part and a tessellation of them (see the module documentation).
pub struct BrepReference {
    mesh: ControlMesh,
    surface: TriangleSurface,
    /// Group of each triangle of `surface`.
    triangle_group: Vec<u32>,
    exact: Vec<Option<ExactSurface>>,
    /// Chordal tolerance of the exactly measured faces' facets (model units): how far a
    /// projection may land from them and still be on the face.
    chord: f64,
    /// Names of faces the reference leaves out ([`BrepReference::leave_out`]).
    left_out: BTreeSet<String>,
}

impl BrepReference {
    /// `mesh`: a tessellation of the part with one group per B-rep face (a STEP model's
    /// mesh); `exact`: the exact surface of each group, `None` where there is none to
    /// evaluate; `chord`: the chordal tolerance of the faces with an exact surface in
    /// model units.
    pub fn new(mesh: ControlMesh, exact: &[Option<AnalyticSurface>], chord: f64) -> Result<Self> {
        if exact.len() != mesh.groups.len() {
            return Err(Error::Parameter(format!(
                "B-rep reference: {} exact surfaces for {} faces",
                exact.len(),
                mesh.groups.len()
            )));
        }
        let surface = TriangleSurface::from_control_mesh(&mesh)?;
        let triangle_group = (0..surface.triangles().len() as u32)
            .map(|t| {
                mesh.face_groups
                    .get(surface.source_face(t) as usize)
                    .copied()
                    .unwrap_or(0)
            })
            .collect();
        let exact = exact
            .iter()
            .map(|s| s.and_then(ExactSurface::new))
            .collect();
        Ok(BrepReference {
            mesh,
            surface,
            triangle_group,
            exact,
            chord: chord.max(0.0),
            left_out: BTreeSet::new(),
        })
    }

    /// Leaves out of every measurement the decoded faces (groups) of these names: faces the
    /// reference lacks because some tessellation of the part could not make them, which a
    /// codec that encoded another tessellation may still have (it is charged neither for
    /// having them nor, since the reference lacks them, for not having them).
    pub fn leave_out(&mut self, names: impl IntoIterator<Item = String>) {
        self.left_out.extend(names);
    }

    /// How each face (group) is measured.
    pub fn rulers(&self) -> Vec<FaceRuler> {
        self.exact
            .iter()
            .map(|s| match s {
                Some(_) => FaceRuler::Exact,
                None => FaceRuler::Facets,
            })
            .collect()
    }

    /// The reference tessellation.
    pub fn mesh(&self) -> &ControlMesh {
        &self.mesh
    }

    /// Distance from each of `points` to the part.
    pub fn distances(&self, points: &[DVec3]) -> Vec<f64> {
        closest_points(points, &self.surface)
            .iter()
            .zip(points)
            .map(|(cp, &p)| {
                let group = self.triangle_group[cp.triangle as usize] as usize;
                match self.exact.get(group).copied().flatten() {
                    Some(s) => {
                        let on_surface = s.project(p);
                        let on_face = self.surface.distance(on_surface) <= 2.0 * self.chord;
                        if on_face {
                            s.distance(p)
                        } else {
                            cp.distance
                        }
                    }
                    None => cp.distance,
                }
            })
            .collect()
    }

    /// Sampled symmetric distance between `decoded` and the part, as
    /// [`scode::metrics::hausdorff`] measures two meshes (same sample counts and seeds,
    /// `decoded` as A); `diagonal` is the reference's.
    pub fn measure(&self, decoded: &ControlMesh) -> Result<DistanceReport> {
        let kept;
        let left_out = |g: u32| {
            decoded
                .groups
                .get(g as usize)
                .is_some_and(|group| self.left_out.contains(&group.name))
        };
        let decoded = if decoded.face_groups.iter().any(|&g| left_out(g)) {
            let mut m = ControlMesh {
                positions: decoded.positions.clone(),
                groups: decoded.groups.clone(),
                ..ControlMesh::default()
            };
            for f in 0..decoded.face_count() {
                let g = decoded.face_groups[f];
                if !left_out(g) {
                    m.push_face(decoded.face(f), g);
                }
            }
            kept = m;
            &kept
        } else {
            decoded
        };
        let opts = DistanceOptions::default();
        let dec = TriangleSurface::from_control_mesh(decoded)?;
        let from_decoded: Vec<DVec3> = sample_surface(
            dec.positions(),
            dec.triangles(),
            opts.samples,
            opts.include_vertices,
            opts.seed,
        )
        .into_iter()
        .map(|s| s.point)
        .collect();
        let mut ab = stats(&self.distances(&from_decoded));
        // The max also at points along the decoded surface's long edges (thin slivers), as
        // `scode info --against` takes them.
        let spacing = scode::metrics::DEFAULT_EDGE_SPACING.resolve(self.mesh.diagonal());
        let edges = scode::metrics::EdgeSamples::new(dec.positions(), dec.triangles(), spacing);
        let along: Vec<DVec3> = (0..edges.len()).map(|i| edges.get(i).point).collect();
        let edge_max = self.distances(&along).into_iter().fold(0.0, f64::max);
        ab.max = ab.max.max(edge_max);
        ab.count += along.len();
        let from_reference: Vec<DVec3> = sample_surface(
            self.surface.positions(),
            self.surface.triangles(),
            opts.samples,
            opts.include_vertices,
            opts.seed ^ 0xB,
        )
        .into_iter()
        .map(|s| {
            let group = self.triangle_group[s.triangle as usize] as usize;
            match self.exact.get(group).copied().flatten() {
                Some(e) => e.project(s.point),
                None => s.point,
            }
        })
        .collect();
        let ba = one_sided_distances(&from_reference, &dec);
        let diagonal = self.mesh.diagonal();
        Ok(DistanceReport::from_sides(&ab, &ba, diagonal))
    }
}

fn stats(d: &[f64]) -> OneSided {
    let n = d.len().max(1) as f64;
    OneSided {
        max: d.iter().copied().fold(0.0, f64::max),
        rms: (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
        mean: d.iter().sum::<f64>() / n,
        count: d.len(),
        argmax: DVec3::ZERO,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scode::mesh::{Axis, Group};

    /// A grid of `nu` x `nv` quads (split into triangles) mapped by `at(u, v)`, u and v in
    /// [0, 1], u periodic (the seam shares vertices), appended to `mesh` as `group`.
    fn grid(
        mesh: &mut ControlMesh,
        group: u32,
        (nu, nv): (usize, usize),
        at: impl Fn(f64, f64) -> DVec3,
    ) {
        let base = mesh.positions.len() as u32;
        for j in 0..=nv {
            for i in 0..nu {
                mesh.positions
                    .push(at(i as f64 / nu as f64, j as f64 / nv as f64));
            }
        }
        let id = |i: usize, j: usize| base + (j * nu + i % nu) as u32;
        for j in 0..nv {
            for i in 0..nu {
                for tri in [
                    [id(i, j), id(i + 1, j), id(i + 1, j + 1)],
                    [id(i, j), id(i + 1, j + 1), id(i, j + 1)],
                ] {
                    mesh.face_vertices.extend(tri);
                    mesh.face_offsets.push(mesh.face_vertices.len() as u32);
                    mesh.face_groups.push(group);
                }
            }
        }
    }

    const TAU: f64 = std::f64::consts::TAU;
    const R_CYL: f64 = 10.0;
    const H_CYL: f64 = 20.0;
    const R_SPH: f64 = 5.0;
    const C_SPH: DVec3 = DVec3::new(30.0, 0.0, 10.0);
    /// Largest radial offsets of the perturbed tessellations.
    const D_CYL: f64 = 0.04;
    const D_SPH: f64 = 0.06;

    /// A cylinder (radius 10 about z, height 20) and a sphere (radius 5) tessellated on
    /// `nu` x `nv` grids; with `perturbed`, every vertex moved off the surface along its
    /// normal by a smooth offset of at most `D_CYL` and `D_SPH`.
    fn part(nu: usize, nv: usize, perturbed: bool) -> ControlMesh {
        let mut mesh = ControlMesh::new();
        mesh.groups = vec![Group::default(), Group::default()];
        let k = if perturbed { 1.0 } else { 0.0 };
        grid(&mut mesh, 0, (nu, nv), |u, v| {
            let t = TAU * u;
            let r = R_CYL + k * D_CYL * (2.0 * t).sin() * v;
            DVec3::new(r * t.cos(), r * t.sin(), H_CYL * v)
        });
        // The poles are rows of coincident vertices (degenerate triangles have no area
        // and are never sampled).
        grid(&mut mesh, 1, (nu, nv), |u, v| {
            let (t, p) = (TAU * u, std::f64::consts::PI * v);
            let r = R_SPH + k * D_SPH * t.cos() * p.sin();
            C_SPH + r * DVec3::new(p.sin() * t.cos(), p.sin() * t.sin(), p.cos())
        });
        mesh
    }

    fn exact() -> [Option<AnalyticSurface>; 2] {
        [
            Some(AnalyticSurface::Cylinder {
                axis: Axis {
                    origin: DVec3::ZERO,
                    direction: DVec3::Z,
                },
                radius: R_CYL,
            }),
            Some(AnalyticSurface::Sphere {
                center: C_SPH,
                radius: R_SPH,
            }),
        ]
    }

    /// Closed-form distance of `p` to the part's two surfaces, as the group says.
    fn closed_form(p: DVec3, group: u32) -> f64 {
        if group == 0 {
            (p.truncate().length() - R_CYL).abs()
        } else {
            (p.distance(C_SPH) - R_SPH).abs()
        }
    }

    #[test]
    fn distance_to_exact_cylinder_and_sphere_matches_closed_form() {
        // A coarse reference: its facets sag up to 10 * (1 - cos(pi / 32)) = 0.048 from the
        // cylinder, as large as the offsets measured, so a facet ruler would be far off.
        let (nu, nv) = (32, 16);
        let sag = R_CYL * (1.0 - (std::f64::consts::PI / nu as f64).cos());
        let reference = BrepReference::new(part(nu, nv, false), &exact(), sag).unwrap();
        assert_eq!(reference.rulers(), [FaceRuler::Exact, FaceRuler::Exact]);
        // The decoded surface: a fine perturbed tessellation, whose own chord (below 1e-4)
        // is under 1 % of the offsets.
        let decoded = part(800, 400, true);
        // Closed form over the decoded vertices (the offsets peak at vertices of the grid).
        let mut want = [0.0f64; 2];
        for (f, &g) in decoded.face_groups.iter().enumerate() {
            for &v in decoded.face(f) {
                let d = closed_form(decoded.positions[v as usize], g);
                want[g as usize] = want[g as usize].max(d);
            }
        }
        assert!((want[0] - D_CYL).abs() < 1e-3 * D_CYL, "{want:?}");
        assert!((want[1] - D_SPH).abs() < 1e-3 * D_SPH, "{want:?}");
        let report = reference.measure(&decoded).unwrap();
        let expected = want[0].max(want[1]);
        assert!(
            (report.max_a_to_b - expected).abs() < 0.01 * expected,
            "decoded to B-rep {} vs closed form {expected}",
            report.max_a_to_b
        );
        assert!(
            (report.max - expected).abs() < 0.01 * expected,
            "symmetric {} vs closed form {expected}",
            report.max
        );
        // Per face, on the cylinder's vertices alone.
        let cyl: Vec<DVec3> = decoded.positions[..800 * 401].to_vec();
        let got = reference.distances(&cyl).into_iter().fold(0.0, f64::max);
        assert!(
            (got - want[0]).abs() < 0.01 * want[0],
            "{got} vs {}",
            want[0]
        );
        // The same decoded surface measured against the reference's facets is off by far
        // more than 1 %: the exact surfaces are what the numbers above rest on.
        let facets = scode::metrics::hausdorff(
            &decoded,
            reference.mesh(),
            &scode::metrics::DistanceOptions::default(),
        )
        .unwrap();
        assert!(
            (facets.max - expected).abs() > 0.05 * expected,
            "facets {} vs {expected}",
            facets.max
        );
    }

    #[test]
    fn a_point_beyond_the_face_is_measured_to_the_face_not_its_surface() {
        let reference = BrepReference::new(part(48, 24, false), &exact(), 0.1).unwrap();
        // On the cylinder's surface, 5 beyond its top edge: 5 from the face.
        let p = DVec3::new(R_CYL, 0.0, H_CYL + 5.0);
        let d = reference.distances(&[p])[0];
        assert!((d - 5.0).abs() < 0.1, "{d}");
        // A B-spline face (no exact surface) is measured on its facets.
        let facets = BrepReference::new(part(48, 24, false), &[None, None], 0.1).unwrap();
        assert_eq!(facets.rulers(), [FaceRuler::Facets, FaceRuler::Facets]);
        let mid = DVec3::new(R_CYL, 0.0, 5.0);
        let d = facets.distances(&[mid])[0];
        assert!(d < 1e-9, "{d}");
        let e = BrepReference::new(part(8, 4, false), &[None], 0.1);
        assert!(e.is_err());
    }

    #[test]
    fn faces_left_out_of_the_reference_are_not_measured() {
        let mut reference = BrepReference::new(part(48, 24, false), &exact(), 0.1).unwrap();
        // The decoded part has a face the reference lacks: a patch 3 above the cylinder.
        let mut decoded = part(48, 24, false);
        decoded.groups[1].name = "kept".into();
        decoded.groups.push(Group {
            name: "extra".into(),
            ..Group::default()
        });
        grid(&mut decoded, 2, (4, 4), |u, v| {
            DVec3::new(u - 0.5, v - 0.5, H_CYL + 3.0)
        });
        let before = reference.measure(&decoded).unwrap();
        assert!(before.max_a_to_b > 2.0, "{before:?}");
        reference.leave_out(["extra".to_string()]);
        let after = reference.measure(&decoded).unwrap();
        assert!(after.max_a_to_b < 0.1, "{after:?}");
    }
}
