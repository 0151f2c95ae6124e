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

use std::collections::HashMap;

use glam::DVec3;

/// Bit pattern of a position used as a hash key. `-0.0` is mapped to `+0.0` (adding `0.0`
/// does exactly that in IEEE arithmetic) so that the two zeros weld. Only used for lookup:
/// output order never depends on hashing.
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
pub fn weld_where(positions: &[DVec3], eligible: impl Fn(usize) -> bool) -> Welded {
    // Key -> unique index of the first eligible vertex there (None: only ineligible so far).
    let mut first_eligible: HashMap<[u64; 3], Option<u32>> =
        HashMap::with_capacity(positions.len());
    let mut unique = Vec::with_capacity(positions.len());
    let mut remap = Vec::with_capacity(positions.len());
    let mut coincident_kept = 0;
    for (i, &p) in positions.iter().enumerate() {
        let next = unique.len() as u32;
        let is_eligible = eligible(i);
        let slot = first_eligible.entry(key(p));
        let idx = match slot {
            std::collections::hash_map::Entry::Vacant(e) => {
                e.insert(is_eligible.then_some(next));
                next
            }
            std::collections::hash_map::Entry::Occupied(mut e) => match (*e.get(), is_eligible) {
                (Some(rep), true) => rep,
                (None, true) => {
                    e.insert(Some(next));
                    coincident_kept += 1;
                    next
                }
                (_, false) => {
                    coincident_kept += 1;
                    next
                }
            },
        };
        if idx == next {
            unique.push(p);
        }
        remap.push(idx);
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
}
