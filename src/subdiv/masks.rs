//! The scalar weights of every subdivision, limit and tangent mask (reference
//! `loop-subdivision.md` §3-§5). One place, used by refinement, limit evaluation and stencils.

use std::f64::consts::PI;

use glam::DVec3;

/// Vertex classes (Hoppe 1994 plus the boundary-patch interior class). Stored as `u8` per
/// vertex and level because the class is all the rules need and arrays stay small.
pub(crate) mod vclass {
    /// No crease edge: Loop's smooth rule.
    pub const SMOOTH: u8 = 0;
    /// One crease edge: smooth vertex rule; its crease edges use the smooth edge mask.
    pub const DART: u8 = 1;
    /// Two crease edges, regular (3 triangles in every closed-patch sector).
    pub const CREASE_REGULAR: u8 = 2;
    /// Two crease edges, non-regular.
    pub const CREASE_NONREG: u8 = 3;
    /// Tagged corner or three or more crease edges: fixed.
    pub const CORNER: u8 = 4;
    /// Vertex inside a boundary patch (or isolated): fixed, no crease semantics.
    pub const FIXED: u8 = 5;

    /// "Special" end of a crease edge (non-regular crease or corner; S-CODE treats them alike).
    #[inline]
    pub fn is_special(c: u8) -> bool {
        c == CREASE_NONREG || c == CORNER || c == FIXED
    }
    #[inline]
    pub fn is_crease(c: u8) -> bool {
        c == CREASE_REGULAR || c == CREASE_NONREG
    }
    #[inline]
    pub fn is_smooth_rule(c: u8) -> bool {
        c == SMOOTH || c == DART
    }
}

/// Edge rules (low 3 bits) and flags. One byte per edge per level.
pub(crate) mod eclass {
    /// 3/8 (a + b) + 1/8 (c + d).
    pub const SMOOTH: u8 = 0;
    /// (a + b) / 2 on a crease whose ends are of the same kind.
    pub const MID: u8 = 1;
    /// 5/8 a + 3/8 b: crease edge, `a` ordinary (regular), `b` special.
    pub const W58A: u8 = 2;
    /// 3/8 a + 5/8 b: crease edge, `b` ordinary, `a` special.
    pub const W58B: u8 = 3;
    /// Midpoint (in the patch frame) of an edge inside a boundary patch.
    pub const LINEAR: u8 = 4;
    pub const RULE_MASK: u8 = 0x07;
    /// The edge is a crease (flagged sharp or on the mesh boundary).
    pub const CREASE: u8 = 0x10;
    /// The edge descends from an edge listed in `ControlMesh::sharp_edges`.
    pub const SHARP: u8 = 0x20;
    /// The edge lies on the mesh boundary (one face).
    pub const BOUNDARY: u8 = 0x40;

    /// Rule of a crease edge from its end classes (reference §3.2).
    #[inline]
    pub fn crease_rule(ca: u8, cb: u8) -> u8 {
        use super::vclass;
        if ca == vclass::DART || cb == vclass::DART {
            return SMOOTH;
        }
        match (vclass::is_special(ca), vclass::is_special(cb)) {
            (false, true) => W58A,
            (true, false) => W58B,
            _ => MID,
        }
    }

    /// Weights `(w_a, w_b)` of a crease-type rule (not `SMOOTH`).
    #[inline]
    pub fn pair_weights(rule: u8) -> (f64, f64) {
        match rule {
            W58A => (0.625, 0.375),
            W58B => (0.375, 0.625),
            _ => (0.5, 0.5),
        }
    }
}

/// Loop's beta (NOT Warren's): `(1/k) (5/8 - (3/8 + 1/4 cos(2 pi / k))^2)`.
#[inline]
pub fn loop_beta(k: usize) -> f64 {
    let k = k as f64;
    let c = 0.375 + 0.25 * (2.0 * PI / k).cos();
    (0.625 - c * c) / k
}

/// Limit-mask centre factor `omega_k = 3 / (8 beta_k)`; limit = (omega v + sum) / (omega + k).
#[inline]
pub fn loop_omega(k: usize) -> f64 {
    3.0 / (8.0 * loop_beta(k))
}

/// Per-valence tables, so the inner loops never call `cos`. Valences above the table are
/// computed on the fly.
#[derive(Clone, Debug)]
pub(crate) struct ValenceTables {
    /// `beta[k]`
    pub beta: Vec<f64>,
    /// `(centre, neighbour)` limit weights per valence.
    pub limit: Vec<(f64, f64)>,
    /// `(cos, sin)(2 pi i / k)` for i < k, concatenated over k (offset k (k - 1) / 2).
    pub trig: Vec<(f64, f64)>,
}

impl ValenceTables {
    pub fn new(max_k: usize) -> Self {
        let n = max_k.max(12) + 1;
        let mut beta = vec![0.0; n];
        let mut limit = vec![(1.0, 0.0); n];
        for k in 1..n {
            beta[k] = loop_beta(k);
            let w = loop_omega(k);
            limit[k] = (w / (w + k as f64), 1.0 / (w + k as f64));
        }
        let mut trig = Vec::with_capacity(n * n / 2);
        for k in 0..n {
            for i in 0..k {
                let (s, c) = (2.0 * PI * i as f64 / k as f64).sin_cos();
                trig.push((c, s));
            }
        }
        ValenceTables { beta, limit, trig }
    }
    /// `(cos, sin)(2 pi i / k)`.
    #[inline]
    pub fn cos_sin(&self, k: usize, i: usize) -> (f64, f64) {
        match self.trig.get(k * (k.saturating_sub(1)) / 2 + i) {
            Some(&cs) if k < self.beta.len() => cs,
            _ => {
                let (s, c) = (2.0 * PI * i as f64 / k as f64).sin_cos();
                (c, s)
            }
        }
    }
    #[inline]
    pub fn beta(&self, k: usize) -> f64 {
        match self.beta.get(k) {
            Some(&b) => b,
            None => loop_beta(k),
        }
    }
    #[inline]
    pub fn limit(&self, k: usize) -> (f64, f64) {
        match self.limit.get(k) {
            Some(&w) => w,
            None => {
                let w = loop_omega(k);
                (w / (w + k as f64), 1.0 / (w + k as f64))
            }
        }
    }
}

/// Crease-curve limit weights `(w_l, w_c, w_r)` applied one step later (reference §4.2):
/// `(1,4,1)/6` for a regular centre, `(1,3,1)/5` for a non-regular one.
#[inline]
pub fn crease_limit_weights(centre_regular: bool) -> (f64, f64) {
    if centre_regular {
        (1.0 / 6.0, 4.0 / 6.0)
    } else {
        (0.2, 0.6)
    }
}

/// Normalised direction or zero.
#[inline]
pub(crate) fn normalize_or_zero(v: DVec3) -> DVec3 {
    let l = v.length();
    if l > 0.0 && l.is_finite() {
        v / l
    } else {
        DVec3::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beta_and_omega_tables() {
        // reference §3.1 / §4.1
        assert!((loop_beta(3) - 3.0 / 16.0).abs() < 1e-15);
        assert!((loop_beta(4) - 31.0 / 256.0).abs() < 1e-15);
        assert!((loop_beta(5) - 0.0840932).abs() < 1e-7);
        assert!((loop_beta(6) - 1.0 / 16.0).abs() < 1e-15);
        assert!((loop_beta(7) - 0.0490249).abs() < 1e-7);
        assert!((loop_beta(8) - 0.0400678).abs() < 1e-7);
        assert!((loop_omega(3) - 2.0).abs() < 1e-12);
        assert!((loop_omega(4) - 96.0 / 31.0).abs() < 1e-12);
        assert!((loop_omega(6) - 6.0).abs() < 1e-12);
        assert!((loop_omega(8) - 9.3591340).abs() < 1e-6);
        let t = ValenceTables::new(8);
        assert!((t.limit(4).0 - 24.0 / 55.0).abs() < 1e-12);
        assert!((t.limit(4).1 - 31.0 / 220.0).abs() < 1e-12);
        assert!((t.limit(6).0 - 0.5).abs() < 1e-12);
        assert!((t.limit(40).0 + 40.0 * t.limit(40).1 - 1.0).abs() < 1e-12);
    }

    #[test]
    fn crease_rules_by_type() {
        use vclass::*;
        assert_eq!(eclass::crease_rule(CREASE_REGULAR, CREASE_REGULAR), eclass::MID);
        assert_eq!(eclass::crease_rule(CORNER, CREASE_NONREG), eclass::MID);
        assert_eq!(eclass::crease_rule(CREASE_REGULAR, CORNER), eclass::W58A);
        assert_eq!(eclass::crease_rule(CREASE_NONREG, CREASE_REGULAR), eclass::W58B);
        assert_eq!(eclass::crease_rule(DART, CREASE_REGULAR), eclass::SMOOTH);
    }
}
