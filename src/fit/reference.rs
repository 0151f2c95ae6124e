//! What the fit measures the decoded surface against: the input's triangles, or a finer
//! tessellation of the same faces the caller gave, prepared for closest-point queries as a
//! whole and face by face, with each triangle's chord allowance.

use super::allowance::{add_analytic_surface_allowance, add_curved_edge_allowance, OwnFaces};
use super::curves::CurveNetwork;
use super::encoder::FitReport;
use super::exact::ExactSurface;
use super::measure::ErrorMeter;
use crate::error::Result;
use crate::mesh::{ControlMesh, PatchKind};
use crate::metrics::{DistanceOptions, TriangleSurface};

/// A triangle mesh of the model's faces with a closest-point structure per face: what the
/// fit projects onto and the measurement charges each face's decoded points against.
pub(super) struct Facets {
    pub mesh: ControlMesh,
    pub tris: Vec<[u32; 3]>,
    /// Per group, the indices of its triangles.
    pub group_tris: Vec<Vec<u32>>,
    /// Per group, a closest-point structure over its own triangles (`None` without any).
    pub group_surfaces: Vec<Option<TriangleSurface>>,
}

impl Facets {
    /// The facets of `mesh`, a triangle mesh whose faces are `tris`.
    pub fn new(mesh: ControlMesh, tris: Vec<[u32; 3]>) -> Facets {
        let group_tris = triangles_by_group(&mesh);
        let group_surfaces = group_surfaces_of(&mesh, &tris, &group_tris);
        Facets {
            mesh,
            tris,
            group_tris,
            group_surfaces,
        }
    }
}

/// How a reference's facets stand for the surface they tessellate.
#[derive(Clone, Copy)]
pub(super) enum FacetAllowance<'a> {
    /// They are the reference: the plain distance is measured.
    Plain,
    /// Each facet's estimated chord error (from its vertex normals, the analytic surface of
    /// cylinder and cone faces, and curved edges' sagitta) is allowed on top
    /// ([`super::encoder::FitOptions::chord_allowance`]).
    Estimated,
    /// A B-rep's tessellation: a face with an exact surface is measured against it (its
    /// facets carry no allowance and say only where the face is), any other face against
    /// its facets plus their chordal tolerance `facet_chord[g]` (an allowance of minus
    /// that), which bounds the distance to the face from above.
    Brep {
        exact: &'a [Option<ExactSurface>],
        facet_chord: &'a [f64],
    },
}

/// The whole-model side of a reference: one closest-point structure over all its
/// triangles, each triangle's chord allowance and each group's largest.
pub(super) struct Allowances {
    surface: TriangleSurface,
    chord: Vec<f64>,
    group_max_chord: Vec<f64>,
    /// By group, the facets' chordal tolerance of a B-rep's tessellation (else empty).
    facet_chord: Vec<f64>,
}

impl Allowances {
    /// The allowances of `facets` for faces of the patch kinds `kinds`, as `rule` says;
    /// with the curve network of the same mesh, estimated allowances of triangles along
    /// curved chains get their edges' sagitta too.
    pub fn new(
        facets: &Facets,
        net: Option<&CurveNetwork>,
        kinds: &[PatchKind],
        rule: FacetAllowance,
    ) -> Result<Self> {
        let surface = TriangleSurface::new(facets.mesh.positions.clone(), facets.tris.clone())?;
        let mut facet_chord = Vec::new();
        let chord = match rule {
            FacetAllowance::Plain => vec![0.0; facets.tris.len()],
            FacetAllowance::Estimated => {
                let mut chord = super::allowance::chord_allowance(&facets.mesh, &facets.tris);
                if let Some(net) = net {
                    add_curved_edge_allowance(&facets.mesh, &facets.tris, net, &mut chord);
                }
                add_analytic_surface_allowance(
                    &facets.mesh.positions,
                    &facets.tris,
                    &facets.mesh.face_groups,
                    kinds,
                    &mut chord,
                );
                chord
            }
            FacetAllowance::Brep {
                exact,
                facet_chord: c,
            } => {
                facet_chord = c.to_vec();
                facets
                    .mesh
                    .face_groups
                    .iter()
                    .map(|&g| match exact.get(g as usize) {
                        Some(Some(_)) => 0.0,
                        _ => -c.get(g as usize).copied().unwrap_or(0.0),
                    })
                    .collect()
            }
        };
        let group_max_chord = facets
            .group_tris
            .iter()
            .map(|ids| ids.iter().fold(0.0f64, |m, &t| m.max(chord[t as usize])))
            .collect();
        Ok(Allowances {
            surface,
            chord,
            group_max_chord,
            facet_chord,
        })
    }

    /// The error meter of decoded surfaces against `facets` (the facets these allowances
    /// are of), faces also held to their `exact` surfaces.
    pub fn meter<'a>(
        &'a self,
        facets: &'a Facets,
        exact: &'a [Option<ExactSurface>],
        sampling: &DistanceOptions,
        tol: f64,
    ) -> ErrorMeter<'a> {
        ErrorMeter::new(
            &facets.mesh,
            &facets.tris,
            &self.surface,
            &self.chord,
            OwnFaces {
                surfaces: &facets.group_surfaces,
                triangles: &facets.group_tris,
                max_allowance: &self.group_max_chord,
                exact,
                facet_chord: &self.facet_chord,
            },
            sampling,
            tol,
        )
    }
}

/// The caller's reference tessellation as facets, when it holds the input's faces (the same
/// groups by name, in order) with valid indices and finite positions; else `None`, with a
/// note when there was one. A segmented input's groups are not the input's: never then.
pub(super) fn reference_facets(
    reference: Option<&ControlMesh>,
    mesh: &ControlMesh,
    segmented: bool,
    report: &mut FitReport,
) -> Option<Facets> {
    let accepted = reference.filter(|r| {
        !segmented
            && r.groups.len() == mesh.groups.len()
            && r.groups
                .iter()
                .zip(&mesh.groups)
                .all(|(a, b)| a.name == b.name)
            // Indices in range and finite positions (it is the caller's mesh, not checked
            // like the input).
            && r.face_groups.len() == r.face_count()
            && r.face_groups.iter().all(|&g| (g as usize) < r.groups.len())
            && (0..r.face_count()).all(|f| {
                r.face(f)
                    .iter()
                    .all(|&v| (v as usize) < r.positions.len())
            })
            && r.positions.iter().all(|p| p.is_finite())
    });
    if reference.is_some() && accepted.is_none() {
        report.notes.push(
            "the reference tessellation does not hold the input's faces (or has invalid indices or \
             positions): measured against the input"
                .into(),
        );
    }
    let r_mesh = triangulated(accepted?);
    let r_tris: Vec<[u32; 3]> = r_mesh.faces().map(|f| [f[0], f[1], f[2]]).collect();
    report.notes.push(format!(
        "measured against a reference tessellation of {} triangles (input: {})",
        r_tris.len(),
        mesh.face_count()
    ));
    Some(Facets::new(r_mesh, r_tris))
}

/// A closest-point structure per group over the group's own triangles (`None` for a group
/// without any). Each holds the group's own vertices only (in first-use order): the same
/// triangles in the same order, so the same closest points, without a copy of every
/// position per group (hundreds of groups times tens of thousands of vertices).
fn group_surfaces_of(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group_triangles: &[Vec<u32>],
) -> Vec<Option<TriangleSurface>> {
    let mut local = vec![u32::MAX; mesh.vertex_count()];
    group_triangles
        .iter()
        .map(|ids| {
            let t: Vec<[u32; 3]> = ids.iter().map(|&t| tris[t as usize]).collect();
            if t.is_empty() {
                return None;
            }
            let mut positions = Vec::new();
            let mut used = Vec::new();
            let t: Vec<[u32; 3]> = t
                .iter()
                .map(|tri| {
                    tri.map(|v| {
                        if local[v as usize] == u32::MAX {
                            local[v as usize] = positions.len() as u32;
                            positions.push(mesh.positions[v as usize]);
                            used.push(v);
                        }
                        local[v as usize]
                    })
                })
                .collect();
            for v in used {
                local[v as usize] = u32::MAX;
            }
            TriangleSurface::new(positions, t).ok()
        })
        .collect()
}

/// `m` with its polygons fan-split into triangles (same vertices, groups and face groups).
pub(super) fn triangulated(m: &ControlMesh) -> ControlMesh {
    let mut t = ControlMesh::new();
    t.positions = m.positions.clone();
    t.groups = m.groups.clone();
    for f in 0..m.face_count() {
        let face = m.face(f);
        for i in 1..face.len().saturating_sub(1) {
            t.push_face(&[face[0], face[i], face[i + 1]], m.face_groups[f]);
        }
    }
    t
}

/// Per group of a triangle mesh, the indices of its triangles (faces).
fn triangles_by_group(m: &ControlMesh) -> Vec<Vec<u32>> {
    let mut by_group: Vec<Vec<u32>> = vec![Vec::new(); m.groups.len()];
    for (t, &g) in m.face_groups.iter().enumerate() {
        if let Some(b) = by_group.get_mut(g as usize) {
            b.push(t as u32);
        }
    }
    by_group
}
