//! The whole-model decimation done face by face, so that a refinement round redoes only the
//! faces whose problem changed, and the faces are decimated in parallel.
//!
//! Each CAD face is decimated on its own triangles, in its own vertex numbering: its
//! interior vertices collapse and its chain vertices that are not control points slide along
//! its boundary, with the costs and tests of the one-mesh [`decimate`](super::decimate) (the
//! quadrics start from all triangles around a vertex). A chain is shared by two faces and
//! each slides it on its own; the control mesh is watertight when both dropped the same
//! vertices of it (a chain's kept vertices, in chain order, are its control edges whichever
//! way each vertex slid). A vertex that one face kept and the other dropped is made a control
//! point of both, and those faces are decimated again. Each face's link condition sees its
//! own triangles only, so the joined result is checked to be manifold (an edge that two faces
//! both made between their shared vertices fails it), and the whole mesh is decimated as one
//! when it is not.
//!
//! A face's problem changes between rounds only through its vertices' roles and cost scales
//! and its rule; the last two results of each face are kept with what they were made from,
//! and reused while that is bit-identical.

use super::{
    collapse_while_allowed, decimate, finish, open_boundary, vertex_quadrics, DecimateInput,
    Decimated, GroupRule, Quadric, State, VertexRole,
};
use crate::fit::map_ordered;
use crate::mesh::topology::HalfEdgeMesh;
use crate::mesh::{ControlMesh, PatchKind};
use glam::DVec3;

/// How many times faces are decimated again to agree on their shared chains before the
/// whole mesh is decimated as one instead (each time only makes more vertices control
/// points, so one or two suffice).
const MAX_AGREEMENT_PASSES: usize = 4;

/// What of a face's problem does not change between rounds: its triangles in its own vertex
/// numbering (local vertex i is input vertex `vertices[i]`).
struct FaceMesh {
    /// Input vertices of the face's triangles, ascending.
    vertices: Vec<u32>,
    /// The face's input triangles (ascending) and their corners (local ids).
    faces: Vec<u32>,
    triangles: Vec<[u32; 3]>,
    /// Per local vertex: its quadric over all its input triangles (of every face), and
    /// whether it is on the input's open boundary.
    quadrics: Vec<Quadric>,
    open_boundary: Vec<bool>,
}

/// What of a face's problem changes between rounds; a result is reused while its key is
/// bit-identical.
#[derive(Clone, PartialEq)]
struct FaceKey {
    roles: Vec<VertexRole>,
    cost_scale: Vec<u64>,
    rule: GroupRule,
}

/// A face's surviving triangles: (input face id, input corners).
type FaceResult = Vec<(u32, [u32; 3])>;

/// The model's decimation across the rounds of one fit: each face's mesh and its last
/// results.
#[derive(Default)]
pub(crate) struct FaceDecimator {
    meshes: Vec<FaceMesh>,
    min_area2: f64,
    /// Per face, up to two (key, result) pairs, the latest first: a face whose chains needed
    /// agreeing is decimated twice a round, with and without the extra control points.
    kept: Vec<Vec<(FaceKey, FaceResult)>>,
}

/// How a [`FaceDecimator::decimate`] went: faces decimated anew (once or more, to agree on
/// their chains), and whether the faces' results did not join into a manifold mesh, so the
/// whole mesh was decimated as one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct FaceDecimation {
    pub faces_redone: usize,
    pub whole_mesh: bool,
}

impl FaceDecimator {
    /// Decimates `input` (see the module documentation). Every call of one decimator must
    /// have the same positions, triangles and groups.
    pub fn decimate(&mut self, input: &DecimateInput<'_>) -> (Decimated, FaceDecimation) {
        let n_groups = input.rules.len();
        if self.meshes.len() != n_groups {
            self.prepare(input);
        }
        let mut roles = input.roles.to_vec();
        let mut report = FaceDecimation::default();
        let mut redone = vec![false; n_groups];
        let mut keys: Vec<FaceKey> = (0..n_groups).map(|g| self.key(input, &roles, g)).collect();
        for pass in 0.. {
            let redo: Vec<usize> = (0..n_groups)
                .filter(|&g| self.find(g, &keys[g]).is_none())
                .collect();
            for &g in &redo {
                redone[g] = true;
            }
            let solved = map_ordered(&redo, |&g| self.solve(input, &keys[g], g));
            for (&g, result) in redo.iter().zip(solved) {
                let kept = &mut self.kept[g];
                kept.insert(0, (keys[g].clone(), result));
                kept.truncate(2);
            }
            let disputed = self.disputed_chain_vertices(&keys, input.positions.len());
            if disputed.is_empty() {
                break;
            }
            if pass + 1 >= MAX_AGREEMENT_PASSES {
                report.whole_mesh = true;
                break;
            }
            for v in disputed {
                roles[v as usize] = VertexRole::Keep;
            }
            keys = (0..n_groups).map(|g| self.key(input, &roles, g)).collect();
        }
        report.faces_redone = redone.iter().filter(|&&r| r).count();
        let results: Vec<Option<&FaceResult>> =
            (0..n_groups).map(|g| self.find(g, &keys[g])).collect();
        let mut tris = input.triangles.to_vec();
        let mut alive = vec![true; tris.len()];
        for (mesh, result) in self.meshes.iter().zip(&results) {
            let Some(result) = result else { continue };
            for &f in &mesh.faces {
                alive[f as usize] = false;
            }
            for &(f, t) in result.iter() {
                alive[f as usize] = true;
                tris[f as usize] = t;
            }
        }
        if report.whole_mesh || !is_manifold(input.positions, &tris, &alive) {
            report.whole_mesh = true;
            return (decimate(input), report);
        }
        let mut used = vec![false; input.positions.len()];
        for (t, _) in tris.iter().zip(&alive).filter(|x| *x.1) {
            for &v in t {
                used[v as usize] = true;
            }
        }
        (finish(input, &tris, &alive, |v| used[v as usize]), report)
    }

    /// Splits the input into its faces' meshes.
    fn prepare(&mut self, input: &DecimateInput<'_>) {
        let n_groups = input.rules.len();
        let (quadrics, min_area2) = vertex_quadrics(input.positions, input.triangles);
        let open = open_boundary(input.positions.len(), input.triangles);
        let mut faces_of: Vec<Vec<u32>> = vec![Vec::new(); n_groups];
        for (f, &g) in input.face_groups.iter().enumerate() {
            if let Some(list) = faces_of.get_mut(g as usize) {
                list.push(f as u32);
            }
        }
        self.meshes = faces_of
            .into_iter()
            .map(|faces| face_mesh(input, faces, &quadrics, &open))
            .collect();
        self.min_area2 = min_area2;
        self.kept = (0..n_groups).map(|_| Vec::new()).collect();
    }

    /// Face `g`'s key under the vertex roles `roles`.
    fn key(&self, input: &DecimateInput<'_>, roles: &[VertexRole], g: usize) -> FaceKey {
        let vertices = &self.meshes[g].vertices;
        FaceKey {
            roles: vertices.iter().map(|&v| roles[v as usize]).collect(),
            cost_scale: vertices
                .iter()
                .map(|&v| input.cost_scale.map_or(1.0, |s| s[v as usize]).to_bits())
                .collect(),
            rule: input.rules[g],
        }
    }

    /// Chain vertices (not control points under the faces' `keys`) that some faces dropped
    /// and others kept, under each face's kept result for its key.
    fn disputed_chain_vertices(&self, keys: &[FaceKey], n_vertices: usize) -> Vec<u32> {
        // Per vertex: faces holding it, faces keeping it.
        let mut holding = vec![0u8; n_vertices];
        let mut keeping = vec![0u8; n_vertices];
        let mut kept: Vec<u32> = Vec::new();
        for (g, (mesh, key)) in self.meshes.iter().zip(keys).enumerate() {
            let drops = || {
                (mesh.vertices.iter().zip(&key.roles))
                    .filter(|(_, &r)| r == VertexRole::ChainDrop)
                    .map(|(&v, _)| v)
            };
            for v in drops() {
                holding[v as usize] = holding[v as usize].saturating_add(1);
            }
            let Some(result) = self.find(g, key) else {
                continue;
            };
            kept.clear();
            kept.extend(result.iter().flat_map(|(_, t)| *t));
            kept.sort_unstable();
            kept.dedup();
            for v in drops().filter(|v| kept.binary_search(v).is_ok()) {
                keeping[v as usize] = keeping[v as usize].saturating_add(1);
            }
        }
        (0..n_vertices as u32)
            .filter(|&v| keeping[v as usize] > 0 && keeping[v as usize] < holding[v as usize])
            .collect()
    }

    /// Face `g`'s kept result for `key`, if any.
    fn find(&self, g: usize, key: &FaceKey) -> Option<&FaceResult> {
        self.kept[g].iter().find(|(k, _)| k == key).map(|(_, r)| r)
    }

    /// Decimates face `g` under `key`: its vertices collapse as they would in the whole
    /// mesh (same costs, same tests, cheapest first).
    fn solve(&self, input: &DecimateInput<'_>, key: &FaceKey, g: usize) -> FaceResult {
        let mesh = &self.meshes[g];
        let positions: Vec<_> = mesh
            .vertices
            .iter()
            .map(|&v| input.positions[v as usize])
            .collect();
        let face_groups = vec![0u32; mesh.triangles.len()];
        let cost_scale: Vec<f64> = key.cost_scale.iter().map(|&b| f64::from_bits(b)).collect();
        let local = DecimateInput {
            positions: &positions,
            triangles: &mesh.triangles,
            face_groups: &face_groups,
            roles: &key.roles,
            rules: std::slice::from_ref(&key.rule),
            cost_scale: Some(&cost_scale),
            domain: input.domain.and_then(|d| d.get(g..=g)),
        };
        let mut st = State::new(&local);
        st.quadric.clone_from(&mesh.quadrics);
        st.open_boundary.clone_from(&mesh.open_boundary);
        st.min_area2 = self.min_area2;
        collapse_while_allowed(&mut st);
        st.tris
            .iter()
            .zip(&st.alive)
            .zip(&mesh.faces)
            .filter(|((_, &alive), _)| alive)
            .map(|((t, _), &f)| (f, t.map(|v| mesh.vertices[v as usize])))
            .collect()
    }
}

/// A face's mesh from its input triangles `faces`.
fn face_mesh(
    input: &DecimateInput<'_>,
    faces: Vec<u32>,
    quadrics: &[Quadric],
    open: &[bool],
) -> FaceMesh {
    let mut vertices: Vec<u32> = faces
        .iter()
        .flat_map(|&f| input.triangles[f as usize])
        .collect();
    vertices.sort_unstable();
    vertices.dedup();
    let local = |v: u32| vertices.binary_search(&v).ok().map(|i| i as u32);
    let triangles: Vec<[u32; 3]> = faces
        .iter()
        .map(|&f| input.triangles[f as usize].map(|v| local(v).expect("a corner is a vertex")))
        .collect();
    FaceMesh {
        quadrics: vertices.iter().map(|&v| quadrics[v as usize]).collect(),
        open_boundary: vertices.iter().map(|&v| open[v as usize]).collect(),
        triangles,
        faces,
        vertices,
    }
}

/// Whether the `alive` triangles make a manifold mesh (the half-edge structure the codec
/// builds accepts them): no edge with more than two of them or used twice in one direction,
/// no vertex where two sheets touch.
fn is_manifold(positions: &[DVec3], tris: &[[u32; 3]], alive: &[bool]) -> bool {
    let mut mesh = ControlMesh::new();
    mesh.positions = positions.to_vec();
    let group = mesh.push_group("joined", PatchKind::Closed);
    for (t, _) in tris.iter().zip(alive).filter(|x| *x.1) {
        mesh.push_face(t, group);
    }
    HalfEdgeMesh::build(&mesh).is_ok()
}
