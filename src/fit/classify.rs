//! Step 1 of the fit: the input's faces. An ungrouped mesh is segmented into face-like
//! regions first; then each group gets its patch kind (the input's own cylinder or cone
//! where its vertices lie on it, else the caller's hint checked against the geometry, or the
//! geometry alone) and the surface its decimation must keep to.

use std::collections::BTreeMap;

use glam::DVec3;

use super::decimate::SurfaceRef;
use super::encoder::{FitOptions, FitReport, SurfaceHint};
use super::plan::GroupPlan;
use super::primitives::{fit_cone, fit_cylinder, fit_plane, fit_sphere, fit_torus};
use super::segment::{segment, SegmentOptions};
use crate::error::Result;
use crate::mesh::{AnalyticSurface, Axis, BoundarySurface, ControlMesh, PatchKind, Tolerance};

/// The input's faces as the fit works on them.
pub(super) struct Faces {
    /// The input's triangles (polygons fan-split), grouped by CAD face: the segmenter's
    /// regions for an ungrouped input. What the fit starts from and fits to.
    pub mesh: ControlMesh,
    /// `mesh`'s faces as triangles.
    pub tris: Vec<[u32; 3]>,
    /// The input had no groups: `mesh`'s groups are the segmenter's regions (so the caller's
    /// per-group hints and exact surfaces do not apply).
    pub segmented: bool,
    /// By group: its patch kind at the first round's thresholds.
    pub plans: Vec<GroupPlan>,
    /// By group: what its collapses must respect (plane normals are fitted once here).
    pub surfaces: Vec<SurfaceRef>,
}

/// Classifies the faces of `mesh` (a triangle mesh), segmenting it first when it has at
/// most one group. `hints[g]` is what the input says group g's surface is.
pub(super) fn classify_faces(
    mut mesh: ControlMesh,
    hints: &[SurfaceHint],
    opts: &FitOptions,
    tol: f64,
    report: &mut FitReport,
) -> Result<Faces> {
    let diag = mesh.diagonal();
    let mut hints: Vec<SurfaceHint> = hints.to_vec();
    hints.resize(mesh.groups.len(), SurfaceHint::Unknown);
    if opts.exact_surfaces.is_empty() {
        // Sphere and torus patches only where the input has exact surfaces (STEP): measured
        // against a tessellation, a face next to a sphere or torus patch follows its facets
        // only with many more control points (the shared crease is refined in the patch's
        // angles, through the input's chain vertices, where a Cartesian crease is fitted to
        // the facets), and the corpus meshes came out larger in total.
        for h in &mut hints {
            if matches!(h, SurfaceHint::Sphere | SurfaceHint::Torus) {
                *h = SurfaceHint::Freeform;
            }
        }
    }
    let segmented = mesh.groups.len() <= 1;
    if segmented {
        let seg_opts = SegmentOptions {
            sharp_angle_deg: opts.sharp_angle_deg,
            // Region growing merges more with a looser tolerance, and merged regions hide
            // features a patch cannot follow: cap it.
            tolerance: Tolerance::Absolute(0.25 * tol.min(2e-3 * diag)),
            ..Default::default()
        };
        let (seg, seg_report) = segment(&mesh, &seg_opts)?;
        report.notes.push(format!(
            "segmented into {} faces: {}",
            seg.groups.len(),
            seg_report.summary()
        ));
        mesh = seg;
        report.segmented = true;
    }
    let tris: Vec<[u32; 3]> = mesh.faces().map(|f| [f[0], f[1], f[2]]).collect();
    let plans: Vec<GroupPlan> = (0..mesh.groups.len() as u32)
        .map(|g| {
            GroupPlan::new(if segmented {
                mesh.groups[g as usize].patch
            } else {
                exact_surface_kind(&mesh, &tris, g, tol)
                    .unwrap_or_else(|| classify_group(&mesh, &tris, g, hints[g as usize], tol))
            })
        })
        .collect();
    let surfaces: Vec<SurfaceRef> = plans
        .iter()
        .enumerate()
        .map(|(g, plan)| collapse_surface(&mesh, &tris, g as u32, &plan.kind))
        .collect();
    Ok(Faces {
        mesh,
        tris,
        segmented,
        plans,
        surfaces,
    })
}

/// Area-weighted vertex normals over the faces of one group.
fn group_points_normals(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group: u32,
) -> (Vec<DVec3>, Vec<DVec3>) {
    let mut normal: BTreeMap<u32, DVec3> = BTreeMap::new();
    for (f, t) in tris.iter().enumerate() {
        if mesh.face_groups[f] != group {
            continue;
        }
        let p = t.map(|i| mesh.positions[i as usize]);
        let n = (p[1] - p[0]).cross(p[2] - p[0]);
        for &i in t {
            *normal.entry(i).or_insert(DVec3::ZERO) += n;
        }
    }
    let points = normal.keys().map(|&i| mesh.positions[i as usize]).collect();
    let normals = normal.values().map(|n| n.normalize_or_zero()).collect();
    (points, normals)
}

/// Chooses a group's patch kind from its hint and its geometry: a boundary patch only when
/// the analytic surface fits the group's vertices within a fraction of the tolerance.
fn classify_group(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group: u32,
    hint: SurfaceHint,
    tol: f64,
) -> PatchKind {
    let (points, normals) = group_points_normals(mesh, tris, group);
    if points.len() < 3 {
        return PatchKind::Closed;
    }
    let within = |r: &super::primitives::SurfaceFit| r.residuals.max <= 0.25 * tol;
    let try_plane = || {
        fit_plane(&points)
            .filter(within)
            .map(|_| PatchKind::Boundary(BoundarySurface::Plane))
    };
    let try_cyl = || {
        fit_cylinder(&points, &normals)
            .filter(within)
            .and_then(|f| match f.surface {
                AnalyticSurface::Cylinder { axis, .. } => {
                    Some(PatchKind::Boundary(BoundarySurface::Cylinder { axis }))
                }
                _ => None,
            })
    };
    let try_cone = || {
        fit_cone(&points, &normals)
            .filter(within)
            .and_then(|f| match f.surface {
                AnalyticSurface::Cone { axis, .. } => {
                    Some(PatchKind::Boundary(BoundarySurface::Cone { axis }))
                }
                _ => None,
            })
    };
    let try_sphere = || {
        fit_sphere(&points)
            .filter(within)
            .and_then(|f| match f.surface {
                AnalyticSurface::Sphere { center, .. } => sphere_patch(&points, center, tol),
                _ => None,
            })
    };
    let try_torus = || {
        fit_torus(&points, &normals)
            .filter(within)
            .and_then(|f| match f.surface {
                AnalyticSurface::Torus {
                    axis, major_radius, ..
                } => torus_patch(&points, axis, major_radius, tol),
                _ => None,
            })
    };
    let kind = match hint {
        SurfaceHint::Plane => try_plane(),
        SurfaceHint::Cylinder => try_cyl(),
        SurfaceHint::Cone => try_cone(),
        SurfaceHint::Sphere => try_sphere(),
        SurfaceHint::Torus => try_torus(),
        SurfaceHint::Freeform => None,
        SurfaceHint::Unknown => try_plane().or_else(try_cyl).or_else(try_cone),
    };
    kind.unwrap_or(PatchKind::Closed)
}

/// The input's own cylinder or cone for a group (a STEP face's exact axis and apex), when
/// the group's vertices lie on it within a quarter of the tolerance; `None` otherwise (and
/// for planes, whose exact description adds nothing to the plane fitted to the vertices).
/// Taking it instead of a fitted axis keeps a fit error out of the patch's shape.
fn exact_surface_kind(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group: u32,
    tol: f64,
) -> Option<PatchKind> {
    let kind = mesh.groups.get(group as usize)?.patch;
    let PatchKind::Boundary(surface) = kind else {
        return None;
    };
    let (points, _) = group_points_normals(mesh, tris, group);
    if points.len() < 3 {
        return None;
    }
    let radial = |axis: &crate::mesh::Axis, p: DVec3| {
        let d = p - axis.origin;
        let h = d.dot(axis.direction);
        (h, (d - h * axis.direction).length())
    };
    let fits = match surface {
        BoundarySurface::Plane => false,
        BoundarySurface::Sphere { axis } => return sphere_patch(&points, axis.origin, tol),
        BoundarySurface::Torus { axis, major_radius } => {
            return torus_patch(&points, axis, major_radius, tol)
        }
        BoundarySurface::Cylinder { axis } => {
            let r: Vec<f64> = points.iter().map(|&p| radial(&axis, p).1).collect();
            let mean = r.iter().sum::<f64>() / r.len() as f64;
            r.iter().all(|x| (x - mean).abs() <= 0.25 * tol)
        }
        BoundarySurface::Cone { axis } => {
            let hr: Vec<(f64, f64)> = points.iter().map(|&p| radial(&axis, p)).collect();
            let (num, den) = hr
                .iter()
                .fold((0.0, 0.0), |a, &(h, r)| (a.0 + r * h, a.1 + h * h));
            let slope = if den > 0.0 { num / den } else { return None };
            let scale = 1.0 / (1.0 + slope * slope).sqrt();
            hr.iter()
                .all(|&(h, r)| ((r - slope * h) * scale).abs() <= 0.25 * tol)
        }
    };
    fits.then_some(kind)
}

/// The surface a group's collapses must keep facing: the analytic one for boundary patches
/// (a plane's normal fitted to the group's vertices), none for closed patches.
fn collapse_surface(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group: u32,
    kind: &PatchKind,
) -> SurfaceRef {
    match *kind {
        PatchKind::Closed => SurfaceRef::Free,
        PatchKind::Boundary(BoundarySurface::Plane) => {
            let (pts, _) = group_points_normals(mesh, tris, group);
            let normal = fit_plane(&pts)
                .and_then(|f| match f.surface {
                    AnalyticSurface::Plane { normal, .. } => Some(normal),
                    _ => None,
                })
                .unwrap_or(DVec3::Z);
            SurfaceRef::Plane { normal }
        }
        PatchKind::Boundary(BoundarySurface::Cylinder { axis }) => SurfaceRef::Cylinder { axis },
        PatchKind::Boundary(BoundarySurface::Cone { axis }) => SurfaceRef::Cone { axis },
        PatchKind::Boundary(BoundarySurface::Sphere { axis }) => SurfaceRef::Sphere {
            center: axis.origin,
        },
        PatchKind::Boundary(BoundarySurface::Torus { axis, major_radius }) => {
            SurfaceRef::Torus { axis, major_radius }
        }
    }
}

/// Largest angle (radians) a sphere patch may reach from its middle direction, and a torus
/// patch may span about its spine circle: the decoder interpolates between a boundary
/// patch's curves in the surface's angles, which needs every control face well within a
/// half turn, and a patch this wide still gets such faces from its boundary curves alone.
const MAX_PATCH_HALF_ANGLE: f64 = 1.2;

/// A sphere boundary patch for points on the sphere about `center` (within a quarter of the
/// tolerance), with its axis perpendicular to their mean direction so that its poles are a
/// quarter turn away from the patch's middle; `None` for a patch too wide for one (a
/// hemisphere or more, a whole ball).
fn sphere_patch(points: &[DVec3], center: DVec3, tol: f64) -> Option<PatchKind> {
    let radii: Vec<f64> = points.iter().map(|&p| (p - center).length()).collect();
    let mean = radii.iter().sum::<f64>() / radii.len() as f64;
    if !mean.is_finite() || mean <= 0.0 || radii.iter().any(|r| (r - mean).abs() > 0.25 * tol) {
        return None;
    }
    let middle = points
        .iter()
        .map(|&p| (p - center).normalize_or_zero())
        .sum::<DVec3>()
        .try_normalize()?;
    let widest = points
        .iter()
        .map(|&p| (p - center).normalize_or_zero().dot(middle))
        .fold(1.0, f64::min);
    if widest < MAX_PATCH_HALF_ANGLE.cos() {
        return None;
    }
    Some(PatchKind::Boundary(BoundarySurface::Sphere {
        axis: Axis {
            origin: center,
            direction: middle.any_orthonormal_vector(),
        },
    }))
}

/// The torus boundary patch for points on it (within a quarter of the tolerance), if the
/// torus is a ring (its tube does not reach the axis) and the points span less than
/// `2 * MAX_PATCH_HALF_ANGLE` about the spine circle.
fn torus_patch(points: &[DVec3], axis: Axis, major_radius: f64, tol: f64) -> Option<PatchKind> {
    // Per point: the distance to the spine circle.
    let tube: Vec<f64> = points
        .iter()
        .map(|&p| {
            let d = p - axis.origin;
            let radial = (d - axis.direction * d.dot(axis.direction)).normalize_or_zero();
            (d - radial * major_radius).length()
        })
        .collect();
    let minor = tube.iter().sum::<f64>() / tube.len() as f64;
    if !minor.is_finite()
        || minor <= 0.0
        || minor >= major_radius
        || tube.iter().any(|t| (t - minor).abs() > 0.25 * tol)
    {
        return None;
    }
    // The angle about the spine in the meridian plane: (distance from the axis - R, height).
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut first = None;
    for &p in points {
        let d = p - axis.origin;
        let h = d.dot(axis.direction);
        let s = (d - axis.direction * h).length();
        let v = h.atan2(s - major_radius);
        let v0 = *first.get_or_insert(v);
        let dv = (v - v0 + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        lo = lo.min(dv);
        hi = hi.max(dv);
    }
    (hi - lo <= 2.0 * MAX_PATCH_HALF_ANGLE).then_some(PatchKind::Boundary(BoundarySurface::Torus {
        axis,
        major_radius,
    }))
}
