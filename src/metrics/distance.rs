//! Sampled one-sided and symmetric (Hausdorff-style) distances between two meshes.

use glam::DVec3;

use super::sampling::{sample_surface, EdgeSamples, SampleCount, SurfaceSample};
use super::surface::{ClosestPoint, TriangleSurface};
use crate::mesh::Tolerance;
#[cfg(feature = "internals")]
use {
    super::sampling::{surface_area, TriangleSamples},
    super::surface::fan_triangulate,
    crate::error::Result,
    crate::mesh::ControlMesh,
};

/// How densely to sample each mesh when measuring distances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DistanceOptions {
    /// Random area-weighted samples: on the reference (B) this many; on the measured
    /// surface (A) as many per unit of B's area ([`sample_density`]: a decoded surface close
    /// to B gets about as many).
    pub samples: SampleCount,
    /// Also measure from every mesh vertex (catches errors at corners and creases).
    pub include_vertices: bool,
    /// Seed of the sampler; the same seed gives the same report.
    pub seed: u64,
    /// Also measure from points along every edge longer than this, this far apart at most
    /// ([`EdgeSamples`]; a relative spacing is a fraction of the two meshes' joint
    /// bounding-box diagonal): the thin slivers random samples miss. `None`: no edge points.
    pub edge_spacing: Option<Tolerance>,
}

/// The edge spacing of [`DistanceOptions::default`]: twice the encoder's default tolerance.
pub const DEFAULT_EDGE_SPACING: Tolerance = Tolerance::Relative(2e-3);

/// The edge spacing for checking a surface held within `tol` of a mesh whose diagonal is
/// `diagonal`: twice the tolerance, and never sparser than [`DEFAULT_EDGE_SPACING`] of that
/// diagonal, so that the check samples at least the edge points `scode info --against`
/// samples (its diagonal is the joint one, at least as long).
pub fn edge_spacing_for_tolerance(tol: f64, diagonal: f64) -> f64 {
    (2.0 * tol).min(DEFAULT_EDGE_SPACING.resolve(diagonal))
}

impl Default for DistanceOptions {
    fn default() -> Self {
        DistanceOptions {
            samples: SampleCount::Total(60_000),
            include_vertices: true,
            seed: 0x5C0D_E5C0_DE5C_0DE5,
            edge_spacing: Some(DEFAULT_EDGE_SPACING),
        }
    }
}

/// Statistics of the distances from sample points of one mesh to the other surface.
#[cfg(feature = "internals")]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OneSided {
    pub max: f64,
    pub rms: f64,
    pub mean: f64,
    /// Number of sample points measured.
    pub count: usize,
    /// The sample point that attains `max` (the first one in sample order on ties).
    pub argmax: DVec3,
}

/// Distances between two surfaces A and B, in model units.
///
/// The symmetric values follow the usual Hausdorff convention: the larger of the two
/// directions (`max` is the sampled Hausdorff distance). `diagonal` is the bounding-box
/// diagonal of A and B together, for relative errors ([`DistanceReport::relative`]).
#[cfg(feature = "internals")]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DistanceReport {
    pub max_a_to_b: f64,
    pub max_b_to_a: f64,
    pub rms_a_to_b: f64,
    pub rms_b_to_a: f64,
    pub mean_a_to_b: f64,
    pub mean_b_to_a: f64,
    /// max(max_a_to_b, max_b_to_a): the (sampled) Hausdorff distance.
    pub max: f64,
    /// max(rms_a_to_b, rms_b_to_a).
    pub rms: f64,
    /// max(mean_a_to_b, mean_b_to_a).
    pub mean: f64,
    pub diagonal: f64,
    pub samples_a: usize,
    pub samples_b: usize,
    /// The sample of A farthest from B, and of B farthest from A: where to look.
    pub worst_a_to_b: DVec3,
    pub worst_b_to_a: DVec3,
}

#[cfg(feature = "internals")]
impl DistanceReport {
    /// The report of two one-sided measurements, A to B and B to A, of surfaces whose
    /// common bounding-box diagonal is `diagonal`.
    pub fn from_sides(ab: &OneSided, ba: &OneSided, diagonal: f64) -> DistanceReport {
        DistanceReport {
            max_a_to_b: ab.max,
            max_b_to_a: ba.max,
            rms_a_to_b: ab.rms,
            rms_b_to_a: ba.rms,
            mean_a_to_b: ab.mean,
            mean_b_to_a: ba.mean,
            max: ab.max.max(ba.max),
            rms: ab.rms.max(ba.rms),
            mean: ab.mean.max(ba.mean),
            diagonal,
            samples_a: ab.count,
            samples_b: ba.count,
            worst_a_to_b: ab.argmax,
            worst_b_to_a: ba.argmax,
        }
    }

    /// The same report with every distance divided by `diagonal` (unchanged if it is 0).
    pub fn relative(&self) -> DistanceReport {
        let s = if self.diagonal > 0.0 {
            1.0 / self.diagonal
        } else {
            1.0
        };
        DistanceReport {
            max_a_to_b: self.max_a_to_b * s,
            max_b_to_a: self.max_b_to_a * s,
            rms_a_to_b: self.rms_a_to_b * s,
            rms_b_to_a: self.rms_b_to_a * s,
            mean_a_to_b: self.mean_a_to_b * s,
            mean_b_to_a: self.mean_b_to_a * s,
            max: self.max * s,
            rms: self.rms * s,
            mean: self.mean * s,
            diagonal: 1.0,
            ..*self
        }
    }
}

/// Queries are processed in fixed chunks of this many points: within a chunk each query
/// uses the previous answer as a distance bound (neighbouring samples are close), and the
/// chunking does not depend on the thread count, so results are bit-identical with and
/// without the `parallel` feature.
const CHUNK: usize = 256;

/// Closest points on `surface` to each of `points`, in the order of `points`.
#[cfg(feature = "internals")]
pub fn closest_points(points: &[DVec3], surface: &TriangleSurface) -> Vec<ClosestPoint> {
    closest_points_near(points, surface, f64::MAX)
}

/// Closest points on `surface` to each of `points`, for points expected within `radius` of
/// it: each query first searches only that far, or only as far as the previous point's hit
/// if that is nearer (a small radius prunes almost the whole tree), and searches everywhere
/// only when nothing is that near. Same answers as [`closest_points`].
pub fn closest_points_near(
    points: &[DVec3],
    surface: &TriangleSurface,
    radius: f64,
) -> Vec<ClosestPoint> {
    closest_points_near_with(points.len(), |i| points[i], surface, radius, |_, _, h| *h)
}

/// [`closest_points_near`] for the `count` points `point(0..count)`, which are made as they
/// are queried rather than held (a decoded face can have millions of samples), and whose
/// hits are kept only as `keep(i, point, hit)`. The points are visited in the same chunks
/// with the same bounds, so the answers are those of [`closest_points_near`].
pub fn closest_points_near_with<R: Copy + Default + Send>(
    count: usize,
    point: impl Fn(usize) -> DVec3 + Sync,
    surface: &TriangleSurface,
    radius: f64,
    keep: impl Fn(usize, DVec3, &ClosestPoint) -> R + Sync,
) -> Vec<R> {
    let chunk_fn = |start: usize, out: &mut [R]| {
        let mut prev: Option<DVec3> = None;
        for (k, o) in out.iter_mut().enumerate() {
            let p = point(start + k);
            // |p - q| bounds the distance since q is on the surface; pad for rounding.
            let bound = prev.map_or(radius, |q| radius.min((p - q).length() * (1.0 + 1e-9)));
            let hit = surface
                .closest_point_within(p, bound.max(1e-300))
                .unwrap_or_else(|| surface.closest_point(p));
            prev = Some(hit.point).filter(|q| q.is_finite());
            *o = keep(start + k, p, &hit);
        }
    };
    let mut out = vec![R::default(); count];
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        out.par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, o)| chunk_fn(c * CHUNK, o));
    }
    #[cfg(not(feature = "parallel"))]
    {
        for (c, o) in out.chunks_mut(CHUNK).enumerate() {
            chunk_fn(c * CHUNK, o);
        }
    }
    out
}

/// Distances from each of `points` to `surface`, in the order of `points`.
#[cfg(feature = "internals")]
pub fn point_distances(points: &[DVec3], surface: &TriangleSurface) -> Vec<f64> {
    closest_points(points, surface)
        .iter()
        .map(|h| h.distance)
        .collect()
}

/// Statistics of the distances from `points` to `surface` (sequential, ordered reduction).
#[cfg(feature = "internals")]
pub fn one_sided_distances(points: &[DVec3], surface: &TriangleSurface) -> OneSided {
    one_sided_of(points, &point_distances(points, surface), points.len())
}

/// Statistics of the distances `d` of `points` (sequential, ordered reduction): the max over
/// all, the mean and RMS over the first `area` (the vertices and area-weighted points; edge
/// points, placed by length, would weigh the edges of long triangles above their area).
#[cfg(feature = "internals")]
pub(super) fn one_sided_of(points: &[DVec3], d: &[f64], area: usize) -> OneSided {
    let mut out = OneSided {
        count: d.len(),
        ..Default::default()
    };
    let (mut sum, mut sum2) = (0.0, 0.0);
    for (i, &x) in d.iter().enumerate() {
        if i < area {
            sum += x;
            sum2 += x * x;
        }
        if x > out.max || i == 0 {
            out.max = x;
            out.argmax = points[i];
        }
    }
    let area = area.min(d.len());
    if area > 0 {
        out.mean = sum / area as f64;
        out.rms = (sum2 / area as f64).sqrt();
    }
    out
}

/// Sampled symmetric distance between the surfaces of `a` and `b` (polygons are fan
/// triangulated). Errors if either mesh is invalid or has no faces.
#[cfg(feature = "internals")]
pub fn hausdorff(
    a: &ControlMesh,
    b: &ControlMesh,
    opts: &DistanceOptions,
) -> Result<DistanceReport> {
    let sa = blocked_surface(a)?;
    let sb = blocked_surface(b)?;
    let diagonal = match (a.bounding_box(), b.bounding_box()) {
        (Some((l1, h1)), Some((l2, h2))) => (h1.max(h2) - l1.min(l2)).length(),
        _ => 0.0,
    };
    let spacing = edge_spacing(opts, diagonal);
    let density = sample_density(opts, surface_area(sb.positions(), sb.triangles()));
    let (pa, na) = measured_samples(&sa, opts, density, spacing);
    let (pb, nb) = reference_samples(sb.positions(), sb.triangles(), opts, spacing);
    let pb: Vec<DVec3> = pb.iter().map(|s| s.point).collect();
    let (da, db) = (point_distances(&pa, &sb), point_distances(&pb, &sa));
    let (ab, ba) = (one_sided_of(&pa, &da, na), one_sided_of(&pb, &db, nb));
    Ok(DistanceReport::from_sides(&ab, &ba, diagonal))
}

/// Triangles of one leaf of [`blocked_surface`]'s index.
#[cfg(feature = "internals")]
const LEAF_TRIANGLES: usize = 16;

/// `mesh` fan-triangulated and indexed by runs of consecutive triangles: a decoded
/// surface (subdivision lists each control face's descendants together) gets a tree many
/// times smaller than one leaf per triangle, which matters at millions of triangles; a mesh
/// in any other order stays correct (runs end where their box outgrows a typical triangle's).
#[cfg(feature = "internals")]
pub(super) fn blocked_surface(mesh: &ControlMesh) -> Result<TriangleSurface> {
    let (triangles, _) = fan_triangulate(mesh)?;
    TriangleSurface::with_blocks(mesh.positions.clone(), triangles, LEAF_TRIANGLES)
}

/// `opts`' edge spacing in model units for meshes of joint diagonal `diagonal` (0: none).
#[cfg(feature = "internals")]
pub(super) fn edge_spacing(opts: &DistanceOptions, diagonal: f64) -> f64 {
    opts.edge_spacing.map_or(0.0, |t| t.resolve(diagonal))
}

/// The samples of the reference B of a measurement (the input mesh, for a decoded file):
/// its vertices (with `opts.include_vertices`), `opts.samples` area-weighted random points,
/// then the points of its thin triangles' long edges at `spacing` (none for 0); and how many
/// come before the edge points (the mean and RMS are theirs). The encoder measures the same
/// samples of its input as `scode info --against` does.
pub fn reference_samples(
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    opts: &DistanceOptions,
    spacing: f64,
) -> (Vec<SurfaceSample>, usize) {
    let mut samples = sample_surface(
        positions,
        triangles,
        opts.samples,
        opts.include_vertices,
        opts.seed ^ 0xB,
    );
    let area = samples.len();
    let edges = EdgeSamples::new(positions, triangles, spacing);
    samples.extend((0..edges.len()).map(|i| edges.get(i)));
    (samples, area)
}

/// Points per unit area of the random samples of the measured surface A: `opts.samples` over
/// the reference's `reference_area` (fixed for a reference, so a face of A keeps its points
/// while the rest of A changes; see [`TriangleSamples`]).
pub fn sample_density(opts: &DistanceOptions, reference_area: f64) -> f64 {
    match opts.samples {
        SampleCount::Total(n) if reference_area > 0.0 => n as f64 / reference_area,
        SampleCount::Total(_) => 0.0,
        #[cfg(feature = "internals")]
        SampleCount::PerArea(d) => d,
    }
}

/// The sample points of the measured surface A (`s`): its vertices (with
/// `opts.include_vertices`), its random points at `density` ([`TriangleSamples`]), then the
/// points of its thin triangles' long edges at `spacing`; and how many come before the
/// edge points.
#[cfg(feature = "internals")]
fn measured_samples(
    s: &TriangleSurface,
    opts: &DistanceOptions,
    density: f64,
    spacing: f64,
) -> (Vec<DVec3>, usize) {
    let (positions, triangles) = (s.positions(), s.triangles());
    let mut points: Vec<DVec3> = sample_surface(
        positions,
        triangles,
        SampleCount::Total(0),
        opts.include_vertices,
        0,
    )
    .into_iter()
    .map(|s| s.point)
    .collect();
    let random = TriangleSamples::new(positions, triangles, density, opts.seed);
    points.extend((0..random.len()).map(|i| random.get(i).point));
    let area = points.len();
    let edges = EdgeSamples::new(positions, triangles, spacing);
    points.extend((0..edges.len()).map(|i| edges.get(i).point));
    (points, area)
}
