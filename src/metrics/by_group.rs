//! The sampled symmetric distance between a subdivided surface handed out group by group
//! ([`UniformSurface`]) and a mesh: what `scode info --against` and `scode report` measure
//! (and the encoder's measurement samples alike).
//!
//! At a file's default level a CAD model has tens of millions of triangles, and a
//! closest-point index over all of them takes gigabytes. Every group (CAD face) is indexed
//! on its own instead, and only while its samples and the mesh's samples near it are
//! measured: memory holds the level's positions and a few groups' triangles at a time.
//! A mesh sample's distance to the surface is the smallest over the groups that can hold a
//! nearer point: first the groups whose boxes come within `near` of it, then, for the few
//! samples farther than `near` from every group, every group whose box is nearer than the
//! nearest known point of the surface.

use glam::DVec3;

use super::distance::{blocked_surface, closest_points_near_with};
use super::distance::{edge_spacing, one_sided_of};
use super::distance::{reference_samples, sample_density};
use super::distance::{DistanceOptions, DistanceReport, OneSided};
use super::sampling::surface_area;
use super::sampling::{space_filling_order, EdgeSamples, TriangleSamples};
use super::surface::{box_distance, TriangleSurface};
use crate::error::{Error, Result};
use crate::mesh::ControlMesh;
use crate::subdiv::par::map_heavy;
use crate::subdiv::UniformSurface;

/// Triangles of one leaf of a group's closest-point index (subdivision lists each control
/// face's descendants together, so runs of consecutive triangles are compact).
const LEAF_TRIANGLES: usize = 16;

/// Points of a group's surface kept to bound the distance of far samples (see the module
/// comment): a few, so that the bound costs `samples * groups * POINTS` distances at most.
const KNOWN_POINTS: usize = 8;

/// What one pass over a group's triangles keeps: enough to split the samples and to find
/// which groups a point can be near.
struct GroupOutline {
    lo: DVec3,
    hi: DVec3,
    /// Some level-n vertices of the group: points of the surface.
    known: Vec<DVec3>,
    /// The group's vertices (level-n ids, increasing, once each).
    vertices: Vec<u32>,
}

impl GroupOutline {
    fn box_distance(&self, p: DVec3) -> f64 {
        box_distance(self.lo, self.hi, p)
    }
}

/// [`super::hausdorff`] with the surface of `a` as A: the vertices of its
/// triangles (when `opts.include_vertices`), each group's area-weighted random points
/// ([`TriangleSamples`], the same points as the whole surface's) and the points of its long
/// edges (an edge between two groups from both), against `b`'s samples made as `hausdorff`
/// makes them.
/// `near` is a distance most samples are expected within; it only sets how the work is
/// split, never the result.
pub fn hausdorff_by_group(
    a: &UniformSurface,
    b: &ControlMesh,
    opts: &DistanceOptions,
    near: f64,
) -> Result<DistanceReport> {
    let positions = a.positions();
    let outlines = map_heavy(a.group_count(), |g| outline(a, g));
    if outlines.iter().all(|o| o.vertices.is_empty()) {
        return Err(Error::Mesh("the decoded surface has no triangles".into()));
    }
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for o in outlines.iter().filter(|o| !o.vertices.is_empty()) {
        (lo, hi) = (lo.min(o.lo), hi.max(o.hi));
    }
    let diagonal = match b.bounding_box() {
        Some((l, h)) => (hi.max(h) - lo.min(l)).length(),
        None => (hi - lo).length(),
    };
    let spacing = edge_spacing(opts, diagonal);
    let sb = blocked_surface(b)?;
    let density = sample_density(opts, surface_area(sb.positions(), sb.triangles()));
    let (pb, nb) = reference_samples(sb.positions(), sb.triangles(), opts, spacing);
    let pb: Vec<DVec3> = pb.iter().map(|s| s.point).collect();
    let near = if near > 0.0 && near.is_finite() {
        near
    } else {
        f64::MAX
    };

    // A to B: every vertex once, in increasing id, then each group's random samples.
    let mut used = vec![false; positions.len()];
    for o in &outlines {
        for &v in &o.vertices {
            used[v as usize] = true;
        }
    }
    let ids: Vec<u32> = if opts.include_vertices {
        (0..positions.len() as u32)
            .filter(|&v| used[v as usize])
            .collect()
    } else {
        Vec::new()
    };
    drop(used);
    let vertex_d = closest_points_near_with(
        ids.len(),
        |i| positions[ids[i] as usize],
        &sb,
        near,
        |_, _, h| h.distance,
    );
    // Each group's triangles made once: its random and edge points against B, and B's
    // points near its box against it.
    let grid = PointGrid::new(&pb);
    let parts = map_heavy(outlines.len(), |g| {
        let mut tris = Vec::new();
        a.group_triangles(g, &mut tris);
        let samples = GroupPoints {
            triangles: &tris,
            density,
            seed: opts.seed,
            spacing,
        };
        let own = samples.distances(positions, &sb, near);
        let o = &outlines[g];
        let mut nearby = Vec::new();
        grid.visit(o.lo - DVec3::splat(near), o.hi + DVec3::splat(near), |i| {
            if o.box_distance(pb[i as usize]) <= near {
                nearby.push((i, near));
            }
        });
        (own, nearest_in_group(positions, o, tris, &pb, &nearby))
    });
    let mut ab = Summary::default();
    for (i, &d) in vertex_d.iter().enumerate() {
        ab.add(positions[ids[i] as usize], d, true);
    }
    let mut best = vec![f64::INFINITY; pb.len()];
    for ((own, count), hits) in parts {
        for (k, &(p, d)) in own.iter().enumerate() {
            ab.add(p, d, k < count);
        }
        for (i, d) in hits {
            best[i as usize] = best[i as usize].min(d);
        }
    }

    // B to A: the points farther than `near` from every group.
    far_to_groups(a, &outlines, &pb, near, &mut best);
    let ba = one_sided_of(&pb, &best, nb);
    Ok(DistanceReport::from_sides(&ab.one_sided(), &ba, diagonal))
}

/// Running statistics of one side's distances, in sample order (as `one_sided_of`: the
/// max over all samples, the mean and RMS over the vertices and area-weighted points).
#[derive(Default)]
struct Summary {
    sums: [f64; 2],
    count: usize,
    area: usize,
    max: f64,
    argmax: DVec3,
}

impl Summary {
    fn add(&mut self, p: DVec3, d: f64, area: bool) {
        if d > self.max || self.count == 0 {
            self.max = d;
            self.argmax = p;
        }
        self.count += 1;
        if area {
            self.area += 1;
            self.sums[0] += d;
            self.sums[1] += d * d;
        }
    }

    fn one_sided(&self) -> OneSided {
        let n = self.area.max(1) as f64;
        OneSided {
            max: self.max,
            rms: (self.sums[1] / n).sqrt(),
            mean: self.sums[0] / n,
            count: self.count,
            argmax: self.argmax,
        }
    }
}

/// Group `g`'s box, vertices and a few of its points.
fn outline(a: &UniformSurface, g: usize) -> GroupOutline {
    let positions = a.positions();
    let mut tris = Vec::new();
    a.group_triangles(g, &mut tris);
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    let mut vertices: Vec<u32> = Vec::with_capacity(tris.len());
    for t in &tris {
        let [p, q, r] = t.map(|v| positions[v as usize]);
        (lo, hi) = (lo.min(p).min(q).min(r), hi.max(p).max(q).max(r));
        vertices.extend_from_slice(t);
    }
    vertices.sort_unstable();
    vertices.dedup();
    let step = vertices.len().div_ceil(KNOWN_POINTS).max(1);
    let known = vertices
        .iter()
        .step_by(step)
        .map(|&v| positions[v as usize])
        .collect();
    GroupOutline {
        lo,
        hi,
        known,
        vertices,
    }
}

/// One group's own samples besides its vertices: random points by area at `density`
/// ([`TriangleSamples`]), then the points along its thin triangles' long edges at `spacing`.
struct GroupPoints<'t> {
    triangles: &'t [[u32; 3]],
    density: f64,
    seed: u64,
    spacing: f64,
}

impl GroupPoints<'_> {
    /// The points and their distances to `input`, and how many are random points.
    fn distances(
        &self,
        positions: &[DVec3],
        input: &TriangleSurface,
        near: f64,
    ) -> (Vec<(DVec3, f64)>, usize) {
        let random = TriangleSamples::new(positions, self.triangles, self.density, self.seed);
        let edges = EdgeSamples::new(positions, self.triangles, self.spacing);
        let point = |i: usize| match i.checked_sub(random.len()) {
            None => random.get(i).point,
            Some(e) => edges.get(e).point,
        };
        let count = random.len() + edges.len();
        let d = closest_points_near_with(count, point, input, near, |_, p, h| (p, h.distance));
        (d, random.len())
    }
}

/// Lowers `best` (each of `points`' distance to the groups found within `near` of it) to the
/// distance to the whole surface of `a` for the points still farther than `near`: bounded
/// by the known points of the surface, then measured against every group that can hold a
/// nearer point.
fn far_to_groups(
    a: &UniformSurface,
    outlines: &[GroupOutline],
    points: &[DVec3],
    near: f64,
    best: &mut [f64],
) {
    let far: Vec<(u32, f64)> = (0..points.len())
        .filter(|&i| best[i] > near)
        .map(|i| {
            let p = points[i];
            let bound = outlines
                .iter()
                .flat_map(|o| o.known.iter())
                .map(|&k| (p - k).length())
                .fold(best[i], f64::min);
            (i as u32, bound)
        })
        .collect();
    if far.is_empty() {
        return;
    }
    let found = map_heavy(outlines.len(), |g| {
        let o = &outlines[g];
        let candidates: Vec<(u32, f64)> = far
            .iter()
            .filter(|&&(i, bound)| o.box_distance(points[i as usize]) <= bound)
            .copied()
            .collect();
        if candidates.is_empty() {
            return Vec::new();
        }
        let mut tris = Vec::new();
        a.group_triangles(g, &mut tris);
        nearest_in_group(a.positions(), o, tris, points, &candidates)
    });
    for (i, d) in found.into_iter().flatten() {
        best[i as usize] = best[i as usize].min(d);
    }
}

/// For each `(point, bound)` of `candidates`, the distance from the point to the group of
/// outline `o`, whose triangles are `tris` (level-n ids), if it is within the bound (padded
/// for rounding).
fn nearest_in_group(
    all: &[DVec3],
    o: &GroupOutline,
    mut tris: Vec<[u32; 3]>,
    points: &[DVec3],
    candidates: &[(u32, f64)],
) -> Vec<(u32, f64)> {
    if candidates.is_empty() || o.vertices.is_empty() {
        return Vec::new();
    }
    // The group's own vertices, numbered locally.
    let positions: Vec<DVec3> = o.vertices.iter().map(|&v| all[v as usize]).collect();
    for t in &mut tris {
        for v in t {
            *v = o.vertices.binary_search(v).unwrap_or(0) as u32;
        }
    }
    let Ok(surface) = TriangleSurface::with_blocks(positions, tris, LEAF_TRIANGLES) else {
        return Vec::new();
    };
    // Visited along a space-filling curve, consecutive points are near each other: the
    // previous hit is a point of the surface, and the distance to it bounds the search
    // without changing which points are found within their bounds.
    let order = space_filling_order(candidates.iter().map(|c| points[c.0 as usize]));
    let mut prev: Option<DVec3> = None;
    order
        .iter()
        .map(|&k| candidates[k as usize])
        .filter_map(|(i, bound)| {
            let p = points[i as usize];
            let bound = prev.map_or(bound, |q| bound.min((p - q).length()));
            let hit = if bound >= f64::MAX {
                Some(surface.closest_point(p))
            } else {
                surface.closest_point_within(p, bound * (1.0 + 1e-9) + 1e-300)
            };
            if let Some(h) = hit.filter(|h| h.point.is_finite()) {
                prev = Some(h.point);
            }
            hit.map(|h| (i, h.distance))
        })
        .collect()
}

/// Points bucketed in a uniform grid of about one point per cell, for "which points lie in
/// this box" (a group's box widened by `near`).
struct PointGrid {
    lo: DVec3,
    cell: f64,
    dims: [usize; 3],
    /// Points of cell c: `ids[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    ids: Vec<u32>,
}

impl PointGrid {
    fn new(points: &[DVec3]) -> PointGrid {
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for &p in points.iter().filter(|p| p.is_finite()) {
            (lo, hi) = (lo.min(p), hi.max(p));
        }
        if points.iter().all(|p| !p.is_finite()) {
            (lo, hi) = (DVec3::ZERO, DVec3::ZERO);
        }
        let extent = (hi - lo).max_element().max(f64::MIN_POSITIVE);
        let per_axis = (points.len() as f64).cbrt().clamp(1.0, 256.0);
        let cell = extent / per_axis;
        let dims = ((hi - lo) / cell)
            .floor()
            .to_array()
            .map(|d| (d as usize).saturating_add(1).min(257));
        let mut grid = PointGrid {
            lo,
            cell,
            dims,
            start: Vec::new(),
            ids: Vec::new(),
        };
        let cells: Vec<usize> = points.iter().map(|&p| grid.cell_of(p)).collect();
        let mut start = vec![0u32; dims[0] * dims[1] * dims[2] + 1];
        for &c in &cells {
            start[c + 1] += 1;
        }
        for c in 1..start.len() {
            start[c] += start[c - 1];
        }
        let mut fill = start.clone();
        let mut ids = vec![0u32; points.len()];
        for (i, &c) in cells.iter().enumerate() {
            ids[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        grid.start = start;
        grid.ids = ids;
        grid
    }

    fn coords(&self, p: DVec3) -> [usize; 3] {
        let c = ((p - self.lo) / self.cell).floor().to_array();
        [0, 1, 2].map(|k| {
            if c[k] > 0.0 {
                (c[k] as usize).min(self.dims[k] - 1)
            } else {
                0
            }
        })
    }

    fn cell_of(&self, p: DVec3) -> usize {
        let [x, y, z] = self.coords(p);
        (z * self.dims[1] + y) * self.dims[0] + x
    }

    /// Calls `f` with every point in the cells that meet the box `lo..hi` (a superset of the
    /// points in the box), in cell order.
    fn visit(&self, lo: DVec3, hi: DVec3, mut f: impl FnMut(u32)) {
        let (a, b) = (self.coords(lo), self.coords(hi));
        for z in a[2]..=b[2] {
            for y in a[1]..=b[1] {
                let row = (z * self.dims[1] + y) * self.dims[0];
                let (s, e) = (self.start[row + a[0]], self.start[row + b[0] + 1]);
                for &i in &self.ids[s as usize..e as usize] {
                    f(i);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::hausdorff;
    use crate::subdiv::{subdivide, SubdivOptions, DEFAULT_MAX_FACES};

    /// A closed two-group patch (an octahedron, its top and bottom halves), subdivided.
    fn octahedron() -> ControlMesh {
        let mut m = ControlMesh::new();
        for p in [
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ] {
            m.positions.push(DVec3::from_array(p));
        }
        m.groups.push(Default::default());
        m.groups.push(Default::default());
        for k in 0..4u32 {
            m.push_face(&[k, (k + 1) % 4, 4], 0);
            m.push_face(&[(k + 1) % 4, k, 5], 1);
        }
        m
    }

    /// The by-group distance agrees with the whole-mesh one: the same input samples give
    /// the same input-to-surface distances (every group that can hold the nearest point is
    /// searched), and the surface's own samples, split by group (and the points of edges
    /// between groups taken from both), give the same figures to within sampling noise.
    #[test]
    fn agrees_with_the_whole_surface_measurement() {
        let control = octahedron();
        let level = 3;
        let by_group = UniformSurface::new(&control, level, DEFAULT_MAX_FACES).unwrap();
        let limit = SubdivOptions {
            limit: true,
            normals: false,
            ..Default::default()
        };
        let (whole, _) = subdivide(&control, level, &limit).unwrap();
        // The "input": the control mesh scaled a little, so the distances are not zero.
        let mut input = control.clone();
        for p in &mut input.positions {
            *p *= 1.1;
        }
        let opts = DistanceOptions::default();
        for near in [1e-3, 0.05, 10.0] {
            let r = hausdorff_by_group(&by_group, &input, &opts, near).unwrap();
            let w = hausdorff(&whole, &input, &opts).unwrap();
            assert_eq!(r.max_b_to_a, w.max_b_to_a, "near {near}");
            assert_eq!(r.rms_b_to_a, w.rms_b_to_a, "near {near}");
            assert_eq!(r.mean_b_to_a, w.mean_b_to_a, "near {near}");
            assert_eq!(r.worst_b_to_a, w.worst_b_to_a, "near {near}");
            // Each group's outline edges are its own boundary: sampled from both sides.
            assert!(r.samples_a >= w.samples_a && r.samples_a < w.samples_a + w.samples_a / 50);
            assert!((r.max_a_to_b - w.max_a_to_b).abs() <= 1e-3 * w.max_a_to_b);
            assert!((r.rms_a_to_b - w.rms_a_to_b).abs() <= 1e-2 * w.rms_a_to_b);
        }
    }

    /// Figures do not depend on `near` or on the thread count.
    #[test]
    fn near_only_splits_the_work() {
        let control = octahedron();
        let surface = UniformSurface::new(&control, 2, DEFAULT_MAX_FACES).unwrap();
        let mut input = control.clone();
        input.positions[4].z = 3.0;
        let opts = DistanceOptions::default();
        let first = hausdorff_by_group(&surface, &input, &opts, 1e-6).unwrap();
        for near in [1e-2, 1.0, f64::INFINITY] {
            assert_eq!(
                hausdorff_by_group(&surface, &input, &opts, near).unwrap(),
                first
            );
        }
        #[cfg(feature = "parallel")]
        {
            let one = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap()
                .install(|| hausdorff_by_group(&surface, &input, &opts, 1e-2).unwrap());
            assert_eq!(one, first);
        }
    }
}
