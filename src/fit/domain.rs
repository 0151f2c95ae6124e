//! Where a plane face lies within its plane, as a raster: the decimation asks of every
//! interior edge a collapse would create whether the edge stays on the face (a long diagonal
//! of a curved strip or across a hole leaves it, and a plane patch's interior edges decode as
//! straight lines). Closest-point queries on the face's triangles would cost more than the
//! rest of the decimation on models with large plane faces, as the question is asked for
//! every candidate collapse; a cell lookup costs a few multiplications.

use glam::{DVec2, DVec3};

/// The cells of a plane face's frame that come within `dist` of one of its triangles. Shaped
/// as one bit per cell of a regular grid over the face's bounding rectangle: the faces of a CAD
/// model are few and the grid small (the cell is at least `dist`, and it grows so that a face
/// never takes more than `MAX_CELLS` bits).
#[derive(Clone, Debug)]
pub struct PlaneDomain {
    origin: DVec3,
    u: DVec3,
    v: DVec3,
    /// Lower corner of the grid in (u, v) and the cell side.
    min: DVec2,
    cell: f64,
    width: usize,
    height: usize,
    bits: Vec<u64>,
}

/// Largest grid of one face (2^22 cells: 512 KiB).
const MAX_CELLS: f64 = 4_194_304.0;

impl PlaneDomain {
    /// The domain of `triangles` (corner positions) in the plane through their first corner
    /// with unit `normal`: about the points of the plane within `dist` of a triangle (see
    /// below for the bounds). `None` for no triangles, a zero normal or distance.
    pub fn new(triangles: &[[DVec3; 3]], normal: DVec3, dist: f64) -> Option<Self> {
        let n = normal.try_normalize()?;
        let first = triangles.first()?[0];
        if !(dist > 0.0 && dist.is_finite()) {
            return None;
        }
        let u = n.any_orthonormal_vector();
        let v = n.cross(u);
        let to2 = |p: DVec3| DVec2::new((p - first).dot(u), (p - first).dot(v));
        let flat: Vec<[DVec2; 3]> = triangles.iter().map(|t| t.map(to2)).collect();
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for t in &flat {
            for p in t {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
        if !(lo.is_finite() && hi.is_finite()) {
            return None;
        }
        // Cells of a quarter of `dist` grown by three quarters: a point within 0.75 `dist`
        // of the face is always inside, one farther than 1.42 `dist` never (a coarser grid
        // for a face too large for `MAX_CELLS` only admits more).
        let grow = 0.75 * dist;
        lo -= DVec2::splat(dist);
        hi += DVec2::splat(dist);
        let ext = hi - lo;
        let cell = (0.25 * dist).max((ext.x * ext.y / MAX_CELLS).sqrt());
        let width = (ext.x / cell).ceil().max(1.0) as usize;
        let height = (ext.y / cell).ceil().max(1.0) as usize;
        let mut d = PlaneDomain {
            origin: first,
            u,
            v,
            min: lo,
            cell,
            width,
            height,
            bits: vec![0; (width * height).div_ceil(64)],
        };
        for t in &flat {
            d.mark(t, grow);
        }
        Some(d)
    }

    /// Marks the cells whose square grown by `dist` (on each side) meets triangle `t`: row by
    /// row, the triangle's x-extent within the row's grown strip.
    fn mark(&mut self, t: &[DVec2; 3], dist: f64) {
        let ymin = t.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
        let ymax = t.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max);
        let row = |y: f64| ((y - self.min.y) / self.cell).floor();
        let j0 = row(ymin - dist).max(0.0) as usize;
        let j1 = (row(ymax + dist).max(0.0) as usize).min(self.height - 1);
        for j in j0..=j1 {
            let lo = self.min.y + j as f64 * self.cell - dist;
            let hi = lo + self.cell + 2.0 * dist;
            let (mut xa, mut xb) = (f64::INFINITY, f64::NEG_INFINITY);
            let mut take = |x: f64| {
                xa = xa.min(x);
                xb = xb.max(x);
            };
            for k in 0..3 {
                let (p, q) = (t[k], t[(k + 1) % 3]);
                if (lo..=hi).contains(&p.y) {
                    take(p.x);
                }
                for y in [lo, hi] {
                    if (p.y - y) * (q.y - y) < 0.0 {
                        take(p.x + (q.x - p.x) * (y - p.y) / (q.y - p.y));
                    }
                }
            }
            if xa > xb {
                continue;
            }
            let col = |x: f64| ((x - self.min.x) / self.cell).floor();
            let i0 = col(xa - dist).max(0.0) as usize;
            let i1 = (col(xb + dist).max(0.0) as usize).min(self.width - 1);
            for i in i0..=i1 {
                let b = j * self.width + i;
                self.bits[b / 64] |= 1 << (b % 64);
            }
        }
    }

    /// Whether `p` (projected onto the plane) falls in a cell near the face.
    pub fn contains(&self, p: DVec3) -> bool {
        let d = p - self.origin;
        let x = (d.dot(self.u) - self.min.x) / self.cell;
        let y = (d.dot(self.v) - self.min.y) / self.cell;
        if !(x >= 0.0 && y >= 0.0) {
            return false;
        }
        let (i, j) = (x as usize, y as usize);
        if i >= self.width || j >= self.height {
            return false;
        }
        let b = j * self.width + i;
        self.bits[b / 64] & (1 << (b % 64)) != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_with_a_hole() {
        // The frame [0, 10]^2 minus the hole [3, 7]^2, as 8 triangles, in the plane z = 2.
        let p = |x: f64, y: f64| DVec3::new(x, y, 2.0);
        let quad = |a: DVec3, b: DVec3, c: DVec3, d: DVec3| [[a, b, c], [a, c, d]];
        let mut t = Vec::new();
        t.extend(quad(p(0., 0.), p(10., 0.), p(10., 3.), p(0., 3.)));
        t.extend(quad(p(0., 7.), p(10., 7.), p(10., 10.), p(0., 10.)));
        t.extend(quad(p(0., 3.), p(3., 3.), p(3., 7.), p(0., 7.)));
        t.extend(quad(p(7., 3.), p(10., 3.), p(10., 7.), p(7., 7.)));
        let d = PlaneDomain::new(&t, DVec3::Z, 0.1).unwrap();
        for (x, y) in [
            (1.0, 1.0),
            (5.0, 1.5),
            (9.9, 9.9),
            (2.95, 5.0),
            (-0.05, 5.0),
        ] {
            assert!(d.contains(p(x, y)), "({x}, {y}) is on the face");
        }
        // Off the plane counts as its projection.
        assert!(d.contains(DVec3::new(1.0, 1.0, 7.0)));
        for (x, y) in [
            (5.0, 5.0),
            (3.5, 6.5),
            (-1.0, 5.0),
            (5.0, 10.5),
            (11.0, 11.0),
        ] {
            assert!(!d.contains(p(x, y)), "({x}, {y}) is off the face");
        }
    }

    #[test]
    fn long_thin_triangles_mark_only_their_own_cells() {
        // One sliver from (0, 0) to (100, 1): a point at (50, 0.5) is on it, (50, 5) is not
        // (a bounding-box raster would take it).
        let t = [[
            DVec3::ZERO,
            DVec3::new(100.0, 0.0, 0.0),
            DVec3::new(100.0, 1.0, 0.0),
        ]];
        let d = PlaneDomain::new(&t, DVec3::Z, 0.2).unwrap();
        assert!(d.contains(DVec3::new(50.0, 0.3, 0.0)));
        assert!(!d.contains(DVec3::new(50.0, 5.0, 0.0)));
        assert!(!d.contains(DVec3::new(10.0, 0.9, 0.0)));
    }

    #[test]
    fn degenerate_input_has_no_domain() {
        let t = [[DVec3::ZERO; 3]];
        assert!(PlaneDomain::new(&[], DVec3::Z, 1.0).is_none());
        assert!(PlaneDomain::new(&t, DVec3::ZERO, 1.0).is_none());
        assert!(PlaneDomain::new(&t, DVec3::Z, 0.0).is_none());
        // A point triangle still has a (tiny) domain around it.
        let d = PlaneDomain::new(&t, DVec3::Z, 1.0).unwrap();
        assert!(d.contains(DVec3::new(0.5, 0.5, 0.0)));
        assert!(!d.contains(DVec3::new(5.0, 0.0, 0.0)));
    }
}
