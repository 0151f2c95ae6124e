//! Subdivision to an accuracy (`accuracy`), the extraction below a refinement's finest level
//! it rests on, and the flips of plane patches (`flips`).

use super::*;
use crate::mesh::Tolerance;

/// A closed cylinder with plane caps (sparse belts and caps) and a closed model with creases
/// and corners (dense), for the properties every output must have.
fn models() -> Vec<(&'static str, ControlMesh)> {
    let mut out = vec![("tetrahedron", tetrahedron())];
    for cone in [false, true] {
        out.push((
            if cone { "cone belt" } else { "cylinder belt" },
            belt_mesh(8, cone, true).0,
        ));
    }
    out.push(("mixed (open, creases, corners)", mixed_mesh()));
    out.push(("plane 9-gon", plane_ngon(9)));
    out
}

/// Whether undirected edge (a, b) is a boundary edge of the control mesh's limit surface,
/// i.e. lies on a boundary edge of `out`'s own uniform counterpart: for these tests, whether
/// the mesh is open at all.
fn open(m: &ControlMesh) -> bool {
    let mut count = BTreeMap::new();
    for f in m.faces() {
        for k in 0..f.len() {
            *count
                .entry(crate::mesh::edge_key(f[k], f[(k + 1) % f.len()]))
                .or_insert(0) += 1;
        }
    }
    count.values().any(|&c| c == 1)
}

#[test]
fn extraction_below_the_finest_level_matches_a_shallower_refinement() {
    // `extract_at` numbers the vertices along base edges by index arithmetic instead of the
    // finest level's edges: the same output as a refinement built only to the level shown.
    for (name, m) in models() {
        let mut rng = Lcg(3);
        for top in 1..=3u32 {
            let shallow = Refinement::new(&m, top).unwrap();
            let deep = Refinement::new(&m, top + 1).unwrap();
            let p = shallow.positions(&m.positions).unwrap();
            assert_eq!(p, deep.positions_at(&m.positions, top).unwrap(), "{name}");
            for _ in 0..4 {
                let levels: Vec<u8> = (0..shallow.base_face_count())
                    .map(|_| (rng.next() * (top + 1) as f64) as u8)
                    .collect();
                let want = lod::extract(&shallow, &p, None, &levels, Default::default()).unwrap();
                let (got, remap) =
                    lod::extract_at(&deep, top, &p[..], None, &levels, Default::default()).unwrap();
                assert_eq!(got, want, "{name} at top level {top}");
                // The map covers the level's vertices, numbered in id order.
                for (i, &v) in remap.used().iter().enumerate() {
                    assert!((v as usize) < p.len());
                    assert_eq!(remap.get(v as usize), Some(i as u32));
                }
                assert_eq!(remap.get(p.len()), None);
            }
        }
    }
}

#[test]
fn accurate_output_is_watertight_keeps_groups_and_tightens_with_the_tolerance() {
    for (name, m) in models() {
        let mut prev = 0;
        for rel in [0.05, 0.01, 2e-3, 4e-4] {
            let opts = AccuracyOptions {
                tolerance: Tolerance::Relative(rel),
                max_level: 4,
                ..Default::default()
            };
            let out = subdivide_to_tolerance(&m, &opts).unwrap();
            let mesh = &out.mesh;
            mesh.validate().unwrap();
            if !open(&m) {
                check_closed_or_boundary(&mesh.face_vertices, |_, _| false);
            }
            // Every group keeps triangles, in the same group list.
            assert_eq!(mesh.groups, m.groups, "{name}");
            for g in 0..m.groups.len() as u32 {
                assert!(mesh.face_groups.contains(&g), "{name}: group {g} lost");
            }
            assert_eq!(
                out.levels.len(),
                Refinement::new(&m, 0).unwrap().base_face_count()
            );
            assert!(out.levels.iter().all(|&l| l <= 4));
            assert_eq!(
                out.normals.as_ref().map(Vec::len),
                Some(mesh.vertex_count())
            );
            // A tighter tolerance never takes fewer triangles; the bound meets it unless a
            // triangle would need a level beyond the fourth.
            assert!(mesh.face_count() >= prev, "{name} at {rel}");
            prev = mesh.face_count();
            if out.levels.iter().all(|&l| l < 4) {
                assert!(
                    out.bound <= out.tolerance,
                    "{name} at {rel}: {} > {}, levels {:?}",
                    out.bound,
                    out.tolerance,
                    out.levels
                );
            }
            // Sharp edges are edges of the output; corners are output vertices.
            let edges: std::collections::BTreeSet<(u32, u32)> = mesh
                .faces()
                .flat_map(|f| (0..3).map(move |k| crate::mesh::edge_key(f[k], f[(k + 1) % 3])))
                .collect();
            assert!(mesh.sharp_edges.iter().all(|e| edges.contains(e)), "{name}");
            assert_eq!(mesh.corners.len(), m.corners.len(), "{name}");
        }
    }
}

#[test]
fn accurate_output_does_not_depend_on_the_thread_count() {
    let (m, _, _) = belt_mesh(8, true, true);
    let opts = AccuracyOptions {
        tolerance: Tolerance::Relative(2e-3),
        ..Default::default()
    };
    let one = subdivide_to_tolerance(&m, &opts).unwrap();
    #[cfg(feature = "parallel")]
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        assert_eq!(
            pool.install(|| subdivide_to_tolerance(&m, &opts).unwrap()),
            one
        );
    }
    assert_eq!(subdivide_to_tolerance(&m, &opts).unwrap(), one);
}

#[test]
fn accurate_output_is_near_the_limit_surface() {
    // Every output vertex is a limit point or on a chord of limit points, and the vertices
    // of a fine uniform level are within the tolerance of the output (a brute-force check on
    // a small model).
    let m = mixed_mesh();
    let tol = 0.01;
    let opts = AccuracyOptions {
        tolerance: Tolerance::Absolute(tol),
        max_level: 5,
        ..Default::default()
    };
    let out = subdivide_to_tolerance(&m, &opts).unwrap();
    assert!(out.bound <= tol, "bound {}", out.bound);
    let (fine, _) = subdivide(
        &m,
        6,
        &SubdivOptions {
            limit: true,
            normals: false,
            ..Default::default()
        },
    )
    .unwrap();
    let tris: Vec<[DVec3; 3]> = out
        .mesh
        .faces()
        .map(|f| [0, 1, 2].map(|k| out.mesh.positions[f[k] as usize]))
        .collect();
    let worst = fine
        .positions
        .iter()
        .map(|&p| {
            tris.iter()
                .map(|t| crate::subdiv::accuracy::point_triangle_distance_squared(p, t))
                .fold(f64::INFINITY, f64::min)
                .sqrt()
        })
        .fold(0.0, f64::max);
    assert!(worst <= tol, "level-6 limit point {worst} from the output");
    assert!(out.mesh.face_count() < fine.face_count() / 4);
}

#[test]
fn accuracy_limits_and_parameters() {
    let m = tetrahedron();
    let opts = |max_level, max_faces, tolerance| AccuracyOptions {
        tolerance,
        max_level,
        max_faces,
        ..Default::default()
    };
    // The triangles of the finest level shown count, not those of the level measured.
    assert!(subdivide_to_tolerance(&m, &opts(3, 4 * 64, Tolerance::DEFAULT)).is_ok());
    assert!(matches!(
        subdivide_to_tolerance(&m, &opts(3, 4 * 64 - 1, Tolerance::DEFAULT)),
        Err(Error::LimitsExceeded { .. })
    ));
    assert!(matches!(
        subdivide_to_tolerance(&m, &opts(MAX_LEVEL, u64::MAX, Tolerance::DEFAULT)),
        Err(Error::Parameter(_))
    ));
    assert!(matches!(
        subdivide_to_tolerance(&m, &opts(u32::MAX, 1 << 40, Tolerance::DEFAULT)),
        Err(Error::LimitsExceeded { .. })
    ));
    assert!(matches!(
        subdivide_to_tolerance(&m, &opts(u32::MAX, u64::MAX, Tolerance::DEFAULT)),
        Err(Error::Parameter(_))
    ));
    for bad in [f64::NAN, -1.0, f64::INFINITY] {
        assert!(matches!(
            subdivide_to_tolerance(&m, &opts(2, u64::MAX, Tolerance::Absolute(bad))),
            Err(Error::Parameter(_))
        ));
    }
    // A zero tolerance shows everything curved at the finest level.
    let out = subdivide_to_tolerance(&m, &opts(2, u64::MAX, Tolerance::Absolute(0.0))).unwrap();
    assert!(out.levels.iter().all(|&l| l == 2));
    // No faces: an empty surface.
    let mut empty = ControlMesh::new();
    empty.push_vertex(DVec3::ZERO);
    let out = subdivide_to_tolerance(&empty, &opts(2, u64::MAX, Tolerance::DEFAULT)).unwrap();
    assert_eq!(out.mesh.face_count(), 0);
}

#[test]
fn flips_make_a_plane_fan_well_shaped_and_keep_its_outline() {
    // The control polygon of a plane 9-gon, fanned from its first corner as level 0 is.
    let m = plane_ngon(9);
    let fan: Vec<[u32; 3]> = (1..8).map(|i| [0, i, i + 1]).collect();
    let min_angle = |tris: &[[u32; 3]]| {
        tris.iter()
            .map(|t| {
                let p = t.map(|v| m.positions[v as usize]);
                (0..3)
                    .map(|k| (p[(k + 1) % 3] - p[k]).angle_between(p[(k + 2) % 3] - p[k]))
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(f64::INFINITY, f64::min)
    };
    let normal = |t: &[u32; 3]| {
        let p = t.map(|v| m.positions[v as usize]);
        (p[1] - p[0]).cross(p[2] - p[0])
    };
    let outline = |tris: &[[u32; 3]]| {
        let mut count = BTreeMap::new();
        for t in tris {
            for k in 0..3 {
                *count
                    .entry(crate::mesh::edge_key(t[k], t[(k + 1) % 3]))
                    .or_insert(0) += 1;
            }
        }
        count
            .into_iter()
            .filter(|&(_, c)| c == 1)
            .map(|(e, _)| e)
            .collect::<Vec<_>>()
    };
    let mut tris = fan.clone();
    let groups = vec![0; tris.len()];
    let flipped = flips::flip_to_well_shaped(
        &m.positions,
        &mut tris,
        &groups,
        &[true],
        &Default::default(),
        1e-9,
    );
    assert!(flipped > 0);
    assert!(
        min_angle(&tris) > 1.3 * min_angle(&fan),
        "{} vs {}",
        min_angle(&tris),
        min_angle(&fan)
    );
    assert_eq!(outline(&tris), outline(&fan));
    // Lawson's flips end at the Delaunay triangulation: the two angles opposite every inner
    // edge sum to at most pi.
    let opposite = |t: &[u32; 3], a: u32, b: u32| {
        let c = *t.iter().find(|&&v| v != a && v != b).unwrap();
        let p = |v: u32| m.positions[v as usize];
        (p(a) - p(c)).angle_between(p(b) - p(c))
    };
    for (i, t) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if let Some(u) = tris[i + 1..]
                .iter()
                .find(|u| u.contains(&a) && u.contains(&b))
            {
                let sum = opposite(t, a, b) + opposite(u, a, b);
                assert!(sum <= std::f64::consts::PI + 1e-9, "edge {a}-{b}: {sum}");
            }
        }
    }
    let up = normal(&fan[0]);
    assert!(tris.iter().all(|t| normal(t).dot(up) > 0.0));
    // A group that may not flip, or a fixed edge, stays as it is.
    let mut kept = fan.clone();
    flips::flip_to_well_shaped(
        &m.positions,
        &mut kept,
        &groups,
        &[false],
        &Default::default(),
        1e-9,
    );
    assert_eq!(kept, fan);
    let fixed = (2..8).map(|i| crate::mesh::edge_key(0, i)).collect();
    let mut kept = fan.clone();
    flips::flip_to_well_shaped(&m.positions, &mut kept, &groups, &[true], &fixed, 1e-9);
    assert_eq!(kept, fan);
}

#[test]
fn limits_evaluated_on_demand_match_a_full_evaluation() {
    // `LazyLimits` evaluates each vertex at the level it is born at, and only the positions
    // it depends on: the same limit points as the finest level evaluated everywhere, and the
    // same normals for the vertices of that level (read through the level before).
    for (name, m) in models() {
        let r = Refinement::new(&m, 3).unwrap();
        let p3 = r.positions(&m.positions).unwrap();
        let lim = r.limit_positions(&p3, 3).unwrap();
        let nn = r.limit_normals(&p3, 3).unwrap();
        let mut unlimited = |_: &'static str, _: u64| Ok(());
        let mut lazy = crate::subdiv::lazy::LazyLimits::new(&r, &m.positions, &mut unlimited);
        // A scattered third first: the second call adds the rest without redoing it.
        let some: Vec<u32> = (0..p3.len() as u32).filter(|v| v % 3 == 1).collect();
        lazy.evaluate(&some, false);
        assert!(some
            .iter()
            .all(|&v| lazy.has(v, false) && !lazy.has(v, true)));
        let all: Vec<u32> = (0..p3.len() as u32).collect();
        lazy.evaluate(&all, true);
        let born3 = r.level(2).vertex_count();
        for v in 0..p3.len() {
            assert!(close(lazy.limit()[v], lim[v], 1e-12), "{name} v{v}");
            let n = lazy.normals()[v];
            if v >= born3 {
                assert!(close(n, nn[v], 1e-12), "{name} v{v}: {n:?} {:?}", nn[v]);
            } else {
                assert!(n == DVec3::ZERO || n.dot(nn[v]) > 0.5, "{name} v{v}");
            }
        }
    }
}

#[test]
fn gap_filling_does_not_raise_a_flat_region_whose_edge_points_slide_along_their_chords() {
    // A flat grid of uneven triangles with every vertex a corner (as dense CAD
    // tessellations fitted face by face come out) and one vertex lifted. Next to a corner
    // the limit points along an edge are spaced unevenly, so gap filling slides a finer
    // triangle's edge vertices far along the coarser side's chord, within the plane: the
    // surface shown does not move. Only the lifted vertex's neighbourhood needs fine levels;
    // measured by how far its corners move, every flat triangle next to a finer one would be
    // raised in turn, until the whole grid is at the finest level.
    let n = 14;
    let mut rng = Lcg(11);
    let mut m = grid(
        n,
        n,
        |i, j| if (i, j) == (n / 2, n / 2) { 0.6 } else { 0.0 },
    );
    for (idx, p) in m.positions.iter_mut().enumerate() {
        let (i, j) = (idx % (n + 1), idx / (n + 1));
        if i > 0 && i < n && j > 0 && j < n {
            p.x += 0.35 * (rng.next() - 0.5);
            p.y += 0.35 * (rng.next() - 0.5);
        }
    }
    m.corners = (0..m.vertex_count() as u32).collect();
    let opts = AccuracyOptions {
        tolerance: Tolerance::Absolute(1e-3),
        max_level: 3,
        ..Default::default()
    };
    let out = subdivide_to_tolerance(&m, &opts).unwrap();
    out.mesh.validate().unwrap();
    let raised = out.levels.iter().filter(|&&l| l > 0).count();
    // The lifted vertex's surface reaches two rings of triangles (its ring's vertices move
    // too), about 40 of the 392.
    assert!(
        raised <= 80,
        "{raised} of {} base triangles above level 0: {:?}",
        out.levels.len(),
        out.levels
    );
    // Away from the lifted vertex the output is the plane itself.
    let c = m.positions[n / 2 * (n + 2)];
    for p in &out.mesh.positions {
        if (p.truncate() - c.truncate()).length() > 3.0 {
            assert!(p.z.abs() < 1e-12, "{p}");
        }
    }
}
