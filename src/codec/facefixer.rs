//! Face Fixer connectivity coding (Isenburg & Snoeyink 2000), the variant fully specified in
//! `face-fixer.md` §3-§4 and `spec/format.md` §6: the encoder walks the mesh and emits one label
//! per edge (+1 per component); the decoder rebuilds the half-edge structure by undoing the
//! labels in reverse order.
//!
//! The encoder does not compute the decoder-side numbering itself: it runs [`rebuild`] on its own
//! labels and maps the result back, so encoder and decoder cannot disagree about face order,
//! vertex order or which label owns which edge.

use crate::error::{Error, Result};
use crate::mesh::topology::{HalfEdgeMesh, NONE};

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
pub struct Traversal {
    pub labels: Vec<Label>,
    /// Faces of the half-edge mesh (mesh and hole faces) in encoding order, each with the
    /// half-edge it was entered by (`t` in face-fixer.md; the start corner for start faces).
    pub faces: Vec<(u32, u32)>,
}

/// Runs the Face Fixer encoder over every connected component (start face: the lowest
/// unprocessed mesh face, start corner: its first corner).
pub fn encode_traversal(he: &HalfEdgeMesh) -> Traversal {
    let mut walk = TraversalWalk::new(he);
    for f0 in 0..he.real_face_count as u32 {
        if !walk.processed[f0 as usize] {
            walk.component(f0);
        }
    }
    Traversal {
        labels: walk.labels,
        faces: walk.faces,
    }
}

/// Cyclic doubly linked lists over half-edges: the boundary loops of the region the encoder
/// has processed, or the active and suspended boundaries while the decoder undoes labels.
struct Loops {
    next: Vec<u32>,
    prev: Vec<u32>,
}

impl Loops {
    /// Makes `b` follow `a`.
    fn link(&mut self, a: u32, b: u32) {
        self.next[a as usize] = b;
        self.prev[b as usize] = a;
    }
}

/// The encoder's state (face-fixer.md §3): the boundary loops of the processed region, the
/// loop id of every half-edge on one (`NONE` elsewhere), the current loop and its gate, and
/// the suspended loops of the current component as (loop id, gate).
struct TraversalWalk<'a> {
    he: &'a HalfEdgeMesh,
    loops: Loops,
    loop_of: Vec<u32>,
    processed: Vec<bool>,
    labels: Vec<Label>,
    faces: Vec<(u32, u32)>,
    next_id: u32,
    cur: u32,
    gate: u32,
    stack: Vec<(u32, u32)>,
}

impl<'a> TraversalWalk<'a> {
    /// Nothing processed yet.
    fn new(he: &'a HalfEdgeMesh) -> Self {
        let nh = he.origin.len();
        TraversalWalk {
            he,
            loops: Loops {
                next: vec![NONE; nh],
                prev: vec![NONE; nh],
            },
            loop_of: vec![NONE; nh],
            processed: vec![false; he.face_count()],
            labels: Vec::with_capacity(nh / 2 + 16),
            faces: Vec::with_capacity(he.face_count()),
            next_id: 0,
            cur: NONE,
            gate: NONE,
            stack: Vec::new(),
        }
    }

    /// Encodes the component of mesh face `f0`: its start label, then one label per gate
    /// until its last boundary loop closes.
    fn component(&mut self, f0: u32) {
        self.start(f0);
        while self.step() {}
    }

    /// Starts a component at mesh face `f0` and its first corner: the face's half-edges form
    /// the first boundary loop.
    fn start(&mut self, f0: u32) {
        let he = self.he;
        self.processed[f0 as usize] = true;
        let first = he.face_first[f0 as usize];
        self.faces.push((f0, first));
        self.labels.push(Label::F(he.face_degree[f0 as usize]));
        self.cur = self.next_id;
        self.next_id += 1;
        for h in he.face_half_edges(f0) {
            self.loops.link(h, he.next[h as usize]);
            self.loop_of[h as usize] = self.cur;
        }
        self.gate = first;
        self.stack.clear();
    }

    /// Emits the label of the current gate and moves on; false once the component's last
    /// loop has closed.
    fn step(&mut self) -> bool {
        let g = self.gate;
        let t = self.he.twin[g as usize];
        let u = self.he.face[t as usize];
        if !self.processed[u as usize] {
            self.fix_face(g, t, u);
            return true;
        }
        let lt = self.loop_of[t as usize];
        debug_assert_ne!(lt, NONE, "twin of the gate must be on a boundary");
        self.loop_of[g as usize] = NONE;
        self.loop_of[t as usize] = NONE;
        if lt == self.cur {
            self.zip(g, t)
        } else {
            self.merge(g, t, lt);
            true
        }
    }

    /// F / H: face `u` across the gate `g` (entered by `t`) joins the region; its other
    /// half-edges replace the gate in the current loop.
    fn fix_face(&mut self, g: u32, t: u32, u: u32) {
        let he = self.he;
        self.processed[u as usize] = true;
        self.faces.push((u, t));
        let l = he.face_degree[u as usize];
        let (p, n) = (self.loops.prev[g as usize], self.loops.next[g as usize]);
        let mut last = p;
        let mut x = he.next[t as usize];
        for _ in 0..l - 1 {
            self.loops.link(last, x);
            self.loop_of[x as usize] = self.cur;
            last = x;
            x = he.next[x as usize];
        }
        self.loops.link(last, n);
        self.loop_of[g as usize] = NONE;
        self.gate = last;
        self.labels.push(if he.is_hole_face(u) {
            Label::H(l)
        } else {
            Label::F(l)
        });
    }

    /// R, L, E or S: the gate `g` and its twin `t` are both on the current loop and are
    /// zipped. False when that closes the component's last loop.
    fn zip(&mut self, g: u32, t: u32) -> bool {
        let x_empty = self.loops.next[g as usize] == t;
        let y_empty = self.loops.next[t as usize] == g;
        if x_empty && y_empty {
            self.labels.push(Label::E);
            match self.stack.pop() {
                None => return false,
                Some((id, gt)) => {
                    self.cur = id;
                    self.gate = gt;
                }
            }
        } else if x_empty {
            let (p, n) = (self.loops.prev[g as usize], self.loops.next[t as usize]);
            self.loops.link(p, n);
            self.gate = p;
            self.labels.push(Label::R);
        } else if y_empty {
            let (p, n) = (self.loops.prev[t as usize], self.loops.next[g as usize]);
            self.loops.link(p, n);
            self.gate = p;
            self.labels.push(Label::L);
        } else {
            self.split(g, t);
        }
        true
    }

    /// S: zipping `g` with `t` elsewhere on the current loop splits it in two; the part
    /// after the gate stays current, the other is suspended.
    fn split(&mut self, g: u32, t: u32) {
        let (xf, xl) = (self.loops.next[g as usize], self.loops.prev[t as usize]);
        let (yf, yl) = (self.loops.next[t as usize], self.loops.prev[g as usize]);
        self.loops.link(xl, xf);
        self.loops.link(yl, yf);
        // Relabel the smaller part (walk both in lockstep) so the total work is O(n log n).
        let (mut px, mut py) = (xf, yf);
        let x_smaller = loop {
            px = self.loops.next[px as usize];
            if px == xf {
                break true;
            }
            py = self.loops.next[py as usize];
            if py == yf {
                break false;
            }
        };
        let id = self.next_id;
        self.next_id += 1;
        let relabel_from = if x_smaller { xf } else { yf };
        let mut x = relabel_from;
        loop {
            self.loop_of[x as usize] = id;
            x = self.loops.next[x as usize];
            if x == relabel_from {
                break;
            }
        }
        if x_smaller {
            self.stack.push((self.cur, yl));
            self.cur = id;
        } else {
            self.stack.push((id, yl));
        }
        self.gate = xl;
        self.labels.push(Label::S);
    }

    /// M: the gate's twin `t` is on the suspended loop `lt`, which is taken off the stack and
    /// joined into the current loop; the label gives its depth in the stack, the offset of
    /// `t` from its gate and its length.
    fn merge(&mut self, g: u32, t: u32, lt: u32) {
        let idx = self
            .stack
            .iter()
            .rposition(|&(id, _)| id == lt)
            .expect("boundary of the gate's twin is on the stack");
        let i = (self.stack.len() - 1 - idx) as u32;
        let (_, bgate) = self.stack.remove(idx);
        let mut x = bgate;
        let mut pos = 0u32;
        let mut k = 0u32;
        loop {
            if x == t {
                k = pos;
            }
            self.loop_of[x as usize] = self.cur;
            pos += 1;
            x = self.loops.next[x as usize];
            if x == bgate {
                break;
            }
        }
        self.loop_of[t as usize] = NONE;
        let l = pos;
        let (pg, ng) = (self.loops.prev[g as usize], self.loops.next[g as usize]);
        let (pt, nt) = (self.loops.prev[t as usize], self.loops.next[t as usize]);
        self.loops.link(pg, nt);
        self.loops.link(pt, ng);
        self.gate = pg;
        self.labels.push(Label::M { i, k, l });
    }
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

fn bad(field: &'static str, detail: impl Into<String>) -> Error {
    Error::format("connectivity", field, detail)
}

/// Undoes the labels (face-fixer.md §4). Every precondition is checked, so arbitrary label
/// sequences give an error, never a panic.
pub fn rebuild(labels: &[Label]) -> Result<Rebuilt> {
    let components = split_components(labels)?;
    let mut undo = Undo::new(labels, components.face_of_label, components.face_count);
    for &(s, e) in &components.ranges {
        undo.component(s, e)?;
    }
    undo.finish()
}

/// The labels cut into connected components, and the face each F or H label creates.
struct Components {
    /// Label ranges `start..end`, one per component.
    ranges: Vec<(usize, usize)>,
    /// Face number of every F and H label in label order; `NONE` for the others.
    face_of_label: Vec<u32>,
    face_count: u32,
}

/// Forward pass over the labels: a component starts with F and ends when its open
/// boundaries (one more per S, one fewer per M or E) reach zero.
fn split_components(labels: &[Label]) -> Result<Components> {
    let mut ranges = Vec::new();
    let mut open = 0u64;
    let mut start = 0usize;
    let mut face_of_label = vec![NONE; labels.len()];
    let mut nfaces = 0u32;
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
        } else {
            match lab {
                Label::S => open += 1,
                Label::M { .. } | Label::E => open -= 1,
                _ => {}
            }
        }
        if matches!(lab, Label::F(_) | Label::H(_)) {
            face_of_label[j] = nfaces;
            nfaces += 1;
        }
        if open == 0 {
            ranges.push((start, j + 1));
        }
    }
    if open != 0 {
        return Err(bad("labels", "the last component does not end with E"));
    }
    Ok(Components {
        ranges,
        face_of_label,
        face_count: nfaces,
    })
}

/// The half-edge structure while the labels are undone: half-edges in creation order (each
/// label creates one edge, as a pair of twins), the faces finished so far, and the
/// boundaries still open as linked loops.
struct Undo<'a> {
    labels: &'a [Label],
    face_of_label: Vec<u32>,
    next: Vec<u32>,
    twin: Vec<u32>,
    face: Vec<u32>,
    boundary: Loops,
    faces: Vec<RebuiltFace>,
    label_edge: Vec<u32>,
}

/// The active boundary of the component being rebuilt: its gate (`NONE` before the first
/// undone label), its length, and the suspended boundaries as (gate, length).
struct ActiveBoundary {
    gate: u32,
    len: u64,
    stack: Vec<(u32, u64)>,
}

impl<'a> Undo<'a> {
    /// No half-edges yet; `face_of_label` and `face_count` as [`split_components`] found.
    fn new(labels: &'a [Label], face_of_label: Vec<u32>, face_count: u32) -> Self {
        Undo {
            labels,
            face_of_label,
            next: Vec::new(),
            twin: Vec::new(),
            face: Vec::new(),
            boundary: Loops {
                next: Vec::new(),
                prev: Vec::new(),
            },
            faces: vec![
                RebuiltFace {
                    first: NONE,
                    degree: 0,
                    hole: false,
                    start: false
                };
                face_count as usize
            ],
            label_edge: vec![NONE; labels.len()],
        }
    }

    /// A new edge: two twin half-edges `(g, t)`, in no face or boundary yet.
    fn new_pair(&mut self) -> Result<(u32, u32)> {
        let g = self.next.len();
        if g + 2 >= NONE as usize {
            return Err(bad("labels", "too many half-edges"));
        }
        for _ in 0..2 {
            self.next.push(NONE);
            self.face.push(NONE);
            self.boundary.next.push(NONE);
            self.boundary.prev.push(NONE);
        }
        self.twin.push(g as u32 + 1);
        self.twin.push(g as u32);
        Ok((g as u32, g as u32 + 1))
    }

    /// Undoes the labels `s..e` of one component, last first, then closes its start face.
    fn component(&mut self, s: usize, e: usize) -> Result<()> {
        let mut b = ActiveBoundary {
            gate: NONE,
            len: 0,
            stack: Vec::new(),
        };
        for j in (s + 1..e).rev() {
            let lab = self.labels[j];
            let g = match lab {
                Label::E => self.undo_end(&mut b)?,
                Label::R | Label::L => self.undo_zip(&mut b, j, lab)?,
                Label::S => self.undo_split(&mut b, j)?,
                Label::M { i, k, l } => self.undo_merge(&mut b, j, i, k, l)?,
                Label::F(l) | Label::H(l) => self.undo_face(&mut b, j, lab, l)?,
            };
            // The half-edge of the label's edge that lies on the boundary is the new gate.
            b.gate = g;
            self.label_edge[j] = g;
        }
        self.close_start_face(&b, s)
    }

    /// E: a new boundary of one edge; the active one (if any) is suspended.
    fn undo_end(&mut self, b: &mut ActiveBoundary) -> Result<u32> {
        if b.gate != NONE {
            b.stack.push((b.gate, b.len));
        }
        let (g, t) = self.new_pair()?;
        self.boundary.link(g, t);
        self.boundary.link(t, g);
        b.len = 2;
        Ok(g)
    }

    /// R or L: a new edge inserted after the gate, its gate half-edge first (R) or second (L).
    fn undo_zip(&mut self, b: &mut ActiveBoundary, j: usize, lab: Label) -> Result<u32> {
        if b.gate == NONE {
            return Err(bad(
                "labels",
                format!("label {j} ({lab:?}) on an empty boundary"),
            ));
        }
        let (g, t) = self.new_pair()?;
        let (first, second) = if lab == Label::R { (g, t) } else { (t, g) };
        let n = self.boundary.next[b.gate as usize];
        self.boundary.link(b.gate, first);
        self.boundary.link(first, second);
        self.boundary.link(second, n);
        b.len += 2;
        Ok(g)
    }

    /// S: the top suspended boundary is joined to the active one by a new edge.
    fn undo_split(&mut self, b: &mut ActiveBoundary, j: usize) -> Result<u32> {
        let Some((gy, leny)) = b.stack.pop() else {
            return Err(bad(
                "labels",
                format!("label {j} (S) without a suspended boundary"),
            ));
        };
        if b.gate == NONE {
            return Err(bad("labels", format!("label {j} (S) on an empty boundary")));
        }
        let (g, t) = self.new_pair()?;
        let xf = self.boundary.next[b.gate as usize];
        let yf = self.boundary.next[gy as usize];
        self.boundary.link(g, xf);
        self.boundary.link(b.gate, t);
        self.boundary.link(t, yf);
        self.boundary.link(gy, g);
        b.len += leny + 2;
        Ok(g)
    }

    /// M(i, k, l): a new edge cuts the `l - 1` elements after the gate off the active
    /// boundary; they and the edge's twin form a boundary of length `l`, suspended at depth
    /// `i` with its gate `k` elements from the twin.
    fn undo_merge(
        &mut self,
        b: &mut ActiveBoundary,
        j: usize,
        i: u32,
        k: u32,
        l: u32,
    ) -> Result<u32> {
        let gate = b.gate;
        if gate == NONE
            || l < 2
            || k >= l
            || u64::from(l) > b.len.saturating_sub(1) + 1
            || b.len < u64::from(l)
            || i as usize > b.stack.len()
        {
            return Err(bad(
                "labels",
                format!(
                    "label {j} M(i={i}, k={k}, l={l}) does not fit the boundary (length {}, stack depth {})",
                    b.len,
                    b.stack.len()
                ),
            ));
        }
        let (g, t) = self.new_pair()?;
        // Bpart: the l-1 elements after the gate; Apart: the rest, ending at the gate.
        let b1 = self.boundary.next[gate as usize];
        let mut blast = gate;
        for _ in 0..l - 1 {
            blast = self.boundary.next[blast as usize];
        }
        let a_first = self.boundary.next[blast as usize];
        // B = [t, b1 .. blast]
        self.boundary.link(t, b1);
        self.boundary.link(blast, t);
        // A = [g, a_first .. gate]
        self.boundary.link(g, a_first);
        self.boundary.link(gate, g);
        let mut bgate = t;
        for _ in 0..(l - k) % l {
            bgate = self.boundary.next[bgate as usize];
        }
        let at = b.stack.len() - i as usize;
        b.stack.insert(at, (bgate, u64::from(l)));
        b.len = b.len - u64::from(l - 1) + 1;
        Ok(g)
    }

    /// F(l) or H(l): the face (or hole) of the label is the gate and the `l - 2` boundary
    /// elements before it, closed by a new edge whose other half-edge replaces them.
    fn undo_face(&mut self, b: &mut ActiveBoundary, j: usize, lab: Label, l: u32) -> Result<u32> {
        let gate = b.gate;
        if gate == NONE || l < 3 || b.len < u64::from(l) {
            return Err(bad(
                "labels",
                format!(
                    "label {j} ({lab:?}) does not fit the boundary (length {})",
                    b.len
                ),
            ));
        }
        let f = self.face_of_label[j];
        let (g, t) = self.new_pair()?;
        let mut u1 = gate;
        for _ in 0..l - 2 {
            u1 = self.boundary.prev[u1 as usize];
        }
        let (p, n) = (
            self.boundary.prev[u1 as usize],
            self.boundary.next[gate as usize],
        );
        // Face cycle t -> u1 -> ... -> gate -> t.
        self.next[t as usize] = u1;
        self.face[t as usize] = f;
        let mut x = u1;
        loop {
            self.face[x as usize] = f;
            if x == gate {
                self.next[x as usize] = t;
                break;
            }
            self.next[x as usize] = self.boundary.next[x as usize];
            x = self.boundary.next[x as usize];
        }
        self.boundary.link(p, g);
        self.boundary.link(g, n);
        self.faces[f as usize] = RebuiltFace {
            first: t,
            degree: l,
            hole: matches!(lab, Label::H(_)),
            start: false,
        };
        b.len = b.len - u64::from(l - 1) + 1;
        Ok(g)
    }

    /// What is left of a component's boundary must be exactly its start face (label `s`).
    fn close_start_face(&mut self, b: &ActiveBoundary, s: usize) -> Result<()> {
        let Label::F(l0) = self.labels[s] else {
            unreachable!("component start checked above")
        };
        if !b.stack.is_empty() || b.len != u64::from(l0) || l0 < 3 {
            return Err(bad(
                "labels",
                format!("component starting at label {s}: boundary of length {} (stack {}) does not match the start face F{l0}", b.len, b.stack.len()),
            ));
        }
        let f = self.face_of_label[s];
        let mut x = b.gate;
        for _ in 0..l0 {
            self.face[x as usize] = f;
            self.next[x as usize] = self.boundary.next[x as usize];
            x = self.boundary.next[x as usize];
        }
        self.faces[f as usize] = RebuiltFace {
            first: b.gate,
            degree: l0,
            hole: false,
            start: true,
        };
        Ok(())
    }

    /// Checks that every half-edge ended up in a face and derives `prev` and the vertices.
    fn finish(self) -> Result<Rebuilt> {
        let nh = self.next.len();
        if let Some(h) = self.next.iter().position(|&n| n == NONE) {
            return Err(bad("labels", format!("half-edge {h} ends up in no face")));
        }
        let mut prev = vec![NONE; nh];
        for h in 0..nh {
            prev[self.next[h] as usize] = h as u32;
        }
        let vertices = number_vertices(&self.next, &self.twin, &self.faces)?;
        Ok(Rebuilt {
            next: self.next,
            prev,
            twin: self.twin,
            face: self.face,
            vertex: vertices.of_half_edge,
            faces: self.faces,
            label_edge: self.label_edge,
            vertex_count: vertices.count,
            vertex_out: vertices.out,
        })
    }
}

/// The vertices of a rebuilt structure.
struct Vertices {
    /// Tail vertex of every half-edge.
    of_half_edge: Vec<u32>,
    count: usize,
    /// One outgoing half-edge per vertex.
    out: Vec<u32>,
}

/// Finds the vertices as classes of half-edge tails (`next(h)` and `twin(h)` both start at
/// the head of `h`) and numbers them by first appearance walking the mesh faces in order.
fn number_vertices(next: &[u32], twin: &[u32], faces: &[RebuiltFace]) -> Result<Vertices> {
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
    let mut vertex_out = Vec::new();
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
    Ok(Vertices {
        of_half_edge: vertex,
        count: vertex_count as usize,
        out: vertex_out,
    })
}

/// Union-find root of `x`, halving the path on the way.
fn find_root(p: &mut [u32], mut x: u32) -> u32 {
    while p[x as usize] != x {
        p[x as usize] = p[p[x as usize] as usize];
        x = p[x as usize];
    }
    x
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
        let rb = rebuild(&tr.labels).unwrap();
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
            assert!(rebuild(&c).is_err(), "{c:?}");
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
            if let Ok(rb) = rebuild(&labels) {
                for h in 0..rb.next.len() {
                    assert_eq!(rb.twin[rb.twin[h] as usize] as usize, h);
                    assert_eq!(rb.prev[rb.next[h] as usize] as usize, h);
                    assert_eq!(rb.face[rb.next[h] as usize], rb.face[h]);
                }
            }
        }
    }
}
