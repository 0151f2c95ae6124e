//! Constrained edge-collapse decimation of a grouped triangle mesh: the step that turns a
//! dense CAD tessellation into the topology of a coarse control mesh.
//!
//! [`decimate`] takes the whole model as *one* mesh, so a boundary chain shared by two CAD
//! faces is simplified once for both: the control mesh is watertight by construction. The
//! encoder's rounds use [`FaceDecimator`], which decimates each face on its own with the same
//! rules (and joins the faces' chains), so a round redoes only the faces that changed; the
//! one-mesh version is its fallback when the faces' results do not join. Collapses are
//! half-edge collapses `u -> v` (the survivor keeps its input position, which lies on the
//! CAD surface and is the starting point of the fit). What may collapse is decided by each
//! vertex's [`VertexRole`] and each group's [`GroupRule`]:
//!
//! * chain vertices that were not chosen as control points slide along their chain only;
//! * interior vertices of boundary patches (planes, cylinders, cones) are all removed if at
//!   all possible (a boundary patch has no interior control vertices);
//! * interior vertices of closed patches are removed while the quadric error stays below the
//!   group's threshold.
//!
//! Every collapse keeps the mesh manifold (link condition) and keeps triangles facing the
//! way the CAD surface faces (analytic normal for boundary patches, previous normal for
//! closed ones); framed patches also keep every edge within an angular span about the axis,
//! as the cylinder/cone subdivision rule requires (spec/subdivision.md §5).
//! Ties are broken by vertex index, so the result is deterministic.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::DVec3;

use super::domain::PlaneDomain;
use crate::mesh::Axis;

mod by_face;
pub(crate) use by_face::{FaceDecimation, FaceDecimator};

/// What decimation may do with a vertex.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VertexRole {
    /// Never removed: B-rep corners, chosen chain control points.
    Keep,
    /// On a boundary chain but not a control point: removed by sliding onto a chain neighbour.
    ChainDrop,
    /// Strictly inside one group: removable onto any neighbour.
    Interior,
}

/// The surface a group approximates, as far as collapse validity is concerned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SurfaceRef {
    Plane {
        normal: DVec3,
    },
    Cylinder {
        axis: Axis,
    },
    Cone {
        axis: Axis,
    },
    Sphere {
        center: DVec3,
    },
    Torus {
        axis: Axis,
        major_radius: f64,
    },
    /// Freeform: triangles are compared with their normal before the collapse.
    Free,
}

impl SurfaceRef {
    /// Unit normal of the analytic surface at `p` (up to sign), if there is one.
    fn normal_at(&self, p: DVec3) -> Option<DVec3> {
        match *self {
            SurfaceRef::Plane { normal } => Some(normal),
            SurfaceRef::Cylinder { axis } => {
                let d = p - axis.origin;
                let radial = d - axis.direction * d.dot(axis.direction);
                radial.try_normalize()
            }
            SurfaceRef::Cone { axis } => {
                let d = p - axis.origin;
                let h = d.dot(axis.direction);
                let q = d - axis.direction * h;
                let r = q.length();
                if h.abs() < 1e-300 || r < 1e-300 {
                    return None;
                }
                (q / r - axis.direction * (r / h)).try_normalize()
            }
            SurfaceRef::Sphere { center } => (p - center).try_normalize(),
            SurfaceRef::Torus { axis, major_radius } => {
                let d = p - axis.origin;
                let radial = (d - axis.direction * d.dot(axis.direction)).try_normalize()?;
                (p - axis.origin - radial * major_radius).try_normalize()
            }
            SurfaceRef::Free => None,
        }
    }

    /// The angle a control edge from `a` to `b` spans in the surface's angular
    /// coordinates (the largest, for a torus), which the decoder's unwrapping needs well
    /// below 180 degrees; `None` for surfaces without angles.
    fn edge_angle(&self, a: DVec3, b: DVec3) -> Option<f64> {
        match *self {
            SurfaceRef::Cylinder { axis } | SurfaceRef::Cone { axis } => {
                Some(angle_about(&axis, a, b))
            }
            SurfaceRef::Sphere { center } => Some(angle_between(a - center, b - center)),
            SurfaceRef::Torus { axis, major_radius } => {
                let spine = |p: DVec3| {
                    let d = p - axis.origin;
                    let radial = d - axis.direction * d.dot(axis.direction);
                    p - axis.origin - radial.normalize_or_zero() * major_radius
                };
                Some(angle_about(&axis, a, b).max(angle_between(spine(a), spine(b))))
            }
            SurfaceRef::Plane { .. } | SurfaceRef::Free => None,
        }
    }
}

/// Angle between two vectors; 0 when one is zero.
fn angle_between(a: DVec3, b: DVec3) -> f64 {
    let (la, lb) = (a.length(), b.length());
    if la < 1e-300 || lb < 1e-300 {
        return 0.0;
    }
    (a.dot(b) / (la * lb)).clamp(-1.0, 1.0).acos()
}

/// Per-group decimation policy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroupRule {
    /// Boundary patch: every interior vertex should go (cost is ignored).
    pub remove_all_interior: bool,
    /// Closed patch: largest allowed mean squared distance (model units squared) between a
    /// collapsed vertex and the input planes it stands for.
    pub max_cost: f64,
    pub surface: SurfaceRef,
    /// Framed patches: largest angle (radians) an edge may span about the axis.
    pub max_edge_angle: f64,
}

/// A triangle mesh to decimate. `roles` and `face_groups` index `positions`/`triangles`.
pub struct DecimateInput<'a> {
    pub positions: &'a [DVec3],
    pub triangles: &'a [[u32; 3]],
    pub face_groups: &'a [u32],
    pub roles: &'a [VertexRole],
    pub rules: &'a [GroupRule],
    /// Per input vertex, a factor on its closed patch's `max_cost` (1 everywhere when
    /// `None`): the encoder lowers it where the decoded surface was too far off, so a patch
    /// gets control points where its error is instead of everywhere.
    pub cost_scale: Option<&'a [f64]>,
    /// Per group, where a plane face lies in its plane: a collapse in a plane patch may not
    /// create an interior edge that leaves it (a long diagonal of a curved strip, or one
    /// across a hole, cuts outside the face, and a plane's interior edges stay straight).
    pub domain: Option<&'a [Option<PlaneDomain>]>,
}

/// The decimated mesh, still indexing the input's vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct Decimated {
    /// Surviving triangles (input vertex ids) with their groups, in input face order.
    pub triangles: Vec<[u32; 3]>,
    pub face_groups: Vec<u32>,
    /// Surviving vertices, ascending.
    pub vertices: Vec<u32>,
}

/// Symmetric 4x4 quadric (Garland-Heckbert) with the total weight, stored as the 10 upper
/// coefficients: cheap to add, evaluates a mean squared plane distance.
#[derive(Clone, Copy, Debug, Default)]
struct Quadric {
    q: [f64; 10],
    weight: f64,
}

impl Quadric {
    fn plane(n: DVec3, d: f64, w: f64) -> Quadric {
        let (a, b, c) = (n.x, n.y, n.z);
        Quadric {
            q: [
                a * a * w,
                a * b * w,
                a * c * w,
                a * d * w,
                b * b * w,
                b * c * w,
                b * d * w,
                c * c * w,
                c * d * w,
                d * d * w,
            ],
            weight: w,
        }
    }
    fn add(&mut self, o: &Quadric) {
        for i in 0..10 {
            self.q[i] += o.q[i];
        }
        self.weight += o.weight;
    }
    /// Mean squared distance of `p` to the accumulated planes.
    fn eval(&self, p: DVec3) -> f64 {
        let q = &self.q;
        let (x, y, z) = (p.x, p.y, p.z);
        let v = q[0] * x * x
            + 2.0 * q[1] * x * y
            + 2.0 * q[2] * x * z
            + 2.0 * q[3] * x
            + q[4] * y * y
            + 2.0 * q[5] * y * z
            + 2.0 * q[6] * y
            + q[7] * z * z
            + 2.0 * q[8] * z
            + q[9];
        if self.weight > 0.0 {
            (v / self.weight).max(0.0)
        } else {
            0.0
        }
    }
}

/// Heap entry: lower `(class, cost)` first, ties by vertex id. A vertex's entry first holds
/// its cheapest collapse by [`State::cost`] alone, a lower bound of
/// its real cost (a collapse [`State::allowed`] forbids costs infinity): popping lower bounds
/// and re-queueing the real cost gives the same order as queueing real costs, for a fraction
/// of the validity tests. The heap holds at most a few entries per vertex.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    class: u8,
    cost: f64,
    u: u32,
    v: u32,
    stamp: u32,
}

impl Candidate {
    /// Integer sort key: costs are non-negative, so their bit patterns order like the values.
    fn key(&self) -> (u8, u64, u32, u32) {
        let cost = if self.cost > 0.0 {
            self.cost.to_bits()
        } else {
            0
        };
        (self.class, cost, self.u, self.v)
    }
}

impl PartialEq for Candidate {
    fn eq(&self, o: &Self) -> bool {
        self.key() == o.key()
    }
}
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Candidate {
    // Reversed so that BinaryHeap (a max-heap) pops the smallest.
    fn cmp(&self, o: &Self) -> Ordering {
        o.key().cmp(&self.key())
    }
}

/// Reused neighbour lists, so the inner loop does not allocate.
#[derive(Default)]
struct Scratch {
    nu: Vec<u32>,
    nv: Vec<u32>,
    ring: Vec<u32>,
    /// (neighbour, face holding both) pairs of one vertex as `neighbour << 32 | face`, sorted
    /// (one integer compares faster than a tuple, in the same order): its neighbours and every
    /// edge's faces from one pass over its faces.
    pairs: Vec<u64>,
}

struct State<'a> {
    input: &'a DecimateInput<'a>,
    tris: Vec<[u32; 3]>,
    alive: Vec<bool>,
    vfaces: Vec<Vec<u32>>,
    quadric: Vec<Quadric>,
    removed: Vec<bool>,
    stamp: Vec<u32>,
    /// On an edge with a single face. Collapses that pass the link condition never change
    /// this for surviving vertices, so it is computed once.
    open_boundary: Vec<bool>,
    min_area2: f64,
    /// [`DecimateInput::cost_scale`], the survivor of a collapse taking the smaller of the
    /// two (so a collapse over its limit stays over it).
    cost_scale: Vec<f64>,
}

fn tri_normal(p: [DVec3; 3]) -> DVec3 {
    (p[1] - p[0]).cross(p[2] - p[0])
}

/// Angle between the projections of `a` and `b` onto the plane perpendicular to the axis.
fn angle_about(axis: &Axis, a: DVec3, b: DVec3) -> f64 {
    let d = axis.direction;
    let qa = (a - axis.origin) - d * (a - axis.origin).dot(d);
    let qb = (b - axis.origin) - d * (b - axis.origin).dot(d);
    let (la, lb) = (qa.length(), qb.length());
    if la < 1e-300 || lb < 1e-300 {
        return 0.0; // a point on the axis (cone apex) has no angle
    }
    (qa.dot(qb) / (la * lb)).clamp(-1.0, 1.0).acos()
}

/// Each vertex's quadric (the planes of its triangles, weighted by area), and the doubled-
/// area floor below which a triangle counts as degenerate (relative to the mean area).
fn vertex_quadrics(positions: &[DVec3], triangles: &[[u32; 3]]) -> (Vec<Quadric>, f64) {
    let mut quadric = vec![Quadric::default(); positions.len()];
    let mut total_area = 0.0;
    for t in triangles {
        let p = t.map(|i| positions[i as usize]);
        let n2 = tri_normal(p);
        let area = 0.5 * n2.length();
        total_area += area;
        if let Some(n) = n2.try_normalize() {
            let q = Quadric::plane(n, -n.dot(p[0]), area);
            for &i in t {
                quadric[i as usize].add(&q);
            }
        }
    }
    let mean_area = total_area / triangles.len().max(1) as f64;
    (quadric, (2.0 * mean_area * 1e-8).powi(2))
}

/// Which vertices are on an edge with a single triangle.
fn open_boundary(nv: usize, triangles: &[[u32; 3]]) -> Vec<bool> {
    let mut edges: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))))
        .collect();
    edges.sort_unstable();
    let mut open = vec![false; nv];
    for run in edges.chunk_by(|a, b| a == b) {
        if run.len() == 1 {
            open[run[0].0 as usize] = true;
            open[run[0].1 as usize] = true;
        }
    }
    open
}

impl<'a> State<'a> {
    fn new(input: &'a DecimateInput<'a>) -> Self {
        let nv = input.positions.len();
        let mut vfaces = vec![Vec::new(); nv];
        for (f, t) in input.triangles.iter().enumerate() {
            for &i in t {
                vfaces[i as usize].push(f as u32);
            }
        }
        let (quadric, min_area2) = vertex_quadrics(input.positions, input.triangles);
        State {
            input,
            tris: input.triangles.to_vec(),
            alive: vec![true; input.triangles.len()],
            vfaces,
            quadric,
            removed: vec![false; nv],
            stamp: vec![0; nv],
            open_boundary: open_boundary(nv, input.triangles),
            min_area2,
            cost_scale: input
                .cost_scale
                .map_or_else(|| vec![1.0; nv], |s| s.to_vec()),
        }
    }

    fn pos(&self, v: u32) -> DVec3 {
        self.input.positions[v as usize]
    }

    /// The vertices sharing a face with `u`, sorted, into `out`.
    fn neighbours_into(&self, u: u32, out: &mut Vec<u32>) {
        out.clear();
        for &f in &self.vfaces[u as usize] {
            out.extend(self.tris[f as usize].iter().filter(|&&w| w != u));
        }
        out.sort_unstable();
        out.dedup();
    }

    /// Number of faces containing both `u` and `v`, and the first two of them.
    fn edge_faces(&self, u: u32, v: u32) -> (usize, [u32; 2]) {
        let mut count = 0;
        let mut first = [u32::MAX; 2];
        for &f in &self.vfaces[u as usize] {
            if self.tris[f as usize].contains(&v) {
                if count < 2 {
                    first[count] = f;
                }
                count += 1;
            }
        }
        (count, first)
    }

    /// Whether edge (u, w) has one face or faces in two groups.
    fn edge_on_group_boundary(&self, u: u32, w: u32) -> bool {
        let (n, f) = self.edge_faces(u, w);
        n == 1
            || (n == 2
                && self.input.face_groups[f[0] as usize] != self.input.face_groups[f[1] as usize])
    }

    /// Whether collapsing `u` onto `v` turns face `f` (corners `t`, holding `u`, not `v`) of a
    /// closed patch into an *ear along a chain*: a triangle whose corners are all on the
    /// patch boundary and one of which, `w`, keeps this triangle as its only face in the
    /// group while the boundary runs nearly straight through it (angle at `w` above 120
    /// degrees, so `w` is no corner of the patch). Such a triangle has no interior control
    /// point and its two boundary edges are one smooth crease: its subdivision surface sags
    /// from the chain towards the opposite edge (trj6_fine: a cone strip whose side chain
    /// vertex slides onto a corner fans out to three consecutive vertices of the bottom chain
    /// and stays 3x over the tolerance however many control points are added elsewhere).
    fn leaves_ear(&self, u: u32, v: u32, t: [u32; 3], f: u32) -> bool {
        let g = self.input.face_groups[f as usize];
        let rule = &self.input.rules[g as usize];
        if rule.remove_all_interior {
            return false;
        }
        let new = t.map(|i| if i == u { v } else { i });
        if new
            .iter()
            .any(|&w| self.input.roles[w as usize] == VertexRole::Interior)
        {
            return false;
        }
        // Faces of group g at `w` after the collapse (faces holding both u and v vanish;
        // u's other faces move to v).
        let faces_after = |w: u32| -> usize {
            let here = |x: u32| {
                self.vfaces[x as usize].iter().filter(move |&&h| {
                    let th = self.tris[h as usize];
                    self.input.face_groups[h as usize] == g && !(th.contains(&u) && th.contains(&v))
                })
            };
            if w == v {
                here(v).count()
                    + here(u)
                        .filter(|&&h| !self.tris[h as usize].contains(&v))
                        .count()
            } else {
                here(w).count()
            }
        };
        (0..3).any(|k| {
            let w = new[k];
            if faces_after(w) != 1 {
                return false;
            }
            let pw = self.pos(w);
            let (a, b) = (
                self.pos(new[(k + 1) % 3]) - pw,
                self.pos(new[(k + 2) % 3]) - pw,
            );
            let (la, lb) = (a.length(), b.length());
            la > 0.0 && lb > 0.0 && a.dot(b) / (la * lb) < -0.5
        })
    }

    /// Cost class and cost of collapsing `u` onto `v` from what is cheap to know (roles,
    /// the edge's faces, the quadrics), or `None` when that already forbids it. The costly
    /// checks are in [`State::allowed`], done only when the candidate reaches the top of the
    /// queue.
    fn cost(&self, u: u32, v: u32) -> Option<(u8, f64)> {
        let (edge_len, edge) = self.edge_faces(u, v);
        self.cost_on_edge(u, v, edge_len, edge)
    }

    /// [`State::cost`] with the edge's face count and first two faces already known.
    fn cost_on_edge(&self, u: u32, v: u32, edge_len: usize, edge: [u32; 2]) -> Option<(u8, f64)> {
        let role = self.input.roles[u as usize];
        if edge_len == 0 || edge_len > 2 {
            return None;
        }
        let class = match role {
            VertexRole::Keep => return None,
            VertexRole::ChainDrop => {
                // Only along a group boundary: the edge's faces are in different groups, or
                // it has a single face.
                let group_boundary = edge_len == 1
                    || self.input.face_groups[edge[0] as usize]
                        != self.input.face_groups[edge[1] as usize];
                if !group_boundary {
                    return None;
                }
                0
            }
            VertexRole::Interior => {
                let g = self.input.face_groups[self.vfaces[u as usize][0] as usize];
                if self.input.rules[g as usize].remove_all_interior {
                    1
                } else {
                    2
                }
            }
        };
        // A vertex on the open boundary must not be pulled onto an interior edge's end.
        if edge_len == 2 && self.open_boundary[u as usize] && self.open_boundary[v as usize] {
            return None;
        }
        let pv = self.pos(v);
        let cost = match class {
            2 => {
                let mut q = self.quadric[u as usize];
                q.add(&self.quadric[v as usize]);
                let c = q.eval(pv);
                let g = self.input.face_groups[self.vfaces[u as usize][0] as usize];
                // Quadrics only grow, so a collapse over the threshold stays over it.
                let scale = self.cost_scale[u as usize].min(self.cost_scale[v as usize]);
                if c > self.input.rules[g as usize].max_cost * scale {
                    return None;
                }
                c
            }
            // Boundary-patch interiors and chain slides: shortest edges first keeps
            // triangles well shaped.
            _ => (pv - self.pos(u)).length_squared(),
        };
        Some((class, cost))
    }

    /// Whether collapsing `u` onto `v` keeps the mesh manifold and well shaped: the link
    /// condition, no flipped or degenerate triangles, framed edges within their angle, no
    /// ear along a chain. `nu` are `u`'s neighbours (sorted); `scratch` is reused for `v`'s.
    fn allowed(&self, u: u32, v: u32, nu: &[u32], scratch: &mut Vec<u32>) -> bool {
        let (edge_len, _) = self.edge_faces(u, v);
        // Link condition: the common neighbours of u and v are exactly the vertices
        // opposite the edge.
        self.neighbours_into(v, scratch);
        let common = scratch
            .iter()
            .filter(|w| nu.binary_search(w).is_ok())
            .count();
        if common != edge_len {
            return false;
        }
        let pv = self.pos(v);
        for &f in &self.vfaces[u as usize] {
            let t = self.tris[f as usize];
            if t.contains(&v) {
                continue;
            }
            if self.leaves_ear(u, v, t, f) {
                return false;
            }
            let old = t.map(|i| self.pos(i));
            let new = t.map(|i| if i == u { pv } else { self.pos(i) });
            let n_old = tri_normal(old);
            let n_new = tri_normal(new);
            if n_new.length_squared() <= self.min_area2 {
                return false;
            }
            let group = self.input.face_groups[f as usize];
            let rule = &self.input.rules[group as usize];
            let centroid = (new[0] + new[1] + new[2]) / 3.0;
            match rule.surface.normal_at(centroid) {
                Some(s) => {
                    let c_old = (old[0] + old[1] + old[2]) / 3.0;
                    let s_old = rule.surface.normal_at(c_old).unwrap_or(s);
                    let sign = n_old.dot(s_old).signum();
                    if sign * n_new.normalize().dot(s) < 0.3 {
                        return false;
                    }
                }
                None => {
                    if n_old.length_squared() > self.min_area2
                        && n_new.normalize().dot(n_old.normalize()) < 0.5
                    {
                        return false;
                    }
                }
            }
            for &w in t.iter().filter(|&&w| w != u) {
                let spans = rule.surface.edge_angle(pv, self.pos(w));
                if spans.is_some_and(|a| a > rule.max_edge_angle) {
                    return false;
                }
            }
            // Last: the cheaper tests above reject most collapses first.
            if let (Some(domains), SurfaceRef::Plane { .. }) = (self.input.domain, rule.surface) {
                if let Some(Some(domain)) = domains.get(group as usize) {
                    for &w in &t {
                        if w == u || self.edge_on_group_boundary(u, w) {
                            continue;
                        }
                        let pw = self.pos(w);
                        let off = [0.25, 0.5, 0.75]
                            .iter()
                            .any(|&s| !domain.contains(pv + (pw - pv) * s));
                        if off {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }

    /// The cheapest collapse of `u` by [`State::cost`] alone, or, with
    /// `check`, the cheapest one [`State::allowed`] also allows.
    fn best_candidate(&self, u: u32, check: bool, scratch: &mut Scratch) -> Option<Candidate> {
        if self.removed[u as usize] || self.input.roles[u as usize] == VertexRole::Keep {
            return None;
        }
        let Scratch { nu, nv, pairs, .. } = scratch;
        // One pass over u's faces gives its neighbours (as `neighbours_into`) and each
        // edge's faces (as `edge_faces`: faces ascending, since `vfaces` lists stay sorted).
        // One pair per face occurrence and distinct other corner, exactly what
        // `edge_faces` counts.
        pairs.clear();
        for &f in &self.vfaces[u as usize] {
            let t = self.tris[f as usize];
            for (k, &w) in t.iter().enumerate() {
                if w != u && !t[..k].contains(&w) {
                    pairs.push(u64::from(w) << 32 | u64::from(f));
                }
            }
        }
        pairs.sort_unstable();
        nu.clear();
        nu.extend(pairs.iter().map(|&p| (p >> 32) as u32));
        nu.dedup();
        let mut best: Option<Candidate> = None;
        let mut i = 0;
        while i < pairs.len() {
            let v = (pairs[i] >> 32) as u32;
            let mut j = i + 1;
            while j < pairs.len() && (pairs[j] >> 32) as u32 == v {
                j += 1;
            }
            let edge_len = j - i;
            let edge = [
                pairs[i] as u32,
                if edge_len > 1 {
                    pairs[i + 1] as u32
                } else {
                    u32::MAX
                },
            ];
            i = j;
            let Some((class, cost)) = self.cost_on_edge(u, v, edge_len, edge) else {
                continue;
            };
            let c = Candidate {
                class,
                cost,
                u,
                v,
                stamp: self.stamp[u as usize],
            };
            if best.is_some_and(|b| c <= b) {
                continue;
            }
            if check && !self.allowed(u, v, nu, nv) {
                continue;
            }
            best = Some(c);
        }
        best
    }

    fn collapse(&mut self, u: u32, v: u32) {
        let faces = std::mem::take(&mut self.vfaces[u as usize]);
        for f in faces {
            let t = self.tris[f as usize];
            if t.contains(&v) {
                self.alive[f as usize] = false;
                for &w in &t {
                    if w != u {
                        self.vfaces[w as usize].retain(|&g| g != f);
                    }
                }
            } else {
                for c in self.tris[f as usize].iter_mut() {
                    if *c == u {
                        *c = v;
                    }
                }
                self.vfaces[v as usize].push(f);
            }
        }
        self.vfaces[v as usize].sort_unstable();
        let qu = self.quadric[u as usize];
        self.quadric[v as usize].add(&qu);
        self.cost_scale[v as usize] = self.cost_scale[v as usize].min(self.cost_scale[u as usize]);
        self.removed[u as usize] = true;
    }
}

/// Decimates `input` under its constraints, as one mesh. Never fails: vertices that cannot
/// be removed are kept.
pub fn decimate(input: &DecimateInput<'_>) -> Decimated {
    let mut st = State::new(input);
    collapse_while_allowed(&mut st);
    finish(input, &st.tris, &st.alive, |v| {
        !st.removed[v as usize] && !st.vfaces[v as usize].is_empty()
    })
}

/// Collapses vertices, cheapest first, while any collapse is allowed.
fn collapse_while_allowed(st: &mut State<'_>) {
    let nv = st.input.positions.len();
    // One entry per vertex: its cheapest collapse, validity tested only when it reaches the
    // top (see `Candidate`).
    let mut heap = BinaryHeap::new();
    let mut scratch = Scratch::default();
    // Key of each vertex's live entry (the one whose stamp is current), if any: a ring
    // vertex whose recomputed best is that same entry keeps it instead of queueing a copy
    // (same pops in the same order, a smaller heap).
    let mut queued: Vec<Option<(u8, u64, u32, u32)>> = vec![None; nv];
    for u in 0..nv as u32 {
        let c = st.best_candidate(u, false, &mut scratch);
        queued[u as usize] = c.map(|c| c.key());
        heap.extend(c);
    }
    while let Some(c) = heap.pop() {
        if st.removed[c.u as usize] || c.stamp != st.stamp[c.u as usize] {
            continue;
        }
        queued[c.u as usize] = None;
        // Re-validate: the neighbourhood (and the survivor's quadric) may have changed since
        // the entry was queued.
        let cost_now = if st.removed[c.v as usize] {
            None
        } else {
            st.cost(c.u, c.v)
        };
        let unchanged = cost_now.is_some_and(|(class, cost)| {
            class == c.class && cost <= c.cost * (1.0 + 1e-12) + 1e-300
        });
        if !unchanged || {
            st.neighbours_into(c.u, &mut scratch.nu);
            !st.allowed(c.u, c.v, &scratch.nu, &mut scratch.nv)
        } {
            // Queue u's real best collapse (re-tested again when it reaches the top).
            st.stamp[c.u as usize] += 1;
            let next = st.best_candidate(c.u, true, &mut scratch);
            queued[c.u as usize] = next.map(|c| c.key());
            heap.extend(next);
            continue;
        }
        st.collapse(c.u, c.v);
        // The survivor's ring (which now includes u's old ring) and the survivor itself
        // see new neighbourhoods: their costs and link conditions changed.
        let mut ring = std::mem::take(&mut scratch.ring);
        st.neighbours_into(c.v, &mut ring);
        ring.push(c.v);
        for &w in &ring {
            if st.removed[w as usize] {
                continue;
            }
            let next = st.best_candidate(w, false, &mut scratch);
            let key = next.map(|c| c.key());
            if key.is_some() && key == queued[w as usize] {
                continue;
            }
            st.stamp[w as usize] += 1;
            queued[w as usize] = key;
            heap.extend(next.map(|c| Candidate {
                stamp: st.stamp[w as usize],
                ..c
            }));
        }
        scratch.ring = ring;
    }
}

/// The result from the final triangles (`alive` ones of `tris`, input vertex ids and face
/// order) and which vertices survive.
fn finish(
    input: &DecimateInput<'_>,
    tris: &[[u32; 3]],
    alive: &[bool],
    survives: impl Fn(u32) -> bool,
) -> Decimated {
    let (triangles, face_groups) = tris
        .iter()
        .zip(input.face_groups)
        .zip(alive)
        .filter(|x| *x.1)
        .map(|((t, &g), _)| (*t, g))
        .unzip();
    Decimated {
        triangles,
        face_groups,
        vertices: (0..input.positions.len() as u32)
            .filter(|&v| survives(v))
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An n x n grid of the unit square (z = 0), two groups split at x = 0.5 when `split`.
    fn grid(n: usize, split: bool) -> (Vec<DVec3>, Vec<[u32; 3]>, Vec<u32>) {
        let mut p = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                p.push(DVec3::new(i as f64 / n as f64, j as f64 / n as f64, 0.0));
            }
        }
        let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        let mut t = Vec::new();
        let mut g = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let grp = u32::from(split && i >= n / 2);
                t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
                g.push(grp);
                g.push(grp);
            }
        }
        (p, t, g)
    }

    /// A boundary patch on the z = 0 plane: every interior vertex should go.
    fn plane_rule() -> GroupRule {
        GroupRule {
            remove_all_interior: true,
            max_cost: 0.0,
            surface: SurfaceRef::Plane { normal: DVec3::Z },
            max_edge_angle: std::f64::consts::PI,
        }
    }

    /// Decimates one test mesh.
    fn run(
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        face_groups: &[u32],
        roles: &[VertexRole],
        rules: &[GroupRule],
    ) -> Decimated {
        decimate(&DecimateInput {
            positions,
            triangles,
            face_groups,
            roles,
            rules,
            cost_scale: None,
            domain: None,
        })
    }

    fn euler(tris: &[[u32; 3]]) -> i64 {
        let mut e = std::collections::BTreeSet::new();
        let mut v = std::collections::BTreeSet::new();
        for t in tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                e.insert((a.min(b), a.max(b)));
                v.insert(a);
            }
        }
        v.len() as i64 - e.len() as i64 + tris.len() as i64
    }

    #[test]
    fn plane_patch_loses_every_interior_and_dropped_boundary_vertex() {
        let n = 8;
        let (p, t, g) = grid(n, false);
        // Keep the four corners; every other boundary vertex is a chain drop.
        let roles: Vec<VertexRole> = p
            .iter()
            .map(|q| {
                let on_x = q.x == 0.0 || q.x == 1.0;
                let on_y = q.y == 0.0 || q.y == 1.0;
                match (on_x, on_y) {
                    (true, true) => VertexRole::Keep,
                    (true, false) | (false, true) => VertexRole::ChainDrop,
                    _ => VertexRole::Interior,
                }
            })
            .collect();
        let rules = [plane_rule()];
        let out = run(&p, &t, &g, &roles, &rules);
        assert_eq!(out.vertices.len(), 4, "{out:?}");
        assert_eq!(out.triangles.len(), 2);
        assert_eq!(euler(&out.triangles), 1);
        // Orientation kept: normals still +z.
        for t in &out.triangles {
            assert!(tri_normal(t.map(|i| p[i as usize])).z > 0.0);
        }
    }

    #[test]
    fn plane_patch_edges_stay_on_the_face_with_a_domain() {
        // A half annulus (radii 1 and 1.1): its four ends alone make a quad whose straight
        // diagonal runs across the hole.
        let n = 32;
        let mut p = Vec::new();
        for k in 0..=n {
            let a = std::f64::consts::PI * k as f64 / n as f64;
            for r in [1.0, 1.1] {
                p.push(DVec3::new(r * a.cos(), r * a.sin(), 0.0));
            }
        }
        let mut t = Vec::new();
        for k in 0..n as u32 {
            let (i0, o0, i1, o1) = (2 * k, 2 * k + 1, 2 * k + 2, 2 * k + 3);
            t.push([i0, o0, o1]);
            t.push([i0, o1, i1]);
        }
        let g = vec![0u32; t.len()];
        let roles: Vec<VertexRole> = (0..p.len())
            .map(|i| {
                if i < 2 || i >= p.len() - 2 {
                    VertexRole::Keep
                } else {
                    VertexRole::ChainDrop
                }
            })
            .collect();
        let rules = [plane_rule()];
        let surface = crate::metrics::TriangleSurface::new(p.clone(), t.clone()).unwrap();
        let dist = 0.02;
        let corners: Vec<[DVec3; 3]> = t.iter().map(|f| f.map(|v| p[v as usize])).collect();
        let domains = [PlaneDomain::new(&corners, DVec3::Z, dist)];
        // Interior edges (two faces) only: the boundary ones are decoded as curves.
        let off_edges = |out: &Decimated| {
            let mut uses = std::collections::BTreeMap::new();
            for tri in &out.triangles {
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
                }
            }
            uses.into_iter()
                .filter(|&(_, n)| n == 2)
                .filter(|&((a, b), _)| {
                    // The raster admits up to a cell diagonal more than `dist`.
                    let m = 0.5 * (p[a as usize] + p[b as usize]);
                    surface.closest_point_within(m, 2.5 * dist).is_none()
                })
                .count()
        };
        let plain = run(&p, &t, &g, &roles, &rules);
        assert!(off_edges(&plain) > 0, "{plain:?}");
        let out = decimate(&DecimateInput {
            positions: &p,
            triangles: &t,
            face_groups: &g,
            roles: &roles,
            rules: &rules,
            cost_scale: None,
            domain: Some(&domains),
        });
        assert_eq!(off_edges(&out), 0, "{out:?}");
        assert_eq!(euler(&out.triangles), 1);
        assert!(out.vertices.len() < p.len() / 2, "{}", out.vertices.len());
    }

    #[test]
    fn closed_patch_keeps_vertices_where_the_cost_is_high() {
        // A bumpy height field: a zero threshold keeps everything, a huge one removes all
        // the interior vertices it can.
        let n = 6;
        let (mut p, t, g) = grid(n, false);
        for q in &mut p {
            q.z = 0.3 * (6.0 * q.x).sin() * (5.0 * q.y).cos();
        }
        let roles: Vec<VertexRole> = p
            .iter()
            .map(|q| {
                if q.x == 0.0 || q.x == 1.0 || q.y == 0.0 || q.y == 1.0 {
                    VertexRole::Keep
                } else {
                    VertexRole::Interior
                }
            })
            .collect();
        let run = |max_cost: f64| {
            let rules = [GroupRule {
                remove_all_interior: false,
                max_cost,
                surface: SurfaceRef::Free,
                max_edge_angle: std::f64::consts::PI,
            }];
            run(&p, &t, &g, &roles, &rules)
        };
        let strict = run(0.0);
        assert_eq!(strict.vertices.len(), p.len());
        let loose = run(1e9);
        assert!(
            loose.vertices.len() < p.len() - 20,
            "{}",
            loose.vertices.len()
        );
        assert_eq!(euler(&loose.triangles), 1);
    }

    /// Two faces of a bumpy grid (one closed, one plane-like) sharing a seam chain: decimated
    /// face by face, the seam keeps the same vertices on both sides, the result is one
    /// watertight disk, and a second round with one face's rule changed redoes that face only.
    #[test]
    fn faces_decimated_apart_agree_on_their_chains_and_are_reused() {
        let n = 10;
        let (mut p, t, g) = grid(n, true);
        for q in &mut p {
            if q.x < 0.5 {
                q.z = 0.05 * (6.0 * q.x).sin() * (5.0 * q.y).cos();
            }
        }
        let roles: Vec<VertexRole> = p
            .iter()
            .map(|q| {
                let seam = (q.x - 0.5).abs() < 1e-12;
                let border = q.x == 0.0 || q.x == 1.0 || q.y == 0.0 || q.y == 1.0;
                if border {
                    VertexRole::Keep
                } else if seam {
                    VertexRole::ChainDrop
                } else {
                    VertexRole::Interior
                }
            })
            .collect();
        let closed = |max_cost: f64| GroupRule {
            remove_all_interior: false,
            max_cost,
            surface: SurfaceRef::Free,
            max_edge_angle: std::f64::consts::PI,
        };
        let input = |rules| DecimateInput {
            positions: &p,
            triangles: &t,
            face_groups: &g,
            roles: &roles,
            rules,
            cost_scale: None,
            domain: None,
        };
        let rules = [closed(1e-4), plane_rule()];
        let rules = &rules[..];
        let mut decimator = FaceDecimator::default();
        let (first, how) = decimator.decimate(&input(rules));
        assert!(!how.whole_mesh);
        assert_eq!(how.faces_redone, 2);
        let whole = decimate(&input(rules));
        assert_eq!(first.vertices, whole.vertices, "same survivors as one mesh");
        assert_eq!(euler(&first.triangles), 1);
        assert!(
            first.vertices.len() < p.len() / 2,
            "{}",
            first.vertices.len()
        );
        // Every surviving seam vertex is a corner of triangles of both faces.
        for &v in &first.vertices {
            if (p[v as usize].x - 0.5).abs() < 1e-12 {
                let sides: std::collections::BTreeSet<u32> = first
                    .triangles
                    .iter()
                    .zip(&first.face_groups)
                    .filter(|(t, _)| t.contains(&v))
                    .map(|(_, &grp)| grp)
                    .collect();
                assert_eq!(sides.len(), 2, "seam vertex {v} on one side only");
            }
        }
        let (again, how) = decimator.decimate(&input(rules));
        assert_eq!(how.faces_redone, 0);
        assert_eq!(again, first);
        let looser = [closed(1e-2), plane_rule()];
        let (out, how) = decimator.decimate(&input(&looser));
        assert_eq!(how.faces_redone, 1);
        assert!(out.vertices.len() < first.vertices.len());
        assert_eq!(euler(&out.triangles), 1);
    }

    #[test]
    fn chain_drops_slide_only_along_group_boundaries() {
        let n = 8;
        let (p, t, g) = grid(n, true);
        // The seam x = 0.5 is a chain between the groups; keep its ends only.
        let roles: Vec<VertexRole> = p
            .iter()
            .map(|q| {
                let seam = (q.x - 0.5).abs() < 1e-12;
                let border = q.x == 0.0 || q.x == 1.0 || q.y == 0.0 || q.y == 1.0;
                if seam && (q.y == 0.0 || q.y == 1.0) {
                    VertexRole::Keep
                } else if seam {
                    VertexRole::ChainDrop
                } else if border {
                    VertexRole::Keep
                } else {
                    VertexRole::Interior
                }
            })
            .collect();
        let rule = plane_rule();
        let out = run(&p, &t, &g, &roles, &[rule, rule]);
        // No seam vertex survives but its ends, and every surviving vertex is on the x = 0.5
        // line or on the border: groups never leak across the seam.
        for &v in &out.vertices {
            let q = p[v as usize];
            assert!(
                roles[v as usize] == VertexRole::Keep,
                "vertex {v} at {q} survived with role {:?}",
                roles[v as usize]
            );
        }
        for (t, &grp) in out.triangles.iter().zip(&out.face_groups) {
            for &v in t {
                let x = p[v as usize].x;
                if grp == 0 {
                    assert!(x <= 0.5 + 1e-12);
                } else {
                    assert!(x >= 0.5 - 1e-12);
                }
            }
        }
        assert_eq!(euler(&out.triangles), 1);
    }

    #[test]
    fn chain_vertex_does_not_slide_into_an_ear() {
        // A closed-patch strip between a curved bottom chain (y <= 0) and a top chain
        // (y = 1); the left side has one chain vertex S that may slide onto either corner.
        // Sliding onto the nearer bottom corner would leave the triangle (C00, B1, B2): an
        // ear along the bottom chain (B1 keeps it as its only face, the chain runs nearly
        // straight through B1).
        let xy = |x: f64, y: f64| DVec3::new(x, y, 0.0);
        let p = vec![
            xy(0.0, 0.0),   // 0 C00
            xy(1.0, -0.15), // 1 B1
            xy(2.0, -0.2),  // 2 B2
            xy(3.0, -0.15), // 3 B3
            xy(4.0, 0.0),   // 4 C40
            xy(0.0, 1.0),   // 5 C01
            xy(1.0, 1.0),   // 6 T1
            xy(2.0, 1.0),   // 7 T2
            xy(3.0, 1.0),   // 8 T3
            xy(4.0, 1.0),   // 9 C41
            xy(0.0, 0.4),   // 10 S
        ];
        let t = vec![
            [0, 1, 10],
            [10, 1, 2],
            [10, 2, 6],
            [10, 6, 5],
            [2, 7, 6],
            [2, 3, 7],
            [3, 8, 7],
            [3, 4, 8],
            [4, 9, 8],
        ];
        let g = vec![0; t.len()];
        let mut roles = vec![VertexRole::Keep; p.len()];
        roles[10] = VertexRole::ChainDrop;
        let rules = [GroupRule {
            remove_all_interior: false,
            max_cost: f64::MAX,
            surface: SurfaceRef::Free,
            max_edge_angle: std::f64::consts::PI,
        }];
        let out = run(&p, &t, &g, &roles, &rules);
        assert!(!out.vertices.contains(&10), "S stays: {out:?}");
        let mut ear = [0, 1, 2];
        for t in &out.triangles {
            for _ in 0..3 {
                assert_ne!(*t, ear, "ear left along the bottom chain: {out:?}");
                ear.rotate_left(1);
            }
        }
        // S went to the top corner instead: C00 keeps a single 90-degree corner triangle.
        assert!(out
            .triangles
            .iter()
            .any(|t| t.contains(&0) && t.contains(&5)));
    }
}
