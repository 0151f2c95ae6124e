//! The boundary curve network of a grouped mesh: corners (B-rep vertices) and chains
//! (polylines of group-boundary edges between corners), plus each group's boundary loops as
//! sequences of chains.
//!
//! Chains are the unit of sharing between patches: the encoder fits one subdivision crease
//! curve per chain and both adjacent patches use its control points, which is what makes
//! the assembled control mesh watertight (design.md). Fitting that curve needs the crease
//! masks of `src/subdiv/`; this module only provides the topology, a first Douglas-Peucker
//! control polygon per chain, and (built for the tests until then) the seam
//! `CreaseCurveEvaluator` / `chain_fit_error` through which the subdivision code will plug in.

use std::collections::BTreeMap;

use glam::DVec3;

use super::adjacency::EdgeTable;
use crate::error::{Error, Result};
use crate::mesh::{ControlMesh, Tolerance};

/// Parameters of [`build_curve_network`].
#[derive(Clone, Debug, PartialEq)]
pub struct CurveOptions {
    /// A chain vertex where the polyline turns by more than this (angle between the
    /// incoming and outgoing edge directions) becomes a corner.
    pub corner_angle_deg: f64,
    /// Douglas-Peucker tolerance of the control polygons (0 keeps every vertex); default
    /// [`Tolerance::DEFAULT`].
    pub simplify_tolerance: Tolerance,
}

impl Default for CurveOptions {
    fn default() -> Self {
        CurveOptions {
            corner_angle_deg: 60.0,
            simplify_tolerance: Tolerance::DEFAULT,
        }
    }
}

/// Why a vertex is a corner.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum CornerReason {
    /// Three or more groups meet, or the number of boundary edges at the vertex is not two
    /// (junction of chains, end of a dangling boundary).
    Junction,
    /// Two boundary edges with different adjacent groups meet (e.g. where a group boundary
    /// reaches an open mesh boundary).
    GroupChange,
    /// The chain turns sharply.
    SharpTurn,
    /// Inserted to cut a closed loop without corners (or a chain that would start and end at
    /// the same corner) into chains with distinct end points.
    LoopSplit,
}

/// A corner vertex of the network.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Corner {
    pub vertex: u32,
    pub reason: CornerReason,
}

/// A maximal polyline of group-boundary edges between two distinct corners.
#[derive(Clone, Debug, PartialEq)]
pub struct Chain {
    /// Mesh vertices in order, from one corner to the other (both included).
    pub vertices: Vec<u32>,
    /// Adjacent groups, ascending: two for an edge between faces, one for an open
    /// boundary, more along non-manifold edges.
    pub groups: Vec<u32>,
    /// True when the chain lies on the mesh boundary (edges with a single face).
    pub open_boundary: bool,
    /// Indices into `vertices` of the coarse control polygon (Douglas-Peucker within the
    /// tolerance); always includes both ends. Shared by both adjacent patches.
    pub control: Vec<u32>,
}

impl Chain {
    pub fn start(&self) -> u32 {
        self.vertices[0]
    }
    pub fn end(&self) -> u32 {
        self.vertices[self.vertices.len() - 1]
    }
    pub fn edge_count(&self) -> usize {
        self.vertices.len() - 1
    }
}

/// One chain of a group's boundary loop, in the loop's direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoopChain {
    pub chain: u32,
    /// The loop runs the chain from its end to its start.
    pub reversed: bool,
}

/// Boundary loops of one group, each oriented like the group's faces (counter-clockwise
/// seen from outside). For a (nearly) planar group the outer loop comes first: it is the
/// one with the largest signed area about the group normal (holes run clockwise, so their
/// signed area is negative); otherwise the longest loop comes first. A cylinder side face
/// has two loops (the corpus tessellations weld the seam, so no seam chain appears);
/// a closed single-face body (a full sphere) has none.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GroupLoops {
    pub loops: Vec<Vec<LoopChain>>,
}

/// Corners, chains and per-group loops. Corners are sorted by vertex; chains are in a
/// deterministic order (walked from corners in ascending vertex order).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CurveNetwork {
    pub corners: Vec<Corner>,
    pub chains: Vec<Chain>,
    /// Indexed by group.
    pub group_loops: Vec<GroupLoops>,
    /// The Douglas-Peucker tolerance used.
    pub simplify_tolerance: f64,
}

#[cfg(test)]
impl CurveNetwork {
    pub fn is_corner(&self, v: u32) -> bool {
        self.corners.binary_search_by_key(&v, |c| c.vertex).is_ok()
    }

    /// Positions of a chain's vertices.
    pub fn chain_points(&self, mesh: &ControlMesh, chain: usize) -> Vec<DVec3> {
        self.chains[chain]
            .vertices
            .iter()
            .map(|&v| mesh.positions[v as usize])
            .collect()
    }

    /// Positions of a chain's control polygon.
    pub fn control_points(&self, mesh: &ControlMesh, chain: usize) -> Vec<DVec3> {
        let c = &self.chains[chain];
        c.control
            .iter()
            .map(|&i| mesh.positions[c.vertices[i as usize] as usize])
            .collect()
    }

    /// Total number of edges over all chains.
    pub fn edge_count(&self) -> usize {
        self.chains.iter().map(|c| c.edge_count()).sum()
    }
}

/// Seam to the subdivision engine (`src/subdiv/`): evaluates the crease/boundary
/// subdivision curve of a control polygon whose two end points are corners (fixed).
/// The fitting stage will implement it with the shared crease masks (one implementation
/// of each rule); [`PolylineCurve`] is the trivial stand-in used until then.
#[cfg(test)]
pub trait CreaseCurveEvaluator {
    /// Dense points on the limit curve, starting at `control[0]` and ending at
    /// `control[last]`, e.g. the limit positions after a few refinement steps.
    fn dense_curve(&self, control: &[DVec3]) -> Vec<DVec3>;
}

/// Stand-in evaluator: the control polygon itself (what the curve would be without
/// subdivision). Replace with the crease-curve evaluator from `subdiv` when fitting.
#[cfg(test)]
pub struct PolylineCurve;

#[cfg(test)]
impl CreaseCurveEvaluator for PolylineCurve {
    fn dense_curve(&self, control: &[DVec3]) -> Vec<DVec3> {
        control.to_vec()
    }
}

/// Two-sided max distance between the curve evaluated from `control` and the chain
/// polyline `target` (points of each sampled against the other's segments, plus segment
/// midpoints). This is the error the curve fitter will drive below its tolerance.
#[cfg(test)]
pub fn chain_fit_error(
    control: &[DVec3],
    target: &[DVec3],
    evaluator: &dyn CreaseCurveEvaluator,
) -> f64 {
    let curve = evaluator.dense_curve(control);
    polyline_hausdorff(&curve, target)
}

fn point_segment_distance(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let t = crate::metrics::segment_parameter(p, a, b);
    (p - a.lerp(b, t)).length()
}

#[cfg(test)]
fn point_polyline_distance(p: DVec3, line: &[DVec3]) -> f64 {
    match line.len() {
        0 => f64::INFINITY,
        1 => (p - line[0]).length(),
        _ => line
            .windows(2)
            .map(|w| point_segment_distance(p, w[0], w[1]))
            .fold(f64::INFINITY, f64::min),
    }
}

/// Symmetric max distance between two polylines, sampled at vertices and edge midpoints.
#[cfg(test)]
pub fn polyline_hausdorff(a: &[DVec3], b: &[DVec3]) -> f64 {
    let one_sided = |x: &[DVec3], y: &[DVec3]| {
        let mut d: f64 = 0.0;
        for (i, &p) in x.iter().enumerate() {
            d = d.max(point_polyline_distance(p, y));
            if i + 1 < x.len() {
                d = d.max(point_polyline_distance(0.5 * (p + x[i + 1]), y));
            }
        }
        d
    };
    one_sided(a, b).max(one_sided(b, a))
}

/// Douglas-Peucker simplification: indices (ascending, with both ends) of a sub-polyline
/// within `tol` of every point. Iterative (explicit stack) so long chains cannot overflow.
pub fn douglas_peucker(points: &[DVec3], tol: f64) -> Vec<u32> {
    let n = points.len();
    if n <= 2 {
        return (0..n as u32).collect();
    }
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0usize, n - 1)];
    while let Some((s, e)) = stack.pop() {
        if e <= s + 1 {
            continue;
        }
        let (mut worst, mut at) = (-1.0, s);
        for i in s + 1..e {
            let d = point_segment_distance(points[i], points[s], points[e]);
            if d > worst {
                worst = d;
                at = i;
            }
        }
        if worst > tol {
            keep[at] = true;
            stack.push((s, at));
            stack.push((at, e));
        }
    }
    (0..n as u32).filter(|&i| keep[i as usize]).collect()
}

/// Builds the curve network of a grouped mesh. Errors on invalid meshes, on groups whose
/// faces are inconsistently oriented along a boundary, and on bad options.
pub fn build_curve_network(mesh: &ControlMesh, opts: &CurveOptions) -> Result<CurveNetwork> {
    let tol = checked_tolerance(mesh, opts)?;
    let graph = BoundaryGraph::new(mesh);
    let mut corner_reason = graph.corners(opts.corner_angle_deg.to_radians().cos());
    let polylines = graph.polylines(&mut corner_reason);
    let chains = graph.chains(polylines, tol)?;
    let edge_chain = graph.edge_chains(&chains);
    let group_loops =
        build_group_loops(mesh, &graph.edges, &graph.edge_label, &edge_chain, &chains)?;
    Ok(CurveNetwork {
        corners: corner_reason
            .into_iter()
            .map(|(vertex, reason)| Corner { vertex, reason })
            .collect(),
        chains,
        group_loops,
        simplify_tolerance: tol,
    })
}

/// Rejects invalid meshes and out-of-range options; returns the Douglas-Peucker tolerance
/// to use.
fn checked_tolerance(mesh: &ControlMesh, opts: &CurveOptions) -> Result<f64> {
    mesh.validate()?;
    if !(opts.corner_angle_deg > 0.0 && opts.corner_angle_deg <= 180.0) {
        return Err(Error::Parameter(format!(
            "corner angle {} must be in (0, 180] degrees",
            opts.corner_angle_deg
        )));
    }
    let tol = opts.simplify_tolerance.resolve(mesh.diagonal());
    if !(tol >= 0.0 && tol.is_finite()) {
        return Err(Error::Parameter(format!(
            "simplification tolerance {tol} must be finite and >= 0"
        )));
    }
    Ok(tol)
}

/// Label of every edge (an index into the returned label list) and the distinct labels:
/// (adjacent groups ascending, open-boundary flag). Interior edges of one group get
/// `u32::MAX`; every other edge is a group-boundary edge.
fn label_boundary_edges(
    mesh: &ControlMesh,
    edges: &EdgeTable,
) -> (Vec<u32>, Vec<(Vec<u32>, bool)>) {
    let mut label_ids: BTreeMap<(Vec<u32>, bool), u32> = BTreeMap::new();
    let mut labels: Vec<(Vec<u32>, bool)> = Vec::new();
    let mut edge_label = vec![u32::MAX; edges.len()];
    for (e, label) in edge_label.iter_mut().enumerate() {
        let fs = edges.faces(e);
        let mut groups: Vec<u32> = fs
            .iter()
            .map(|&(f, _)| mesh.face_groups[f as usize])
            .collect();
        groups.sort_unstable();
        groups.dedup();
        let open = fs.len() == 1;
        if groups.len() == 1 && fs.len() == 2 {
            continue; // interior edge of one group
        }
        let key = (groups, open);
        let id = *label_ids.entry(key.clone()).or_insert_with(|| {
            labels.push(key);
            (labels.len() - 1) as u32
        });
        *label = id;
    }
    (edge_label, labels)
}

/// Boundary edges of every vertex as CSR (offsets, edge ids ascending per vertex).
fn boundary_edges_per_vertex(
    edges: &EdgeTable,
    edge_label: &[u32],
    nv: usize,
) -> (Vec<u32>, Vec<u32>) {
    let ne = edges.len();
    let is_boundary = |e: usize| edge_label[e] != u32::MAX;
    let mut deg = vec![0u32; nv + 1];
    for e in 0..ne {
        if is_boundary(e) {
            let (a, b) = edges.keys[e];
            deg[a as usize + 1] += 1;
            deg[b as usize + 1] += 1;
        }
    }
    for i in 0..nv {
        deg[i + 1] += deg[i];
    }
    let vstart = deg.clone();
    let mut fill = deg.clone();
    let mut vedges = vec![0u32; *deg.last().unwrap_or(&0) as usize];
    for e in 0..ne {
        if is_boundary(e) {
            let (a, b) = edges.keys[e];
            for v in [a, b] {
                vedges[fill[v as usize] as usize] = e as u32;
                fill[v as usize] += 1;
            }
        }
    }
    (vstart, vedges)
}

/// Number of distinct groups among the faces around each vertex.
fn groups_per_vertex(mesh: &ControlMesh) -> Vec<u32> {
    let mut vg: Vec<(u32, u32)> = Vec::with_capacity(mesh.face_vertices.len());
    for f in 0..mesh.face_count() {
        for &v in mesh.face(f) {
            vg.push((v, mesh.face_groups[f]));
        }
    }
    vg.sort_unstable();
    vg.dedup();
    let mut group_count = vec![0u32; mesh.vertex_count()];
    for &(v, _) in &vg {
        group_count[v as usize] += 1;
    }
    group_count
}

/// Cuts every polyline that starts and ends at the same corner in the middle, making the
/// cut vertex a corner, so that every chain has two distinct ends.
fn cut_self_closing(
    pending: Vec<Vec<u32>>,
    corner_reason: &mut BTreeMap<u32, CornerReason>,
) -> Vec<Vec<u32>> {
    let mut polylines: Vec<Vec<u32>> = Vec::with_capacity(pending.len());
    for p in pending {
        if p.len() >= 3 && p[0] == p[p.len() - 1] {
            let half = (p.len() - 1) / 2;
            corner_reason.insert(p[half], CornerReason::LoopSplit);
            polylines.push(p[..=half].to_vec());
            polylines.push(p[half..].to_vec());
        } else {
            polylines.push(p);
        }
    }
    polylines
}

/// The group-boundary edges of a mesh, labelled by their adjacent groups and listed per
/// vertex: the graph whose corners and chains make the curve network.
struct BoundaryGraph<'a> {
    mesh: &'a ControlMesh,
    edges: EdgeTable,
    /// Per edge: index into `labels`, `u32::MAX` for an interior edge of one group.
    edge_label: Vec<u32>,
    /// Distinct (adjacent groups ascending, open boundary) pairs.
    labels: Vec<(Vec<u32>, bool)>,
    /// Boundary edges per vertex (CSR, ascending edge id).
    vstart: Vec<u32>,
    vedges: Vec<u32>,
}

impl<'a> BoundaryGraph<'a> {
    /// Labels the edges of `mesh` and lists the boundary edges of every vertex.
    fn new(mesh: &'a ControlMesh) -> Self {
        let edges = EdgeTable::new(mesh);
        let (edge_label, labels) = label_boundary_edges(mesh, &edges);
        let (vstart, vedges) = boundary_edges_per_vertex(&edges, &edge_label, mesh.vertex_count());
        BoundaryGraph {
            mesh,
            edges,
            edge_label,
            labels,
            vstart,
            vedges,
        }
    }

    fn is_boundary(&self, e: usize) -> bool {
        self.edge_label[e] != u32::MAX
    }

    /// Boundary edges at vertex `v`, ascending.
    fn vertex_edges(&self, v: u32) -> &[u32] {
        &self.vedges[self.vstart[v as usize] as usize..self.vstart[v as usize + 1] as usize]
    }

    /// The vertex of edge `e` that is not `v`.
    fn other_end(&self, e: u32, v: u32) -> u32 {
        let (a, b) = self.edges.keys[e as usize];
        if a == v {
            b
        } else {
            a
        }
    }

    /// The boundary vertices that are corners, and why: junctions, changes of adjacent
    /// groups, and turns sharper than the angle whose cosine is `cos_turn`.
    fn corners(&self, cos_turn: f64) -> BTreeMap<u32, CornerReason> {
        let mesh = self.mesh;
        let group_count = groups_per_vertex(mesh);
        let mut corner_reason: BTreeMap<u32, CornerReason> = BTreeMap::new();
        for v in 0..mesh.vertex_count() as u32 {
            let es = self.vertex_edges(v);
            if es.is_empty() {
                continue;
            }
            let reason = if es.len() != 2 || group_count[v as usize] >= 3 {
                Some(CornerReason::Junction)
            } else if self.edge_label[es[0] as usize] != self.edge_label[es[1] as usize] {
                Some(CornerReason::GroupChange)
            } else {
                let p = mesh.positions[v as usize];
                let a = mesh.positions[self.other_end(es[0], v) as usize];
                let b = mesh.positions[self.other_end(es[1], v) as usize];
                let (din, dout) = ((p - a).normalize_or_zero(), (b - p).normalize_or_zero());
                (din.dot(dout) < cos_turn).then_some(CornerReason::SharpTurn)
            };
            if let Some(r) = reason {
                corner_reason.insert(v, r);
            }
        }
        corner_reason
    }

    /// Vertices of the boundary polyline that leaves `start` along edge `first` and runs
    /// to the next corner (or, on a corner-less loop, back to `start`), marking its edges
    /// visited.
    fn walk(
        &self,
        start: u32,
        first: u32,
        visited: &mut [bool],
        corner_reason: &BTreeMap<u32, CornerReason>,
    ) -> Vec<u32> {
        let mut verts = vec![start];
        let (mut v, mut e) = (start, first);
        loop {
            visited[e as usize] = true;
            let w = self.other_end(e, v);
            verts.push(w);
            if corner_reason.contains_key(&w) {
                break;
            }
            // A non-corner vertex has exactly two boundary edges.
            let es = self.vertex_edges(w);
            let next = if es[0] == e { es[1] } else { es[0] };
            if visited[next as usize] {
                break; // closed loop back to its start (only for corner-less loops)
            }
            v = w;
            e = next;
        }
        verts
    }

    /// The polylines of all boundary edges, each running between two distinct corners;
    /// corners are added to `corner_reason` where loops had to be cut.
    fn polylines(&self, corner_reason: &mut BTreeMap<u32, CornerReason>) -> Vec<Vec<u32>> {
        let mut visited = vec![false; self.edges.len()];
        let mut pending: Vec<Vec<u32>> = Vec::new();
        let corner_list: Vec<u32> = corner_reason.keys().copied().collect();
        for &c in &corner_list {
            for &e in self.vertex_edges(c) {
                if !visited[e as usize] {
                    pending.push(self.walk(c, e, &mut visited, corner_reason));
                }
            }
        }
        self.cut_cornerless_loops(&mut visited, corner_reason, &mut pending);
        cut_self_closing(pending, corner_reason)
    }

    /// Walks the closed loops that no corner walk reached and cuts each at its lowest
    /// vertex and at the vertex half-way round (both become corners), appending the two
    /// halves to `pending`.
    fn cut_cornerless_loops(
        &self,
        visited: &mut [bool],
        corner_reason: &mut BTreeMap<u32, CornerReason>,
        pending: &mut Vec<Vec<u32>>,
    ) {
        for e0 in 0..self.edges.len() {
            if !self.is_boundary(e0) || visited[e0] {
                continue;
            }
            let (a, _) = self.edges.keys[e0];
            let mut loop_verts = self.walk(a, e0 as u32, visited, corner_reason);
            loop_verts.pop(); // last == first
            let n = loop_verts.len();
            let (imin, _) = loop_verts
                .iter()
                .enumerate()
                .min_by_key(|(_, &v)| v)
                .unwrap_or((0, &a));
            loop_verts.rotate_left(imin);
            let half = n / 2;
            corner_reason.insert(loop_verts[0], CornerReason::LoopSplit);
            corner_reason.insert(loop_verts[half], CornerReason::LoopSplit);
            pending.push(loop_verts[..=half].to_vec());
            let mut second = loop_verts[half..].to_vec();
            second.push(loop_verts[0]);
            pending.push(second);
        }
    }

    /// One chain per polyline, with its edges' label and a Douglas-Peucker control polygon
    /// within `tol`.
    fn chains(&self, polylines: Vec<Vec<u32>>, tol: f64) -> Result<Vec<Chain>> {
        let mut chains: Vec<Chain> = Vec::with_capacity(polylines.len());
        for verts in polylines {
            let e = self
                .edges
                .find(verts[0], verts[1])
                .ok_or_else(|| Error::Mesh("internal: chain edge not found".into()))?;
            let (groups, open) = self.labels[self.edge_label[e] as usize].clone();
            let pts: Vec<DVec3> = verts
                .iter()
                .map(|&v| self.mesh.positions[v as usize])
                .collect();
            let control = douglas_peucker(&pts, tol);
            chains.push(Chain {
                vertices: verts,
                groups,
                open_boundary: open,
                control,
            });
        }
        Ok(chains)
    }

    /// Per edge: the chain it belongs to and its position in that chain, `(u32::MAX, 0)`
    /// for edges in no chain. Maps group boundary cycles onto chains.
    fn edge_chains(&self, chains: &[Chain]) -> Vec<(u32, u32)> {
        let mut edge_chain = vec![(u32::MAX, 0u32); self.edges.len()];
        for (ci, c) in chains.iter().enumerate() {
            for (i, w) in c.vertices.windows(2).enumerate() {
                if let Some(e) = self.edges.find(w[0], w[1]) {
                    edge_chain[e] = (ci as u32, i as u32);
                }
            }
        }
        edge_chain
    }
}

/// Traces every group's boundary half-edges into cycles (rotating around each vertex
/// inside the group to find the successor, which is exact even where a group touches
/// itself at a vertex) and expresses each cycle as a sequence of chains.
fn build_group_loops(
    mesh: &ControlMesh,
    edges: &EdgeTable,
    edge_label: &[u32],
    edge_chain: &[(u32, u32)],
    chains: &[Chain],
) -> Result<Vec<GroupLoops>> {
    // Chain end points, for finding a cycle position where a chain starts.
    let mut is_end = std::collections::BTreeSet::new();
    for c in chains {
        is_end.insert(c.start());
        is_end.insert(c.end());
    }
    let half_edges = HalfEdges::new(mesh, edges, edge_label);
    let nh = mesh.face_vertices.len();
    let mut visited = vec![false; nh];
    let mut traced: Vec<Vec<TracedLoop>> = vec![Vec::new(); mesh.groups.len()];
    for h0 in 0..nh {
        if visited[h0] || !half_edges.is_boundary(h0) {
            continue;
        }
        let g = mesh.face_groups[half_edges.face_of[h0] as usize] as usize;
        let mut cycle = half_edges.trace_cycle(h0, g, &mut visited)?;
        // Start the cycle where a chain starts.
        let Some(s) = cycle
            .iter()
            .position(|&h| is_end.contains(&half_edges.tail(h)))
        else {
            return Err(Error::Mesh(format!(
                "boundary loop of group {g} passes no corner"
            )));
        };
        cycle.rotate_left(s);
        let (loop_chains, length) = half_edges.loop_chains(&cycle, g, edge_chain, chains)?;
        traced[g].push(TracedLoop {
            chains: loop_chains,
            length,
            area: half_edges.vector_area(&cycle),
        });
    }
    let (normal, total) = group_area_vectors(mesh);
    Ok(traced
        .into_iter()
        .enumerate()
        .map(|(g, loops)| order_loops(loops, normal[g], total[g]))
        .collect())
}

/// One traced boundary loop of a group, with what orders it among the group's loops.
#[derive(Clone)]
struct TracedLoop {
    chains: Vec<LoopChain>,
    length: f64,
    /// Vector area of the loop polygon.
    area: DVec3,
}

/// Per group: the sum of its faces' vector areas and the sum of their areas. The two have
/// (nearly) equal length only for a (nearly) planar group.
fn group_area_vectors(mesh: &ControlMesh) -> (Vec<DVec3>, Vec<f64>) {
    let ng = mesh.groups.len();
    let mut normal = vec![DVec3::ZERO; ng];
    let mut total = vec![0.0; ng];
    for f in 0..mesh.face_count() {
        let face = mesh.face(f);
        let mut n = DVec3::ZERO;
        for i in 0..face.len() {
            let p = mesh.positions[face[i] as usize];
            let q = mesh.positions[face[(i + 1) % face.len()] as usize];
            n += p.cross(q);
        }
        let g = mesh.face_groups[f] as usize;
        normal[g] += 0.5 * n;
        total[g] += 0.5 * n.length();
    }
    (normal, total)
}

/// Orders one group's loops as [`GroupLoops`] documents: by signed area about the group
/// normal for a planar group (outer loop first), else by length; ties keep tracing order.
fn order_loops(loops: Vec<TracedLoop>, normal: DVec3, total: f64) -> GroupLoops {
    let planar = normal.length() >= 0.99 * total && total > 0.0;
    let axis = normal.normalize_or_zero();
    let key = |i: usize| {
        if planar {
            loops[i].area.dot(axis)
        } else {
            loops[i].length
        }
    };
    let mut order: Vec<usize> = (0..loops.len()).collect();
    order.sort_by(|&a, &b| key(b).total_cmp(&key(a)).then(a.cmp(&b)));
    GroupLoops {
        loops: order.iter().map(|&i| loops[i].chains.clone()).collect(),
    }
}

/// The mesh's half-edges (id = face corner index `face_offsets[f] + i`, running from that
/// corner to the next one of the face) and the group boundary among them.
struct HalfEdges<'a> {
    mesh: &'a ControlMesh,
    edges: &'a EdgeTable,
    edge_label: &'a [u32],
    /// Face of every half-edge.
    face_of: Vec<u32>,
}

impl<'a> HalfEdges<'a> {
    fn new(mesh: &'a ControlMesh, edges: &'a EdgeTable, edge_label: &'a [u32]) -> Self {
        let mut face_of = vec![0u32; mesh.face_vertices.len()];
        for f in 0..mesh.face_count() {
            for h in mesh.face_offsets[f]..mesh.face_offsets[f + 1] {
                face_of[h as usize] = f as u32;
            }
        }
        HalfEdges {
            mesh,
            edges,
            edge_label,
            face_of,
        }
    }

    fn edge_of(&self, h: usize) -> usize {
        self.edges.face_edge[h] as usize
    }

    /// True when half-edge `h` lies on its group's boundary.
    fn is_boundary(&self, h: usize) -> bool {
        self.edge_label[self.edge_of(h)] != u32::MAX
    }

    /// The vertex half-edge `h` starts at.
    fn tail(&self, h: usize) -> u32 {
        self.mesh.face_vertices[h]
    }

    /// The vertex half-edge `h` ends at, and the half-edge of the same face leaving it.
    fn head(&self, h: usize) -> (u32, usize) {
        let mesh = self.mesh;
        let f = self.face_of[h] as usize;
        let (s, e) = (
            mesh.face_offsets[f] as usize,
            mesh.face_offsets[f + 1] as usize,
        );
        let next = if h + 1 == e { s } else { h + 1 };
        (mesh.face_vertices[next], next)
    }

    /// The next boundary half-edge of the group after `h`, found by rotating around the
    /// head of `h` through the group's faces.
    fn successor(&self, h: usize) -> Result<usize> {
        let mesh = self.mesh;
        let (b, mut cur) = self.head(h);
        // A vertex is surrounded by at most all faces: bounds the walk on broken input.
        for _ in 0..=mesh.face_count() {
            let e = self.edge_of(cur);
            if self.edge_label[e] != u32::MAX {
                return Ok(cur);
            }
            // Interior edge of the group: continue in the other face around b.
            let f = self.face_of[cur];
            let Some(&(g, gi)) = self.edges.faces(e).iter().find(|&&(g, _)| g != f) else {
                break;
            };
            let gs = mesh.face_offsets[g as usize] as usize;
            let gk = mesh.face(g as usize).len();
            let nxt = gs + (gi as usize + 1) % gk;
            if mesh.face_vertices[nxt] != b {
                return Err(Error::Mesh(format!(
                    "faces {f} and {g} of group {} are inconsistently oriented",
                    mesh.face_groups[f as usize]
                )));
            }
            cur = nxt;
        }
        Err(Error::Mesh(format!(
            "cannot walk around vertex {b} inside its group"
        )))
    }

    /// The boundary cycle of group `g` through half-edge `h0`, marking its half-edges
    /// visited; errors if the walk runs into another cycle or does not close.
    fn trace_cycle(&self, h0: usize, g: usize, visited: &mut [bool]) -> Result<Vec<usize>> {
        let nh = visited.len();
        let mut cycle = Vec::new();
        let mut h = h0;
        loop {
            if visited[h] {
                if h == h0 {
                    break;
                }
                return Err(Error::Mesh(format!(
                    "boundary of group {g} is not a set of simple cycles"
                )));
            }
            visited[h] = true;
            cycle.push(h);
            h = self.successor(h)?;
            if cycle.len() > nh {
                return Err(Error::Mesh(format!(
                    "boundary walk of group {g} does not close"
                )));
            }
        }
        Ok(cycle)
    }

    /// The chains that `cycle` (starting where a chain starts) runs through, in order, and
    /// the cycle's length; errors if the cycle enters or leaves a chain part-way.
    fn loop_chains(
        &self,
        cycle: &[usize],
        g: usize,
        edge_chain: &[(u32, u32)],
        chains: &[Chain],
    ) -> Result<(Vec<LoopChain>, f64)> {
        let positions = &self.mesh.positions;
        let mut lp: Vec<LoopChain> = Vec::new();
        let mut length = 0.0;
        let mut i = 0;
        while i < cycle.len() {
            let h = cycle[i];
            let (ci, _) = edge_chain[self.edge_of(h)];
            if ci == u32::MAX {
                return Err(Error::Mesh(format!("group {g}: boundary edge in no chain")));
            }
            let c = &chains[ci as usize];
            let reversed = self.tail(h) != c.start();
            let n = c.edge_count();
            // The next n half-edges must be this chain's edges, in order.
            for k in 0..n {
                let hk = cycle.get(i + k).copied().ok_or_else(|| {
                    Error::Mesh(format!("group {g}: loop ends inside chain {ci}"))
                })?;
                let pos = if reversed { n - 1 - k } else { k };
                let (a, b) = (c.vertices[pos], c.vertices[pos + 1]);
                let t = self.tail(hk);
                let expect = if reversed { b } else { a };
                if edge_chain[self.edge_of(hk)].0 != ci || t != expect {
                    return Err(Error::Mesh(format!(
                        "group {g}: loop leaves chain {ci} before its end"
                    )));
                }
                length += (positions[a as usize] - positions[b as usize]).length();
            }
            lp.push(LoopChain {
                chain: ci,
                reversed,
            });
            i += n;
        }
        Ok((lp, length))
    }

    /// Vector area of the polygon of `cycle` (for outer-loop detection).
    fn vector_area(&self, cycle: &[usize]) -> DVec3 {
        let positions = &self.mesh.positions;
        let mut area = DVec3::ZERO;
        for &h in cycle {
            let (b, _) = self.head(h);
            area += positions[self.tail(h) as usize].cross(positions[b as usize]);
        }
        0.5 * area
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::fit::test_support::{corpus_dir, grid_cube, load_corpus};
    use crate::mesh::PatchKind;

    /// Checks the structural invariants of a network against its mesh.
    pub(crate) fn check_network(mesh: &ControlMesh, net: &CurveNetwork, name: &str) {
        let edges = EdgeTable::new(mesh);
        let mut boundary = std::collections::BTreeSet::new();
        for e in 0..edges.len() {
            let fs = edges.faces(e);
            let g0 = mesh.face_groups[fs[0].0 as usize];
            if fs.len() != 2 || fs.iter().any(|&(f, _)| mesh.face_groups[f as usize] != g0) {
                boundary.insert(edges.keys[e]);
            }
        }
        let mut seen = std::collections::BTreeSet::new();
        for (ci, c) in net.chains.iter().enumerate() {
            assert!(c.vertices.len() >= 2, "{name}: chain {ci} too short");
            assert_ne!(c.start(), c.end(), "{name}: chain {ci} is closed");
            assert!(
                net.is_corner(c.start()) && net.is_corner(c.end()),
                "{name}: chain {ci} ends"
            );
            for &v in &c.vertices[1..c.vertices.len() - 1] {
                assert!(!net.is_corner(v), "{name}: corner {v} inside chain {ci}");
            }
            for w in c.vertices.windows(2) {
                let k = crate::mesh::edge_key(w[0], w[1]);
                assert!(
                    boundary.contains(&k),
                    "{name}: chain {ci} uses non-boundary edge"
                );
                assert!(seen.insert(k), "{name}: edge {k:?} in two chains");
            }
            // Control polygon keeps the ends and stays within tolerance.
            assert_eq!(c.control[0], 0);
            assert_eq!(*c.control.last().unwrap() as usize, c.vertices.len() - 1);
            let pts = net.chain_points(mesh, ci);
            let ctrl = net.control_points(mesh, ci);
            assert!(
                polyline_hausdorff(&ctrl, &pts) <= net.simplify_tolerance * (1.0 + 1e-9) + 1e-12,
                "{name}: control polygon of chain {ci} off tolerance"
            );
        }
        assert_eq!(seen, boundary, "{name}: boundary edges not all covered");
        // Loops: closed, each chain once per adjacent group.
        let mut uses: BTreeMap<(u32, u32), usize> = BTreeMap::new();
        for (g, gl) in net.group_loops.iter().enumerate() {
            for lp in &gl.loops {
                assert!(!lp.is_empty());
                let ends = |l: &LoopChain| {
                    let c = &net.chains[l.chain as usize];
                    if l.reversed {
                        (c.end(), c.start())
                    } else {
                        (c.start(), c.end())
                    }
                };
                for k in 0..lp.len() {
                    let (_, e) = ends(&lp[k]);
                    let (s, _) = ends(&lp[(k + 1) % lp.len()]);
                    assert_eq!(e, s, "{name}: loop of group {g} not closed");
                    *uses.entry((g as u32, lp[k].chain)).or_insert(0) += 1;
                }
            }
        }
        for (ci, c) in net.chains.iter().enumerate() {
            for &g in &c.groups {
                assert_eq!(
                    uses.get(&(g, ci as u32)),
                    Some(&1),
                    "{name}: chain {ci} group {g}"
                );
            }
        }
        assert_eq!(
            uses.values().sum::<usize>(),
            net.chains.iter().map(|c| c.groups.len()).sum::<usize>()
        );
    }

    #[test]
    fn cube_network() {
        let m = grid_cube(4);
        let net = build_curve_network(&m, &CurveOptions::default()).unwrap();
        assert_eq!(net.corners.len(), 8);
        assert!(net
            .corners
            .iter()
            .all(|c| c.reason == CornerReason::Junction));
        assert_eq!(net.chains.len(), 12);
        assert!(net
            .chains
            .iter()
            .all(|c| c.edge_count() == 4 && c.groups.len() == 2));
        // Straight edges simplify to their two corners.
        assert!(net.chains.iter().all(|c| c.control == vec![0, 4]));
        for gl in &net.group_loops {
            assert_eq!(gl.loops.len(), 1);
            assert_eq!(gl.loops[0].len(), 4);
        }
        check_network(&m, &net, "cube");
        // Two adjacent groups run a shared chain in opposite directions.
        let c0 = 0u32;
        let dirs: Vec<bool> = net
            .group_loops
            .iter()
            .flat_map(|gl| gl.loops.iter().flatten())
            .filter(|l| l.chain == c0)
            .map(|l| l.reversed)
            .collect();
        assert_eq!(dirs.len(), 2);
        assert_ne!(dirs[0], dirs[1]);
    }

    #[test]
    fn corner_less_loops_and_open_boundaries() {
        // An open tube (no caps) of two groups split along a circle: three closed loops
        // without corners (two open rims + the circle between the groups), each cut at two
        // corners.
        let mut m = ControlMesh::new();
        let k = 12;
        for ring in 0..3 {
            for i in 0..k {
                let t = i as f64 / k as f64 * std::f64::consts::TAU;
                m.push_vertex(DVec3::new(t.cos(), t.sin(), ring as f64));
            }
        }
        let g0 = m.push_group("a", PatchKind::Closed);
        let g1 = m.push_group("b", PatchKind::Closed);
        for ring in 0..2u32 {
            for i in 0..k as u32 {
                let j = (i + 1) % k as u32;
                let (a, b) = (ring * k as u32 + i, ring * k as u32 + j);
                let (c, d) = (a + k as u32, b + k as u32);
                let g = if ring == 0 { g0 } else { g1 };
                m.push_face(&[a, b, d], g);
                m.push_face(&[a, d, c], g);
            }
        }
        let net = build_curve_network(&m, &CurveOptions::default()).unwrap();
        assert_eq!(net.corners.len(), 6);
        assert!(net
            .corners
            .iter()
            .all(|c| c.reason == CornerReason::LoopSplit));
        assert_eq!(net.chains.len(), 6);
        assert_eq!(net.chains.iter().filter(|c| c.open_boundary).count(), 4);
        assert_eq!(net.group_loops[0].loops.len(), 2);
        check_network(&m, &net, "tube");
        // Sharp turns: a square rim needs corners at its four turns.
        let sq = grid_cube(3);
        let mut one = sq.clone();
        // Drop the top side: its rim becomes an open boundary of the four walls.
        let keep: Vec<usize> = (0..one.face_count())
            .filter(|&f| one.face_groups[f] != 1)
            .collect();
        let mut open = ControlMesh::new();
        open.positions = one.positions.clone();
        open.groups = one.groups.clone();
        for f in keep {
            let face = one.face(f).to_vec();
            open.push_face(&face, one.face_groups[f]);
        }
        one = open;
        let net = build_curve_network(&one, &CurveOptions::default()).unwrap();
        check_network(&one, &net, "open box");
        assert_eq!(net.corners.len(), 8);
    }

    #[test]
    fn planar_face_with_hole_outer_loop_first() {
        // A 4 x 4 plate without its central 2 x 2 quads: one planar group, two open
        // boundary loops; the outer loop must come first and run counter-clockwise.
        let mut m = ControlMesh::new();
        for j in 0..5 {
            for i in 0..5 {
                m.push_vertex(DVec3::new(i as f64, j as f64, 0.0));
            }
        }
        let g = m.push_group("plate", PatchKind::Closed);
        let id = |i: u32, j: u32| j * 5 + i;
        for j in 0..4 {
            for i in 0..4 {
                if (1..3).contains(&i) && (1..3).contains(&j) {
                    continue;
                }
                m.push_face(&[id(i, j), id(i + 1, j), id(i + 1, j + 1)], g);
                m.push_face(&[id(i, j), id(i + 1, j + 1), id(i, j + 1)], g);
            }
        }
        let net = build_curve_network(&m, &CurveOptions::default()).unwrap();
        check_network(&m, &net, "plate");
        let loops = &net.group_loops[0].loops;
        assert_eq!(loops.len(), 2);
        let verts = |lp: &Vec<LoopChain>| -> Vec<u32> {
            lp.iter()
                .flat_map(|l| net.chains[l.chain as usize].vertices.clone())
                .collect()
        };
        assert!(verts(&loops[0]).contains(&id(0, 0)));
        assert!(verts(&loops[1]).contains(&id(1, 1)));
        // Square corners are sharp turns (90 degrees > 60).
        assert!(net
            .corners
            .iter()
            .any(|c| c.vertex == id(4, 4) && c.reason == CornerReason::SharpTurn));
    }

    #[test]
    fn douglas_peucker_bounds() {
        let pts: Vec<DVec3> = (0..100)
            .map(|i| {
                let t = i as f64 / 99.0 * std::f64::consts::PI;
                DVec3::new(t.cos(), t.sin(), 0.0)
            })
            .collect();
        for tol in [1e-1, 1e-2, 1e-4] {
            let keep = douglas_peucker(&pts, tol);
            let sub: Vec<DVec3> = keep.iter().map(|&i| pts[i as usize]).collect();
            assert!(polyline_hausdorff(&sub, &pts) <= tol);
            assert_eq!(keep[0], 0);
            assert_eq!(*keep.last().unwrap(), 99);
        }
        assert!(douglas_peucker(&pts, 1e-1).len() < douglas_peucker(&pts, 1e-4).len());
        // The seam: polyline stand-in error equals the polyline distance.
        let e = chain_fit_error(&[pts[0], pts[99]], &pts, &PolylineCurve);
        assert!((e - 1.0).abs() < 1e-3);
    }

    #[test]
    fn corpus_networks() {
        let Some(dir) = corpus_dir() else {
            eprintln!("corpus not found; skipping");
            return;
        };
        let mut names: Vec<String> = Vec::new();
        for sub in ["tess", "abc"] {
            for e in std::fs::read_dir(dir.join(sub)).unwrap().flatten() {
                let n = e.file_name().to_string_lossy().to_string();
                if n.ends_with("_coarse.obj")
                    || n.ends_with("_cadexport.obj")
                    || (sub == "abc" && n.ends_with(".obj"))
                {
                    names.push(format!("{sub}/{n}"));
                }
            }
        }
        names.sort();
        assert!(names.len() >= 19);
        for name in names {
            let Some(m) = load_corpus(&name) else { return };
            let t = std::time::Instant::now();
            let net = build_curve_network(&m, &CurveOptions::default()).unwrap();
            let dt = t.elapsed();
            check_network(&m, &net, &name);
            let loops: usize = net.group_loops.iter().map(|g| g.loops.len()).sum();
            let multi = net.group_loops.iter().filter(|g| g.loops.len() > 1).count();
            let none = net
                .group_loops
                .iter()
                .filter(|g| g.loops.is_empty())
                .count();
            let splits = net
                .corners
                .iter()
                .filter(|c| c.reason == CornerReason::LoopSplit)
                .count();
            let ctrl: usize = net.chains.iter().map(|c| c.control.len() - 1).sum();
            println!(
                "{name}: {} groups, {} corners ({} loop splits), {} chains, {} chain edges -> {} control edges, {} loops ({} groups with holes/multiple loops, {} without boundary) [{:?}]",
                m.groups.len(), net.corners.len(), splits, net.chains.len(), net.edge_count(), ctrl, loops, multi, none, dt
            );
        }
    }
}
