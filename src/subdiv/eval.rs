//! Position evaluation: subdivision masks, limit masks and limit normals over one level.
//!
//! Masks are produced by `*_mask(.., emit)` functions that call `emit(index, weight)`; the
//! same producers drive position evaluation (Cartesian sums, or a frame combination for
//! cylinder/cone patches) and the sparse stencils, so there is one implementation of each
//! rule.

use std::f64::consts::PI;

use glam::DVec3;

use super::frame::Frame;
use super::masks::{crease_limit_weights, eclass, normalize_or_zero, vclass, ValenceTables};
use super::next_level::Connectivity;
use super::topology::{Base, NONE};

/// Subdivision mask of old vertex `v` (its new position at the next level).
#[inline]
pub(crate) fn vertex_mask(
    l: &impl Connectivity,
    t: &ValenceTables,
    v: usize,
    emit: &mut impl FnMut(u32, f64),
) {
    let c = l.vertex_class(v);
    if vclass::is_smooth_rule(c) {
        let ring = l.ring_edges(v);
        let k = ring.len();
        let b = t.beta(k);
        emit(v as u32, 1.0 - k as f64 * b);
        for e in ring {
            emit(l.other_end(e, v as u32), b);
        }
    } else if vclass::is_crease(c) {
        emit(v as u32, 0.75);
        for e in l.ring_edges(v) {
            if l.edge_class(e as usize) & eclass::CREASE != 0 {
                emit(l.other_end(e, v as u32), 0.125);
            }
        }
    } else {
        emit(v as u32, 1.0);
    }
}

/// Subdivision mask of the new vertex on edge `e`.
#[inline]
pub(crate) fn edge_mask(l: &impl Connectivity, e: usize, emit: &mut impl FnMut(u32, f64)) {
    let [a, b] = l.edge_ends(e);
    let rule = l.edge_class(e) & eclass::RULE_MASK;
    let [fl, fr] = l.edge_faces(e);
    if rule == eclass::SMOOTH && fr != NONE {
        emit(a, 0.375);
        emit(b, 0.375);
        emit(l.opposite_vertex(fl, e as u32), 0.125);
        emit(l.opposite_vertex(fr, e as u32), 0.125);
    } else {
        let (wa, wb) = eclass::pair_weights(rule);
        emit(a, wa);
        emit(b, wb);
    }
}

/// Small fixed buffer of `(point, weight)` for frame combinations (framed masks have at
/// most 4 terms; longer masks fall back to the Cartesian sum).
struct Terms {
    buf: [(DVec3, f64); 8],
    n: usize,
    overflow: bool,
}

impl Terms {
    #[inline]
    fn new() -> Self {
        Terms {
            buf: [(DVec3::ZERO, 0.0); 8],
            n: 0,
            overflow: false,
        }
    }
    #[inline]
    fn push(&mut self, p: DVec3, w: f64) {
        if self.n < self.buf.len() {
            self.buf[self.n] = (p, w);
            self.n += 1;
        } else {
            self.overflow = true;
        }
    }
    fn finish(&self, frame: &Frame) -> Option<DVec3> {
        (!self.overflow).then(|| frame.combine(&self.buf[..self.n]))
    }
}

#[inline]
fn frame_of(base: &Base, id: u16) -> Option<&Frame> {
    if id == 0 {
        None
    } else {
        base.frames.get(id as usize - 1)
    }
}

/// Position of the new vertex `v` (old vertex rule) from level positions `p`.
#[inline]
pub(crate) fn eval_vertex(
    l: &impl Connectivity,
    t: &ValenceTables,
    base: &Base,
    p: &(impl std::ops::Index<usize, Output = DVec3> + ?Sized),
    v: usize,
) -> DVec3 {
    let mut acc = DVec3::ZERO;
    if let Some(fr) = frame_of(base, l.vertex_frame(v)) {
        let mut terms = Terms::new();
        vertex_mask(l, t, v, &mut |i, w| {
            acc += p[i as usize] * w;
            terms.push(p[i as usize], w);
        });
        return terms.finish(fr).unwrap_or(acc);
    }
    vertex_mask(l, t, v, &mut |i, w| acc += p[i as usize] * w);
    acc
}

/// Position of the new vertex on edge `e`.
#[inline]
pub(crate) fn eval_edge(
    l: &impl Connectivity,
    base: &Base,
    p: &(impl std::ops::Index<usize, Output = DVec3> + ?Sized),
    e: usize,
) -> DVec3 {
    let mut acc = DVec3::ZERO;
    if let Some(fr) = frame_of(base, l.edge_frame(e)) {
        let mut terms = Terms::new();
        edge_mask(l, e, &mut |i, w| {
            acc += p[i as usize] * w;
            terms.push(p[i as usize], w);
        });
        return terms.finish(fr).unwrap_or(acc);
    }
    edge_mask(l, e, &mut |i, w| acc += p[i as usize] * w);
    acc
}

/// The two crease ring edges of a crease vertex, in ring order.
#[inline]
fn crease_pair(l: &impl Connectivity, v: usize) -> Option<(u32, u32)> {
    let mut it = l
        .ring_edges(v)
        .filter(|&e| l.edge_class(e as usize) & eclass::CREASE != 0);
    Some((it.next()?, it.next()?))
}

/// Limit mask (Cartesian composition) of vertex `v` at this level (reference §4.1-4.2).
pub(crate) fn limit_mask(
    l: &impl Connectivity,
    t: &ValenceTables,
    v: usize,
    emit: &mut impl FnMut(u32, f64),
) {
    let c = l.vertex_class(v);
    if vclass::is_smooth_rule(c) {
        let ring = l.ring_edges(v);
        let (wc, wn) = t.limit(ring.len());
        emit(v as u32, wc);
        for e in ring {
            emit(l.other_end(e, v as u32), wn);
        }
    } else if vclass::is_crease(c) {
        let Some((ea, eb)) = crease_pair(l, v) else {
            emit(v as u32, 1.0);
            return;
        };
        let (ws, wc) = crease_limit_weights(c == vclass::CREASE_REGULAR);
        vertex_mask(l, t, v, &mut |i, w| emit(i, w * wc));
        edge_mask(l, ea as usize, &mut |i, w| emit(i, w * ws));
        edge_mask(l, eb as usize, &mut |i, w| emit(i, w * ws));
    } else {
        emit(v as u32, 1.0);
    }
}

/// Limit position of vertex `v` from level positions `p`.
pub(crate) fn eval_limit(
    l: &impl Connectivity,
    t: &ValenceTables,
    base: &Base,
    p: &(impl std::ops::Index<usize, Output = DVec3> + ?Sized),
    v: usize,
) -> DVec3 {
    let c = l.vertex_class(v);
    if vclass::is_crease(c) {
        if let Some(fr) = frame_of(base, l.vertex_frame(v)) {
            if let Some((ea, eb)) = crease_pair(l, v) {
                let (ws, wc) = crease_limit_weights(c == vclass::CREASE_REGULAR);
                let vp = eval_vertex(l, t, base, p, v);
                let a = eval_edge(l, base, p, ea as usize);
                let b = eval_edge(l, base, p, eb as usize);
                return fr.combine(&[(a, ws), (vp, wc), (b, ws)]);
            }
        }
    }
    let mut acc = DVec3::ZERO;
    limit_mask(l, t, v, &mut |i, w| acc += p[i as usize] * w);
    acc
}

/// Frame of the boundary patch containing face `f` of level `j`, if any.
#[inline]
fn face_frame(base: &Base, j: u32, f: u32) -> Option<&Frame> {
    let b = (f as usize) >> (2 * j);
    if base.boundary_patch[b] {
        frame_of(base, base.group_frame[base.group[b] as usize])
    } else {
        None
    }
}

/// Face of wedge `i` of `v`'s ring (between ring edges i and i+1).
#[inline]
pub(crate) fn wedge_face(l: &impl Connectivity, v: usize, e: u32) -> u32 {
    let [a, _] = l.edge_ends(e as usize);
    let ef = l.edge_faces(e as usize);
    if a as usize == v {
        ef[0]
    } else {
        ef[1]
    }
}

/// Limit normal of vertex `v` at level `j` (reference §5). Crease and corner vertices get
/// the normalised mean of their sector normals, or with `wedge = Some(i)` the normal of the
/// sector containing ring wedge i (the face between ring edges i and i+1).
pub(crate) fn eval_normal(
    l: &impl Connectivity,
    t: &ValenceTables,
    base: &Base,
    j: u32,
    p: &(impl std::ops::Index<usize, Output = DVec3> + ?Sized),
    v: usize,
    wedge: Option<usize>,
) -> DVec3 {
    let c = l.vertex_class(v);
    // The ring and its points on the stack (valences above 32 are rare enough to allocate):
    // every rule below reads the points several times.
    let (mut small, mut large) = ([0u32; 32], Vec::new());
    let it = l.ring_edges(v);
    let ring: &[u32] = if it.len() <= small.len() {
        let n = it.len();
        for (s, e) in small.iter_mut().zip(it) {
            *s = e;
        }
        &small[..n]
    } else {
        large.extend(it);
        &large
    };
    if ring.is_empty() {
        return DVec3::ZERO;
    }
    let (mut small_pts, mut large_pts) = ([DVec3::ZERO; 32], Vec::new());
    let pts: &[DVec3] = if ring.len() <= small_pts.len() {
        for (q, &e) in small_pts.iter_mut().zip(ring) {
            *q = p[l.other_end(e, v as u32) as usize];
        }
        &small_pts[..ring.len()]
    } else {
        large_pts.extend(ring.iter().map(|&e| p[l.other_end(e, v as u32) as usize]));
        &large_pts
    };
    let pv = p[v];
    let is_boundary = l.edge_faces(ring[0] as usize)[1] == NONE;
    let nw = if is_boundary {
        ring.len() - 1
    } else {
        ring.len()
    };
    let ring_pt = |i: usize| pts[i % pts.len()];
    if vclass::is_smooth_rule(c) && !is_boundary {
        let k = ring.len();
        let (mut t1, mut t2) = (DVec3::ZERO, DVec3::ZERO);
        for (i, &q) in pts.iter().enumerate() {
            let (co, s) = t.cos_sin(k, i);
            t1 += q * co;
            t2 += q * s;
        }
        let n = t1.cross(t2);
        let n = if n.dot(fan_normal(&mut |i| ring_pt(i), pv, 0, nw)) < 0.0 {
            -n
        } else {
            n
        };
        return normalize_or_zero(n);
    }
    if c == vclass::FIXED || !(vclass::is_crease(c) || c == vclass::CORNER) {
        let fan = fan_normal(&mut |i| ring_pt(i), pv, 0, nw);
        let framed = (0..nw).find_map(|i| face_frame(base, j, wedge_face(l, v, ring[i])));
        if let Some(fr) = framed {
            let n = fr.surface_normal(pv);
            if n != DVec3::ZERO {
                return if n.dot(fan) < 0.0 { -n } else { n };
            }
        }
        return normalize_or_zero(fan);
    }
    crease_normal(l, t, base, j, p, v, wedge, ring, nw, &mut |i| ring_pt(i))
}

/// Area-weighted normal sum of the wedges `[i0, i0 + n)` of the fan of points `pts(i)` about
/// `centre`.
#[inline]
fn fan_normal(pts: &mut impl FnMut(usize) -> DVec3, centre: DVec3, i0: usize, n: usize) -> DVec3 {
    let mut s = DVec3::ZERO;
    for i in i0..i0 + n {
        s += (pts(i) - centre).cross(pts(i + 1) - centre);
    }
    s
}

/// [`eval_normal`] of a crease or corner vertex `v` with ring `ring` (`nw` wedges) and ring
/// points `ring_pt`.
#[allow(clippy::too_many_arguments)]
fn crease_normal(
    l: &impl Connectivity,
    t: &ValenceTables,
    base: &Base,
    j: u32,
    p: &(impl std::ops::Index<usize, Output = DVec3> + ?Sized),
    v: usize,
    wedge: Option<usize>,
    ring: &[u32],
    nw: usize,
    ring_pt: &mut impl FnMut(usize) -> DVec3,
) -> DVec3 {
    let c = l.vertex_class(v);
    let pv = p[v];
    // Crease / corner: one step later (reference §5.2-5.3).
    let vp = eval_vertex(l, t, base, p, v);
    // The next level's points on the ring edges, each made once: the sectors read each
    // several times (their fans, tangents and neighbours).
    let (mut small, mut large) = ([None; 32], Vec::new());
    let made: &mut [Option<DVec3>] = if ring.len() <= small.len() {
        &mut small[..ring.len()]
    } else {
        large.resize(ring.len(), None);
        &mut large
    };
    let mut q = |i: usize| {
        let i = i % ring.len();
        *made[i].get_or_insert_with(|| eval_edge(l, base, p, ring[i] as usize))
    };
    // The limit point, made once for every framed boundary-patch sector.
    let mut limit = None;
    let is_crease_edge =
        |i: usize| l.edge_class(ring[i % ring.len()] as usize) & eclass::CREASE != 0;
    let Some(start) = (0..ring.len()).find(|&i| is_crease_edge(i)) else {
        // a tagged corner without creases: no curve tangents; use the fan normal
        return normalize_or_zero(fan_normal(ring_pt, pv, 0, nw));
    };
    let mut total = DVec3::ZERO;
    let mut i = 0;
    while i < nw {
        // sector: wedges from start+i until the next crease edge
        let s0 = start + i;
        let mut nt = 1;
        while i + nt < nw && !is_crease_edge(s0 + nt) {
            nt += 1;
        }
        let fan = fan_normal(&mut q, vp, s0, nt);
        let framed = face_frame(base, j, wedge_face(l, v, ring[s0 % ring.len()]));
        let in_bp = {
            let f = wedge_face(l, v, ring[s0 % ring.len()]) as usize;
            base.boundary_patch[f >> (2 * j)]
        };
        let mut n = DVec3::ZERO;
        if let (true, Some(fr)) = (in_bp, framed) {
            // analytic normal at the vertex's limit point
            n = fr.surface_normal(*limit.get_or_insert_with(|| eval_limit(l, t, base, p, v)));
        } else if in_bp {
            n = fan;
        } else if c == vclass::CORNER {
            let (ta, tb) = (q(s0) - vp, q(s0 + nt) - vp);
            let cr = ta.cross(tb);
            if cr.length() > 1e-3 * ta.length() * tb.length() {
                n = cr;
            }
        }
        if n == DVec3::ZERO {
            let p0 = q(s0);
            let pn = q(s0 + nt);
            let along = p0 - pn;
            let across = if nt == 1 {
                p0 + pn - 2.0 * vp
            } else if nt == 2 {
                q(s0 + 1) - vp
            } else if nt == 3 && c == vclass::CREASE_REGULAR {
                2.0 * vp + p0 + pn - 2.0 * q(s0 + 1) - 2.0 * q(s0 + 2)
            } else {
                let th = PI / nt as f64;
                let mut a = (p0 + pn) * th.sin();
                for m in 1..nt {
                    a += q(s0 + m) * ((2.0 * th.cos() - 2.0) * (m as f64 * th).sin());
                }
                a
            };
            n = along.cross(across);
        }
        if n.length_squared() <= 1e-24 * fan.length_squared() {
            // degenerate tangents (e.g. a corner with a single crease edge)
            n = fan;
        }
        if n.dot(fan) < 0.0 {
            n = -n;
        }
        if let Some(w) = wedge {
            let rel = (w + ring.len() - start) % ring.len();
            if (i..i + nt).contains(&rel) {
                return normalize_or_zero(n);
            }
        }
        total += normalize_or_zero(n);
        i += nt;
    }
    normalize_or_zero(total)
}
