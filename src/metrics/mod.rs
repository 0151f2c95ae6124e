//! Point-to-surface distances between triangle meshes: closest-point queries with a BVH,
//! deterministic surface sampling and Hausdorff / RMS / mean distance reports.
//!
//! One implementation serves the encoder (error control while fitting), the tests and the
//! report (design.md: "Distances live in `metrics`"). Nothing here depends on `fit` or
//! `codec`.

#[cfg(feature = "internals")]
mod by_group;
mod distance;
#[cfg(feature = "internals")]
mod rate;
mod sampling;
mod surface;

#[cfg(feature = "internals")]
pub use by_group::hausdorff_by_group;
#[cfg(feature = "internals")]
pub use distance::{
    closest_points, hausdorff, one_sided_distances, point_distances, DistanceReport, OneSided,
    DEFAULT_EDGE_SPACING,
};
pub use distance::{
    closest_points_near, closest_points_near_with, edge_spacing_for_tolerance, DistanceOptions,
};
pub(crate) use distance::{reference_samples, sample_density};
#[cfg(feature = "internals")]
pub use rate::{measure_against_input, raw_binary_bytes, RateDistortion};
pub(crate) use sampling::surface_area;
#[cfg(test)]
pub(crate) use sampling::SplitMixForTests;
#[cfg(feature = "internals")]
pub use sampling::{sample_surface, RandomSamples};
pub use sampling::{space_filling_order, EdgeSamples, SampleCount, SurfaceSample, TriangleSamples};
pub(crate) use surface::box_distance;
#[cfg(feature = "internals")]
pub use surface::{closest_point_on_triangle, ClosestPoint};
pub use surface::{segment_parameter, TriangleSurface};

#[cfg(test)]
mod tests {
    use super::sampling::SplitMix64;
    use super::*;
    use crate::mesh::{ControlMesh, PatchKind};
    use glam::DVec3;

    /// Random triangle soup-ish mesh: a jittered grid surface folded in 3D plus a few
    /// random triangles (including a degenerate one), so queries hit vertices, edges and
    /// faces.
    fn random_mesh(seed: u64, n: usize) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let mut rng = SplitMix64::new(seed);
        let mut pos = Vec::new();
        for i in 0..=n {
            for j in 0..=n {
                let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
                let z = 0.3 * (3.0 * x).sin() * (2.0 * y).cos() + 0.05 * rng.next_f64();
                pos.push(DVec3::new(x + 0.01 * rng.next_f64(), y, z));
            }
        }
        let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
        let mut tris = Vec::new();
        for i in 0..n {
            for j in 0..n {
                tris.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
                tris.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
            }
        }
        for _ in 0..5 {
            let base = pos.len() as u32;
            for _ in 0..3 {
                pos.push(DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64()) * 1.5);
            }
            tris.push([base, base + 1, base + 2]);
        }
        // A degenerate (collinear) triangle.
        let base = pos.len() as u32;
        pos.extend([DVec3::ZERO, DVec3::new(0.5, 0.5, 0.5), DVec3::ONE]);
        tris.push([base, base + 1, base + 2]);
        (pos, tris)
    }

    fn brute(p: DVec3, pos: &[DVec3], tris: &[[u32; 3]]) -> f64 {
        tris.iter()
            .map(|t| {
                let (q, _) = closest_point_on_triangle(
                    p,
                    pos[t[0] as usize],
                    pos[t[1] as usize],
                    pos[t[2] as usize],
                );
                (p - q).length()
            })
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn closest_point_on_triangle_regions() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        let cases = [
            (DVec3::new(0.2, 0.2, 1.0), DVec3::new(0.2, 0.2, 0.0)),
            (DVec3::new(-1.0, -1.0, 0.3), a),
            (DVec3::new(2.0, -0.1, 0.0), b),
            (DVec3::new(-0.1, 3.0, 0.0), c),
            (DVec3::new(0.5, -2.0, 0.0), DVec3::new(0.5, 0.0, 0.0)),
            (DVec3::new(-2.0, 0.5, 0.0), DVec3::new(0.0, 0.5, 0.0)),
            (DVec3::new(1.0, 1.0, 0.0), DVec3::new(0.5, 0.5, 0.0)),
        ];
        for (p, want) in cases {
            let (q, bc) = closest_point_on_triangle(p, a, b, c);
            assert!((q - want).length() < 1e-15, "{p} -> {q}, want {want}");
            let r = a * bc[0] + b * bc[1] + c * bc[2];
            assert!((r - q).length() < 1e-15);
        }
    }

    #[test]
    fn bvh_matches_brute_force() {
        // Per-triangle leaves, and runs of 5 and 16 triangles per leaf (random triangle
        // order: the blocks' boxes overlap a lot, the answers must not change).
        for (seed, block) in (0..4u64).flat_map(|s| [(s, 0), (s, 5), (s, 16)]) {
            let (pos, tris) = random_mesh(seed, 12);
            let surf = if block == 0 {
                TriangleSurface::new(pos.clone(), tris.clone()).unwrap()
            } else {
                TriangleSurface::with_blocks(pos.clone(), tris.clone(), block).unwrap()
            };
            let mut rng = SplitMix64::new(100 + seed);
            for k in 0..2000 {
                // Mix of near-surface and far points.
                let scale = if k % 2 == 0 { 1.2 } else { 5.0 };
                let p = DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64()) * scale
                    - DVec3::splat(0.1 * scale);
                let hit = surf.closest_point(p);
                let want = brute(p, &pos, &tris);
                assert!(
                    (hit.distance - want).abs() <= 1e-9,
                    "seed {seed} point {p}: bvh {} brute {want}",
                    hit.distance
                );
                // The reported triangle + barycentrics reproduce the closest point.
                let [a, b, c] = surf.triangle_points(hit.triangle);
                let bc = hit.barycentric;
                let r = a * bc[0] + b * bc[1] + c * bc[2];
                assert!((r - hit.point).length() <= 1e-9, "bary mismatch");
                assert!(((p - hit.point).length() - hit.distance).abs() <= 1e-12);
            }
            // Chunked, bounded queries agree with the plain ones.
            let pts: Vec<DVec3> = (0..1000)
                .map(|_| DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64()))
                .collect();
            let d = point_distances(&pts, &surf);
            for (p, d) in pts.iter().zip(d) {
                assert!((d - brute(*p, &pos, &tris)).abs() <= 1e-9);
            }
            // A search radius smaller than many distances changes nothing either.
            for hit in pts.iter().zip(closest_points_near(&pts, &surf, 0.05)) {
                assert!((hit.1.distance - brute(*hit.0, &pos, &tris)).abs() <= 1e-9);
            }
        }
    }

    #[test]
    fn sampling_is_deterministic_and_area_weighted() {
        // Two triangles, areas 1/2 and 3/2.
        let pos = vec![
            DVec3::ZERO,
            DVec3::X,
            DVec3::Y,
            DVec3::new(10.0, 0.0, 0.0),
            DVec3::new(13.0, 0.0, 0.0),
            DVec3::new(10.0, 1.0, 0.0),
        ];
        let tris = vec![[0, 1, 2], [3, 4, 5]];
        let s1 = sample_surface(&pos, &tris, SampleCount::Total(20_000), true, 7);
        let s2 = sample_surface(&pos, &tris, SampleCount::Total(20_000), true, 7);
        assert_eq!(s1, s2);
        assert_eq!(s1.len(), 20_006);
        let on_second = s1[6..].iter().filter(|s| s.triangle == 1).count() as f64;
        let frac = on_second / 20_000.0;
        assert!(
            (frac - 0.75).abs() < 0.02,
            "fraction on big triangle {frac}"
        );
        for s in &s1 {
            let t = tris[s.triangle as usize].map(|v| pos[v as usize]);
            let r = t[0] * s.barycentric[0] + t[1] * s.barycentric[1] + t[2] * s.barycentric[2];
            assert!((r - s.point).length() < 1e-12);
            assert!(s
                .barycentric
                .iter()
                .all(|&b| (-1e-12..=1.0 + 1e-12).contains(&b)));
        }
        // Per-area density.
        let s3 = sample_surface(&pos, &tris, SampleCount::PerArea(100.0), false, 1);
        assert_eq!(s3.len(), 200);
        // Another seed gives other points.
        let s4 = sample_surface(&pos, &tris, SampleCount::Total(10), false, 8);
        assert_ne!(&s4[..], &s1[6..16]);
    }

    /// Random samples made one at a time are the points of one generator stream read in
    /// order: sample i from its outputs 3i to 3i + 2.
    #[test]
    fn random_samples_one_at_a_time_follow_the_stream() {
        let pos = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 0.5)];
        let tris = vec![[0, 1, 2], [1, 3, 2]];
        let samples = RandomSamples::new(&pos, &tris, SampleCount::Total(50), 0xABC);
        let total =
            0.5 + 0.5 * (DVec3::new(-1.0, 1.0, 0.0).cross(DVec3::new(0.0, 1.0, 0.5))).length();
        let mut rng = SplitMix64::new(0xABC);
        for i in 0..samples.len() {
            let (target, r1, r2) = (rng.next_f64() * total, rng.next_f64(), rng.next_f64());
            let s = samples.get(i);
            assert_eq!(s.triangle, u32::from(target >= 0.5), "sample {i}");
            let sq = r1.sqrt();
            assert_eq!(
                s.barycentric,
                [1.0 - sq, sq * (1.0 - r2), sq * r2],
                "sample {i}"
            );
        }
    }

    /// A triangle's random points depend on the triangle alone: listed among other
    /// triangles, in another order, with its corners rotated, it gets the same points; and
    /// the points of many triangles number about the density times their area.
    #[test]
    fn triangle_samples_are_the_triangles_own() {
        let (pos, tris) = random_mesh(5, 10);
        let density = 2000.0;
        let all = TriangleSamples::new(&pos, &tris, density, 9);
        let area = surface_area(&pos, &tris);
        let n = all.len() as f64;
        assert!((n - density * area).abs() < 0.05 * density * area, "{n}");
        let points_of = |samples: &TriangleSamples, t: u32| -> Vec<[u64; 3]> {
            let mut p: Vec<[u64; 3]> = (0..samples.len())
                .map(|i| samples.get(i))
                .filter(|s| s.triangle == t)
                .map(|s| s.point.to_array().map(f64::to_bits))
                .collect();
            p.sort_unstable();
            p
        };
        for t in [0u32, 7, 50, tris.len() as u32 - 1] {
            let tri = tris[t as usize];
            let alone = [[tri[1], tri[2], tri[0]]];
            let rotated = TriangleSamples::new(&pos, &alone, density, 9);
            assert_eq!(points_of(&rotated, 0), points_of(&all, t), "triangle {t}");
        }
    }

    /// A surface far larger than its density was meant for gets a bounded number of points.
    #[test]
    fn triangle_samples_are_bounded() {
        let pos = vec![DVec3::ZERO, DVec3::X * 1e6, DVec3::Y * 1e6];
        let samples = TriangleSamples::new(&pos, &[[0, 1, 2]], 1.0, 1);
        assert!(
            samples.len() <= 1 << 22 && samples.len() > 1 << 21,
            "{}",
            samples.len()
        );
    }

    /// The space-filling order is a permutation that keeps neighbours together: on a grid
    /// given in a scrambled order, consecutive points of the order are a few cells apart
    /// on average, where the scrambled order jumps across the grid.
    #[test]
    fn space_filling_order_keeps_neighbours_together() {
        let n = 20;
        let mut points: Vec<DVec3> = (0..n * n * n)
            .map(|i| DVec3::new((i % n) as f64, ((i / n) % n) as f64, (i / (n * n)) as f64))
            .collect();
        let mut rng = SplitMix64::new(7);
        for i in (1..points.len()).rev() {
            points.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
        }
        let order = space_filling_order(points.iter().copied());
        let mut seen = order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..points.len() as u32).collect::<Vec<u32>>());
        let mean_step = |ids: &mut dyn Iterator<Item = usize>| {
            let p: Vec<DVec3> = ids.map(|i| points[i]).collect();
            p.windows(2).map(|w| (w[1] - w[0]).length()).sum::<f64>() / (p.len() - 1) as f64
        };
        let curve = mean_step(&mut order.iter().map(|&i| i as usize));
        let scrambled = mean_step(&mut (0..points.len()));
        assert!(curve < 2.0 && scrambled > 8.0, "{curve} {scrambled}");
    }

    fn grid_mesh(n: usize, z: f64, quads: bool) -> ControlMesh {
        let mut m = ControlMesh::new();
        let g = m.push_group("face_0", PatchKind::Closed);
        for i in 0..=n {
            for j in 0..=n {
                m.push_vertex(DVec3::new(i as f64 / n as f64, j as f64 / n as f64, z));
            }
        }
        let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
        for i in 0..n {
            for j in 0..n {
                let q = [idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)];
                if quads {
                    m.push_face(&q, g);
                } else {
                    m.push_face(&[q[0], q[1], q[2]], g);
                    m.push_face(&[q[0], q[2], q[3]], g);
                }
            }
        }
        m
    }

    #[test]
    fn hausdorff_known_answers() {
        let opts = DistanceOptions {
            samples: SampleCount::Total(5000),
            ..Default::default()
        };
        // Identical surfaces (one as quads, one as triangles): zero.
        let a = grid_mesh(6, 0.0, true);
        let b = grid_mesh(4, 0.0, false);
        let r = hausdorff(&a, &b, &opts).unwrap();
        assert!(r.max < 1e-12, "{r:?}");
        // Parallel unit squares 0.25 apart: every distance is 0.25.
        let c = grid_mesh(3, 0.25, false);
        let r = hausdorff(&a, &c, &opts).unwrap();
        for v in [
            r.max,
            r.rms,
            r.mean,
            r.max_a_to_b,
            r.rms_b_to_a,
            r.mean_b_to_a,
        ] {
            assert!((v - 0.25).abs() < 1e-12, "{r:?}");
        }
        assert!((r.diagonal - 2.0625f64.sqrt()).abs() < 1e-12);
        assert!((r.relative().max - 0.25 / 2.0625f64.sqrt()).abs() < 1e-12);
        // A bump: one vertex of a lifted by h. A -> B max is h (the vertex); B -> A is
        // smaller (the bump is a thin pyramid); the report is asymmetric accordingly.
        let mut d = grid_mesh(4, 0.0, false);
        d.positions[12].z = 0.1; // centre vertex (2, 2)
        let r = hausdorff(&d, &b, &opts).unwrap();
        assert!((r.max_a_to_b - 0.1).abs() < 1e-12);
        assert!(r.max_b_to_a < 0.1 && r.max_b_to_a > 0.0);
        assert_eq!(r.max, r.max_a_to_b);
        // Determinism.
        assert_eq!(r, hausdorff(&d, &b, &opts).unwrap());
    }

    /// Point-to-triangle distance written independently of `closest_point_on_triangle`:
    /// project onto the plane; if the projection is inside (same-side tests with cross
    /// products) the distance is the plane distance, else the nearest of the three edges.
    fn independent_point_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
        let seg = |a: DVec3, b: DVec3| {
            let ab = b - a;
            let t = if ab.length_squared() > 0.0 {
                ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (p - (a + ab * t)).length()
        };
        let edges = seg(a, b).min(seg(b, c)).min(seg(c, a));
        let n = (b - a).cross(c - a);
        if n.length_squared() == 0.0 {
            return edges;
        }
        let n = n.normalize();
        let q = p - n * (p - a).dot(n);
        let inside = (b - a).cross(q - a).dot(n) >= 0.0
            && (c - b).cross(q - b).dot(n) >= 0.0
            && (a - c).cross(q - c).dot(n) >= 0.0;
        if inside {
            (p - q).length().min(edges)
        } else {
            edges
        }
    }

    /// Max and RMS of the brute-force distances from `points` to every triangle of `mesh`.
    fn brute_one_sided(points: &[DVec3], mesh: &ControlMesh) -> (f64, f64) {
        let mut tris = Vec::new();
        for f in mesh.faces() {
            for i in 1..f.len() - 1 {
                tris.push([f[0], f[i], f[i + 1]].map(|v| mesh.positions[v as usize]));
            }
        }
        let d: Vec<f64> = points
            .iter()
            .map(|&p| {
                tris.iter()
                    .map(|t| independent_point_triangle(p, t[0], t[1], t[2]))
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        let max = d.iter().copied().fold(0.0, f64::max);
        let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
        (max, rms)
    }

    /// The Hausdorff report (BVH closest points) agrees with a brute-force scan of every
    /// triangle with an independently written point-triangle distance, on the same sample
    /// points, for two different non-trivial meshes (a quad grid with a bump against a
    /// jittered, tilted triangle grid of another resolution).
    #[test]
    fn hausdorff_matches_brute_force_point_triangle() {
        // Vertices and random points only, remade below (edge points: `sampling`'s tests).
        let opts = DistanceOptions {
            samples: SampleCount::Total(3000),
            edge_spacing: None,
            ..Default::default()
        };
        let mut a = grid_mesh(9, 0.0, true);
        for p in &mut a.positions {
            p.z = 0.08 * (4.0 * p.x).sin() * (3.0 * p.y).cos();
        }
        let mut b = grid_mesh(7, 0.02, false);
        let mut rng = SplitMix64::new(42);
        for p in &mut b.positions {
            p.z += 0.1 * p.x + 0.03 * rng.next_f64();
            p.x += 0.01 * (rng.next_f64() - 0.5);
        }
        b.positions[20].z += 0.3; // a spike: the max of B -> A
        let r = hausdorff(&a, &b, &opts).unwrap();
        let points = |m: &ControlMesh, seed: u64| -> Vec<DVec3> {
            let s = TriangleSurface::from_control_mesh(m).unwrap();
            sample_surface(s.positions(), s.triangles(), opts.samples, true, seed)
                .into_iter()
                .map(|s| s.point)
                .collect()
        };
        let pb = points(&b, opts.seed ^ 0xB);
        // A's random points: as many per unit of B's area, each triangle's its own.
        let (sa, sb) = (
            TriangleSurface::from_control_mesh(&a).unwrap(),
            TriangleSurface::from_control_mesh(&b).unwrap(),
        );
        let density = sample_density(&opts, surface_area(sb.positions(), sb.triangles()));
        let mut pa: Vec<DVec3> = (0..a.vertex_count()).map(|v| a.positions[v]).collect();
        let random = TriangleSamples::new(sa.positions(), sa.triangles(), density, opts.seed);
        pa.extend((0..random.len()).map(|i| random.get(i).point));
        let expected = density * surface_area(sa.positions(), sa.triangles());
        let got = random.len() as f64;
        assert!(
            (got - expected).abs() < 0.05 * expected,
            "{got} vs {expected}"
        );
        assert_eq!(pa.len(), r.samples_a);
        assert_eq!(pb.len(), r.samples_b);
        let (max_ab, rms_ab) = brute_one_sided(&pa, &b);
        let (max_ba, rms_ba) = brute_one_sided(&pb, &a);
        for (got, want) in [
            (r.max_a_to_b, max_ab),
            (r.rms_a_to_b, rms_ab),
            (r.max_b_to_a, max_ba),
            (r.rms_b_to_a, rms_ba),
            (r.max, max_ab.max(max_ba)),
            (r.rms, rms_ab.max(rms_ba)),
        ] {
            assert!(
                (got - want).abs() <= 1e-12,
                "report {got} vs brute force {want}"
            );
        }
        // The spike is seen (it is a sampled vertex of B) and is well above the jitter.
        assert!(r.max_b_to_a > 0.25, "{r:?}");
        // The report's relative figures are these distances over the joint diagonal.
        let rd = RateDistortion::new(1000, &b, &r);
        assert!((rd.max_error - r.max / r.diagonal).abs() < 1e-15);
        assert!((rd.rms_error - r.rms / r.diagonal).abs() < 1e-15);
        // 64 vertices, 98 triangles as float32 xyz + u32 indices.
        assert_eq!(raw_binary_bytes(&b), 12 * 64 + 12 * 98);
        assert!((rd.bits_per_vertex - 8000.0 / 64.0).abs() < 1e-12);
    }

    #[test]
    fn rejects_bad_input() {
        assert!(TriangleSurface::new(vec![DVec3::ZERO], vec![]).is_err());
        assert!(TriangleSurface::new(vec![DVec3::ZERO; 3], vec![[0, 1, 3]]).is_err());
        assert!(TriangleSurface::new(vec![DVec3::NAN; 3], vec![[0, 1, 2]]).is_err());
        let empty = ControlMesh::new();
        assert!(hausdorff(
            &empty,
            &grid_mesh(1, 0.0, true),
            &DistanceOptions::default()
        )
        .is_err());
    }
}

#[cfg(test)]
mod corpus_tests {
    use super::*;
    use crate::fit::test_support::load_corpus;

    /// Coarse vs fine tessellation of the same CAD model: the distance is small relative to
    /// the size and symmetric-ish; self-distance is zero. Timing printed (run in release).
    #[test]
    fn coarse_vs_fine_tessellation() {
        let (Some(coarse), Some(fine)) = (
            load_corpus("tess/block_fillet3_coarse.obj"),
            load_corpus("tess/block_fillet3_fine.obj"),
        ) else {
            return;
        };
        let opts = DistanceOptions {
            samples: SampleCount::Total(20_000),
            ..Default::default()
        };
        let r = hausdorff(&coarse, &fine, &opts).unwrap();
        let rel = r.relative();
        // Coarse chords of 1/15-diagonal edges on a fillet: sagitta well below 1 %.
        assert!(rel.max > 0.0 && rel.max < 1e-2, "{rel:?}");
        assert!(rel.rms <= rel.max && rel.mean <= rel.rms);
        let same = hausdorff(&fine, &fine, &opts).unwrap();
        assert!(same.max < 1e-9 * same.diagonal);
    }
}
