//! Quantisation and predictive coding of vertex positions (`spec/format.md` §8).
//!
//! Everything after quantisation is integer arithmetic, so encoder and decoder compute the same
//! predictions on every platform. One routine ([`walk`]) drives both directions through the
//! [`ResidualCoder`] trait, so the two sides cannot drift apart.

use glam::DVec3;

use super::facefixer::Rebuilt;
#[cfg(any(feature = "encoder", feature = "internals"))]
use super::rangecoder::RangeEncoder;
use super::rangecoder::{unzigzag, zigzag, BitModel, IntModel, RangeDecoder};
use super::Budget;
use crate::error::{Error, Result};
use crate::mesh::topology::NONE;

/// Node-convention quantiser over a cube: `q = round((x - min) / step)`, `x = min + q * step`,
/// `step = extent / (2^bits - 1)` (geometry-coding.md §1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantizer {
    pub min: [f64; 3],
    pub extent: f64,
    pub bits: u8,
    /// Whether min/extent are stored as f32 (exactly representable) or f64.
    pub as_f32: bool,
}

impl Quantizer {
    /// Chooses the box for `positions`: f32 storage when that loses (almost) nothing. The
    /// box's extent is the positions' extent times `step_scale` (>= 1), which scales the step.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn for_positions(positions: &[DVec3], bits: u8, step_scale: f64) -> Self {
        let Some(first) = positions.first() else {
            return Quantizer {
                min: [0.0; 3],
                extent: 0.0,
                bits,
                as_f32: true,
            };
        };
        let (lo, hi) = positions
            .iter()
            .fold((*first, *first), |(lo, hi), &p| (lo.min(p), hi.max(p)));
        let extent64 = (hi - lo).max_element() * step_scale.max(1.0);
        // f32 candidate: min rounded down, extent rounded up so the box still covers everything.
        let min32: [f64; 3] = [0, 1, 2].map(|i| f32_round_down(lo[i]));
        let need = (0..3).map(|i| hi[i] - min32[i]).fold(0.0f64, f64::max) * step_scale.max(1.0);
        let extent32 = f32_round_up(need);
        let ok32 = min32.iter().all(|v| v.is_finite())
            && extent32.is_finite()
            && extent32 <= extent64 * (1.0 + 1e-4) + f64::MIN_POSITIVE;
        if ok32 {
            Quantizer {
                min: min32,
                extent: extent32,
                bits,
                as_f32: true,
            }
        } else {
            Quantizer {
                min: lo.to_array(),
                extent: extent64,
                bits,
                as_f32: false,
            }
        }
    }

    pub fn max_q(&self) -> i32 {
        ((1u32 << self.bits) - 1) as i32
    }

    /// Grid step (0 for a degenerate box).
    pub fn step(&self) -> f64 {
        self.extent / f64::from(self.max_q())
    }

    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn quantize(&self, p: DVec3) -> [i32; 3] {
        let step = self.step();
        [0, 1, 2].map(|i| {
            if step > 0.0 {
                let q = ((p[i] - self.min[i]) / step).round();
                q.clamp(0.0, f64::from(self.max_q())) as i32
            } else {
                0
            }
        })
    }

    pub fn dequantize(&self, q: [i32; 3]) -> DVec3 {
        let step = self.step();
        DVec3::new(
            self.min[0] + f64::from(q[0]) * step,
            self.min[1] + f64::from(q[1]) * step,
            self.min[2] + f64::from(q[2]) * step,
        )
    }
}

/// Largest f32 <= x (x finite and within the f32 range, else the result is not finite).
#[cfg(any(feature = "encoder", feature = "internals"))]
fn f32_round_down(x: f64) -> f64 {
    let f = x as f32;
    let f = if f64::from(f) > x {
        f32_step(f, false)
    } else {
        f
    };
    f64::from(f)
}

/// Smallest f32 >= x.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn f32_round_up(x: f64) -> f64 {
    let f = x as f32;
    let f = if f64::from(f) < x {
        f32_step(f, true)
    } else {
        f
    };
    f64::from(f)
}

/// The next representable f32 above (`up`) or below a finite `f`.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn f32_step(f: f32, up: bool) -> f32 {
    if f == 0.0 {
        let tiny = f32::from_bits(1);
        return if up { tiny } else { -tiny };
    }
    let bits = f.to_bits();
    // Moving away from zero increments the magnitude bits.
    if (f > 0.0) == up {
        f32::from_bits(bits + 1)
    } else {
        f32::from_bits(bits - 1)
    }
}

/// Prediction classes (first part of the residual context): how many parallelogram-type
/// predictions were offered (1, 2, 3+), or a fallback (average of decoded neighbours, or no
/// decoded neighbour at all); from version 2 also predictions along a crease (one, or two and
/// more). Residuals of each class have their own spread, hence their own models.
const KIND_NEIGHBOURS: usize = 0;
const KIND_START: usize = 4;
/// Plane-predicted coordinates (§8.3) take the context block after the version-1 kinds, so the
/// version-1 context numbering is unchanged.
const PLANE_CTX: usize = 5;
const KIND_CREASE_ONE: usize = 6;
const KIND_CREASE_MORE: usize = 7;
/// Version 3: at least one of the crease predictions follows a circle around a cylinder or
/// cone axis (§8.2, *arc candidates*).
const KIND_ARC: usize = 8;
/// Context count: (kind or plane) x magnitude bucket.
const CONTEXTS: usize = (KIND_ARC + 1) * 3;
/// Vertices are visited by the number of decoded neighbours, capped at this.
const MAX_LEVEL: usize = 6;

/// Codes (encoder) or recovers (decoder) one quantised coordinate.
pub trait ResidualCoder {
    /// `slot` holds the actual value when encoding and receives it when decoding. Returns the
    /// magnitude class of the residual (for contexts).
    fn code(&mut self, ctx: usize, pred: i32, slot: &mut i32) -> Result<u32>;
    /// Codes one "use this parallelogram" flag (`slot` as in `code`).
    fn flag(&mut self, ctx: usize, slot: &mut bool) -> Result<()>;
    /// True for the encoder (which knows the values and makes the choices).
    fn encoding(&self) -> bool;
    /// Charges walk steps whose number the file decides (the decoder's work bound).
    fn work(&mut self, _steps: u64) -> Result<()> {
        Ok(())
    }
}

/// Contexts of the parallelogram-selection flags: (number of candidates 2, 3, 4+) x
/// (index 0, 1, 2, 3+).
const FLAG_CONTEXTS: usize = 12;
/// At most this many parallelograms are considered per vertex (subset search is 2^n).
const MAX_CANDIDATES: usize = 4;

fn class_of(r: i32) -> u32 {
    32 - (zigzag(r) + 1).leading_zeros() - 1
}

fn bucket(class: u32) -> usize {
    match class {
        0..=1 => 0,
        2..=4 => 1,
        _ => 2,
    }
}

#[cfg(any(feature = "encoder", feature = "internals"))]
pub struct GeomEncoder<'a> {
    pub enc: &'a mut RangeEncoder,
    models: Vec<IntModel>,
    flags: Vec<BitModel>,
}

#[cfg(any(feature = "encoder", feature = "internals"))]
impl<'a> GeomEncoder<'a> {
    pub fn new(enc: &'a mut RangeEncoder) -> Self {
        GeomEncoder {
            enc,
            models: vec![IntModel::default(); CONTEXTS],
            flags: vec![BitModel::default(); FLAG_CONTEXTS],
        }
    }
}

#[cfg(any(feature = "encoder", feature = "internals"))]
impl ResidualCoder for GeomEncoder<'_> {
    fn code(&mut self, ctx: usize, pred: i32, slot: &mut i32) -> Result<u32> {
        let r = *slot - pred;
        self.models[ctx].encode(self.enc, zigzag(r));
        Ok(class_of(r))
    }

    fn flag(&mut self, ctx: usize, slot: &mut bool) -> Result<()> {
        self.enc.encode_bit(&mut self.flags[ctx], *slot);
        Ok(())
    }

    fn encoding(&self) -> bool {
        true
    }
}

pub(crate) struct GeomDecoder<'a, 'b> {
    pub dec: &'a mut RangeDecoder<'b>,
    models: Vec<IntModel>,
    flags: Vec<BitModel>,
    max_q: i32,
    budget: &'a mut Budget,
}

impl<'a, 'b> GeomDecoder<'a, 'b> {
    pub fn new(dec: &'a mut RangeDecoder<'b>, max_q: i32, budget: &'a mut Budget) -> Self {
        GeomDecoder {
            dec,
            models: vec![IntModel::default(); CONTEXTS],
            flags: vec![BitModel::default(); FLAG_CONTEXTS],
            max_q,
            budget,
        }
    }
}

impl ResidualCoder for GeomDecoder<'_, '_> {
    fn code(&mut self, ctx: usize, pred: i32, slot: &mut i32) -> Result<u32> {
        let z = self.models[ctx].decode(self.dec, 2 * self.max_q as u32, "residual")?;
        let r = unzigzag(z);
        let v = pred + r;
        if v < 0 || v > self.max_q {
            return Err(Error::format(
                "geometry",
                "residual",
                format!("coordinate {v} outside the grid 0..={}", self.max_q),
            ));
        }
        *slot = v;
        Ok(class_of(r))
    }

    fn flag(&mut self, ctx: usize, slot: &mut bool) -> Result<()> {
        *slot = self.dec.decode_bit(&mut self.flags[ctx])?;
        Ok(())
    }

    fn encoding(&self) -> bool {
        false
    }

    fn work(&mut self, steps: u64) -> Result<()> {
        self.budget.work(steps)
    }
}

/// Integer plane through three grid points, kept per planar group (`spec/format.md` §8.3).
#[derive(Clone, Copy, Debug, Default)]
struct PlaneState {
    pts: [[i64; 3]; 3],
    n: u8,
    /// Normal `(b - a) x (c - a)` and its L1 norm (twice the L1 "area").
    normal: [i64; 3],
    area: i64,
}

// The decoder charges 112 bytes per group for its plane state (`codec::GROUP_BYTES`).
const _: () = assert!(std::mem::size_of::<PlaneState>() <= 112);

fn sub(a: [i64; 3], b: [i64; 3]) -> [i64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [i64; 3], b: [i64; 3]) -> [i64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn l1(v: [i64; 3]) -> i64 {
    v[0].abs() + v[1].abs() + v[2].abs()
}

fn dot(a: [i64; 3], b: [i64; 3]) -> i64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl PlaneState {
    fn add(&mut self, p: [i64; 3]) {
        match self.n {
            0 => {
                self.pts[0] = p;
                self.n = 1;
            }
            1 => {
                if p != self.pts[0] {
                    self.pts[1] = p;
                    self.n = 2;
                }
            }
            2 => {
                let (a, b) = (self.pts[0], self.pts[1]);
                let n = cross(sub(b, a), sub(p, a));
                if n != [0, 0, 0] {
                    self.pts[2] = p;
                    self.normal = n;
                    self.area = l1(n);
                    self.n = 3;
                } else if dot(sub(p, a), sub(p, a)) > dot(sub(b, a), sub(b, a)) {
                    self.pts[1] = p;
                }
            }
            _ => {
                let [a, b, c] = self.pts;
                for cand in [[a, b, p], [a, p, c], [p, b, c]] {
                    let n = cross(sub(cand[1], cand[0]), sub(cand[2], cand[0]));
                    let area = l1(n);
                    if area > self.area {
                        self.pts = cand;
                        self.normal = n;
                        self.area = area;
                    }
                }
            }
        }
    }
}

/// Rounds `num / den` to the nearest integer, ties away from zero (den != 0).
fn div_round(num: i128, den: i128) -> i128 {
    let sign = if (num < 0) != (den < 0) { -1 } else { 1 };
    sign * ((2 * num.abs() + den.abs()) / (2 * den.abs()))
}

/// Outgoing half-edges of `v` in rotation order (`next = twin(prev(h))`), into `out`.
fn rotation(rb: &Rebuilt, v: u32, out: &mut Vec<u32>) {
    out.clear();
    let start = rb.vertex_out[v as usize];
    let mut h = start;
    loop {
        out.push(h);
        h = rb.twin[rb.prev[h as usize] as usize];
        if h == start || out.len() > rb.next.len() {
            break;
        }
    }
}

/// A cylinder or cone axis in grid units, as the decoder sees it (spec §8.2, *arc
/// candidates*): the stored origin (integers, exact in f64) and the stored i16 direction
/// divided by its length. Arc predictions are computed in binary64 with the operation order
/// written out below (no fused multiply-add), so both sides get the same bits everywhere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridAxis {
    pub origin: [f64; 3],
    pub dir: [f64; 3],
}

impl GridAxis {
    pub fn new(origin: [i64; 3], dir: [i16; 3]) -> Self {
        let d = dir.map(f64::from);
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        GridAxis {
            origin: origin.map(|o| o as f64),
            dir: d.map(|c| c / len),
        }
    }

    /// Height along the axis and the radial vector of grid point `p`.
    fn split(&self, p: [i32; 3]) -> (f64, [f64; 3]) {
        let r0 = [0, 1, 2].map(|c| f64::from(p[c]) - self.origin[c]);
        let h = fdot(r0, self.dir);
        (h, [0, 1, 2].map(|c| r0[c] - h * self.dir[c]))
    }

    fn point(&self, h: f64, r: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|c| self.origin[c] + h * self.dir[c] + r[c])
    }
}

/// Per-face cylinder/cone axes for the arc candidates (version 3): `face_axis[f]` indexes
/// `axes`, or is `NONE` for faces of other groups.
#[derive(Clone, Copy)]
pub struct ArcAxes<'a> {
    pub face_axis: &'a [u32],
    pub axes: &'a [GridAxis],
}

fn fdot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn fcross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Two points lie on one circle around `axis` when their radii and heights differ by less
/// than this (grid units).
const ARC_SLACK: f64 = 2.0;

/// Twice `p`, rounded, if it is a usable candidate.
fn twice_rounded(p: [f64; 3]) -> Option<[i64; 3]> {
    let t = p.map(|c| (2.0 * c).round());
    t.iter()
        .all(|c| c.is_finite() && c.abs() < 2f64.powi(40))
        .then(|| t.map(|c| c as i64))
}

/// The point midway between `a` and `b` on their common circle around `axis`, if they share
/// one (as twice its value).
fn arc_midpoint(axis: &GridAxis, a: [i32; 3], b: [i32; 3]) -> Option<[i64; 3]> {
    let ((ha, ra), (hb, rb)) = (axis.split(a), axis.split(b));
    let (la, lb) = (fdot(ra, ra).sqrt(), fdot(rb, rb).sqrt());
    if (la - lb).abs() >= ARC_SLACK || (ha - hb).abs() >= ARC_SLACK || la < 1.0 || lb < 1.0 {
        return None;
    }
    let s = [0, 1, 2].map(|c| ra[c] + rb[c]);
    let ls = fdot(s, s).sqrt();
    if ls < 1.0 {
        return None;
    }
    let k = (la + lb) * 0.5 / ls;
    twice_rounded(axis.point((ha + hb) * 0.5, s.map(|c| c * k)))
}

/// The point after `u`, `w` on their common circle around `axis` (rotating `w` by the angle
/// from `u` to `w`, height extrapolated), if they share one (as twice its value).
fn arc_extrapolation(axis: &GridAxis, u: [i32; 3], w: [i32; 3]) -> Option<[i64; 3]> {
    let ((hu, ru), (hw, rw)) = (axis.split(u), axis.split(w));
    let lu = fdot(ru, ru).sqrt();
    let lw0 = fdot(rw, rw).sqrt();
    if (lu - lw0).abs() >= ARC_SLACK || (hu - hw).abs() >= ARC_SLACK || lu < 1.0 || lw0 < 1.0 {
        return None;
    }
    let e1 = ru.map(|c| c / lu);
    let e2 = fcross(axis.dir, e1);
    let (x, y) = (fdot(rw, e1), fdot(rw, e2));
    let lw = (x * x + y * y).sqrt();
    if lw < 1.0 {
        return None;
    }
    let (a, b) = ((x * x - y * y) / lw, (2.0 * x * y) / lw);
    let r = [0, 1, 2].map(|c| e1[c] * a + e2[c] * b);
    twice_rounded(axis.point(2.0 * hw - hu, r))
}

/// The axes of the faces on both sides of the given half-edges, each once, in that order.
fn edge_axes(rb: &Rebuilt, arcs: &ArcAxes, hs: &[u32], out: &mut Vec<u32>) {
    out.clear();
    for &h in hs {
        for e in [h, rb.twin[h as usize]] {
            let f = rb.face[e as usize] as usize;
            if rb.faces[f].hole {
                continue;
            }
            let a = arcs.face_axis.get(f).copied().unwrap_or(NONE);
            if a != NONE && !out.contains(&a) {
                out.push(a);
            }
        }
    }
}

/// Version-2 predictions along creases (spec §8.2): a vertex on a crease chain (sharp or
/// mesh-boundary edges) is predicted from the chain, not from parallelograms across faces of
/// two different CAD faces. For `v` with crease neighbours `C` (rotation order): if `|C| = 2`
/// and both are decoded, their midpoint; then for every decoded `w` in `C` whose own crease
/// neighbours other than `v` are exactly one decoded `u`, the extrapolation `2w - u`. Pushed
/// as twice their value, at most `MAX_CANDIDATES` in all. Version 3 (`arcs`): where the two
/// points a prediction is made from lie on one circle around the axis of a cylinder or cone
/// face next to the chain, the point on that circle replaces the straight-line one. Returns
/// whether any candidate is such an arc, and adds to `steps` the length of the neighbours'
/// rotations it walked.
#[allow(clippy::too_many_arguments)]
fn crease_candidates(
    rb: &Rebuilt,
    crease: &[bool],
    arcs: Option<&ArcAxes>,
    v: u32,
    out_edges: &[u32],
    known: &[bool],
    q: &[[i32; 3]],
    scratch: &mut Vec<u32>,
    axes_near: &mut Vec<u32>,
    cands: &mut Vec<[i64; 3]>,
    steps: &mut u64,
) -> bool {
    let head = |h: u32| rb.vertex[rb.next[h as usize] as usize];
    let p = |w: u32| q[w as usize].map(i64::from);
    let mut nbs = [0u32; 2];
    let mut nb_edges = [0u32; 2];
    let mut n_nbs = 0usize;
    let mut known_nbs = [(0u32, 0u32); MAX_CANDIDATES];
    let mut n_known = 0usize;
    for &h in out_edges {
        if crease[h as usize] {
            let w = head(h);
            if n_nbs < 2 {
                nbs[n_nbs] = w;
                nb_edges[n_nbs] = h;
            }
            n_nbs += 1;
            if known[w as usize] && n_known < MAX_CANDIDATES {
                known_nbs[n_known] = (w, h);
                n_known += 1;
            }
        }
    }
    let mut any_arc = false;
    if n_nbs == 2 && known[nbs[0] as usize] && known[nbs[1] as usize] {
        let (qa, qb) = (q[nbs[0] as usize], q[nbs[1] as usize]);
        let mut arc = None;
        if let Some(arcs) = arcs {
            edge_axes(rb, arcs, &nb_edges, axes_near);
            arc = axes_near
                .iter()
                .find_map(|&a| arc_midpoint(&arcs.axes[a as usize], qa, qb));
        }
        any_arc |= arc.is_some();
        let (a, b) = (p(nbs[0]), p(nbs[1]));
        cands.push(arc.unwrap_or([0, 1, 2].map(|c| a[c] + b[c])));
    }
    for &(w, hvw) in &known_nbs[..n_known] {
        if cands.len() >= MAX_CANDIDATES {
            break;
        }
        rotation(rb, w, scratch);
        *steps += scratch.len() as u64;
        let mut other = None;
        let mut n_other = 0usize;
        for &h in scratch.iter() {
            if crease[h as usize] && head(h) != v {
                other = Some((head(h), h));
                n_other += 1;
            }
        }
        if let (1, Some((u, hwu))) = (n_other, other) {
            if known[u as usize] {
                let mut arc = None;
                if let Some(arcs) = arcs {
                    edge_axes(rb, arcs, &[hvw, hwu], axes_near);
                    arc = axes_near.iter().find_map(|&a| {
                        arc_extrapolation(&arcs.axes[a as usize], q[u as usize], q[w as usize])
                    });
                }
                any_arc |= arc.is_some();
                let (pw, pu) = (p(w), p(u));
                cands.push(arc.unwrap_or([0, 1, 2].map(|c| 4 * pw[c] - 2 * pu[c])));
            }
        }
    }
    any_arc
}

/// Visits every vertex (spec §8.2: highest number of decoded neighbours first, then the
/// isolated vertices), predicts it and lets `coder` code the residuals.
///
/// `q` has one entry per coded vertex; `face_plane_group[f]` is the group id of face `f` when
/// that group is a plane patch, else `NONE`. `crease[h]` (version 2 on; `None` for version-1
/// files) says whether half-edge `h` lies on a sharp or mesh-boundary edge; `arcs` (version 3
/// on) gives the cylinder and cone axes for arc candidates.
#[allow(clippy::too_many_arguments)]
pub fn walk(
    rb: &Rebuilt,
    face_plane_group: &[u32],
    plane_groups: usize,
    bits: u8,
    crease: Option<&[bool]>,
    arcs: Option<&ArcAxes>,
    q: &mut [[i32; 3]],
    coder: &mut impl ResidualCoder,
) -> Result<()> {
    let mut vertex_walk = VertexWalk {
        rb,
        face_plane_group,
        crease,
        arcs,
        max_q: ((1u32 << bits) - 1) as i32,
        known: vec![false; q.len()],
        level: vec![0u8; rb.vertex_count],
        buckets: vec![Vec::new(); MAX_LEVEL + 1],
        planes: vec![PlaneState::default(); plane_groups],
        plane_stamp: vec![NONE; plane_groups],
        prev_vertex: None,
        last_class: 0,
        incident: Vec::new(),
        out_edges: Vec::new(),
        cands: Vec::new(),
        scratch: Vec::new(),
        axes_near: Vec::new(),
        next_seed: 0,
    };
    while let Some(v) = vertex_walk.next_vertex() {
        vertex_walk.code_vertex(v, q, coder)?;
    }
    vertex_walk.code_isolated(q, coder)
}

/// The state of [`walk`]: its inputs, what is known so far, and scratch lists reused from
/// vertex to vertex.
struct VertexWalk<'a> {
    rb: &'a Rebuilt,
    face_plane_group: &'a [u32],
    crease: Option<&'a [bool]>,
    arcs: Option<&'a ArcAxes<'a>>,
    /// Largest grid coordinate.
    max_q: i32,
    /// Whether each coded vertex has been visited.
    known: Vec<bool>,
    /// Number of visited neighbours of each traversal vertex, capped at `MAX_LEVEL`.
    level: Vec<u8>,
    /// Vertices by level (entries go stale when a vertex's level rises or it is visited).
    buckets: Vec<Vec<u32>>,
    /// The plane of each plane group so far, and the last vertex that looked it up.
    planes: Vec<PlaneState>,
    plane_stamp: Vec<u32>,
    prev_vertex: Option<u32>,
    /// Magnitude class of the last residual coded (for the contexts).
    last_class: u32,
    /// Plane groups around the current vertex.
    incident: Vec<u32>,
    /// Outgoing half-edges of the current vertex in rotation order.
    out_edges: Vec<u32>,
    /// Candidate predictions of the current vertex, each as twice its value.
    cands: Vec<[i64; 3]>,
    scratch: Vec<u32>,
    axes_near: Vec<u32>,
    /// Every traversal vertex below this has been visited.
    next_seed: usize,
}

impl VertexWalk<'_> {
    /// The next vertex to visit: the top of the highest non-empty level bucket (skipping
    /// stale entries), else the lowest unvisited traversal vertex (a new component); `None`
    /// once every traversal vertex is visited.
    fn next_vertex(&mut self) -> Option<u32> {
        for lv in (1..=MAX_LEVEL).rev() {
            while let Some(v) = self.buckets[lv].pop() {
                if !self.known[v as usize] && usize::from(self.level[v as usize]) == lv {
                    return Some(v);
                }
            }
        }
        let nt = self.rb.vertex_count;
        while self.next_seed < nt && self.known[self.next_seed] {
            self.next_seed += 1;
        }
        (self.next_seed < nt).then_some(self.next_seed as u32)
    }

    /// Predicts vertex `v`, codes its coordinates in `q` and marks it visited.
    fn code_vertex(
        &mut self,
        v: u32,
        q: &mut [[i32; 3]],
        coder: &mut impl ResidualCoder,
    ) -> Result<()> {
        rotation(self.rb, v, &mut self.out_edges);
        // Predictions along a crease (version 2), else parallelogram-type predictions in
        // rotation order; each as twice its value.
        self.cands.clear();
        let mut arc = false;
        if let Some(cr) = self.crease {
            let mut steps = 0;
            arc = crease_candidates(
                self.rb,
                cr,
                self.arcs,
                v,
                &self.out_edges,
                &self.known,
                q,
                &mut self.scratch,
                &mut self.axes_near,
                &mut self.cands,
                &mut steps,
            );
            coder.work(steps)?;
        }
        let n_crease = self.cands.len();
        if n_crease == 0 {
            parallelogram_candidates(self.rb, &self.out_edges, &self.known, q, &mut self.cands);
        }
        let count = self.cands.len();
        let (best, plane_axis) = self.planes_around(v);
        let (pred, kind) = if count == 0 {
            let (pred, kind) = self.fallback_prediction(q);
            (pred.map(|c| c.clamp(0, i64::from(self.max_q)) as i32), kind)
        } else {
            (
                self.averaged_prediction(q[v as usize], plane_axis, coder)?,
                candidate_kind(count, n_crease, arc),
            )
        };
        let mut slot = q[v as usize];
        self.code_coordinates(best, plane_axis, kind, pred, &mut slot, coder)?;
        q[v as usize] = slot;
        self.mark_visited(v, slot);
        Ok(())
    }

    /// The prediction when there is no candidate, unclamped, and its context kind: the mean
    /// of the visited neighbours (`KIND_NEIGHBOURS`), else the previous vertex or the grid's
    /// centre (`KIND_START`).
    fn fallback_prediction(&self, q: &[[i32; 3]]) -> ([i64; 3], usize) {
        let rb = self.rb;
        let p = |w: u32| q[w as usize].map(i64::from);
        let mut sum = [0i64; 3];
        let mut n = 0i64;
        for &h in &self.out_edges {
            let w = rb.vertex[rb.next[h as usize] as usize];
            if self.known[w as usize] {
                let pw = p(w);
                for c in 0..3 {
                    sum[c] += pw[c];
                }
                n += 1;
            }
        }
        if n > 0 {
            (
                sum.map(|s| div_round(i128::from(s), i128::from(n)) as i64),
                KIND_NEIGHBOURS,
            )
        } else {
            let pr = match self.prev_vertex {
                Some(w) => p(w),
                None => [i64::from(self.max_q / 2); 3],
            };
            (pr, KIND_START)
        }
    }

    /// Collects the plane groups around `v` into `incident` (each once: a group is taken when
    /// its stamp is not yet `v`, so a vertex of high valence costs no more per edge) and
    /// returns the one whose plane has the largest defining triangle, with that plane's
    /// dominant axis (predicted from the plane, not from the parallelograms). No sort needed:
    /// ties on the area are broken by the group id.
    fn planes_around(&mut self, v: u32) -> (Option<u32>, Option<usize>) {
        let rb = self.rb;
        self.incident.clear();
        for &h in &self.out_edges {
            let pg = self
                .face_plane_group
                .get(rb.face[h as usize] as usize)
                .copied()
                .unwrap_or(NONE);
            if pg != NONE && self.plane_stamp[pg as usize] != v {
                self.plane_stamp[pg as usize] = v;
                self.incident.push(pg);
            }
        }
        let planes = &self.planes;
        let best = self
            .incident
            .iter()
            .filter(|&&g| planes[g as usize].n == 3)
            .max_by(|&&a, &&b| {
                planes[a as usize]
                    .area
                    .cmp(&planes[b as usize].area)
                    .then(b.cmp(&a))
            })
            .copied();
        let plane_axis = best.map(|g| {
            let n = planes[g as usize].normal;
            (0..3)
                .max_by(|&x, &y| n[x].abs().cmp(&n[y].abs()).then(y.cmp(&x)))
                .unwrap_or(0)
        });
        (best, plane_axis)
    }

    /// The prediction from the candidates: the average of a subset of them, all of them
    /// unless the encoder signals otherwise with one flag per candidate (spec §8.2); the last
    /// flag is implied when all earlier ones are 0. The encoder picks the subset whose
    /// average is nearest `actual` off the plane's axis `plane_axis`.
    fn averaged_prediction(
        &self,
        actual: [i32; 3],
        plane_axis: Option<usize>,
        coder: &mut impl ResidualCoder,
    ) -> Result<[i32; 3]> {
        let (cands, max_q) = (&self.cands, self.max_q);
        let count = cands.len();
        let average = |mask: usize| -> [i32; 3] {
            let mut sum = [0i64; 3];
            let mut n = 0i64;
            for (i, c) in cands.iter().enumerate() {
                if mask & (1 << i) != 0 {
                    for k in 0..3 {
                        sum[k] += c[k];
                    }
                    n += 1;
                }
            }
            sum.map(|s| {
                (div_round(i128::from(s), i128::from(2 * n)) as i64).clamp(0, i64::from(max_q))
                    as i32
            })
        };
        let full = (1usize << count) - 1;
        let mut mask = full;
        if count >= 2 {
            if coder.encoding() {
                let cost = |m: usize| -> u32 {
                    let p = average(m);
                    (0..3)
                        .filter(|&k| Some(k) != plane_axis)
                        .map(|k| (actual[k] - p[k]).unsigned_abs())
                        .sum()
                };
                let mut best_cost = cost(full);
                for m in 1..full {
                    let c = cost(m);
                    if c < best_cost {
                        best_cost = c;
                        mask = m;
                    }
                }
            }
            let base = (count.min(4) - 2) * 4;
            let mut any = false;
            for i in 0..count {
                if i + 1 == count && !any {
                    mask |= 1 << i;
                    break;
                }
                let mut bit = mask & (1 << i) != 0;
                coder.flag(base + i.min(3), &mut bit)?;
                if bit {
                    mask |= 1 << i;
                    any = true;
                } else {
                    mask &= !(1 << i);
                }
            }
        }
        Ok(average(mask))
    }

    /// Codes the three coordinates in `slot` against `pred` with context kind `kind`. On the
    /// plane of group `best`, the coordinate along its dominant axis `plane_axis` is coded
    /// last, predicted from the plane through the other two.
    fn code_coordinates(
        &mut self,
        best: Option<u32>,
        plane_axis: Option<usize>,
        kind: usize,
        pred: [i32; 3],
        slot: &mut [i32; 3],
        coder: &mut impl ResidualCoder,
    ) -> Result<()> {
        match best {
            None => {
                for c in 0..3 {
                    let ctx = kind * 3 + bucket(self.last_class);
                    self.last_class = coder.code(ctx, pred[c], &mut slot[c])?;
                }
            }
            Some(g) => {
                let pl = self.planes[g as usize];
                let n = pl.normal;
                let k = plane_axis.unwrap_or(0);
                for c in (0..3).filter(|&c| c != k) {
                    let ctx = kind * 3 + bucket(self.last_class);
                    self.last_class = coder.code(ctx, pred[c], &mut slot[c])?;
                }
                let a = pl.pts[0];
                let num: i128 = (0..3)
                    .filter(|&c| c != k)
                    .map(|c| i128::from(n[c]) * (i128::from(slot[c]) - i128::from(a[c])))
                    .sum();
                let pk = i128::from(a[k]) + div_round(-num, i128::from(n[k]));
                let pk = pk.clamp(0, i128::from(self.max_q)) as i32;
                let ctx = PLANE_CTX * 3 + bucket(self.last_class);
                self.last_class = coder.code(ctx, pk, &mut slot[k])?;
            }
        }
        Ok(())
    }

    /// Records `v` as visited at grid point `slot`: the planes of its plane groups take the
    /// point, and its unvisited neighbours go up a level.
    fn mark_visited(&mut self, v: u32, slot: [i32; 3]) {
        let rb = self.rb;
        self.known[v as usize] = true;
        self.prev_vertex = Some(v);
        let pt = slot.map(i64::from);
        for &g in &self.incident {
            self.planes[g as usize].add(pt);
        }
        for &h in &self.out_edges {
            let w = rb.vertex[rb.next[h as usize] as usize] as usize;
            if !self.known[w] && usize::from(self.level[w]) < MAX_LEVEL {
                self.level[w] += 1;
                self.buckets[usize::from(self.level[w])].push(w as u32);
            }
        }
    }

    /// Codes the isolated vertices (those after the traversal's): each as a delta from the
    /// previous vertex.
    fn code_isolated(&mut self, q: &mut [[i32; 3]], coder: &mut impl ResidualCoder) -> Result<()> {
        for v in self.rb.vertex_count..q.len() {
            let pred = match self.prev_vertex {
                Some(w) => q[w as usize],
                None => [self.max_q / 2; 3],
            };
            let mut slot = q[v];
            for c in 0..3 {
                let ctx = KIND_START * 3 + bucket(self.last_class);
                self.last_class = coder.code(ctx, pred[c], &mut slot[c])?;
            }
            q[v] = slot;
            self.prev_vertex = Some(v as u32);
        }
        Ok(())
    }
}

/// Context kind of a prediction from `count` candidates of which `n_crease` lie along a
/// crease (`arc`: one of those follows a circle round an axis).
fn candidate_kind(count: usize, n_crease: usize, arc: bool) -> usize {
    match n_crease {
        0 => count.min(3),
        _ if arc => KIND_ARC,
        1 => KIND_CREASE_ONE,
        _ => KIND_CREASE_MORE,
    }
}

/// Parallelogram-type predictions (spec §8.2) for the vertex whose outgoing half-edges are
/// `out_edges`, in rotation order, each as twice its value, at most `MAX_CANDIDATES` in
/// `cands`: in a triangle, across the edge opposite the vertex when the triangle beyond it
/// is known; in a larger face, from the next three corners (and the previous three, from
/// degree 5 on).
fn parallelogram_candidates(
    rb: &Rebuilt,
    out_edges: &[u32],
    known: &[bool],
    q: &[[i32; 3]],
    cands: &mut Vec<[i64; 3]>,
) {
    let kn = |w: u32| known[w as usize];
    let p = |w: u32| q[w as usize].map(i64::from);
    let mut add2 = |pr2: [i64; 3]| {
        if cands.len() < MAX_CANDIDATES {
            cands.push(pr2);
        }
    };
    for &h in out_edges {
        let f = rb.face[h as usize] as usize;
        let rf = rb.faces[f];
        if rf.hole {
            continue;
        }
        // The face's vertices k steps forward and back from v's corner: each walk is at
        // most 3 steps, so a face of high degree costs no more per corner.
        let ahead = |k: u32| {
            let mut x = h;
            for _ in 0..k {
                x = rb.next[x as usize];
            }
            rb.vertex[x as usize]
        };
        let back = |k: u32| {
            let mut x = h;
            for _ in 0..k {
                x = rb.prev[x as usize];
            }
            rb.vertex[x as usize]
        };
        let d = rf.degree;
        if d == 3 {
            let (a, b) = (ahead(1), ahead(2));
            if !(kn(a) && kn(b)) {
                continue;
            }
            let tw = rb.twin[rb.next[h as usize] as usize];
            let kf = rb.faces[rb.face[tw as usize] as usize];
            if kf.hole {
                continue;
            }
            let k2 = rb.vertex[rb.next[rb.next[tw as usize] as usize] as usize];
            let kl = rb.vertex[rb.prev[tw as usize] as usize];
            if !(kn(k2) && kn(kl)) {
                continue;
            }
            let (pa, pb, p2, pl) = (p(a), p(b), p(k2), p(kl));
            add2([0, 1, 2].map(|c| 2 * (pa[c] + pb[c]) - p2[c] - pl[c]));
        } else {
            let (a, b, c3) = (ahead(1), ahead(2), ahead(3));
            if kn(a) && kn(b) && kn(c3) {
                let (pa, pb, pc) = (p(a), p(b), p(c3));
                add2([0, 1, 2].map(|c| 2 * (pa[c] + pc[c] - pb[c])));
            }
            if d >= 5 {
                let (a, b, c3) = (back(1), back(2), back(3));
                if kn(a) && kn(b) && kn(c3) {
                    let (pa, pb, pc) = (p(a), p(b), p(c3));
                    add2([0, 1, 2].map(|c| 2 * (pa[c] + pc[c] - pb[c])));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_quantisation_known_answers() {
        let q = Quantizer {
            min: [0.0; 3],
            extent: 1.0,
            bits: 10,
            as_f32: true,
        };
        assert!((q.step() - 1.0 / 1023.0).abs() < 1e-15);
        assert_eq!(q.quantize(DVec3::splat(0.3)), [307; 3]);
        assert!((q.dequantize([307; 3]).x - 0.300098).abs() < 1e-6);
        assert_eq!(q.quantize(DVec3::ONE), [1023; 3]);
    }

    #[test]
    fn f32_rounding_brackets_the_value() {
        for x in [0.1f64, -0.1, 1e-30, -1e-30, 0.0, 123456.789, -7.25, 1e30] {
            let (lo, hi) = (f32_round_down(x), f32_round_up(x));
            assert!(lo <= x && x <= hi, "{x}: {lo} {hi}");
            assert_eq!(lo as f32 as f64, lo);
            assert_eq!(hi as f32 as f64, hi);
        }
        assert_eq!(f32_round_down(-7.25), -7.25);
    }

    #[test]
    fn box_covers_points_and_bounds_error() {
        let pts = vec![
            DVec3::new(-1.234567, 2.0, 1e-3),
            DVec3::new(3.3, -0.7, 5.123456789),
            DVec3::new(0.1, 0.2, 0.3),
        ];
        for bits in [4u8, 10, 16, 24] {
            let q = Quantizer::for_positions(&pts, bits, 1.0);
            for &p in &pts {
                let r = q.dequantize(q.quantize(p));
                assert!((r - p).abs().max_element() <= q.step() / 2.0 * (1.0 + 1e-9) + 1e-12);
            }
        }
    }

    #[test]
    fn arc_predictions_follow_the_circle() {
        let z = GridAxis::new([0, 0, 0], [0, 0, 1000]);
        // Quarter circle of radius 100: midpoint at 45 degrees (twice 70.71 -> 141).
        assert_eq!(
            arc_midpoint(&z, [100, 0, 7], [0, 100, 7]),
            Some([141, 141, 14])
        );
        // Rotating on by the same angle, height extrapolated.
        assert_eq!(
            arc_extrapolation(&z, [100, 0, 5], [0, 100, 6]),
            Some([-200, 0, 14])
        );
        // Off the circle (radii or heights differ by 2 or more): no arc.
        assert_eq!(arc_midpoint(&z, [100, 0, 0], [0, 102, 0]), None);
        assert_eq!(arc_extrapolation(&z, [100, 0, 0], [0, 100, 2]), None);
        // On the axis: no direction to rotate.
        assert_eq!(arc_midpoint(&z, [0, 0, 0], [0, 0, 1]), None);
        // Opposite points: the chord midpoint is on the axis, no arc.
        assert_eq!(arc_midpoint(&z, [100, 0, 0], [-100, 0, 0]), None);
        // An axis off the origin, along x.
        let x = GridAxis::new([0, 50, 50], [-7, 0, 0]);
        assert_eq!(
            arc_extrapolation(&x, [3, 60, 50], [3, 50, 60]),
            Some([6, 80, 100])
        );
    }

    #[test]
    fn plane_prediction_worked_example() {
        // geometry-coding.md §2.1: n = (90552, 180388, 180542), D_z predicted as 297.
        let a = [102i64, 205, 665];
        let b = [716i64, 153, 409];
        let c = [563i64, 460, 179];
        let n = cross(sub(b, a), sub(c, a));
        assert_eq!(n, [90552, 180388, 180542]);
        let num = i128::from(n[0]) * (123 - 102) + i128::from(n[1]) * (563 - 205);
        assert_eq!(i128::from(a[2]) + div_round(-num, i128::from(n[2])), 297);
        assert_eq!(div_round(5, 2), 3);
        assert_eq!(div_round(-5, 2), -3);
        assert_eq!(div_round(-4, 3), -1);
    }
}
