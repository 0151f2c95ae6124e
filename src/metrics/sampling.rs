//! Deterministic, area-weighted sampling of a triangle mesh.

use glam::DVec3;

/// How many random samples to draw (mesh vertices can be added on top).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SampleCount {
    /// Exactly this many area-weighted random samples.
    Total(usize),
    /// This many samples per unit area (rounded down, at least one if the mesh has area).
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
                SampleCount::PerArea(d) if d > 0.0 && d.is_finite() => {
                    ((d * total) as usize).max(1)
                }
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

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Sample `i` (< [`RandomSamples::len`]): a triangle chosen with probability proportional
    /// to its area (binary search in the cumulative areas), then a point uniformly inside it
    /// (square-root warp).
    pub fn get(&self, i: usize) -> SurfaceSample {
        let total = self.cumulative.last().copied().unwrap_or(0.0);
        let mut rng = SplitMix64::after(self.seed, 3 * i as u64);
        let target = rng.next_f64() * total;
        let t = self
            .cumulative
            .partition_point(|&c| c <= target)
            .min(self.triangles.len() - 1);
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
