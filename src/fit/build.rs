//! Step 3 of the fit: the round's control mesh topology, from the plan's chain
//! control points and decimation thresholds.

use std::collections::BTreeMap;

use super::chains::{chain_controls, Chains};
use super::classify::Faces;
use super::decimate::{
    DecimateInput, FaceDecimation, FaceDecimator, GroupRule, SurfaceRef, VertexRole,
};
use super::domain::PlaneDomain;
use super::plan::{chain_frame, Plan};
use crate::mesh::{edge_key, ControlMesh, PatchKind};

/// A Cartesian chain whose tolerance has been halved down to this fraction of the
/// tolerance (its groups failed about four times) and which already keeps every vertex
/// cannot be refined any further: its interior control points become corners, so the
/// decoded crease is the chain polyline itself. A smooth crease through few control points
/// cannot follow a chain that turns by tens of degrees at a vertex (e.g. a three-vertex
/// chain between a blade and a hub, 49 degrees at the middle vertex); least squares then
/// cuts the turn and the blade's patch sags behind its facets near that vertex.
const STUCK_CHAIN_TOL: f64 = 0.125;

/// Everything one build round produces.
pub(super) struct Built {
    pub control: ControlMesh,
    /// Control edge -> chain index, for sharp edges.
    pub edge_chain: BTreeMap<(u32, u32), usize>,
    /// How the decimation went (faces redone).
    pub decimation: FaceDecimation,
}

/// Step 3: control points on chains, then the constrained decimation of the whole
/// mesh: chain vertices that are not control points slide away along their chain, boundary
/// patches lose every interior vertex, closed patches are simplified while their quadric
/// error allows. Sharp edges are the group boundaries, corners the B-rep vertices (and the
/// vertices of stuck chains): watertight by construction. `decimator` keeps each face's
/// decimation for the next round, which redoes only the faces whose problem changed.
pub(super) fn build_topology(
    faces: &Faces,
    chains: &Chains,
    plan: &Plan,
    tol: f64,
    plane_domains: &[Option<PlaneDomain>],
    decimator: &mut FaceDecimator,
) -> Built {
    let (mesh, tris, net) = (&faces.mesh, &faces.tris[..], &chains.net);
    let (plans, surfaces, vertex_cost) = (&plan.groups[..], &faces.surfaces, &plan.vertex_cost);
    let nv = mesh.vertex_count();
    let (roles, pinned) = vertex_roles(faces, chains, plan, tol);
    let rules: Vec<GroupRule> = plans
        .iter()
        .zip(surfaces)
        .map(|(group, &surface)| {
            let closed = matches!(group.kind, PatchKind::Closed);
            GroupRule {
                remove_all_interior: !closed,
                max_cost: (group.cost_factor * tol).powi(2),
                // A boundary patch turned closed is checked like any freeform face.
                surface: if closed { SurfaceRef::Free } else { surface },
                max_edge_angle: 80f64.to_radians(),
            }
        })
        .collect();
    let (dec, decimation) = decimator.decimate(&DecimateInput {
        positions: &mesh.positions,
        triangles: tris,
        face_groups: &mesh.face_groups,
        roles: &roles,
        rules: &rules,
        // Distance factors to the squared-distance units of `max_cost`.
        cost_scale: Some(&vertex_cost.iter().map(|f| f * f).collect::<Vec<f64>>()),
        domain: (!plane_domains.is_empty()).then_some(plane_domains),
    });
    // Compact into a control mesh.
    let mut index = vec![u32::MAX; nv];
    let mut control = ControlMesh::new();
    let mut origin = Vec::new();
    for &v in &dec.vertices {
        index[v as usize] = control.push_vertex(mesh.positions[v as usize]);
        origin.push(v);
    }
    for g in &mesh.groups {
        control.groups.push(g.clone());
    }
    for (g, group) in plans.iter().enumerate() {
        control.groups[g].patch = group.kind;
    }
    for (t, &g) in dec.triangles.iter().zip(&dec.face_groups) {
        control.push_face(&t.map(|v| index[v as usize]), g);
    }
    // Sharp edges: every edge between two groups; mesh-boundary edges are creases anyway.
    let mut edge_faces: BTreeMap<(u32, u32), Vec<u32>> = BTreeMap::new();
    for f in 0..control.face_count() {
        let face = control.face(f);
        for k in 0..face.len() {
            let e = edge_key(face[k], face[(k + 1) % face.len()]);
            edge_faces
                .entry(e)
                .or_default()
                .push(control.face_groups[f]);
        }
    }
    // A faceted group's edges are all sharp (its vertices all corners): its decoded surface
    // is its control faces.
    for (&(a, b), groups) in &edge_faces {
        let faceted = groups.iter().any(|&g| plans[g as usize].faceted);
        if groups.len() == 2 && (groups[0] != groups[1] || faceted) {
            control.set_sharp(a, b);
        }
    }
    for v in net.corners.iter().map(|c| c.vertex).chain(pinned) {
        let i = index[v as usize];
        if i != u32::MAX {
            control.corners.insert(i);
        }
    }
    // Which chain each control edge on a chain belongs to.
    let mut vertex_chain: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (ci, chain) in net.chains.iter().enumerate() {
        for &v in &chain.vertices {
            vertex_chain.entry(v).or_default().push(ci);
        }
    }
    let mut edge_chain = BTreeMap::new();
    for &(a, b) in edge_faces.keys() {
        let (oa, ob) = (origin[a as usize], origin[b as usize]);
        if let (Some(ca), Some(cb)) = (vertex_chain.get(&oa), vertex_chain.get(&ob)) {
            if let Some(&c) = ca.iter().find(|c| cb.contains(c)) {
                let boundary = edge_faces[&(a, b)].len() == 1
                    || edge_faces[&(a, b)].first() != edge_faces[&(a, b)].last();
                if boundary {
                    edge_chain.insert((a, b), c);
                }
            }
        }
    }
    Built {
        control,
        edge_chain,
        decimation,
    }
}

/// What the decimation may do with each input vertex: corners, chain control points and
/// the vertices of faceted groups stay, other chain vertices slide along their chain, the
/// rest are free. Also returns the vertices that become control corners besides the B-rep
/// vertices: the interior vertices of stuck Cartesian chains (a crease through corners only
/// is the chain's polyline itself, see [`STUCK_CHAIN_TOL`]) and those of faceted groups.
fn vertex_roles(
    faces: &Faces,
    chains: &Chains,
    plan: &Plan,
    tol: f64,
) -> (Vec<VertexRole>, Vec<u32>) {
    let nv = faces.mesh.vertex_count();
    let mut roles = vec![VertexRole::Interior; nv];
    let mut pinned: Vec<u32> = Vec::new();
    for c in &chains.net.corners {
        roles[c.vertex as usize] = VertexRole::Keep;
    }
    for (ci, chain) in chains.net.chains.iter().enumerate() {
        let points = chains.points(&faces.mesh, ci);
        let frame = chain_frame(&chain.groups, &plan.groups);
        let min_interior = if chains.loop_len[ci] < 3 { 2 } else { 0 };
        let keep = chain_controls(
            &points,
            frame,
            plan.chain_tol[ci],
            plan.chain_step[ci],
            min_interior,
        );
        if frame.is_none()
            && points.len() >= 3
            && keep.len() == points.len()
            && plan.chain_tol[ci] <= STUCK_CHAIN_TOL * tol
        {
            pinned.extend_from_slice(&chain.vertices[1..points.len() - 1]);
        }
        for (i, &v) in chain.vertices.iter().enumerate() {
            if roles[v as usize] == VertexRole::Keep {
                continue;
            }
            roles[v as usize] = if keep.binary_search(&i).is_ok() {
                VertexRole::Keep
            } else {
                VertexRole::ChainDrop
            };
        }
    }
    for (t, tri) in faces.tris.iter().enumerate() {
        if plan.groups[faces.mesh.face_groups[t] as usize].faceted {
            for &v in tri {
                roles[v as usize] = VertexRole::Keep;
                pinned.push(v);
            }
        }
    }
    pinned.sort_unstable();
    pinned.dedup();
    (roles, pinned)
}
