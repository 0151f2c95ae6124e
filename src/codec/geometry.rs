//! Quantisation and predictive coding of vertex positions (`spec/format.md` §8).
//!
//! Everything after quantisation is integer arithmetic, so encoder and decoder compute the same
//! predictions on every platform. One routine ([`walk`]) drives both directions through the
//! [`ResidualCoder`] trait, so the two sides cannot drift apart.

use glam::DVec3;

use super::facefixer::Rebuilt;
use super::rangecoder::{zigzag, unzigzag, IntModel, RangeDecoder, RangeEncoder};
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
    /// Chooses the box for `positions`: f32 storage when that loses (almost) nothing.
    pub fn for_positions(positions: &[DVec3], bits: u8) -> Self {
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
        let extent64 = (hi - lo).max_element();
        // f32 candidate: min rounded down, extent rounded up so the box still covers everything.
        let min32: [f64; 3] = [0, 1, 2].map(|i| f32_round_down(lo[i]));
        let need = (0..3)
            .map(|i| hi[i] - min32[i])
            .fold(0.0f64, f64::max);
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

fn f32_round_down(x: f64) -> f64 {
    let f = x as f32;
    let f = if f64::from(f) > x { f.next_down() } else { f };
    f64::from(f)
}

fn f32_round_up(x: f64) -> f64 {
    let f = x as f32;
    let f = if f64::from(f) < x { f.next_up() } else { f };
    f64::from(f)
}

/// Which rule produced a prediction; also the first part of the residual context.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
enum Kind {
    /// Quad whose other three vertices are known: `a + c - b` inside the face.
    QuadInFace = 0,
    /// Triangle across a known face: parallelogram.
    TriangleAcross = 1,
    /// Polygon vertex next to the entry edge: reflect the neighbour across the entry vertex.
    PolygonAcross = 2,
    /// Polygon vertex after three known ones: `u[i-1] + u[i-3] - u[i-2]`.
    PolygonChain = 3,
    /// A known neighbour in the face (delta).
    Delta = 4,
    /// No known neighbour: previous vertex in geometry order.
    Start = 5,
}

const KINDS: usize = 6;
/// Context count: (kind or plane) x magnitude bucket.
const CONTEXTS: usize = (KINDS + 1) * 3;
const PLANE_CTX: usize = KINDS;

/// Codes (encoder) or recovers (decoder) one quantised coordinate.
pub trait ResidualCoder {
    /// `slot` holds the actual value when encoding and receives it when decoding. Returns the
    /// magnitude class of the residual (for contexts).
    fn code(&mut self, ctx: usize, pred: i32, slot: &mut i32) -> Result<u32>;
}

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

pub struct GeomEncoder<'a> {
    pub enc: &'a mut RangeEncoder,
    models: Vec<IntModel>,
}

impl<'a> GeomEncoder<'a> {
    pub fn new(enc: &'a mut RangeEncoder) -> Self {
        GeomEncoder {
            enc,
            models: vec![IntModel::default(); CONTEXTS],
        }
    }
}

impl ResidualCoder for GeomEncoder<'_> {
    fn code(&mut self, ctx: usize, pred: i32, slot: &mut i32) -> Result<u32> {
        let r = *slot - pred;
        self.models[ctx].encode(self.enc, zigzag(r));
        Ok(class_of(r))
    }
}

pub struct GeomDecoder<'a, 'b> {
    pub dec: &'a mut RangeDecoder<'b>,
    models: Vec<IntModel>,
    max_q: i32,
}

impl<'a, 'b> GeomDecoder<'a, 'b> {
    pub fn new(dec: &'a mut RangeDecoder<'b>, max_q: i32) -> Self {
        GeomDecoder {
            dec,
            models: vec![IntModel::default(); CONTEXTS],
            max_q,
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

/// Visits every vertex in geometry order (first appearance walking the mesh faces in encoding
/// order, then the isolated vertices), predicts it and lets `coder` code the residuals.
///
/// `q` has one entry per coded vertex; `face_plane_group[f]` is the group id of face `f` when
/// that group is a plane patch, else `NONE`.
pub fn walk(
    rb: &Rebuilt,
    face_plane_group: &[u32],
    plane_groups: usize,
    bits: u8,
    q: &mut [[i32; 3]],
    coder: &mut impl ResidualCoder,
) -> Result<()> {
    let max_q = ((1u32 << bits) - 1) as i32;
    let mut known = vec![false; q.len()];
    let mut planes = vec![PlaneState::default(); plane_groups];
    let mut prev_vertex: Option<u32> = None;
    let mut last_class = 0u32;
    let mut cycle: Vec<u32> = Vec::new();
    let mut incident: Vec<u32> = Vec::new();
    for (fi, rf) in rb.faces.iter().enumerate() {
        if rf.hole {
            continue;
        }
        cycle.clear();
        cycle.extend(rb.face_vertices(fi));
        let d = cycle.len();
        for i in 0..d {
            let v = cycle[i];
            if known[v as usize] {
                continue;
            }
            let at = |k: isize| cycle[(i as isize + k).rem_euclid(d as isize) as usize];
            let kn = |w: u32| known[w as usize];
            let p = |w: u32| q[w as usize];
            let (pred, kind) = if d == 4 && kn(at(-1)) && kn(at(1)) && kn(at(2)) {
                (add3(p(at(-1)), p(at(1)), p(at(2))), Kind::QuadInFace)
            } else if i == 2 && !rf.start && !rb.is_hole(rb.twin[rf.first as usize]) {
                // Across the entry edge: K = face(g) starting at g = twin(t).
                let g = rb.twin[rf.first as usize];
                let kf = rb.faces[rb.face[g as usize] as usize];
                let k2 = rb.vertex[rb.next[rb.next[g as usize] as usize] as usize];
                let klast = rb.vertex[rb.prev[g as usize] as usize];
                let (u0, u1) = (p(cycle[0]), p(cycle[1]));
                if d == 3 {
                    let pr = if kf.degree == 3 {
                        add3(u0, u1, p(k2))
                    } else {
                        let (a, b) = (p(k2), p(klast));
                        [0, 1, 2].map(|c| {
                            (2 * (i64::from(u0[c]) + i64::from(u1[c])) - i64::from(a[c])
                                - i64::from(b[c]))
                            .div_euclid(2) as i32
                        })
                    };
                    (pr, Kind::TriangleAcross)
                } else {
                    (add3(u1, u1, p(klast)), Kind::PolygonAcross)
                }
            } else if d >= 4 && i >= 1 && kn(at(-1)) && kn(at(-2)) && kn(at(-3)) {
                (add3(p(at(-1)), p(at(-3)), p(at(-2))), Kind::PolygonChain)
            } else if kn(at(-1)) {
                (p(at(-1)), Kind::Delta)
            } else if let Some(&w) = cycle.iter().find(|&&w| kn(w)) {
                (p(w), Kind::Delta)
            } else {
                let pr = match prev_vertex {
                    Some(w) => p(w),
                    None => [max_q / 2; 3],
                };
                (pr, Kind::Start)
            };
            let pred = pred.map(|c| c.clamp(0, max_q));
            // Plane groups around v (each once, ascending ids) -> best plane.
            incident.clear();
            let mut h = rb.vertex_out[v as usize];
            let start = h;
            let mut guard = 0usize;
            loop {
                let f = rb.face[h as usize] as usize;
                let pg = face_plane_group.get(f).copied().unwrap_or(NONE);
                if pg != NONE && !incident.contains(&pg) {
                    incident.push(pg);
                }
                h = rb.twin[rb.prev[h as usize] as usize];
                guard += 1;
                if h == start || guard > rb.next.len() {
                    break;
                }
            }
            incident.sort_unstable();
            let best = incident
                .iter()
                .filter(|&&g| planes[g as usize].n == 3)
                .max_by(|&&a, &&b| {
                    planes[a as usize]
                        .area
                        .cmp(&planes[b as usize].area)
                        .then(b.cmp(&a))
                })
                .copied();
            let mut slot = q[v as usize];
            match best {
                None => {
                    for c in 0..3 {
                        let ctx = kind as usize * 3 + bucket(last_class);
                        last_class = coder.code(ctx, pred[c], &mut slot[c])?;
                    }
                }
                Some(g) => {
                    let pl = planes[g as usize];
                    let n = pl.normal;
                    let k = (0..3)
                        .max_by(|&x, &y| n[x].abs().cmp(&n[y].abs()).then(y.cmp(&x)))
                        .unwrap_or(0);
                    for c in (0..3).filter(|&c| c != k) {
                        let ctx = kind as usize * 3 + bucket(last_class);
                        last_class = coder.code(ctx, pred[c], &mut slot[c])?;
                    }
                    let a = pl.pts[0];
                    let num: i128 = (0..3)
                        .filter(|&c| c != k)
                        .map(|c| i128::from(n[c]) * (i128::from(slot[c]) - i128::from(a[c])))
                        .sum();
                    let pk = i128::from(a[k]) + div_round(-num, i128::from(n[k]));
                    let pk = pk.clamp(0, i128::from(max_q)) as i32;
                    let ctx = PLANE_CTX * 3 + bucket(last_class.min(1));
                    coder.code(ctx, pk, &mut slot[k])?;
                }
            }
            q[v as usize] = slot;
            known[v as usize] = true;
            prev_vertex = Some(v);
            let pt = slot.map(i64::from);
            for &g in &incident {
                planes[g as usize].add(pt);
            }
        }
    }
    // Isolated vertices: delta from the previous vertex.
    for v in rb.vertex_count..q.len() {
        let pred = match prev_vertex {
            Some(w) => q[w as usize],
            None => [max_q / 2; 3],
        };
        let mut slot = q[v];
        for c in 0..3 {
            let ctx = Kind::Start as usize * 3 + bucket(last_class);
            last_class = coder.code(ctx, pred[c], &mut slot[c])?;
        }
        q[v] = slot;
        prev_vertex = Some(v as u32);
    }
    Ok(())
}

/// `a + b - c` per component.
fn add3(a: [i32; 3], b: [i32; 3], c: [i32; 3]) -> [i32; 3] {
    [0, 1, 2].map(|i| a[i] + b[i] - c[i])
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
    fn box_covers_points_and_bounds_error() {
        let pts = vec![
            DVec3::new(-1.234567, 2.0, 1e-3),
            DVec3::new(3.3, -0.7, 5.123456789),
            DVec3::new(0.1, 0.2, 0.3),
        ];
        for bits in [4u8, 10, 16, 24] {
            let q = Quantizer::for_positions(&pts, bits);
            for &p in &pts {
                let r = q.dequantize(q.quantize(p));
                assert!((r - p).abs().max_element() <= q.step() / 2.0 * (1.0 + 1e-9) + 1e-12);
            }
        }
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
