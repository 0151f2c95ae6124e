//! Face Fixer connectivity coding (Isenburg & Snoeyink 2000), the variant fully specified in
//! `face-fixer.md` §3-§4 and `spec/format.md` §6: the encoder walks the mesh and emits one label
//! per edge (+1 per component); the decoder rebuilds the half-edge structure by undoing the
//! labels in reverse order.
//!
//! The encoder does not compute the decoder-side numbering itself: it runs [`rebuild`] on its own
//! labels and maps the result back, so encoder and decoder cannot disagree about face order,
//! vertex order or which label owns which edge.

use super::Budget;
use crate::error::{Error, Result};
#[cfg(any(feature = "encoder", feature = "internals"))]
use crate::mesh::topology::HalfEdgeMesh;
use crate::mesh::topology::NONE;

/// One Face Fixer label. `F(l)`/`H(l)`: a face / hole of degree `l` is fixed to the gate;
/// `R`, `L`, `S`, `E`: the gate is zipped with its right / left neighbour / an element
/// elsewhere in the active boundary / its only partner; `M`: zipped with an element of a
/// suspended boundary (depth `i` in the stack, offset `k` from its gate, length `l`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Label {
    F(u32),
    H(u32),
    R,
    L,
    S,
    E,
    M { i: u32, k: u32, l: u32 },
}

/// Result of the encoder's traversal.
#[cfg(any(feature = "encoder", feature = "internals"))]
pub struct Traversal {
    pub labels: Vec<Label>,
    /// Faces of the half-edge mesh (mesh and hole faces) in encoding order, each with the
    /// half-edge it was entered by (`t` in face-fixer.md; the start corner for start faces).
    pub faces: Vec<(u32, u32)>,
}

/// Runs the Face Fixer encoder over every connected component (start face: the lowest
/// unprocessed mesh face, start corner: its first corner).
#[cfg(any(feature = "encoder", feature = "internals"))]
pub fn encode_traversal(he: &HalfEdgeMesh) -> Traversal {
    let nh = he.origin.len();
    let mut a_next = vec![NONE; nh];
    let mut a_prev = vec![NONE; nh];
    let mut loop_of = vec![NONE; nh];
    let mut processed = vec![false; he.face_count()];
    let mut labels = Vec::with_capacity(nh / 2 + 16);
    let mut faces = Vec::with_capacity(he.face_count());
    let mut next_id = 0u32;
    let mut stack: Vec<(u32, u32)> = Vec::new();

    for f0 in 0..he.real_face_count as u32 {
        if processed[f0 as usize] {
            continue;
        }
        processed[f0 as usize] = true;
        let first = he.face_first[f0 as usize];
        faces.push((f0, first));
        labels.push(Label::F(he.face_degree[f0 as usize]));
        let mut cur = next_id;
        next_id += 1;
        for h in he.face_half_edges(f0) {
            let n = he.next[h as usize];
            a_next[h as usize] = n;
            a_prev[n as usize] = h;
            loop_of[h as usize] = cur;
        }
        let mut gate = first;
        stack.clear();
        loop {
            let g = gate;
            let t = he.twin[g as usize];
            let u = he.face[t as usize];
            if !processed[u as usize] {
                processed[u as usize] = true;
                faces.push((u, t));
                let l = he.face_degree[u as usize];
                let (p, n) = (a_prev[g as usize], a_next[g as usize]);
                let mut last = p;
                let mut x = he.next[t as usize];
                for _ in 0..l - 1 {
                    a_next[last as usize] = x;
                    a_prev[x as usize] = last;
                    loop_of[x as usize] = cur;
                    last = x;
                    x = he.next[x as usize];
                }
                a_next[last as usize] = n;
                a_prev[n as usize] = last;
                loop_of[g as usize] = NONE;
                gate = last;
                labels.push(if he.is_hole_face(u) {
                    Label::H(l)
                } else {
                    Label::F(l)
                });
                continue;
            }
            let lt = loop_of[t as usize];
            debug_assert_ne!(lt, NONE, "twin of the gate must be on a boundary");
            loop_of[g as usize] = NONE;
            loop_of[t as usize] = NONE;
            if lt == cur {
                let x_empty = a_next[g as usize] == t;
                let y_empty = a_next[t as usize] == g;
                if x_empty && y_empty {
                    labels.push(Label::E);
                    match stack.pop() {
                        None => break,
                        Some((id, gt)) => {
                            cur = id;
                            gate = gt;
                        }
                    }
                } else if x_empty {
                    let (p, n) = (a_prev[g as usize], a_next[t as usize]);
                    a_next[p as usize] = n;
                    a_prev[n as usize] = p;
                    gate = p;
                    labels.push(Label::R);
                } else if y_empty {
                    let (p, n) = (a_prev[t as usize], a_next[g as usize]);
                    a_next[p as usize] = n;
                    a_prev[n as usize] = p;
                    gate = p;
                    labels.push(Label::L);
                } else {
                    let (xf, xl) = (a_next[g as usize], a_prev[t as usize]);
                    let (yf, yl) = (a_next[t as usize], a_prev[g as usize]);
                    a_next[xl as usize] = xf;
                    a_prev[xf as usize] = xl;
                    a_next[yl as usize] = yf;
                    a_prev[yf as usize] = yl;
                    // Relabel the smaller part (walk both in lockstep) so the total work is
                    // O(n log n).
                    let (mut px, mut py) = (xf, yf);
                    let x_smaller = loop {
                        px = a_next[px as usize];
                        if px == xf {
                            break true;
                        }
                        py = a_next[py as usize];
                        if py == yf {
                            break false;
                        }
                    };
                    let id = next_id;
                    next_id += 1;
                    let relabel_from = if x_smaller { xf } else { yf };
                    let mut x = relabel_from;
                    loop {
                        loop_of[x as usize] = id;
                        x = a_next[x as usize];
                        if x == relabel_from {
                            break;
                        }
                    }
                    if x_smaller {
                        stack.push((cur, yl));
                        cur = id;
                    } else {
                        stack.push((id, yl));
                    }
                    gate = xl;
                    labels.push(Label::S);
                }
            } else {
                let idx = stack
                    .iter()
                    .rposition(|&(id, _)| id == lt)
                    .expect("boundary of the gate's twin is on the stack");
                let i = (stack.len() - 1 - idx) as u32;
                let (_, bgate) = stack.remove(idx);
                let mut x = bgate;
                let mut pos = 0u32;
                let mut k = 0u32;
                loop {
                    if x == t {
                        k = pos;
                    }
                    loop_of[x as usize] = cur;
                    pos += 1;
                    x = a_next[x as usize];
                    if x == bgate {
                        break;
                    }
                }
                loop_of[t as usize] = NONE;
                let l = pos;
                let (pg, ng) = (a_prev[g as usize], a_next[g as usize]);
                let (pt, nt) = (a_prev[t as usize], a_next[t as usize]);
                a_next[pg as usize] = nt;
                a_prev[nt as usize] = pg;
                a_next[pt as usize] = ng;
                a_prev[ng as usize] = pt;
                gate = pg;
                labels.push(Label::M { i, k, l });
            }
        }
    }
    Traversal { labels, faces }
}

/// One face of the rebuilt structure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RebuiltFace {
    /// Entry half-edge `t` (start faces: the start corner); the face's vertex cycle starts at
    /// its tail.
    pub first: u32,
    pub degree: u32,
    pub hole: bool,
    /// True for the first face of a connected component.
    pub start: bool,
}

/// Connectivity rebuilt from labels. Half-edges are numbered in creation order; faces and
/// vertices in encoding order (vertices by first appearance walking the mesh faces).
pub struct Rebuilt {
    pub next: Vec<u32>,
    pub prev: Vec<u32>,
    pub twin: Vec<u32>,
    pub face: Vec<u32>,
    /// Tail vertex of every half-edge.
    pub vertex: Vec<u32>,
    pub faces: Vec<RebuiltFace>,
    /// For every label, the half-edge of the edge it owns (`NONE` for start labels).
    pub label_edge: Vec<u32>,
    pub vertex_count: usize,
    /// One outgoing half-edge per vertex.
    pub vertex_out: Vec<u32>,
    /// Bytes charged to the budget for these arrays; whoever drops them releases them.
    pub bytes: u64,
}

impl Rebuilt {
    /// Vertex ids of face `f` starting at its first half-edge.
    pub fn face_vertices(&self, f: usize) -> impl Iterator<Item = u32> + '_ {
        let rf = self.faces[f];
        let mut h = rf.first;
        (0..rf.degree).map(move |_| {
            let v = self.vertex[h as usize];
            h = self.next[h as usize];
            v
        })
    }

    pub fn is_hole(&self, h: u32) -> bool {
        self.faces[self.face[h as usize] as usize].hole
    }
}

/// The element `n` links away from `from`.
fn walk(links: &[u32], mut from: u32, n: u64) -> u32 {
    for _ in 0..n {
        from = links[from as usize];
    }
    from
}

fn bad(field: &'static str, detail: impl Into<String>) -> Error {
    Error::format("connectivity", field, detail)
}

/// Bytes of a [`RebuiltFace`] and of an entry of the stack of suspended boundaries, as the
/// budget charges them.
const FACE_RECORD_BYTES: u64 = 12;
const STACK_ENTRY_BYTES: u64 = 16;
const REBUILD_MEMORY: &str = "decode memory for the connectivity rebuild (bytes)";
const _: () = assert!(
    std::mem::size_of::<RebuiltFace>() as u64 <= FACE_RECORD_BYTES
        && std::mem::size_of::<(u32, u64)>() as u64 <= STACK_ENTRY_BYTES
);

/// Bytes a [`Rebuilt`] of `labels` labels, `half_edges` half-edges, `faces` faces and `roots`
/// vertex classes holds: label edges; next, prev, twin, face and vertex per half-edge; face
/// records; one outgoing half-edge per vertex.
pub(crate) fn rebuilt_bytes(labels: u64, half_edges: u64, faces: u64, roots: u64) -> u64 {
    4 * labels + 20 * half_edges + FACE_RECORD_BYTES * faces + 4 * roots
}

/// Undoes the labels (face-fixer.md §4). Every precondition is checked, so arbitrary label
/// sequences give an error, never a panic. Every array is charged to `budget` before it is
/// allocated and the scratch arrays are released when they are freed (the result's arrays
/// stay charged: [`Rebuilt::bytes`]); the walks of merge labels, whose length the labels
/// decide, are charged to its work bound.
pub(crate) fn rebuild(labels: &[Label], budget: &mut Budget) -> Result<Rebuilt> {
    // Every label but a component's first makes a pair of half-edges, numbered in u32 with
    // NONE reserved.
    if labels.len() >= (NONE / 2) as usize {
        return Err(bad("labels", "too many half-edges"));
    }
    let nl = labels.len() as u64;
    budget.charge(REBUILD_MEMORY, 8 * nl)?;
    let ComponentScan {
        face_of_label,
        mut label_edge,
        faces: nfaces,
        components: ncomps,
        max_depth,
    } = scan_components(labels)?;

    let nh = 2 * (labels.len() - ncomps);
    let nh64 = nh as u64;
    // next, twin and face (kept), the active boundary's two links and the stack (scratch),
    // the faces (kept).
    let scratch = 4 * nl + 8 * nh64 + STACK_ENTRY_BYTES * max_depth;
    budget.charge(
        REBUILD_MEMORY,
        12 * nh64
            + 8 * nh64
            + STACK_ENTRY_BYTES * max_depth
            + FACE_RECORD_BYTES * u64::from(nfaces),
    )?;
    let mut unzip = Unzip::with_capacity(nh, max_depth, nfaces);
    let mut s = 0;
    while s < labels.len() {
        let e = label_edge[s] as usize;
        label_edge[s] = NONE;
        unzip.undo_component(labels, &face_of_label, &mut label_edge, s..e, budget)?;
        s = e;
    }
    let Unzip {
        next,
        twin,
        face,
        faces,
        ..
    } = unzip;
    drop(face_of_label);
    budget.release(scratch);
    if let Some(h) = next.iter().position(|&n| n == NONE) {
        return Err(bad("labels", format!("half-edge {h} ends up in no face")));
    }
    // prev and the vertex of every half-edge (kept), the union-find and its numbering
    // (scratch).
    budget.charge(REBUILD_MEMORY, 16 * nh64)?;
    let mut prev = vec![NONE; nh];
    for h in 0..nh {
        prev[next[h] as usize] = h as u32;
    }
    let vertices = number_vertices(&next, &twin, &faces, budget)?;
    budget.release(8 * nh64);
    Ok(Rebuilt {
        next,
        prev,
        twin,
        face,
        vertex: vertices.vertex,
        faces,
        label_edge,
        vertex_count: vertices.count as usize,
        vertex_out: vertices.out,
        bytes: rebuilt_bytes(nl, nh64, u64::from(nfaces), vertices.roots as u64),
    })
}

/// What [`scan_components`] finds in the labels before anything is rebuilt.
struct ComponentScan {
    /// Face number of every F and H label (`NONE` for the other labels).
    face_of_label: Vec<u32>,
    /// At a component's first label, the end of its component (one past its last label);
    /// `NONE` elsewhere.
    label_edge: Vec<u32>,
    /// Number of faces (F and H labels).
    faces: u32,
    /// Number of connected components.
    components: usize,
    /// Bound on the stack of suspended boundaries within one component.
    max_depth: u64,
}

/// Forward pass over the labels: splits them into components by counting open boundaries,
/// numbers the faces, and bounds the stack of suspended boundaries (an E or M label of a
/// component adds at most one entry). Fails when a component does not start with F or the
/// last one is not closed by E.
fn scan_components(labels: &[Label]) -> Result<ComponentScan> {
    let mut face_of_label = vec![NONE; labels.len()];
    let mut label_edge = vec![NONE; labels.len()];
    let (mut open, mut start, mut nfaces, mut ncomps) = (0u64, 0usize, 0u32, 0usize);
    let (mut depth, mut max_depth) = (0u64, 0u64);
    for (j, lab) in labels.iter().enumerate() {
        if open == 0 {
            if !matches!(lab, Label::F(_)) {
                return Err(bad(
                    "labels",
                    format!("label {j} starts a component but is not F"),
                ));
            }
            start = j;
            open = 1;
            depth = 0;
        } else {
            match lab {
                Label::S => open += 1,
                Label::M { .. } | Label::E => {
                    open -= 1;
                    depth += 1;
                }
                _ => {}
            }
        }
        max_depth = max_depth.max(depth);
        if matches!(lab, Label::F(_) | Label::H(_)) {
            face_of_label[j] = nfaces;
            nfaces += 1;
        }
        if open == 0 {
            label_edge[start] = j as u32 + 1;
            ncomps += 1;
        }
    }
    if open != 0 {
        return Err(bad("labels", "the last component does not end with E"));
    }
    Ok(ComponentScan {
        face_of_label,
        label_edge,
        faces: nfaces,
        components: ncomps,
        max_depth,
    })
}

/// The half-edge structure as the rebuild grows it, and the active boundary the labels of a
/// component are undone on (read backwards from the component's last label).
struct Unzip {
    next: Vec<u32>,
    twin: Vec<u32>,
    face: Vec<u32>,
    /// The active boundary: a cyclic list of half-edges, linked both ways.
    a_next: Vec<u32>,
    a_prev: Vec<u32>,
    /// Suspended boundaries: each one's gate and length.
    stack: Vec<(u32, u64)>,
    faces: Vec<RebuiltFace>,
    /// Gate of the active boundary (`NONE` while it is empty) and its length.
    gate: u32,
    len: u64,
}

impl Unzip {
    /// Empty arrays with room for `half_edges` half-edges, a stack `max_depth` deep and
    /// `faces` faces (all charged by the caller).
    fn with_capacity(half_edges: usize, max_depth: u64, faces: u32) -> Self {
        Unzip {
            next: Vec::with_capacity(half_edges),
            twin: Vec::with_capacity(half_edges),
            face: Vec::with_capacity(half_edges),
            a_next: Vec::with_capacity(half_edges),
            a_prev: Vec::with_capacity(half_edges),
            stack: Vec::with_capacity(max_depth as usize),
            faces: vec![
                RebuiltFace {
                    first: NONE,
                    degree: 0,
                    hole: false,
                    start: false
                };
                faces as usize
            ],
            gate: NONE,
            len: 0,
        }
    }

    /// Appends a pair of twin half-edges, unlinked, and returns them.
    fn new_pair(&mut self) -> Result<(u32, u32)> {
        let g = self.next.len();
        if g + 2 >= NONE as usize {
            return Err(bad("labels", "too many half-edges"));
        }
        for _ in 0..2 {
            self.next.push(NONE);
            self.face.push(NONE);
            self.a_next.push(NONE);
            self.a_prev.push(NONE);
        }
        self.twin.push(g as u32 + 1);
        self.twin.push(g as u32);
        Ok((g as u32, g as u32 + 1))
    }

    /// Undoes the labels of the component `labels[component]`: its labels after the first
    /// in reverse order, then its start face. Records in `label_edge` the half-edge each
    /// label owns.
    fn undo_component(
        &mut self,
        labels: &[Label],
        face_of_label: &[u32],
        label_edge: &mut [u32],
        component: std::ops::Range<usize>,
        budget: &mut Budget,
    ) -> Result<()> {
        let s = component.start;
        self.gate = NONE;
        self.len = 0;
        self.stack.clear();
        for j in (s + 1..component.end).rev() {
            let lab = labels[j];
            match lab {
                Label::E => self.undo_e()?,
                Label::R | Label::L => self.undo_neighbour_zip(j, lab)?,
                Label::S => self.undo_s(j)?,
                Label::M { i, k, l } => self.undo_m(j, i, k, l, budget)?,
                Label::F(l) | Label::H(l) => self.undo_face(j, lab, l, face_of_label[j])?,
            }
            label_edge[j] = self.gate;
        }
        self.close_start_face(labels, s, face_of_label[s])
    }

    /// E: the active boundary (if any) is suspended and a new one of two half-edges starts.
    fn undo_e(&mut self) -> Result<()> {
        let (gate, len) = (self.gate, self.len);
        if gate != NONE {
            self.stack.push((gate, len));
        }
        let (g, t) = self.new_pair()?;
        let (a_next, a_prev) = (&mut self.a_next, &mut self.a_prev);
        a_next[g as usize] = t;
        a_prev[t as usize] = g;
        a_next[t as usize] = g;
        a_prev[g as usize] = t;
        self.gate = g;
        self.len = 2;
        Ok(())
    }

    /// R or L (label `j`): a pair is inserted after the gate, the new gate first (R) or
    /// second (L).
    fn undo_neighbour_zip(&mut self, j: usize, lab: Label) -> Result<()> {
        let gate = self.gate;
        if gate == NONE {
            return Err(bad(
                "labels",
                format!("label {j} ({lab:?}) on an empty boundary"),
            ));
        }
        let (g, t) = self.new_pair()?;
        let (first, second) = if lab == Label::R { (g, t) } else { (t, g) };
        let (a_next, a_prev) = (&mut self.a_next, &mut self.a_prev);
        let n = a_next[gate as usize];
        a_next[gate as usize] = first;
        a_prev[first as usize] = gate;
        a_next[first as usize] = second;
        a_prev[second as usize] = first;
        a_next[second as usize] = n;
        a_prev[n as usize] = second;
        self.gate = g;
        self.len += 2;
        Ok(())
    }

    /// S (label `j`): the top suspended boundary is joined to the active one by a pair.
    fn undo_s(&mut self, j: usize) -> Result<()> {
        let Some((gy, leny)) = self.stack.pop() else {
            return Err(bad(
                "labels",
                format!("label {j} (S) without a suspended boundary"),
            ));
        };
        let gate = self.gate;
        if gate == NONE {
            return Err(bad("labels", format!("label {j} (S) on an empty boundary")));
        }
        let (g, t) = self.new_pair()?;
        let (a_next, a_prev) = (&mut self.a_next, &mut self.a_prev);
        let xf = a_next[gate as usize];
        let yf = a_next[gy as usize];
        a_next[g as usize] = xf;
        a_prev[xf as usize] = g;
        a_next[gate as usize] = t;
        a_prev[t as usize] = gate;
        a_next[t as usize] = yf;
        a_prev[yf as usize] = t;
        a_next[gy as usize] = g;
        a_prev[g as usize] = gy;
        self.gate = g;
        self.len += leny + 2;
        Ok(())
    }

    /// M(i, k, l) (label `j`): the active boundary is cut in two by a pair; the part of
    /// length `l` after the gate is suspended `i` entries deep, with its gate `k` back.
    fn undo_m(&mut self, j: usize, i: u32, k: u32, l: u32, budget: &mut Budget) -> Result<()> {
        let (gate, len) = (self.gate, self.len);
        if gate == NONE
            || l < 2
            || k >= l
            || u64::from(l) > len.saturating_sub(1) + 1
            || len < u64::from(l)
            || i as usize > self.stack.len()
        {
            return Err(bad(
                "labels",
                format!("label {j} M(i={i}, k={k}, l={l}) does not fit the boundary (length {len}, stack depth {})", self.stack.len()),
            ));
        }
        // Bpart: the l-1 elements after the gate; Apart: the rest, ending at the
        // gate. The walks to Bpart's end and to B's gate go the shorter way round
        // and are charged first (their length is the file's to choose), and so is
        // inserting B i entries deep.
        let (l64, b_gate_at) = (u64::from(l), u64::from((l - k) % l));
        let (b_end_ahead, b_end_back) = (l64 - 1, len - l64 + 1);
        let b_gate_back = l64 - b_gate_at;
        budget.work(b_end_ahead.min(b_end_back) + b_gate_at.min(b_gate_back) + u64::from(i))?;
        let (g, t) = self.new_pair()?;
        let (a_next, a_prev) = (&mut self.a_next, &mut self.a_prev);
        let blast = if b_end_ahead <= b_end_back {
            walk(a_next, gate, b_end_ahead)
        } else {
            walk(a_prev, gate, b_end_back)
        };
        let b1 = a_next[gate as usize];
        let a_first = a_next[blast as usize];
        // B = [t, b1 .. blast]
        a_next[t as usize] = b1;
        a_prev[b1 as usize] = t;
        a_next[blast as usize] = t;
        a_prev[t as usize] = blast;
        // A = [g, a_first .. gate]
        a_next[g as usize] = a_first;
        a_prev[a_first as usize] = g;
        a_next[gate as usize] = g;
        a_prev[g as usize] = gate;
        let bgate = if b_gate_at <= b_gate_back {
            walk(a_next, t, b_gate_at)
        } else {
            walk(a_prev, t, b_gate_back)
        };
        let at = self.stack.len() - i as usize;
        self.stack.insert(at, (bgate, u64::from(l)));
        self.gate = g;
        self.len = len - u64::from(l - 1) + 1;
        Ok(())
    }

    /// F(l) or H(l) (label `j`, face `f`): the face (or hole) of degree `l` ending at the
    /// gate is closed by a pair; its other half-edge replaces the face on the boundary.
    fn undo_face(&mut self, j: usize, lab: Label, l: u32, f: u32) -> Result<()> {
        let (gate, len) = (self.gate, self.len);
        if gate == NONE || l < 3 || len < u64::from(l) {
            return Err(bad(
                "labels",
                format!("label {j} ({lab:?}) does not fit the boundary (length {len})"),
            ));
        }
        let (g, t) = self.new_pair()?;
        let (a_next, a_prev) = (&mut self.a_next, &mut self.a_prev);
        let (next, face) = (&mut self.next, &mut self.face);
        let mut u1 = gate;
        for _ in 0..l - 2 {
            u1 = a_prev[u1 as usize];
        }
        let (p, n) = (a_prev[u1 as usize], a_next[gate as usize]);
        // Face cycle t -> u1 -> ... -> gate -> t.
        next[t as usize] = u1;
        face[t as usize] = f;
        let mut x = u1;
        loop {
            face[x as usize] = f;
            if x == gate {
                next[x as usize] = t;
                break;
            }
            next[x as usize] = a_next[x as usize];
            x = a_next[x as usize];
        }
        a_next[p as usize] = g;
        a_prev[g as usize] = p;
        a_next[g as usize] = n;
        a_prev[n as usize] = g;
        self.faces[f as usize] = RebuiltFace {
            first: t,
            degree: l,
            hole: matches!(lab, Label::H(_)),
            start: false,
        };
        self.gate = g;
        self.len = len - u64::from(l - 1) + 1;
        Ok(())
    }

    /// The component's first label, F(l0) (label `s`, face `f`): what is left of the active
    /// boundary must be exactly that face, which it becomes.
    fn close_start_face(&mut self, labels: &[Label], s: usize, f: u32) -> Result<()> {
        let Label::F(l0) = labels[s] else {
            unreachable!("component start checked above")
        };
        let len = self.len;
        if !self.stack.is_empty() || len != u64::from(l0) || l0 < 3 {
            return Err(bad(
                "labels",
                format!("component starting at label {s}: boundary of length {len} (stack {}) does not match the start face F{l0}", self.stack.len()),
            ));
        }
        let mut x = self.gate;
        for _ in 0..l0 {
            self.face[x as usize] = f;
            self.next[x as usize] = self.a_next[x as usize];
            x = self.a_next[x as usize];
        }
        self.faces[f as usize] = RebuiltFace {
            first: self.gate,
            degree: l0,
            hole: false,
            start: true,
        };
        Ok(())
    }
}

/// The vertices of a rebuilt structure (see [`number_vertices`]).
struct VertexNumbering {
    /// Tail vertex of every half-edge.
    vertex: Vec<u32>,
    count: u32,
    /// One outgoing half-edge per vertex.
    out: Vec<u32>,
    /// Number of union-find classes (an upper bound on the vertices, charged before `out`
    /// is allocated).
    roots: usize,
}

/// Root of `x`'s class in the union-find `p`, halving the path on the way.
fn find_root(p: &mut [u32], mut x: u32) -> u32 {
    while p[x as usize] != x {
        p[x as usize] = p[p[x as usize] as usize];
        x = p[x as usize];
    }
    x
}

/// Vertices: union-find over half-edge tails (next(h) and twin(h) both start at head(h)),
/// numbered by first appearance walking the mesh faces in order. The caller has charged the
/// union-find and `vertex`; the outgoing half-edges are charged here. Fails when a vertex
/// lies on hole faces only.
fn number_vertices(
    next: &[u32],
    twin: &[u32],
    faces: &[RebuiltFace],
    budget: &mut Budget,
) -> Result<VertexNumbering> {
    let nh = next.len();
    let mut parent: Vec<u32> = (0..nh as u32).collect();
    for h in 0..nh {
        let (a, b) = (
            find_root(&mut parent, next[h]),
            find_root(&mut parent, twin[h]),
        );
        if a != b {
            parent[a.max(b) as usize] = a.min(b);
        }
    }
    let mut id_of_root = vec![NONE; nh];
    let mut vertex = vec![NONE; nh];
    let mut vertex_count = 0u32;
    // At most one vertex per union-find root.
    let roots = (0..nh).filter(|&h| parent[h] == h as u32).count();
    budget.charge(REBUILD_MEMORY, 4 * roots as u64)?;
    let mut vertex_out = Vec::with_capacity(roots);
    for rf in faces.iter().filter(|f| !f.hole) {
        let mut h = rf.first;
        for _ in 0..rf.degree {
            let r = find_root(&mut parent, h) as usize;
            if id_of_root[r] == NONE {
                id_of_root[r] = vertex_count;
                vertex_count += 1;
                vertex_out.push(h);
            }
            h = next[h as usize];
        }
    }
    for (h, vh) in vertex.iter_mut().enumerate() {
        let r = find_root(&mut parent, h as u32) as usize;
        if id_of_root[r] == NONE {
            return Err(bad("labels", "a vertex lies on hole faces only"));
        }
        *vh = id_of_root[r];
    }
    Ok(VertexNumbering {
        vertex,
        count: vertex_count,
        out: vertex_out,
        roots,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::ControlMesh;
    use glam::DVec3;
    use Label::*;

    pub fn mesh_from(nv: usize, faces: &[Vec<u32>]) -> ControlMesh {
        let mut m = ControlMesh::new();
        for i in 0..nv {
            m.push_vertex(DVec3::new(i as f64, 0.0, 0.0));
        }
        let g = m.push_group("", Default::default());
        for f in faces {
            m.push_face(f, g);
        }
        m
    }

    fn cube_faces() -> Vec<Vec<u32>> {
        vec![
            vec![0, 2, 3, 1],
            vec![4, 5, 7, 6],
            vec![0, 1, 5, 4],
            vec![2, 6, 7, 3],
            vec![0, 4, 6, 2],
            vec![1, 3, 7, 5],
        ]
    }

    fn torus(n: u32, m: u32) -> Vec<Vec<u32>> {
        crate::codec::samples::torus(n, m)
            .faces()
            .map(<[u32]>::to_vec)
            .collect()
    }

    /// Encodes, rebuilds, and checks the rebuilt faces against the input (through the
    /// vertex mapping the traversal implies). Returns the labels and the rebuilt mesh faces.
    fn round_trip(nv: usize, faces: &[Vec<u32>]) -> (Vec<Label>, Vec<Vec<u32>>) {
        let m = mesh_from(nv, faces);
        let he = HalfEdgeMesh::build(&m).unwrap();
        let tr = encode_traversal(&he);
        let rb = rebuild(&tr.labels, &mut Budget::unlimited()).unwrap();
        assert_eq!(rb.faces.len(), tr.faces.len());
        let mut map = vec![NONE; rb.vertex_count];
        let mut out = Vec::new();
        for (i, rf) in rb.faces.iter().enumerate() {
            let (f, entry) = tr.faces[i];
            assert_eq!(rf.hole, he.is_hole_face(f));
            assert_eq!(rf.degree, he.face_degree[f as usize]);
            let mut h = entry;
            let verts: Vec<u32> = rb.face_vertices(i).collect();
            for &v in &verts {
                let orig = he.origin[h as usize];
                if map[v as usize] == NONE {
                    map[v as usize] = orig;
                }
                assert_eq!(map[v as usize], orig, "vertex mapping inconsistent");
                h = he.next[h as usize];
            }
            if !rf.hole {
                out.push(verts);
            }
        }
        (tr.labels, out)
    }

    #[test]
    fn tetrahedron_vector() {
        let faces = vec![vec![0, 2, 1], vec![0, 1, 3], vec![0, 3, 2], vec![1, 2, 3]];
        let (labels, out) = round_trip(4, &faces);
        assert_eq!(labels, vec![F(3), F(3), F(3), R, F(3), R, E]);
        assert_eq!(
            out,
            vec![vec![0, 1, 2], vec![1, 0, 3], vec![1, 3, 2], vec![2, 3, 0]]
        );
    }

    #[test]
    fn cube_vector() {
        let (labels, out) = round_trip(8, &cube_faces());
        assert_eq!(
            labels,
            vec![F(4), F(4), F(4), R, F(4), R, F(4), R, R, F(4), R, R, E]
        );
        assert_eq!(
            out,
            vec![
                vec![0, 1, 2, 3],
                vec![1, 0, 4, 5],
                vec![1, 5, 6, 2],
                vec![2, 6, 7, 3],
                vec![3, 7, 4, 0],
                vec![4, 7, 6, 5]
            ]
        );
    }

    #[test]
    fn open_box_vector() {
        let mut faces = cube_faces();
        faces.remove(1);
        let (labels, out) = round_trip(8, &faces);
        assert_eq!(
            labels,
            vec![F(4), F(4), F(4), R, F(4), R, F(4), R, R, H(4), R, R, E]
        );
        assert_eq!(out.len(), 5);
        assert_eq!(out[4], vec![3, 7, 4, 0]);
    }

    #[test]
    fn torus_vectors() {
        let (labels, _) = round_trip(12, &torus(4, 3));
        let m = M { i: 0, k: 2, l: 3 };
        assert_eq!(
            labels,
            vec![
                F(4),
                F(4),
                F(4),
                F(4),
                R,
                F(4),
                F(4),
                R,
                F(4),
                F(4),
                R,
                F(4),
                R,
                S,
                R,
                R,
                F(4),
                F(4),
                R,
                F(4),
                R,
                R,
                m,
                R,
                E
            ]
        );
        let (labels, _) = round_trip(20, &torus(5, 4));
        assert_eq!(labels.len(), 41);
        assert_eq!(labels.iter().filter(|l| **l == S).count(), 1);
        assert!(labels.contains(&M { i: 0, k: 2, l: 4 }));
    }

    #[test]
    fn open_cylinder_and_house_vectors() {
        let mut faces = Vec::new();
        for i in 0..2u32 {
            for j in 0..6u32 {
                faces.push(vec![
                    i * 6 + j,
                    i * 6 + (j + 1) % 6,
                    (i + 1) * 6 + (j + 1) % 6,
                    (i + 1) * 6 + j,
                ]);
            }
        }
        let (labels, _) = round_trip(18, &faces);
        let expected = [
            F(4),
            H(6),
            F(4),
            R,
            F(4),
            F(4),
            R,
            F(4),
            F(4),
            R,
            R,
            F(4),
            R,
            F(4),
            R,
            F(4),
            R,
            R,
            F(4),
            R,
            H(6),
            R,
            R,
            R,
            F(4),
            R,
            R,
            F(4),
            R,
            R,
            E,
        ];
        assert_eq!(labels, expected);
        let house = vec![
            vec![0, 2, 3, 1],
            vec![0, 1, 5, 4],
            vec![2, 6, 7, 3],
            vec![0, 4, 8, 6, 2],
            vec![1, 3, 7, 9, 5],
            vec![4, 5, 9, 8],
            vec![6, 8, 9, 7],
        ];
        let (labels, _) = round_trip(10, &house);
        assert_eq!(
            labels,
            vec![
                F(4),
                F(5),
                F(4),
                R,
                F(5),
                R,
                F(4),
                R,
                R,
                F(4),
                R,
                F(4),
                R,
                R,
                R,
                E
            ]
        );
    }

    #[test]
    fn genus_two_and_components() {
        // Two 5x4 tori glued along one removed face each: remove face 0 of each, and identify
        // the boundary loops.
        let t = torus(5, 4);
        let mut faces: Vec<Vec<u32>> = t[1..].to_vec();
        // Second torus: vertices 20..40, but its removed face's loop is identified with the
        // first torus's loop (reversed orientation).
        let hole = &t[0]; // (0, 4, 5, 1)
                          // The second torus is reversed, so its boundary runs opposite to the first one's.
        let map2 = |v: u32| -> u32 {
            if hole.contains(&v) {
                v
            } else {
                v + 20
            }
        };
        for f in &t[1..] {
            let mut g: Vec<u32> = f.iter().map(|&v| map2(v)).collect();
            g.reverse();
            faces.push(g);
        }
        let (labels, _) = round_trip(40, &faces);
        assert_eq!(labels.iter().filter(|l| matches!(l, M { .. })).count(), 2);
        // Plus a separate tetrahedron component.
        faces.push(vec![40, 42, 41]);
        faces.push(vec![40, 41, 43]);
        faces.push(vec![40, 43, 42]);
        faces.push(vec![41, 42, 43]);
        let (labels, out) = round_trip(44, &faces);
        assert_eq!(labels.iter().filter(|l| **l == E).count(), 2 + 1);
        assert_eq!(out.len(), faces.len());
    }

    #[test]
    fn garbage_labels_error_not_panic() {
        let cases: Vec<Vec<Label>> = vec![
            vec![R],
            vec![F(3), R],
            vec![F(3), E, E],
            vec![F(3), S, E],
            vec![F(4), F(3), E],
            vec![F(3), M { i: 3, k: 0, l: 2 }, E],
            vec![F(3), M { i: 0, k: 5, l: 2 }, E, E],
            vec![F(3), F(100), E],
            vec![F(2), E],
            vec![F(3), H(3), R, R, E],
        ];
        for c in cases {
            assert!(rebuild(&c, &mut Budget::unlimited()).is_err(), "{c:?}");
        }
    }

    fn label_strategy() -> impl proptest::strategy::Strategy<Value = Label> {
        use proptest::prelude::*;
        prop_oneof![
            (3u32..7).prop_map(F),
            (3u32..7).prop_map(H),
            Just(R),
            Just(L),
            Just(S),
            Just(E),
            (0u32..3, 0u32..6, 0u32..7).prop_map(|(i, k, l)| M { i, k, l }),
        ]
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 2000, ..Default::default() })]
        /// Arbitrary label sequences never panic; whatever rebuilds is a consistent closed
        /// half-edge structure.
        #[test]
        fn random_labels_never_panic(labels in proptest::collection::vec(label_strategy(), 0..60)) {
            if let Ok(rb) = rebuild(&labels, &mut Budget::unlimited()) {
                for h in 0..rb.next.len() {
                    assert_eq!(rb.twin[rb.twin[h] as usize] as usize, h);
                    assert_eq!(rb.prev[rb.next[h] as usize] as usize, h);
                    assert_eq!(rb.face[rb.next[h] as usize], rb.face[h]);
                }
            }
        }
    }
}
