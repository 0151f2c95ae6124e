//! Exact vertex welding.
//!
//! Formats that store each group (OBJ via exporters that re-index per object, glTF primitives)
//! or each triangle (STL) with its own vertex copies lose the sharing between CAD faces that
//! the control mesh needs. Identical f64 coordinates are merged here; nothing within a
//! tolerance is merged, because two distinct CAD vertices may legitimately be very close.
//!
//! Readers weld only vertices that lie on an open boundary of the mesh as stored (or that no
//! face uses): that is where duplication cuts a surface apart. Coincident vertices inside an
//! already-closed surface are kept apart, because merging them would join separate solids of
//! an assembly that touch at a point or edge and create non-manifold edges (the corpus
//! assemblies `trj2`, `trj3`, `trj4`, `bug33398` have such contacts).

use glam::DVec3;

/// Bit pattern of a position used as the sort key. `-0.0` is mapped to `+0.0` (adding `0.0`
/// does exactly that in IEEE arithmetic) so that the two zeros weld. Only used to find duplicates:
/// output order is always first-occurrence order.
#[inline]
fn key(p: DVec3) -> [u64; 3] {
    [
        (p.x + 0.0).to_bits(),
        (p.y + 0.0).to_bits(),
        (p.z + 0.0).to_bits(),
    ]
}

/// Result of [`weld`]: the unique positions in order of first occurrence, and for every input
/// vertex the index of its unique position.
#[derive(Clone, Debug, PartialEq)]
pub struct Welded {
    pub positions: Vec<DVec3>,
    /// `remap[i]` = index in `positions` of input vertex `i`.
    pub remap: Vec<u32>,
    /// Vertices left separate although an earlier vertex has the same coordinates (because
    /// one of them was not eligible for welding).
    pub coincident_kept: usize,
}

impl Welded {
    /// Number of input vertices merged into an earlier one.
    pub fn merged(&self) -> usize {
        self.remap.len() - self.positions.len()
    }
}

/// Merges vertices with identical coordinates (`-0.0 == 0.0`). The first occurrence keeps its
/// relative order and its exact coordinates. Positions must be finite (readers check that
/// first), otherwise NaNs would never weld.
pub fn weld(positions: &[DVec3]) -> Welded {
    weld_where(positions, |_| true)
}

/// Like [`weld`], but only vertices `i` with `eligible(i)` are merged, and only with each
/// other; the others keep their own index (and are counted in
/// [`Welded::coincident_kept`] when they share coordinates with an earlier vertex).
///
/// Implemented by sorting `(key, index)` pairs rather than hashing: O(n log n) whatever the
/// input (no hash flooding from crafted files) and deterministic by construction.
pub fn weld_where(positions: &[DVec3], eligible: impl Fn(usize) -> bool) -> Welded {
    let n = positions.len();
    let mut order: Vec<([u64; 3], u32)> = positions
        .iter()
        .enumerate()
        .map(|(i, &p)| (key(p), i as u32))
        .collect();
    order.sort_unstable();
    // representative[i]: the vertex `i` merges into (itself if it stays).
    let mut representative: Vec<u32> = (0..n as u32).collect();
    let mut coincident_kept = 0;
    let mut start = 0;
    while start < order.len() {
        let mut end = start + 1;
        while end < order.len() && order[end].0 == order[start].0 {
            end += 1;
        }
        // Within a run of equal positions, indices ascend: the first eligible vertex is the
        // representative of every later eligible one.
        let mut rep: Option<u32> = None;
        for (k, &(_, i)) in order[start..end].iter().enumerate() {
            if eligible(i as usize) {
                match rep {
                    Some(r) => {
                        representative[i as usize] = r;
                        continue;
                    }
                    None => rep = Some(i),
                }
            }
            if k > 0 {
                coincident_kept += 1;
            }
        }
        start = end;
    }
    let mut unique = Vec::with_capacity(n);
    let mut remap = Vec::with_capacity(n);
    for (i, &p) in positions.iter().enumerate() {
        let r = representative[i] as usize;
        if r == i {
            remap.push(unique.len() as u32);
            unique.push(p);
        } else {
            // r < i, so its new index is already known.
            remap.push(remap[r]);
        }
    }
    Welded {
        positions: unique,
        remap,
        coincident_kept,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welds_exact_duplicates_in_first_occurrence_order() {
        let p = |x, y, z| DVec3::new(x, y, z);
        let input = [
            p(1.0, 0.0, 0.0),
            p(0.0, 1.0, 0.0),
            p(1.0, 0.0, 0.0),
            p(0.0, -0.0, 0.0),
            p(-0.0, 0.0, 0.0),
            p(0.0, 1.0, 1e-300),
        ];
        let w = weld(&input);
        assert_eq!(w.remap, vec![0, 1, 0, 2, 2, 3]);
        assert_eq!(w.positions.len(), 4);
        assert_eq!(w.merged(), 2);
        // The first occurrence's exact bits are kept (-0.0 stays -0.0 for vertex 2).
        assert!(w.positions[2].y.is_sign_negative());
    }

    #[test]
    fn only_eligible_vertices_weld() {
        let p = DVec3::new(1.0, 2.0, 3.0);
        let q = DVec3::new(4.0, 5.0, 6.0);
        // 0 ineligible, 1 and 3 eligible (weld together), 2 ineligible, 4 eligible elsewhere.
        let w = weld_where(&[p, p, p, p, q], |i| i % 2 == 1 || i == 4);
        assert_eq!(w.remap, vec![0, 1, 2, 1, 3]);
        assert_eq!(w.merged(), 1);
        assert_eq!(w.coincident_kept, 2);
    }

    #[test]
    fn nearly_equal_positions_stay_apart() {
        let a = DVec3::new(0.1 + 0.2, 0.0, 0.0);
        let b = DVec3::new(0.3, 0.0, 0.0);
        assert_eq!(weld(&[a, b]).positions.len(), 2);
    }

    /// Quadratic reference: the definition of `weld_where`, spelled out.
    fn reference(positions: &[DVec3], eligible: &[bool]) -> Welded {
        let same = |a: DVec3, b: DVec3| key(a) == key(b);
        let mut unique: Vec<DVec3> = Vec::new();
        let mut remap = Vec::new();
        let mut coincident_kept = 0;
        for (i, &p) in positions.iter().enumerate() {
            let earlier = (0..i).find(|&j| eligible[i] && eligible[j] && same(positions[j], p));
            match earlier {
                Some(j) => remap.push(remap[j]),
                None => {
                    if (0..i).any(|j| same(positions[j], p)) {
                        coincident_kept += 1;
                    }
                    remap.push(unique.len() as u32);
                    unique.push(p);
                }
            }
        }
        Welded {
            positions: unique,
            remap,
            coincident_kept,
        }
    }

    proptest::proptest! {
        #[test]
        fn matches_reference(
            cells in proptest::collection::vec((0u8..4, 0u8..3, proptest::bool::ANY, proptest::bool::ANY), 0..40)
        ) {
            let positions: Vec<DVec3> = cells
                .iter()
                .map(|&(x, y, neg, _)| {
                    let z = if neg { -0.0 } else { 0.0 };
                    DVec3::new(f64::from(x), f64::from(y), z)
                })
                .collect();
            let eligible: Vec<bool> = cells.iter().map(|&(_, _, _, e)| e).collect();
            let got = weld_where(&positions, |i| eligible[i]);
            let want = reference(&positions, &eligible);
            proptest::prop_assert_eq!(got.remap, want.remap);
            proptest::prop_assert_eq!(got.coincident_kept, want.coincident_kept);
            proptest::prop_assert_eq!(got.positions.len(), want.positions.len());
        }
    }
}
