//! How far the input's own facets may be from the CAD surface (the "chord allowance" the
//! tolerance does not charge the codec for, or, against a B-rep, the facets' chordal
//! tolerance it charges on top), and against which input triangles a decoded point's excess
//! over that allowance is measured.
//!
//! Two simple measures overcharge coarse tessellations of curved faces (corpus trj4:
//! cylinder bands with 50-degree facets, sagittas of 1-2 mm against a 0.3 mm tolerance):
//! * the allowance estimated from the angle between vertex normals misses the sagitta of a
//!   facet that is slanted across the surface (a long chord on one side, a vertex on the
//!   arc on the other: the area-weighted normals at the chord's ends are nearly parallel).
//!   For cylinder and cone groups the surface is known, so the deviation of each facet from
//!   it is computed instead ([`add_analytic_surface_allowance`]);
//! * charging a decoded point against the *nearest* input triangle only: in the sagitta's
//!   shadow of a coarse curved face there are often other triangles (a plane meeting it at
//!   a concave edge, a touching part of an assembly) that are nearer than the face's own
//!   facets but have no allowance. The point is also measured against its own face's
//!   triangles ([`OwnFaces`]).

use std::collections::BTreeMap;

use glam::DVec3;

use super::curves::CurveNetwork;
use super::exact::ExactSurface;
use crate::mesh::{edge_key, AnalyticSurface, Axis, BoundarySurface, ControlMesh, PatchKind};
use crate::metrics::TriangleSurface;

/// The input's faces (groups) one by one: a closest-point structure per group and the
/// global indices of its triangles (the chord allowance is indexed by those).
///
/// Why per group: the excess of a decoded point is its distance to an input triangle minus
/// that triangle's allowance, and the right triangle to charge it against is the smallest
/// such difference, not necessarily the nearest triangle. The decoded patch of a face is
/// meant to follow that face, so its own triangles are the candidates that matter besides
/// the nearest one.
#[derive(Clone, Copy)]
pub(crate) struct OwnFaces<'a> {
    /// Indexed by group; `None` for a group without triangles.
    pub surfaces: &'a [Option<TriangleSurface>],
    /// Indexed by group: global triangle index of each of the group surface's triangles.
    pub triangles: &'a [Vec<u32>],
    /// Indexed by group: the largest allowance of its triangles (at least 0), which bounds
    /// how far its own triangles need searching; a group without one is searched everywhere.
    pub max_allowance: &'a [f64],
    /// Indexed by group: the face's exact surface when the input knows it (STEP faces), or
    /// empty. A decoded point of a group with one is measured against that surface where it
    /// lies over the face ([`OwnFaces::against`]).
    pub exact: &'a [Option<ExactSurface>],
    /// Indexed by group: how far the group's facets may lie from the B-rep face they
    /// tessellate (the tessellation's chordal tolerance), or empty when the facets are the
    /// reference themselves.
    pub facet_chord: &'a [f64],
}

impl OwnFaces<'_> {
    /// Distance from `p` to group `g`'s exact surface; minus infinity without one.
    fn exact_distance(&self, p: DVec3, g: usize) -> f64 {
        match self.exact.get(g) {
            Some(Some(s)) => s.distance(p),
            _ => f64::NEG_INFINITY,
        }
    }

    /// The excess of `p` against group `g`, given its excess `facet_excess` against the
    /// group's nearest facet (its distance less that facet's allowance).
    ///
    /// Without an exact surface that is the answer: a B-rep face's facets carry the
    /// negative allowance `-c` (`c` its chordal tolerance), so the excess is an upper bound
    /// of the distance to the face, whose points all lie within `c` of the facets. With one
    /// (the facets then carry no allowance) the distance to the exact surface is the
    /// distance to the face where `p`'s projection lies over the face, which is taken to be
    /// where the projection (or `p` itself) is within `c` of the facets; elsewhere `p` is
    /// beyond the face's outline (a plane patch's chord across a hole's arc), and only the
    /// facets bound its distance: `facet_excess + c`.
    fn against(&self, p: DVec3, g: usize, facet_excess: f64) -> f64 {
        let Some(Some(s)) = self.exact.get(g) else {
            return facet_excess;
        };
        let c = self.facet_chord.get(g).copied().unwrap_or(0.0);
        let e = s.distance(p);
        if facet_excess <= c {
            return e;
        }
        let over_face = match self.surfaces.get(g) {
            Some(Some(facets)) => facets.closest_point_within(s.project(p), c).is_some(),
            _ => false,
        };
        if over_face {
            e
        } else {
            (facet_excess + c).max(e)
        }
    }

    /// Excess over the chord allowance of a decoded point `p` of group `group`, given its
    /// excess `nearest_excess` against the nearest input triangle (of group
    /// `nearest_group`): the smaller of the excess against that triangle's group and against
    /// `group`'s own input triangles, each as [`OwnFaces::against`] measures it.
    pub fn excess(
        &self,
        p: DVec3,
        group: usize,
        nearest_group: usize,
        nearest_excess: f64,
        chord: &[f64],
    ) -> f64 {
        let nearest_excess = self.against(p, nearest_group, nearest_excess);
        if nearest_excess <= 0.0 || nearest_group == group {
            // Only positive excesses are reported, and the nearest triangle of the own
            // group is also its nearest own triangle: skip the second query.
            return nearest_excess;
        }
        if self.exact_distance(p, group) >= nearest_excess {
            return nearest_excess;
        }
        let (Some(Some(surface)), Some(ids)) =
            (self.surfaces.get(group), self.triangles.get(group))
        else {
            return nearest_excess;
        };
        // An own triangle farther than `nearest_excess` plus the largest allowance cannot
        // beat `nearest_excess` (nor, on an exact surface, farther than that plus the
        // facets' chord, whose projections are off the face), so search only that far
        // (padded for rounding): a hit within it is the same closest point as an unbounded
        // search finds.
        let exact_chord = match self.exact.get(group) {
            Some(Some(_)) => self.facet_chord.get(group).copied().unwrap_or(0.0),
            _ => 0.0,
        };
        let bound = self
            .max_allowance
            .get(group)
            .map(|&a| (nearest_excess + a + exact_chord) * (1.0 + 1e-9) + 1e-300)
            .filter(|b| b.is_finite());
        let hit = match bound {
            Some(b) if b <= 0.0 => return nearest_excess,
            Some(b) => match surface.closest_point_within(p, b) {
                Some(hit) => hit,
                None => return nearest_excess,
            },
            None => surface.closest_point(p),
        };
        let allowance = ids
            .get(hit.triangle as usize)
            .and_then(|&t| chord.get(t as usize))
            .copied()
            .unwrap_or(0.0);
        nearest_excess.min(self.against(p, group, hit.distance - allowance))
    }
}

/// The analytic surface of a cylinder or cone group, fitted to the group's vertices about
/// the patch's axis: the radius of a cylinder, the opening of a cone about its apex (least
/// squares on `r = slope * h`). `None` for planes (their facets lie on them), closed
/// patches (no analytic surface) and degenerate fits.
fn fit_about_axis(kind: &PatchKind, points: &[DVec3]) -> Option<AnalyticSurface> {
    if points.is_empty() {
        return None;
    }
    match *kind {
        PatchKind::Boundary(BoundarySurface::Cylinder { axis }) => {
            let radius =
                points.iter().map(|&p| axial(&axis, p).1).sum::<f64>() / points.len() as f64;
            radius
                .is_finite()
                .then_some(AnalyticSurface::Cylinder { axis, radius })
        }
        PatchKind::Boundary(BoundarySurface::Cone { axis }) => {
            let (num, den) = points.iter().fold((0.0, 0.0), |a, &p| {
                let (h, r) = axial(&axis, p);
                (a.0 + r * h, a.1 + h * h)
            });
            let slope = num / den;
            if !(den > 0.0 && slope.is_finite() && slope != 0.0) {
                return None;
            }
            // A negative slope is the cone opening the other way along the axis.
            let direction = axis.direction * slope.signum();
            Some(AnalyticSurface::Cone {
                axis: Axis {
                    origin: axis.origin,
                    direction,
                },
                half_angle: slope.abs().atan(),
            })
        }
        _ => None,
    }
}

/// Height along the axis and distance from it.
fn axial(axis: &Axis, p: DVec3) -> (f64, f64) {
    let d = p - axis.origin;
    let h = d.dot(axis.direction);
    (h, (d - h * axis.direction).length())
}

/// Barycentric sample grid of a facet: all `(i, j, k)/N` with `i + j + k = N`. A flat
/// facet inscribed in a cylinder or cone deviates from it most in its interior or on an
/// edge; at N = 8 the sampled maximum is within about 2 % of the true one.
const FACET_GRID: usize = 8;

/// Raises the allowance of every triangle of a cylinder or cone group to the triangle's
/// largest distance from the group's analytic surface (the surface's axis from the group's
/// patch kind in `kinds`, its radius or opening fitted to the group's vertices).
pub(crate) fn add_analytic_surface_allowance(
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    face_groups: &[u32],
    kinds: &[PatchKind],
    chord: &mut [f64],
) {
    let mut group_points: Vec<Vec<DVec3>> = vec![Vec::new(); kinds.len()];
    let mut seen = vec![u32::MAX; positions.len()];
    for (t, &g) in triangles.iter().zip(face_groups) {
        let Some(points) = group_points.get_mut(g as usize) else {
            continue;
        };
        for &v in t {
            // One entry per (group, vertex) in the common case of contiguous groups.
            if let Some(s) = seen.get_mut(v as usize) {
                if *s != g {
                    *s = g;
                    points.push(positions[v as usize]);
                }
            }
        }
    }
    let surfaces: Vec<Option<AnalyticSurface>> = kinds
        .iter()
        .zip(&group_points)
        .map(|(k, pts)| fit_about_axis(k, pts))
        .collect();
    for ((t, &g), allowance) in triangles.iter().zip(face_groups).zip(chord.iter_mut()) {
        let Some(Some(surface)) = surfaces.get(g as usize) else {
            continue;
        };
        let [a, b, c] = t.map(|v| positions[v as usize]);
        let mut worst = 0.0f64;
        for i in 0..=FACET_GRID {
            for j in 0..=FACET_GRID - i {
                let k = FACET_GRID - i - j;
                let p = (a * i as f64 + b * j as f64 + c * k as f64) / FACET_GRID as f64;
                worst = worst.max(surface.distance(p));
            }
        }
        if worst.is_finite() {
            *allowance = allowance.max(worst);
        }
    }
}

/// Per input triangle, how far its flat facet may be from the CAD surface it tessellates:
/// the largest arc sagitta `L/2 tan(theta/4)` over its edges, where `theta` is the angle
/// between the edge's two vertex normals within the triangle's group (planar facets get 0).
/// A decoded surface that follows the CAD surface is this far from the facets, and the
/// tolerance should not charge the codec for the input's own discretisation.
pub(super) fn chord_allowance(mesh: &ControlMesh, tris: &[[u32; 3]]) -> Vec<f64> {
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
pub(super) fn add_curved_edge_allowance(
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

#[cfg(test)]
mod tests {
    use super::*;

    fn y_axis() -> Axis {
        Axis {
            origin: DVec3::ZERO,
            direction: DVec3::Y,
        }
    }

    /// A cylinder band (radius `r`, `n` vertices per ring, height `h`) whose ring vertices
    /// lie on the cylinder: the chord facets sag by `r (1 - cos(pi / n))`.
    fn band(r: f64, n: usize, h: f64) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        for ring in 0..2 {
            for i in 0..n {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                p.push(DVec3::new(r * a.cos(), ring as f64 * h, r * a.sin()));
            }
        }
        let n32 = n as u32;
        let mut t = Vec::new();
        for i in 0..n32 {
            let j = (i + 1) % n32;
            t.push([i, j, n32 + j]);
            t.push([i, n32 + j, n32 + i]);
        }
        (p, t)
    }

    #[test]
    fn cylinder_facets_get_their_sagitta() {
        let (r, n) = (13.5, 7);
        let (p, t) = band(r, n, 2.0);
        let groups = vec![0u32; t.len()];
        let kinds = [PatchKind::Boundary(BoundarySurface::Cylinder {
            axis: y_axis(),
        })];
        let mut chord = vec![0.0; t.len()];
        add_analytic_surface_allowance(&p, &t, &groups, &kinds, &mut chord);
        let sagitta = r * (1.0 - (std::f64::consts::PI / n as f64).cos());
        for &c in &chord {
            // The grid samples the chord's midpoint (i = k = 4 on a ring edge) exactly.
            assert!((c - sagitta).abs() < 1e-9 * r, "{c} vs {sagitta}");
        }
        // A larger existing allowance is kept.
        let mut chord = vec![10.0; t.len()];
        add_analytic_surface_allowance(&p, &t, &groups, &kinds, &mut chord);
        assert!(chord.iter().all(|&c| c == 10.0));
    }

    #[test]
    fn slanted_facet_of_a_coarse_band_is_covered() {
        // One ring edge spanning 36 degrees on top, the arc's midpoint as a vertex below:
        // the facet from the chord down to the arc deviates by the sagitta at its top.
        let r = 28.7;
        let at = |deg: f64, y: f64| {
            let a = deg.to_radians();
            DVec3::new(r * a.cos(), y, r * a.sin())
        };
        let p = vec![at(-18.0, 0.0), at(18.0, 0.0), at(0.0, -4.0)];
        let t = vec![[0u32, 1, 2]];
        let mut chord = vec![0.0];
        let kinds = [PatchKind::Boundary(BoundarySurface::Cylinder {
            axis: y_axis(),
        })];
        add_analytic_surface_allowance(&p, &t, &[0], &kinds, &mut chord);
        let sagitta = r * (1.0 - 18f64.to_radians().cos());
        // The radius is fitted to the three vertices (all on the cylinder): exact.
        assert!(
            (chord[0] - sagitta).abs() < 1e-9 * r,
            "{} vs {sagitta}",
            chord[0]
        );
    }

    #[test]
    fn cone_facets_measure_distance_to_the_cone() {
        // Cone about +Y with apex at the origin and r = 0.5 h: a chord between two points
        // of the circle at h = 4 (r = 2) a quarter turn apart sags by 2 (1 - cos 45deg)
        // radially, i.e. that times cos(atan 0.5) normal to the cone.
        let p = vec![
            DVec3::new(2.0, 4.0, 0.0),
            DVec3::new(0.0, 4.0, 2.0),
            DVec3::new(0.0, 0.0, 0.0),
        ];
        let t = vec![[0u32, 1, 2]];
        let kinds = [PatchKind::Boundary(BoundarySurface::Cone {
            axis: y_axis(),
        })];
        let mut chord = vec![0.0];
        add_analytic_surface_allowance(&p, &t, &[0], &kinds, &mut chord);
        let want = 2.0 * (1.0 - 45f64.to_radians().cos()) / (1.25f64).sqrt();
        assert!((chord[0] - want).abs() < 1e-9, "{} vs {want}", chord[0]);
    }

    #[test]
    fn planes_and_closed_groups_are_left_alone() {
        let (p, t) = band(5.0, 6, 1.0);
        let groups = vec![0u32; t.len()];
        for kind in [
            PatchKind::Closed,
            PatchKind::Boundary(BoundarySurface::Plane),
        ] {
            let mut chord = vec![0.25; t.len()];
            add_analytic_surface_allowance(&p, &t, &groups, &[kind], &mut chord);
            assert!(chord.iter().all(|&c| c == 0.25));
        }
    }

    #[test]
    fn own_faces_excess_ignores_allowance_free_neighbours_in_the_shadow() {
        // Group 0: a facet at z = 0 with allowance 1 (a coarse curved face); group 1: a
        // facet at z = 0.9 with none (a neighbour nearer to the decoded point at z = 1.2).
        let p = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(4.0, 0.0, 0.0),
            DVec3::new(0.0, 4.0, 0.0),
            DVec3::new(0.0, 0.0, 0.9),
            DVec3::new(4.0, 0.0, 0.9),
            DVec3::new(0.0, 4.0, 0.9),
        ];
        let own = [
            Some(TriangleSurface::new(p.clone(), vec![[0, 1, 2]]).unwrap()),
            Some(TriangleSurface::new(p.clone(), vec![[3, 4, 5]]).unwrap()),
        ];
        let ids = [vec![0u32], vec![1u32]];
        let chord = [1.0, 0.0];
        let faces = OwnFaces {
            surfaces: &own,
            triangles: &ids,
            max_allowance: &[1.0, 0.0],
            exact: &[],
            facet_chord: &[],
        };
        let q = DVec3::new(1.0, 1.0, 1.2);
        // Against the nearest triangle (group 1): 0.3 - 0 = 0.3; against its own: 1.2 - 1.
        let e = faces.excess(q, 0, 1, 0.3, &chord);
        assert!((e - 0.2).abs() < 1e-12, "{e}");
        // A point of group 1 keeps the smaller nearest excess.
        assert!((faces.excess(q, 1, 1, 0.3, &chord) - 0.3).abs() < 1e-12);
        // Non-positive excesses are returned as they are; unknown groups too.
        assert_eq!(faces.excess(q, 0, 1, -0.5, &chord), -0.5);
        assert_eq!(faces.excess(q, 7, 1, 0.3, &chord), 0.3);
    }

    #[test]
    fn exact_surface_charges_the_concave_side_of_a_sagging_facet() {
        // A sphere of radius 10 about the origin and one facet of it: a chord plane at
        // z = 9 (sagitta 1 at its middle, the facets' chordal tolerance). A B-rep's facets
        // on an exact surface carry no allowance.
        let h = 19f64.sqrt(); // (h, 0, 9) is on the sphere
        let p = vec![
            DVec3::new(h, 0.0, 9.0),
            DVec3::new(-h / 2.0, h * 0.75f64.sqrt(), 9.0),
            DVec3::new(-h / 2.0, -h * 0.75f64.sqrt(), 9.0),
        ];
        let own = [Some(TriangleSurface::new(p, vec![[0, 1, 2]]).unwrap())];
        let ids = [vec![0u32]];
        let chord = [0.0];
        let exact = [ExactSurface::new(crate::mesh::AnalyticSurface::Sphere {
            center: DVec3::ZERO,
            radius: 10.0,
        })];
        let faces = OwnFaces {
            surfaces: &own,
            triangles: &ids,
            max_allowance: &[0.0],
            exact: &exact,
            facet_chord: &[1.0],
        };
        // Below the facet, 1.5 inside it: 2.5 from the sphere, whose point above it is
        // over the face.
        let q = DVec3::new(0.0, 0.0, 7.5);
        assert!((faces.excess(q, 0, 0, 1.5, &chord) - 2.5).abs() < 1e-12);
        // Above the facet, on the sphere: no excess.
        let q = DVec3::new(0.0, 0.0, 10.0);
        assert!(faces.excess(q, 0, 0, 1.0, &chord).abs() < 1e-12);
    }

    /// A plane face (the square [0, 4]^2 at z = 0, facets of chordal tolerance 0.1): a point
    /// over the face is its height above the plane away; one beyond the face's outline (a
    /// plane patch's chord across a hole's arc) is not on the face however near the plane,
    /// and is charged its distance to the facets plus their chord; a face without an exact
    /// surface is charged its facets' chord on top of the distance.
    #[test]
    fn a_point_beyond_a_faces_outline_is_charged_the_facets_and_their_chord() {
        let p = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(4.0, 0.0, 0.0),
            DVec3::new(4.0, 4.0, 0.0),
            DVec3::new(0.0, 4.0, 0.0),
        ];
        let own = [Some(
            TriangleSurface::new(p, vec![[0, 1, 2], [0, 2, 3]]).unwrap(),
        )];
        let ids = [vec![0u32, 1]];
        let exact = [ExactSurface::new(crate::mesh::AnalyticSurface::Plane {
            point: DVec3::ZERO,
            normal: DVec3::Z,
        })];
        let plane = OwnFaces {
            surfaces: &own,
            triangles: &ids,
            max_allowance: &[0.0],
            exact: &exact,
            facet_chord: &[0.1],
        };
        let none = [0.0, 0.0];
        let at = |q: DVec3| {
            let d = own[0].as_ref().unwrap().closest_point(q).distance;
            plane.excess(q, 0, 0, d, &none)
        };
        assert!((at(DVec3::new(2.0, 2.0, 0.3)) - 0.3).abs() < 1e-12);
        assert!((at(DVec3::new(5.0, 2.0, 0.0)) - 1.1).abs() < 1e-12);
        // Within the chord of the outline: taken as over the face.
        assert!(at(DVec3::new(4.05, 2.0, 0.0)).abs() < 1e-12);
        // The same face without its exact surface: its facets carry the allowance -0.1.
        let freeform = OwnFaces {
            exact: &[],
            ..plane
        };
        let minus_chord = [-0.1, -0.1];
        let q = DVec3::new(2.0, 2.0, 0.3);
        assert!((freeform.excess(q, 0, 0, 0.3 + 0.1, &minus_chord) - 0.4).abs() < 1e-12);
    }
}
