//! Sparse output of boundary patches (S-CODE §4.2, `spec/subdivision.md` §8).
//!
//! Refinement and positions stay those of the nested 1-to-4 scheme (every point is computed
//! once for the whole mesh, so neighbours share vertices). Only the *output* of a boundary
//! patch differs: it uses the level-n vertices that lie on its control faces' **split**
//! edges (crease edges, and edges shared with a closed patch) and never the vertices inside
//! a control face or on an edge between two boundary-patch faces. A control triangle with
//! k split edges becomes a 0-face (itself), a 1-face (fan from the opposite corner), a
//! 2-face (zipper between the two split edges from their shared corner) or a 3-face (the
//! triangle of the three edge midpoints plus three corner zippers). In cylinder and cone
//! patches two 1-faces whose split edges are opposite sides of a quad form a **belt quad**,
//! output as a zipper between the two split edges: the inserted edges join corresponding
//! points of the two boundary curves, i.e. they run along the rulings. A cylinder or cone
//! group whose faces do not all pair into belt quads is output densely (a fan across a
//! curved face would cut through the solid).

use super::masks::eclass;
use super::next_level::child_faces;
use super::topology::{Base, Level, NONE};
use glam::DVec3;

/// How boundary patches (planes, cylinders, cones) appear in subdivided output.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BoundaryPatchOutput {
    /// S-CODE's scheme: only the patch's split edges are subdivided, no interior vertices.
    #[default]
    Sparse,
    /// The full 1-to-4 grid (every point on the surface, 4^n triangles per control triangle).
    #[cfg(feature = "internals")]
    Dense,
}

/// Marker in [`SparsePlan::unit`] for base faces that are output densely.
pub(crate) const DENSE: u32 = u32::MAX;

/// Decisions of the sparse output that depend only on the control mesh; per base edge /
/// base face flat arrays because they are looked up once per output element.
#[derive(Clone, Debug)]
pub(crate) struct SparsePlan {
    /// Per base edge: the output subdivides it (crease edge, or not both of its faces
    /// output sparsely). Both sides of an edge agree, which keeps the output conforming.
    pub split: Vec<bool>,
    /// Per base face: `DENSE` (closed patch, or a cylinder/cone group that does not pair
    /// into belt quads), itself (a single sparse face of a plane) or the other face of its
    /// belt quad.
    pub unit: Vec<u32>,
}

impl SparsePlan {
    /// The plan of a mesh, or `None` when it has no boundary patch.
    pub fn new(l0: &Level, base: &Base) -> Option<SparsePlan> {
        if !base.boundary_patch.iter().any(|&b| b) {
            return None;
        }
        let split: Vec<bool> = (0..l0.ne()).map(|e| first_split(l0, base, e)).collect();
        let nf = l0.nf();
        let framed = |k: usize| base.group_frame[base.group[k] as usize] != 0;
        let mut unit: Vec<u32> = (0..nf)
            .map(|k| {
                if base.boundary_patch[k] {
                    k as u32
                } else {
                    DENSE
                }
            })
            .collect();
        for (k, &partner) in base.belt.iter().enumerate() {
            if partner != NONE {
                unit[k] = partner;
            }
        }
        // A cylinder/cone group is output sparse only if all of its faces pair into belt
        // quads whose sides stay kept; otherwise the whole group is output densely (a fan
        // across a curved patch would leave the surface). Iterate until stable: making a
        // group dense can split a side of a quad in a neighbouring group.
        let ng = base.group_frame.len();
        let mut split = split;
        loop {
            let mut dense_group = vec![false; ng];
            for k in 0..nf {
                if framed(k) && unit[k] != DENSE {
                    let fe = &l0.face_edges[3 * k..3 * k + 3];
                    let n_split = fe.iter().filter(|&&e| split[e as usize]).count();
                    if unit[k] == k as u32 || n_split != 1 {
                        dense_group[base.group[k] as usize] = true;
                    }
                }
            }
            if !dense_group.iter().any(|&d| d) {
                break;
            }
            for (k, u) in unit.iter_mut().enumerate() {
                if dense_group[base.group[k] as usize] {
                    *u = DENSE;
                }
            }
            let sparse = |f: u32| f != NONE && unit[f as usize] != DENSE;
            for (e, sp) in split.iter_mut().enumerate() {
                let [fl, fr] = l0.edge_faces[e];
                *sp = l0.eclass[e] & eclass::CREASE != 0 || !(sparse(fl) && sparse(fr));
            }
        }
        if unit.iter().all(|&u| u == DENSE) {
            return None;
        }
        Some(SparsePlan { split, unit })
    }
}

/// Whether base edge `e` is split before any cylinder or cone group is made dense: a crease,
/// or an edge not between two boundary-patch faces.
fn first_split(l0: &Level, base: &Base, e: usize) -> bool {
    let patch = |f: u32| f != NONE && base.boundary_patch[f as usize];
    let [fl, fr] = l0.edge_faces[e];
    l0.eclass[e] & eclass::CREASE != 0 || !(patch(fl) && patch(fr))
}

/// Lexicographic order of two points (total: any bits compare).
fn point_order(p: DVec3, q: DVec3) -> std::cmp::Ordering {
    p.to_array()
        .iter()
        .zip(q.to_array())
        .map(|(x, y)| x.total_cmp(&y))
        .find(|o| o.is_ne())
        .unwrap_or(std::cmp::Ordering::Equal)
}

/// Per base triangle, the other triangle of its belt quad, or `NONE` (`spec/subdivision.md`
/// §8, *Belt quads*); empty when `base` has no framed group.
///
/// A 1-face of a framed group (one split edge, two kept ones) may pair with the neighbour
/// across either kept edge (a *rung*) when that is a 1-face of the same group whose split
/// edge shares no vertex with its own. Each face has at most two such neighbours, so the
/// candidates form paths and cycles. A path pairs from one end (an odd one leaves a face
/// unpaired, and its group is output densely anyway). An even cycle has two pairings, each
/// keeping every other rung as a side of a quad; a side is output as a straight edge, which
/// lies on a cylinder or cone only along a ruling, so the cycle keeps the rungs whose
/// largest turn about the axis is smaller (on a tie, those with the rung of smallest end
/// positions). The result depends on the mesh's geometry and connectivity, never on how
/// its faces are numbered: the encoder measures the surface of its own numbering, the
/// decoder builds the file's.
pub(crate) fn belt_partners(l0: &Level, base: &Base, positions: &[DVec3]) -> Vec<u32> {
    if base.frames.is_empty() {
        return Vec::new();
    }
    let nf = l0.nf();
    let split = |e: u32| first_split(l0, base, e as usize);
    let frame_id = |k: usize| base.group_frame[base.group[k] as usize];
    // The split slot of each framed 1-face (3: not one).
    let slot: Vec<u8> = (0..nf)
        .map(|k| {
            let fe = &l0.face_edges[3 * k..3 * k + 3];
            let mut it = (0..3u8).filter(|&s| split(fe[usize::from(s)]));
            match (
                base.boundary_patch[k] && frame_id(k) != 0,
                it.next(),
                it.next(),
            ) {
                (true, Some(s), None) => s,
                _ => 3,
            }
        })
        .collect();
    let split_ends = |k: usize| {
        let s = usize::from(slot[k]);
        [l0.faces[3 * k + s], l0.faces[3 * k + (s + 1) % 3]]
    };
    // Up to two (neighbour, rung edge) per candidate face; the relation is symmetric.
    let mut rungs = vec![[(NONE, NONE); 2]; nf];
    for k in (0..nf).filter(|&k| slot[k] < 3) {
        let [a, b] = split_ends(k);
        let mut n = 0;
        for t in 1..3 {
            let e = l0.face_edges[3 * k + (usize::from(slot[k]) + t) % 3];
            let [fl, fr] = l0.edge_faces[e as usize];
            let k2 = if fl as usize == k { fr } else { fl };
            if k2 == NONE || k2 as usize == k {
                continue;
            }
            let k2u = k2 as usize;
            if slot[k2u] == 3 || base.group[k2u] != base.group[k] {
                continue;
            }
            if split_ends(k2u).iter().all(|&w| w != a && w != b) {
                rungs[k][n] = (k2, e);
                n += 1;
            }
        }
    }
    let frames = &base.frames;
    let turn = |k: u32, e: u32| {
        let [v, w] = l0.edges[e as usize];
        let frame = &frames[usize::from(frame_id(k as usize)) - 1];
        frame.turn(positions[v as usize], positions[w as usize])
    };
    // A rung's ends, the lesser first; rungs compare by those, lesser end first.
    let ends = |e: u32| {
        let [v, w] = l0.edges[e as usize].map(|v| positions[v as usize]);
        if point_order(w, v).is_lt() {
            [w, v]
        } else {
            [v, w]
        }
    };
    let rung_order = |a: [DVec3; 2], b: [DVec3; 2]| {
        point_order(a[0], b[0]).then_with(|| point_order(a[1], b[1]))
    };

    let mut partner = vec![NONE; nf];
    let mut seen = vec![false; nf];
    let (mut nodes, mut between) = (Vec::new(), Vec::new());
    // Walks the component of `start` (a path from its end, or a cycle): its faces in order
    // and the rung after each (a cycle's last rung closes it).
    let walk = |start: usize, seen: &mut [bool], nodes: &mut Vec<u32>, between: &mut Vec<u32>| {
        nodes.clear();
        between.clear();
        let (mut k, mut came) = (start, NONE);
        loop {
            seen[k] = true;
            nodes.push(k as u32);
            match rungs[k].iter().find(|&&(k2, e)| k2 != NONE && e != came) {
                Some(&(k2, e)) if !seen[k2 as usize] => {
                    between.push(e);
                    (k, came) = (k2 as usize, e);
                }
                Some(&(k2, e)) if k2 as usize == start && nodes.len() > 1 => {
                    between.push(e);
                    break;
                }
                _ => break,
            }
        }
    };
    let degree = |k: usize| rungs[k].iter().filter(|r| r.0 != NONE).count();
    for k in 0..nf {
        if slot[k] < 3 && !seen[k] && degree(k) < 2 {
            walk(k, &mut seen, &mut nodes, &mut between);
            for pair in nodes.chunks_exact(2) {
                (partner[pair[0] as usize], partner[pair[1] as usize]) = (pair[1], pair[0]);
            }
        }
    }
    for k in 0..nf {
        if slot[k] == 3 || seen[k] {
            continue;
        }
        walk(k, &mut seen, &mut nodes, &mut between);
        let len = nodes.len();
        if len % 2 == 1 || between.len() != len {
            continue;
        }
        // The rungs of one parity are kept by the pairing that starts at the other.
        let kept = |parity: usize| (parity..len).step_by(2).map(|i| (nodes[i], between[i]));
        let largest_turn =
            |parity: usize| kept(parity).map(|(k, e)| turn(k, e)).fold(0.0f64, f64::max);
        let least_rung = |parity: usize| {
            kept(parity)
                .map(|(_, e)| ends(e))
                .min_by(|a, b| rung_order(*a, *b))
        };
        let order = largest_turn(1).total_cmp(&largest_turn(0)).then_with(|| {
            match (least_rung(1), least_rung(0)) {
                (Some(a), Some(b)) => rung_order(a, b),
                _ => std::cmp::Ordering::Equal,
            }
        });
        let offset = usize::from(order.is_gt());
        for i in (offset..len).step_by(2) {
            let (p, q) = (nodes[i], nodes[(i + 1) % len]);
            (partner[p as usize], partner[q as usize]) = (q, p);
        }
    }
    partner
}

/// Reusable buffers of [`emit_unit`].
#[derive(Default)]
pub(crate) struct Chains {
    ch: [Vec<u32>; 3],
    q: Vec<u32>,
    /// A base edge's chain, for [`UniformFaces::emit`].
    edge: Vec<u32>,
}

/// Appends the triangles of the zipper between chains `p` and `q` (both running the same
/// way, `p` along the region's counter-clockwise boundary, `p[0]`-`q[0]` and
/// `p[N]`-`q[M]` already joined): advance along the chain whose next point has the smaller
/// normalised parameter (`i / N` against `j / M`), ties along `p` if `prefer_p`. With
/// `shared_start` (`p[0] == q[0]`) the first triangle is `(p0, p1, q1)`.
fn zip(p: &[u32], q: &[u32], prefer_p: bool, shared_start: bool, out: &mut Vec<u32>) {
    let (n, m) = (p.len() - 1, q.len() - 1);
    let (mut i, mut j) = (0, 0);
    if shared_start {
        out.extend_from_slice(&[p[0], p[1], q[1]]);
        (i, j) = (1, 1);
    }
    while i < n || j < m {
        let along_p = if i == n {
            false
        } else if j == m {
            true
        } else {
            let (a, b) = ((i + 1) * m, (j + 1) * n);
            a < b || (a == b && prefer_p)
        };
        if along_p {
            out.extend_from_slice(&[p[i], p[i + 1], q[j]]);
            i += 1;
        } else {
            out.extend_from_slice(&[p[i], q[j + 1], q[j]]);
            j += 1;
        }
    }
}

/// Emits the sparse triangles of base face `k` (and of its belt partner, which the caller
/// then skips). `chain(f, s, v)` fills `v` with the output vertices along edge slot `s` of
/// base face `f`, from corner s to corner s+1, both ends included (just the two corners
/// when the edge is not split). Returns the number of triangles appended to `out` (flat).
pub(crate) fn emit_unit(
    l0: &Level,
    plan: &SparsePlan,
    k: usize,
    chain: &mut impl FnMut(usize, usize, &mut Vec<u32>),
    bufs: &mut Chains,
    out: &mut Vec<u32>,
) -> usize {
    let start = out.len();
    let partner = plan.unit[k] as usize;
    let Chains { ch, q, .. } = bufs;
    if partner != k {
        // Belt quad (w0, w1, w2, w3): split sides w0w1 (this face) and w2w3 (partner).
        let fe = &l0.face_edges[3 * k..3 * k + 3];
        let s = (0..3).find(|&s| plan.split[fe[s] as usize]).unwrap_or(0);
        let fe2 = &l0.face_edges[3 * partner..3 * partner + 3];
        let s2 = (0..3).find(|&s| plan.split[fe2[s] as usize]).unwrap_or(0);
        chain(k, s, &mut ch[0]);
        chain(partner, s2, &mut ch[1]);
        q.clear();
        q.extend(ch[1].iter().rev());
        // The control diagonal: slot s+1 shared => diagonal w1-w3 (ties along p).
        let e_next = fe[(s + 1) % 3];
        let prefer_p = fe2.contains(&e_next);
        zip(&ch[0], q, prefer_p, false, out);
        return (out.len() - start) / 3;
    }
    for (s, c) in ch.iter_mut().enumerate() {
        chain(k, s, c);
    }
    // An edge counts as split when its chain has points between the corners.
    let is_split = [ch[0].len() > 2, ch[1].len() > 2, ch[2].len() > 2];
    let c = &l0.faces[3 * k..3 * k + 3];
    match is_split.iter().filter(|&&x| x).count() {
        0 => out.extend_from_slice(c),
        1 => {
            let s = (0..3).find(|&s| is_split[s]).unwrap_or(0);
            zip(&ch[s], &[c[(s + 2) % 3]], true, false, out);
        }
        2 => {
            // u: the unsplit slot; the split edges meet at corner u+2.
            let u = (0..3).find(|&s| !is_split[s]).unwrap_or(0);
            q.clear();
            q.extend(ch[(u + 1) % 3].iter().rev());
            zip(&ch[(u + 2) % 3], q, true, true, out);
        }
        _ => {
            let mid = |v: &Vec<u32>| v[(v.len() - 1) / 2];
            let (m0, m1, m2) = (mid(&ch[0]), mid(&ch[1]), mid(&ch[2]));
            out.extend_from_slice(&[m0, m1, m2]);
            for s in 0..3 {
                let prev = &ch[(s + 2) % 3];
                let half = (prev.len() - 1) / 2;
                q.clear();
                q.extend(prev[half..].iter().rev());
                let this = &ch[s];
                zip(&this[..=(this.len() - 1) / 2], q, true, true, out);
            }
        }
    }
    (out.len() - start) / 3
}

/// What uniform level-n output reads to make the triangles of one base face: level 0 (the
/// sparse faces and the base edges), level n-1, whose faces' children are a dense base
/// face's triangles (its faces, face edges and vertex count are read), and the vertex count
/// of every level below n, which numbers the vertices along a base edge. Borrowed, so a
/// caller can keep just these parts of a refinement once positions are evaluated.
pub(crate) struct UniformFaces<'a> {
    pub l0: &'a Level,
    pub base: &'a Base,
    /// Level n-1; `None` for n = 0.
    pub last: Option<&'a Level>,
    /// Vertex count of levels 0 to n-1.
    pub level_nv: &'a [usize],
    pub n: u32,
    /// `None`: every face dense.
    pub plan: Option<&'a SparsePlan>,
}

impl UniformFaces<'_> {
    /// Appends the output triangles of base face `k` (flat, level-n vertex ids): its 4^n
    /// children when it is dense, its unit's sparse triangles when it is the first face of
    /// its unit (a belt quad is emitted by its first face), none otherwise. Returns how
    /// many triangles it appended.
    pub fn emit(&self, k: usize, bufs: &mut Chains, out: &mut Vec<u32>) -> usize {
        let unit = self.plan.map_or(DENSE, |p| p.unit[k]);
        if unit == DENSE {
            let Some(last) = self.last else {
                out.extend_from_slice(&self.l0.faces[3 * k..3 * k + 3]);
                return 1;
            };
            let q = 1usize << (2 * (self.n - 1));
            for f in k * q..(k + 1) * q {
                out.extend_from_slice(&child_faces(last, f));
            }
            return 4 * q;
        }
        if (unit as usize) < k {
            return 0;
        }
        let (l0, plan) = (self.l0, self.plan.expect("sparse faces have a plan"));
        let mut edge_chain = std::mem::take(&mut bufs.edge);
        let mut chain = |f: usize, s: usize, v: &mut Vec<u32>| {
            let c = &l0.faces[3 * f..3 * f + 3];
            let (a, b) = (c[s], c[(s + 1) % 3]);
            let e = l0.face_edges[3 * f + s] as usize;
            v.clear();
            if !plan.split[e] {
                v.extend_from_slice(&[a, b]);
                return;
            }
            base_edge_chain(l0, self.level_nv, self.n, e, &mut edge_chain);
            if edge_chain[0] == a {
                v.extend_from_slice(&edge_chain);
            } else {
                v.extend(edge_chain.iter().rev());
            }
        };
        let t = emit_unit(l0, plan, k, &mut chain, bufs, out);
        bufs.edge = edge_chain;
        t
    }
}

/// Level-n vertex ids along base edge `e`, from its stored first end to its second
/// (`2^n + 1` ids), by index arithmetic only: the vertex at position `i` was created at
/// level `j = n - 1 - tz(i)` on the level-j descendant `e 2^j + (i >> (tz + 1))` of `e` (the
/// descendants of a base edge are consecutive and ordered along it). `level_nv[j]` is the
/// vertex count of level j.
pub(crate) fn base_edge_chain(
    l0: &Level,
    level_nv: &[usize],
    n: u32,
    e: usize,
    out: &mut Vec<u32>,
) {
    let [a, b] = l0.edges[e];
    out.clear();
    out.push(a);
    for i in 1..1usize << n {
        let tz = i.trailing_zeros();
        let j = n - 1 - tz;
        let k = i >> (tz + 1);
        out.push((level_nv[j as usize] + (e << j) + k) as u32);
    }
    out.push(b);
}

/// Uniform level-n output with sparse boundary patches: flat triangles (level-n vertex
/// ids) and the group of each triangle, in base-face order.
pub(crate) fn uniform(faces: &UniformFaces<'_>) -> (Vec<u32>, Vec<u32>) {
    let mut tris = Vec::new();
    let mut groups = Vec::new();
    let mut bufs = Chains::default();
    for k in 0..faces.l0.nf() {
        let t = faces.emit(k, &mut bufs, &mut tris);
        groups.extend(std::iter::repeat_n(faces.base.group[k], t));
    }
    (tris, groups)
}

/// Keeps the vertices used by `tris` (in id order). Returns the kept positions and normals
/// and the old-to-new map (`u32::MAX` for dropped vertices).
pub(crate) fn compact(
    positions: &[DVec3],
    normals: Option<&[DVec3]>,
    tris: &[u32],
) -> (Vec<DVec3>, Option<Vec<DVec3>>, Vec<u32>) {
    let mut remap = vec![u32::MAX; positions.len()];
    for &v in tris {
        remap[v as usize] = 0;
    }
    let mut next = 0u32;
    let mut kept = Vec::new();
    for (v, r) in remap.iter_mut().enumerate() {
        if *r != u32::MAX {
            *r = next;
            next += 1;
            kept.push(v);
        }
    }
    let pos = kept.iter().map(|&v| positions[v]).collect();
    let nn = normals.map(|n| kept.iter().map(|&v| n[v]).collect());
    (pos, nn, remap)
}
