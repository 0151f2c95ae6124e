//! Deterministic, area-weighted sampling of a triangle mesh.

use glam::DVec3;

/// How many random samples to draw (mesh vertices can be added on top).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SampleCount {
    /// Exactly this many area-weighted random samples.
    Total(usize),
    /// This many samples per unit area (rounded down, at least one if the mesh has area).
    #[cfg(feature = "internals")]
    PerArea(f64),
}

/// One sample point with where it lies on the mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSample {
    pub point: DVec3,
    /// Triangle index (for a vertex sample: a triangle holding that vertex).
    pub triangle: u32,
    pub barycentric: [f64; 3],
}

/// SplitMix64: tiny, fast, and its output depends only on the seed, never on the platform,
/// so the same seed gives the same samples everywhere.
pub(crate) struct SplitMix64(u64);

impl SplitMix64 {
    pub(crate) fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }
    /// The generator seeded with `seed` after `k` outputs.
    fn after(seed: u64, k: u64) -> Self {
        Self::new(seed.wrapping_add(k.wrapping_mul(Self::GAMMA)))
    }
    const GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(Self::GAMMA);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub(crate) fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

/// Samples the surface of `triangles` (indices into `positions`; indices must be in range).
///
/// Random samples are area-weighted: a triangle is chosen with probability proportional to
/// its area (binary search in the cumulative areas), then a point uniformly inside it
/// (square-root warp). With `include_vertices`, every vertex used by a triangle is added
/// first (in vertex order), so sharp features and corners are always represented. The
/// result depends only on the inputs and `seed`.
pub fn sample_surface(
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    count: SampleCount,
    include_vertices: bool,
    seed: u64,
) -> Vec<SurfaceSample> {
    let mut out = Vec::new();
    if include_vertices {
        let mut owner = vec![u32::MAX; positions.len()];
        let mut corner = vec![0u8; positions.len()];
        for (t, tri) in triangles.iter().enumerate() {
            for (k, &v) in tri.iter().enumerate() {
                if owner[v as usize] == u32::MAX {
                    owner[v as usize] = t as u32;
                    corner[v as usize] = k as u8;
                }
            }
        }
        for (v, &t) in owner.iter().enumerate() {
            if t != u32::MAX {
                let mut bc = [0.0; 3];
                bc[corner[v] as usize] = 1.0;
                out.push(SurfaceSample {
                    point: positions[v],
                    triangle: t,
                    barycentric: bc,
                });
            }
        }
    }
    let random = RandomSamples::new(positions, triangles, count, seed);
    out.reserve(random.len());
    out.extend((0..random.len()).map(|i| random.get(i)));
    out
}

/// The area-weighted random samples of [`sample_surface`], each made on its own, so a caller
/// can visit millions of them without storing them: sample i reads the generator's outputs
/// 3i to 3i + 2, and SplitMix64's state after k outputs is the seed plus k times its
/// increment.
pub struct RandomSamples<'a> {
    positions: &'a [DVec3],
    triangles: &'a [[u32; 3]],
    /// Running total of the triangles' areas (the last one is the total area).
    cumulative: Vec<f64>,
    count: usize,
    seed: u64,
}

impl<'a> RandomSamples<'a> {
    /// `count` samples of the surface of `triangles` (none when it has no finite area).
    pub fn new(
        positions: &'a [DVec3],
        triangles: &'a [[u32; 3]],
        count: SampleCount,
        seed: u64,
    ) -> Self {
        let mut cumulative = Vec::with_capacity(triangles.len());
        let mut total = 0.0;
        for tri in triangles {
            let [a, b, c] = tri.map(|v| positions[v as usize]);
            total += 0.5 * (b - a).cross(c - a).length();
            cumulative.push(total);
        }
        let count = if total <= 0.0 || !total.is_finite() {
            0
        } else {
            match count {
                SampleCount::Total(n) => n,
                #[cfg(feature = "internals")]
                SampleCount::PerArea(d) if d > 0.0 && d.is_finite() => {
                    ((d * total) as usize).max(1)
                }
                #[cfg(feature = "internals")]
                SampleCount::PerArea(_) => 0,
            }
        };
        RandomSamples {
            positions,
            triangles,
            cumulative,
            count,
            seed,
        }
    }

    pub fn len(&self) -> usize {
        self.count
    }

    #[cfg(feature = "internals")]
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The triangle of sample `i` (as [`RandomSamples::get`] chooses it).
    fn triangle_of(&self, i: usize) -> u32 {
        let total = self.cumulative.last().copied().unwrap_or(0.0);
        let mut rng = SplitMix64::after(self.seed, 3 * i as u64);
        let target = rng.next_f64() * total;
        self.cumulative
            .partition_point(|&c| c <= target)
            .min(self.triangles.len() - 1) as u32
    }

    /// Sample `i` (< [`RandomSamples::len`]): a triangle chosen with probability proportional
    /// to its area (binary search in the cumulative areas), then a point uniformly inside it
    /// (square-root warp).
    pub fn get(&self, i: usize) -> SurfaceSample {
        let t = self.triangle_of(i) as usize;
        let mut rng = SplitMix64::after(self.seed, 3 * i as u64 + 1);
        let (r1, r2) = (rng.next_f64(), rng.next_f64());
        let s = r1.sqrt();
        let bc = [1.0 - s, s * (1.0 - r2), s * r2];
        let [a, b, c] = self.triangles[t].map(|v| self.positions[v as usize]);
        SurfaceSample {
            point: a * bc[0] + b * bc[1] + c * bc[2],
            triangle: t as u32,
            barycentric: bc,
        }
    }
}

/// The total area of `triangles` over `positions`, summed in order.
pub fn surface_area(positions: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| positions[v as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .sum()
}

/// The most points [`TriangleSamples`] makes of one set of triangles.
const MAX_TRIANGLE_SAMPLES: usize = 1 << 22;

/// Area-weighted random points of a set of triangles in which each triangle's points are a
/// function of that triangle alone: how many (the expected number is `density` times its
/// area) and where are drawn from a generator seeded by `seed` and the bits of its corners,
/// taken in coordinate order. So the same triangle gets the same points wherever it is
/// listed, in whatever order and with its corners in whatever rotation: a surface measured
/// face by face, a face measured again after the rest of the model changed, and a decoded
/// file whose faces were stored in another order all sample the same points. The
/// measurements of decoded surfaces use them (the encoder's, which keeps per-face results,
/// and `scode info --against`'s, which must find the same figures).
pub struct TriangleSamples<'a> {
    positions: &'a [DVec3],
    triangles: &'a [[u32; 3]],
    /// Per sample: its triangle and its number in that triangle, triangle by triangle.
    samples: Vec<(u32, u32)>,
    seed: u64,
}

impl<'a> TriangleSamples<'a> {
    /// The points of `triangles` over `positions` at `density` points per unit area (none
    /// for a density that is not positive and finite).
    pub fn new(positions: &'a [DVec3], triangles: &'a [[u32; 3]], density: f64, seed: u64) -> Self {
        // Each triangle's samples at `density`; `None` once they pass `cap`.
        let draw = |density: f64, cap: f64| -> Option<Vec<(u32, u32)>> {
            let mut samples = Vec::new();
            if !(density > 0.0 && density.is_finite()) {
                return Some(samples);
            }
            for (t, tri) in triangles.iter().enumerate() {
                let (corners, mut rng) = Self::corners(positions, tri, seed);
                let [a, b, c] = corners.map(|k| positions[tri[k] as usize]);
                let expected = density * 0.5 * (b - a).cross(c - a).length();
                if !(expected > 0.0 && expected.is_finite()) {
                    continue;
                }
                let n = expected.floor() + f64::from(u8::from(rng.next_f64() < expected.fract()));
                if samples.len() as f64 + n > cap {
                    return None;
                }
                samples.extend((0..n as u32).map(|k| (t as u32, k)));
            }
            Some(samples)
        };
        // A surface far larger than the one the density was set for (a file measured
        // against an unrelated mesh) is drawn again at the density that makes about
        // `MAX_TRIANGLE_SAMPLES` points on the whole.
        let samples = draw(density, MAX_TRIANGLE_SAMPLES as f64).unwrap_or_else(|| {
            let area = surface_area(positions, triangles);
            draw(MAX_TRIANGLE_SAMPLES as f64 / area, f64::INFINITY).unwrap_or_default()
        });
        TriangleSamples {
            positions,
            triangles,
            samples,
            seed,
        }
    }

    /// The corners of `tri` (0..3) in coordinate order (ties by corner), and the
    /// triangle's generator: seeded by `seed` and the corners' bits in that order.
    fn corners(positions: &[DVec3], tri: &[u32; 3], seed: u64) -> ([usize; 3], SplitMix64) {
        let p = tri.map(|v| positions[v as usize].to_array());
        let mut order = [0usize, 1, 2];
        order.sort_by(|&i, &j| {
            (0..3)
                .map(|k| p[i][k].total_cmp(&p[j][k]))
                .find(|o| o.is_ne())
                .unwrap_or(std::cmp::Ordering::Equal)
                .then(i.cmp(&j))
        });
        let mut h = seed;
        for &i in &order {
            for x in p[i] {
                h = SplitMix64::new(h ^ x.to_bits()).next_u64();
            }
        }
        (order, SplitMix64::new(h))
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    #[cfg(feature = "internals")]
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Sample `i` (< [`TriangleSamples::len`]): a point uniformly inside its triangle
    /// (square-root warp), the `k`-th of the triangle's generator after its count.
    pub fn get(&self, i: usize) -> SurfaceSample {
        let (t, k) = self.samples[i];
        let tri = &self.triangles[t as usize];
        let (corners, rng) = Self::corners(self.positions, tri, self.seed);
        let SplitMix64(state) = rng;
        let mut rng = SplitMix64::after(state, 1 + 2 * u64::from(k));
        let (r1, r2) = (rng.next_f64(), rng.next_f64());
        let s = r1.sqrt();
        let weights = [1.0 - s, s * (1.0 - r2), s * r2];
        let mut barycentric = [0.0; 3];
        let mut point = DVec3::ZERO;
        for (w, &c) in weights.iter().zip(&corners) {
            barycentric[c] = *w;
            point += *w * self.positions[tri[c] as usize];
        }
        SurfaceSample {
            point,
            triangle: t,
            barycentric,
        }
    }
}

/// The indices of `points` in the order of a Z-order (Morton) curve through their box (ties
/// by index): consecutive points of the order are mostly near each other, so a run of
/// closest-point queries in this order can bound each by the previous hit.
pub fn space_filling_order(points: impl Iterator<Item = DVec3> + Clone) -> Vec<u32> {
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for p in points.clone().filter(|p| p.is_finite()) {
        (lo, hi) = (lo.min(p), hi.max(p));
    }
    let scale = (hi - lo).max_element();
    let scale = if scale > 0.0 && scale.is_finite() {
        ((1u32 << 21) - 1) as f64 / scale
    } else {
        0.0
    };
    // Spreads the low 21 bits of `x` to every third bit.
    let spread = |x: u64| {
        let mut x = x & 0x1f_ffff;
        x = (x | x << 32) & 0x1f_0000_0000_ffff;
        x = (x | x << 16) & 0x1f_0000_ff00_00ff;
        x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
        x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
        (x | x << 2) & 0x1249_2492_4924_9249
    };
    let mut keyed: Vec<(u64, u32)> = points
        .enumerate()
        .map(|(i, p)| {
            // Non-finite points sort together (the cast saturates NaN to 0).
            let q = ((p - lo) * scale).to_array().map(|c| c as u64);
            (
                spread(q[0]) | spread(q[1]) << 1 | spread(q[2]) << 2,
                i as u32,
            )
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|x| x.1).collect()
}

/// Points along the long edges of thin triangles: every edge longer than `spacing` of a
/// triangle less than `spacing` high (over its longest edge) gets evenly spaced points
/// between its ends, no farther apart than `spacing`, so every point of such a triangle is
/// within about `spacing` of a sample. Area-weighted random samples rarely land on a thin
/// sliver (a long triangle of little area), which is where a decoded plane can cross its
/// face's concave outline; a well-shaped triangle holds random points in proportion to its
/// area and is left to them. An edge is sampled once: from the triangle in which it runs
/// from the smaller end (by coordinates) to the larger, unless only the other one samples
/// it (the other triangle is well shaped, or there is none: the mesh's boundary). The points
/// are placed from the smaller end, so two meshes holding the same triangles (a face's
/// triangles on their own and the whole surface) place the same points on them.
pub struct EdgeSamples<'a> {
    positions: &'a [DVec3],
    triangles: &'a [[u32; 3]],
    /// Per sampled edge: its triangle, the corner it starts at (it ends at the next one)
    /// and how many segments it is cut into.
    edges: Vec<(u32, u8, u32)>,
    /// Samples before edge k: `start[k]` (one more entry than `edges`).
    start: Vec<usize>,
}

/// `p` before `q` in lexicographic order of their coordinates.
fn before(p: DVec3, q: DVec3) -> bool {
    let (a, b) = (p.to_array(), q.to_array());
    (0..3)
        .map(|k| a[k].total_cmp(&b[k]))
        .find(|o| o.is_ne())
        .is_some_and(|o| o.is_lt())
}

impl<'a> EdgeSamples<'a> {
    /// The samples of `triangles`' edges at `spacing` (none for a spacing that is not a
    /// positive length).
    pub fn new(positions: &'a [DVec3], triangles: &'a [[u32; 3]], spacing: f64) -> Self {
        let mut edges = Vec::new();
        let mut start = vec![0usize];
        if !(spacing > 0.0 && spacing.is_finite()) {
            return EdgeSamples {
                positions,
                triangles,
                edges,
                start,
            };
        }
        let ends = |t: usize, k: usize| (triangles[t][k], triangles[t][(k + 1) % 3]);
        // Every long edge with whether its triangle is thin.
        let mut long = Vec::new();
        for (t, tri) in triangles.iter().enumerate() {
            let [p, q, r] = tri.map(|v| positions[v as usize]);
            let lengths = [(q - p).length(), (r - q).length(), (p - r).length()];
            let longest = lengths[0].max(lengths[1]).max(lengths[2]);
            let thin = (q - p).cross(r - p).length() < spacing * longest;
            for (k, &length) in lengths.iter().enumerate() {
                if length > spacing {
                    long.push((t as u32, k as u8, (length / spacing).ceil(), thin));
                }
            }
        }
        let directed: rustc_hash::FxHashMap<(u32, u32), bool> = long
            .iter()
            .map(|&(t, k, _, thin)| (ends(t as usize, usize::from(k)), thin))
            .collect();
        for (t, k, segments, thin) in long {
            let (a, b) = ends(t as usize, usize::from(k));
            let forward = before(positions[a as usize], positions[b as usize]);
            let other_samples = directed.get(&(b, a)).copied().unwrap_or(false);
            if thin && (forward || !other_samples) {
                let segments = segments.min(f64::from(u32::MAX)) as u32;
                edges.push((t, k, segments));
                let last = start.last().copied().unwrap_or(0);
                start.push(last + segments as usize - 1);
            }
        }
        EdgeSamples {
            positions,
            triangles,
            edges,
            start,
        }
    }

    pub fn len(&self) -> usize {
        self.start.last().copied().unwrap_or(0)
    }

    #[cfg(feature = "internals")]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Sample `i` (< [`EdgeSamples::len`]).
    pub fn get(&self, i: usize) -> SurfaceSample {
        let e = self.start.partition_point(|&s| s <= i) - 1;
        let (t, k, segments) = self.edges[e];
        let j = i - self.start[e] + 1;
        let tri = self.triangles[t as usize];
        let (mut k0, mut k1) = (usize::from(k), (usize::from(k) + 1) % 3);
        let (mut p, mut q) = (
            self.positions[tri[k0] as usize],
            self.positions[tri[k1] as usize],
        );
        if before(q, p) {
            (k0, k1, p, q) = (k1, k0, q, p);
        }
        let w1 = j as f64 / f64::from(segments);
        let w0 = 1.0 - w1;
        let mut barycentric = [0.0; 3];
        barycentric[k0] = w0;
        barycentric[k1] = w1;
        SurfaceSample {
            point: p * w0 + q * w1,
            triangle: t,
            barycentric,
        }
    }
}

/// Seeded generator for tests in other modules (same SplitMix64 stream).
#[cfg(test)]
pub(crate) struct SplitMixForTests(SplitMix64);

#[cfg(test)]
impl SplitMixForTests {
    pub(crate) fn new(seed: u64) -> Self {
        SplitMixForTests(SplitMix64::new(seed))
    }
    pub(crate) fn f(&mut self) -> f64 {
        self.0.next_f64()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The edge points `edges` takes from triangle `t`.
    fn edges_of(edges: &EdgeSamples, t: u32) -> Vec<DVec3> {
        (0..edges.len())
            .map(|i| edges.get(i))
            .filter(|s| s.triangle == t)
            .map(|s| s.point)
            .collect()
    }

    /// A long sliver and a fat triangle sharing the sliver's long edge, numbered so that
    /// the edge runs one way in each: every edge longer than the spacing is sampled once,
    /// its points on it and no farther apart than the spacing.
    #[test]
    fn every_long_edge_once_at_most_the_spacing_apart() {
        let positions = [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(10.0, 0.0, 0.0),
            DVec3::new(5.0, 0.2, 0.0),
            DVec3::new(5.0, -3.0, 0.0),
            DVec3::new(5.0, 0.3, 0.0),
        ];
        // A sliver 0.2 high on 0-1 (which the fat triangle runs the other way), and one
        // 0.1 high on 1-2 (as a boundary edge of the sliver, 1-2 runs from the larger end).
        let triangles = [[0, 1, 2], [1, 0, 3], [2, 1, 4]];
        let spacing = 0.75;
        let edges = EdgeSamples::new(&positions, &triangles, spacing);
        // The shared edge 0-1 (10 long: 14 segments, 13 points) once, from the sliver; 0-2
        // (5.004 long: 7 segments) and 1-2 once; 1-4 and 4-2 (5.009 and 0.1 long) of the
        // second sliver; nothing of the fat triangle (0-3, 3-1 are not a sliver's).
        assert_eq!(edges.len(), 13 + 6 + 6 + 6);
        let mut on_shared: Vec<f64> = (0..edges.len())
            .map(|i| edges.get(i))
            .inspect(|s| {
                let [a, b, c] = triangles[s.triangle as usize].map(|v| positions[v as usize]);
                let back = a * s.barycentric[0] + b * s.barycentric[1] + c * s.barycentric[2];
                assert!((back - s.point).length() < 1e-12);
                assert_eq!(s.barycentric.iter().filter(|&&w| w == 0.0).count(), 1);
            })
            .map(|s| s.point)
            .filter(|p| p.y == 0.0)
            .map(|p| p.x)
            .collect();
        on_shared.sort_by(f64::total_cmp);
        assert_eq!(on_shared.len(), 13);
        assert!(edges_of(&edges, 1).is_empty());
        let mut last = 0.0;
        for x in on_shared.iter().chain([10.0].iter()) {
            assert!(x - last <= spacing + 1e-12 && x - last > 0.0);
            last = *x;
        }
        assert!(EdgeSamples::new(&positions, &triangles, 0.0).is_empty());
        // Fat triangles alone: no edge points.
        assert!(EdgeSamples::new(&positions, &triangles[1..2], spacing).is_empty());
        assert!(EdgeSamples::new(&positions, &triangles, 11.0).is_empty());
    }
}
