//! Well-shaped triangles inside the plane patches of a decoded surface: constrained
//! Delaunay refinement with a smallest angle and a longest edge.
//!
//! A plane patch's triangles are exchanged for a refined constrained Delaunay triangulation
//! (spade) of the patch's outline in the plane: the outline's segments (the edges the patch
//! shares with other patches or the mesh boundary, and its sharp edges) are constraints that
//! refinement never splits, so the patches beside it keep exactly their edges and the mesh
//! stays watertight; corners inside a patch stay vertices. Refinement inserts points until
//! no triangle has an angle under the limit or an area that would allow an edge over the
//! longest edge. Where the outline itself forbids that (two outline segments meeting at a
//! smaller angle, a segment too close to another), triangles next to the outline can stay
//! below the limit. Split the outline to the longest edge first
//! ([`super::split_to_max_edge`]) so that its segments are no longer than the edges inside.
//! A patch whose outline cannot be triangulated in its plane (it crosses itself there) keeps
//! its triangles.

use std::collections::{HashMap, HashSet};

use glam::DVec3;
use spade::{
    AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation,
};

use crate::error::{Error, Result};
use crate::mesh::{edge_key, ControlMesh};

/// Largest distance from its plane, relative to the mesh's diagonal, of a vertex of a patch
/// taken for a plane: rounding, not curvature.
const PLANAR: f64 = 1e-9;

/// The smallest area of a triangle with no angle under `min_angle_deg` whose longest edge
/// is `h`: the isosceles one with both angles beside that edge at the limit, `h^2 tan(a) /
/// 4`. As the refinement's area bound it makes every triangle that meets the angle meet the
/// edge too.
fn area_bound(h: f64, min_angle_deg: f64) -> f64 {
    h * h * min_angle_deg.to_radians().tan() / 4.0
}

/// What [`refine_planes`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlaneRefinement {
    /// Plane patches triangulated anew.
    pub refined: usize,
    /// Plane patches that kept their triangles: outline not a simple region in the plane,
    /// or refinement that did not finish within its vertex budget.
    pub kept: usize,
}

/// Plane patch `g`'s frame and outline, and what refining it gave.
struct Patch {
    origin: DVec3,
    normal: DVec3,
    u: DVec3,
    v: DVec3,
}

impl Patch {
    /// The plane through `tris` (all of one group) if every vertex lies in it.
    fn of(positions: &[DVec3], tris: &[[u32; 3]], tolerance: f64) -> Option<Patch> {
        let p = |v: u32| positions[v as usize];
        let normal = tris
            .iter()
            .map(|&[a, b, c]| (p(b) - p(a)).cross(p(c) - p(a)))
            .sum::<DVec3>()
            .try_normalize()?;
        let origin = p(tris[0][0]);
        let flat = tris
            .iter()
            .flatten()
            .all(|&v| (p(v) - origin).dot(normal).abs() <= tolerance);
        if !flat {
            return None;
        }
        let u = normal.any_orthonormal_vector();
        let v = normal.cross(u);
        Some(Patch {
            origin,
            normal,
            u,
            v,
        })
    }

    fn uv(&self, p: DVec3) -> Point2<f64> {
        let d = p - self.origin;
        Point2::new(round(d.dot(self.u)), round(d.dot(self.v)))
    }

    fn at(&self, q: Point2<f64>) -> DVec3 {
        self.origin + q.x * self.u + q.y * self.v
    }
}

/// spade refuses coordinates below its smallest allowed magnitude; those are zero.
fn round(x: f64) -> f64 {
    if x.abs() < spade::MIN_ALLOWED_VALUE {
        0.0
    } else {
        x
    }
}

/// The triangles of `mesh`'s plane patches refined to `min_angle` (degrees) and
/// `max_edge`; see the module docs. `mesh` must be made of triangles. Refused with
/// `Error::LimitsExceeded` when the triangles would pass `max_faces`.
pub fn refine_planes(
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
    max_edge: f64,
    min_angle: f64,
    max_faces: u64,
) -> Result<(ControlMesh, Option<Vec<DVec3>>, PlaneRefinement)> {
    if !(min_angle > 0.0 && min_angle <= 30.0 && max_edge > 0.0 && max_edge.is_finite()) {
        return Err(Error::Parameter(format!(
            "the smallest angle must be in (0, 30] degrees and the longest edge a positive \
             length, got {min_angle} and {max_edge}"
        )));
    }
    let mut positions = mesh.positions.clone();
    let mut normals = normals.map(<[DVec3]>::to_vec);
    let mut by_group: Vec<Vec<[u32; 3]>> = vec![Vec::new(); mesh.groups.len()];
    for (f, face) in mesh.faces().enumerate() {
        if face.len() != 3 {
            return Err(Error::Parameter(
                "plane refinement needs a mesh of triangles".into(),
            ));
        }
        if let Some(list) = by_group.get_mut(mesh.face_groups[f] as usize) {
            list.push([face[0], face[1], face[2]]);
        }
    }
    let tolerance = PLANAR * mesh.diagonal();
    let mut report = PlaneRefinement::default();
    let mut total: u64 = mesh.face_count() as u64;
    for list in by_group.iter_mut() {
        let Some(patch) = Patch::of(&positions, list, tolerance) else {
            continue;
        };
        let budget = max_faces.saturating_sub(total);
        match refine_patch(
            &patch,
            &mut positions,
            list,
            mesh,
            max_edge,
            min_angle,
            budget,
        )? {
            Some(tris) => {
                total = total - list.len() as u64 + tris.len() as u64;
                if let Some(n) = normals.as_mut() {
                    n.resize(positions.len(), patch.normal);
                }
                *list = tris;
                report.refined += 1;
            }
            None => report.kept += 1,
        }
    }
    // Triangles in the input's order of groups; vertices no triangle uses any more (inside
    // a refined plane) dropped.
    let mut tris = Vec::new();
    let mut groups = Vec::new();
    for (g, list) in by_group.iter().enumerate() {
        tris.extend_from_slice(list);
        groups.extend(std::iter::repeat_n(g as u32, list.len()));
    }
    let mut new_index = vec![u32::MAX; positions.len()];
    let mut kept = Vec::new();
    for &v in tris.iter().flatten() {
        if new_index[v as usize] == u32::MAX {
            new_index[v as usize] = 0;
        }
    }
    for (v, index) in new_index.iter_mut().enumerate() {
        if *index != u32::MAX || mesh.corners.contains(&(v as u32)) {
            *index = kept.len() as u32;
            kept.push(v);
        }
    }
    let remap = |v: u32| new_index[v as usize];
    let out = ControlMesh {
        positions: kept.iter().map(|&v| positions[v]).collect(),
        face_offsets: (0..=tris.len() as u32).map(|i| 3 * i).collect(),
        face_vertices: tris.iter().flatten().map(|&v| remap(v)).collect(),
        face_groups: groups,
        groups: mesh.groups.clone(),
        sharp_edges: mesh
            .sharp_edges
            .iter()
            .map(|&(a, b)| edge_key(remap(a), remap(b)))
            .collect(),
        corners: mesh.corners.iter().map(|&c| remap(c)).collect(),
    };
    let normals = normals.map(|n| kept.iter().map(|&v| n[v]).collect());
    Ok((out, normals, report))
}

/// The refined triangles of one plane patch (new vertices appended to `positions`), or
/// `None` where its outline is not a simple region of the plane.
fn refine_patch(
    patch: &Patch,
    positions: &mut Vec<DVec3>,
    tris: &[[u32; 3]],
    mesh: &ControlMesh,
    max_edge: f64,
    min_angle: f64,
    budget: u64,
) -> Result<Option<Vec<[u32; 3]>>> {
    // The outline: edges used once inside the patch, and sharp edges inside it.
    let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
    for t in tris {
        for s in 0..3 {
            *uses.entry(edge_key(t[s], t[(s + 1) % 3])).or_insert(0) += 1;
        }
    }
    let mut outline: Vec<(u32, u32)> = uses
        .iter()
        .filter(|&(e, &n)| n == 1 || mesh.sharp_edges.contains(e))
        .map(|(&e, _)| e)
        .collect();
    outline.sort_unstable();
    let mut points: Vec<u32> = outline.iter().flat_map(|&(a, b)| [a, b]).collect();
    points.extend(tris.iter().flatten().filter(|v| mesh.corners.contains(v)));
    points.sort_unstable();
    points.dedup();

    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> =
        ConstrainedDelaunayTriangulation::new();
    let mut vertex_of: Vec<u32> = Vec::new();
    let mut handle_of = HashMap::new();
    for &v in &points {
        let Ok(h) = cdt.insert(patch.uv(positions[v as usize])) else {
            return Ok(None);
        };
        if h.index() != vertex_of.len() {
            return Ok(None); // two outline vertices at one point of the plane
        }
        vertex_of.push(v);
        handle_of.insert(v, h);
    }
    for &(a, b) in &outline {
        let (ha, hb) = (handle_of[&a], handle_of[&b]);
        if !cdt.can_add_constraint(ha, hb) {
            return Ok(None);
        }
        cdt.add_constraint(ha, hb);
    }
    if cdt.num_vertices() != vertex_of.len() {
        return Ok(None); // a constraint ran through an outline vertex
    }
    // Refinement ends on its own for angles up to 30 degrees; the budget (a few times the
    // vertices the area bound asks for, within the limits) only stops it on outlines it
    // cannot satisfy.
    let bound = area_bound(max_edge, min_angle);
    let p = |v: u32| positions[v as usize];
    let patch_area: f64 = tris
        .iter()
        .map(|&[a, b, c]| 0.5 * (p(b) - p(a)).cross(p(c) - p(a)).length())
        .sum();
    let expected = 4.0 * patch_area / bound + 10.0 * points.len() as f64 + 1000.0;
    let extra = (expected.min((budget / 2) as f64)) as usize;
    let params = RefinementParameters::<f64>::new()
        .with_angle_limit(AngleLimit::from_deg(min_angle))
        .with_max_allowed_area(bound)
        .keep_constraint_edges()
        .exclude_outer_faces(true)
        .with_max_additional_vertices(extra);
    let result = cdt.refine(params);
    if !result.refinement_complete {
        return Ok(None);
    }
    let excluded: HashSet<_> = result.excluded_faces.iter().copied().collect();
    let first_new = positions.len() as u32;
    let mut out = Vec::new();
    for face in cdt.inner_faces() {
        if excluded.contains(&face.fix()) {
            continue;
        }
        let t = face.vertices().map(|h| {
            let i = h.fix().index();
            // Points past the outline's are the ones refinement added, in order.
            vertex_of
                .get(i)
                .copied()
                .unwrap_or_else(|| first_new + (i - vertex_of.len()) as u32)
        });
        out.push(t);
    }
    for h in cdt.vertices().skip(vertex_of.len()) {
        positions.push(patch.at(h.position()));
    }
    // The same outline (every segment once) and the same area, or the patch keeps its
    // triangles: the mesh around it must not open.
    let p = |v: u32| positions[v as usize];
    let area = |list: &[[u32; 3]]| -> f64 {
        list.iter()
            .map(|&[a, b, c]| 0.5 * (p(b) - p(a)).cross(p(c) - p(a)).dot(patch.normal))
            .sum()
    };
    let mut new_uses: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &out {
        for s in 0..3 {
            *new_uses.entry(edge_key(t[s], t[(s + 1) % 3])).or_insert(0) += 1;
        }
    }
    let same_outline = uses
        .iter()
        .filter(|&(_, &n)| n == 1)
        .all(|(e, _)| new_uses.get(e) == Some(&1))
        && new_uses.values().filter(|&&n| n == 1).count()
            == uses.values().filter(|&&n| n == 1).count();
    let (before, after) = (area(tris), area(&out));
    if !same_outline || (before - after).abs() > 1e-9 * before.abs() {
        positions.truncate(first_new as usize);
        return Ok(None);
    }
    Ok(Some(out))
}
