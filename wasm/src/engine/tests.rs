use std::collections::BTreeMap;

use glam::{DVec3, Vec3};
use scode::codec::{encode, Content, EncodeOptions};
use scode::mesh::{ControlMesh, PatchKind};

use super::*;

/// An octahedron in two CAD faces (upper and lower half) with a sharp equator, encoded as a
/// control mesh.
fn octahedron() -> ControlMesh {
    let mut m = ControlMesh::new();
    for p in [
        DVec3::X,
        DVec3::Y,
        -DVec3::X,
        -DVec3::Y,
        DVec3::Z,
        -DVec3::Z,
    ] {
        m.push_vertex(p);
    }
    let top = m.push_group("top", PatchKind::Closed);
    let bottom = m.push_group("bottom", PatchKind::Closed);
    for i in 0..4u32 {
        let j = (i + 1) % 4;
        m.push_face(&[i, j, 4], top);
        m.push_face(&[j, i, 5], bottom);
    }
    m.sharpen_group_boundaries();
    m
}

fn encoded(mesh: &ControlMesh, content: Content) -> Vec<u8> {
    let opts = EncodeOptions {
        quantization_bits: 16,
        content,
        ..Default::default()
    };
    encode(mesh, &opts).expect("encode")
}

fn model(level: u32) -> Model {
    let bytes = encoded(&octahedron(), Content::ControlMesh { default_level: 3 });
    let mut m = Model::decode(&bytes).expect("decode");
    m.refine(level).expect("refine");
    m
}

/// Undirected edges of the mesh after welding vertices by exact position, with the number of
/// triangles using each.
fn welded_edge_uses(a: &MeshArrays) -> BTreeMap<(u32, u32), u32> {
    let mut ids: BTreeMap<[u32; 3], u32> = BTreeMap::new();
    let weld: Vec<u32> = a
        .positions
        .chunks_exact(3)
        .map(|p| {
            let key = [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()];
            let next = ids.len() as u32;
            *ids.entry(key).or_insert(next)
        })
        .collect();
    let mut uses = BTreeMap::new();
    for t in a.indices.chunks_exact(3) {
        for i in 0..3 {
            let (u, v) = (weld[t[i] as usize], weld[t[(i + 1) % 3] as usize]);
            *uses.entry((u.min(v), u.max(v))).or_insert(0) += 1;
        }
    }
    uses
}

#[test]
fn uniform_levels_have_the_expected_counts_and_unit_normals() {
    let m = model(3);
    assert_eq!(m.base_triangle_count(), 8);
    for level in 0..=3 {
        let a = m.extract_uniform(level).unwrap();
        assert_eq!(a.triangle_count(), 8 << (2 * level));
        assert_eq!(a.normals.len(), a.positions.len());
        assert_eq!(a.groups.len(), a.vertex_count());
        for n in a.normals.chunks_exact(3) {
            let len = Vec3::from_slice(n).length();
            assert!((len - 1.0).abs() < 1e-4, "normal length {len}");
        }
        // The equator has 4 * 2^level edges, each drawn once.
        assert_eq!(a.lines.len(), 6 * (4 << level));
        // Closed surface: every welded edge used by exactly two triangles.
        assert!(welded_edge_uses(&a).values().all(|&u| u == 2));
    }
    assert!(m.extract_uniform(4).is_err());
}

#[test]
fn vertices_on_the_sharp_equator_are_split_with_one_normal_per_side() {
    let m = model(2);
    let a = m.extract_uniform(2).unwrap();
    let mut by_position: BTreeMap<[u32; 3], Vec<usize>> = BTreeMap::new();
    for (i, p) in a.positions.chunks_exact(3).enumerate() {
        by_position
            .entry([p[0].to_bits(), p[1].to_bits(), p[2].to_bits()])
            .or_default()
            .push(i);
    }
    let split: Vec<&Vec<usize>> = by_position.values().filter(|v| v.len() > 1).collect();
    // Level 2 equator: 16 vertices, each in both groups.
    assert_eq!(split.len(), 16);
    for s in split {
        assert_eq!(s.len(), 2);
        let (a0, a1) = (s[0], s[1]);
        assert_ne!(a.groups[a0], a.groups[a1]);
        let n0 = Vec3::from_slice(&a.normals[3 * a0..3 * a0 + 3]);
        let n1 = Vec3::from_slice(&a.normals[3 * a1..3 * a1 + 3]);
        // top side points up, bottom side down: a crease, not an averaged normal
        let (up, down) = if a.groups[a0] == 0 {
            (n0, n1)
        } else {
            (n1, n0)
        };
        assert!(up.z > 0.2 && down.z < -0.2, "{up} {down}");
    }
}

#[test]
fn mixed_levels_are_crack_free_and_lines_follow_the_coarser_side() {
    let mut m = model(3);
    for levels in [
        [0u8, 3, 1, 2, 3, 0, 2, 1],
        [3, 3, 3, 3, 0, 0, 0, 0],
        [1, 0, 0, 0, 0, 0, 0, 3],
    ] {
        let a = m.extract_levels(&levels).unwrap();
        let uses = welded_edge_uses(&a);
        assert!(
            uses.values().all(|&u| u == 2),
            "levels {levels:?}: an edge is not shared by two triangles (crack)"
        );
        for n in a.normals.chunks_exact(3) {
            assert!((Vec3::from_slice(n).length() - 1.0).abs() < 1e-4);
        }
        // Line segments run between vertices of the extracted mesh (on the coarser side's
        // chords, which the finer side's gap-filled vertices were moved onto).
        let vertices: std::collections::BTreeSet<[u32; 3]> = a
            .positions
            .chunks_exact(3)
            .map(|p| [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()])
            .collect();
        for p in a.lines.chunks_exact(3) {
            assert!(vertices.contains(&[p[0].to_bits(), p[1].to_bits(), p[2].to_bits()]));
        }
        // Every line has the coarser side's level: the equator edge between base faces
        // 2i (top) and 2i+1 (bottom) has 2^min(levels) segments.
        let expected: usize = (0..4)
            .map(|i| 1usize << levels[2 * i].min(levels[2 * i + 1]))
            .sum();
        assert_eq!(a.lines.len(), 6 * expected, "levels {levels:?}");
    }
    assert!(m.extract_levels(&[0; 7]).is_err());
    assert!(m.extract_levels(&[4; 8]).is_err());
}

#[test]
fn line_chains_match_the_finest_level_edges() {
    let m = model(3);
    let rf = m.refined.as_ref().unwrap();
    let lines = rf.lines(|_| 3);
    let ln = rf.r.level(3);
    let span = 8;
    let mut expected = Vec::new();
    for le in &rf.line_edges {
        for j in 0..span {
            let [a, b] = ln.edges()[le.edge as usize * span + j];
            for v in [a, b] {
                let p = rf.finest[v as usize].as_vec3();
                expected.extend_from_slice(&[p.x, p.y, p.z]);
            }
        }
    }
    assert_eq!(lines, expected);
}

#[test]
fn zooming_in_raises_levels_and_culled_faces_get_level_zero() {
    let m = model(4);
    let proj = glam::camera::rh::proj::opengl::perspective(0.8, 1.0, 0.01, 100.0);
    let at = |dist: f32| {
        let view =
            glam::camera::rh::view::look_at_mat4(Vec3::new(0.3, 0.2, dist), Vec3::ZERO, Vec3::Y);
        m.view_levels(&(proj * view).to_cols_array(), 800.0, 800.0, 8.0)
            .unwrap()
    };
    let far = at(400.0);
    let mid = at(60.0);
    let near = at(3.0);
    let sum = |l: &[u8]| l.iter().map(|&x| x as u32).sum::<u32>();
    assert!(
        sum(&far) < sum(&mid) && sum(&mid) < sum(&near),
        "{far:?} {mid:?} {near:?}"
    );
    assert!(near.iter().all(|&l| l <= 4));
    // Looking away from the model: everything culled.
    let view = glam::camera::rh::view::look_at_mat4(
        Vec3::new(0.0, 0.0, 5.0),
        Vec3::new(0.0, 0.0, 10.0),
        Vec3::Y,
    );
    let away = m
        .view_levels(&(proj * view).to_cols_array(), 800.0, 800.0, 8.0)
        .unwrap();
    assert!(away.iter().all(|&l| l == 0));
    // The camera inside the model: triangles crossing the camera plane get the finest level.
    let view = glam::camera::rh::view::look_at_mat4(Vec3::ZERO, Vec3::X, Vec3::Z);
    let inside = m
        .view_levels(&(proj * view).to_cols_array(), 800.0, 800.0, 8.0)
        .unwrap();
    assert!(inside.contains(&4));
}

#[test]
fn budget_levels_and_raw_files() {
    let m = model(1);
    assert_eq!(m.level_for_budget(8.0), 0);
    assert_eq!(m.level_for_budget(32.0), 1);
    assert_eq!(m.level_for_budget(1e6), 8);
    let raw = encoded(&octahedron(), Content::RawMesh);
    let mut r = Model::decode(&raw).unwrap();
    assert_eq!(r.level_for_budget(1e9), 0);
    assert!(r.refine(1).is_err());
    r.refine(0).unwrap();
    assert_eq!(r.extract_uniform(0).unwrap().triangle_count(), 8);
}

#[test]
fn garbage_and_truncated_files_are_errors() {
    let bytes = encoded(&octahedron(), Content::ControlMesh { default_level: 3 });
    assert!(Model::decode(b"not a scode file").is_err());
    for cut in [0, 4, bytes.len() / 2, bytes.len() - 1] {
        assert!(Model::decode(&bytes[..cut]).is_err());
    }
    let m = Model::decode(&bytes).unwrap();
    assert!(m.extract_uniform(0).is_err(), "extraction before refine");
}

/// Every spec vector (`../spec/vectors`), shown with pseudo-random per-triangle level maps:
/// closed meshes stay closed after welding by position (no cracks, no T-junctions), at every
/// mix of levels, including boundary patches (`cad_part` has planes and a cylinder).
#[test]
fn spec_vectors_stay_watertight_under_random_level_maps() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../spec/vectors");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .expect("spec/vectors")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "scode"))
        .collect();
    names.sort();
    assert!(
        names.len() >= 5,
        "spec vectors missing in {}",
        dir.display()
    );
    let mut closed_seen = 0;
    let mut lcg = 0x2545_f491_4f6c_dd1du64;
    for path in names {
        let mut m = Model::decode(&std::fs::read(&path).unwrap()).unwrap();
        // Refine raw-mode vectors too: their meshes are valid control meshes.
        m.header.content = Content::ControlMesh { default_level: 3 };
        m.refine(3).unwrap();
        let closed = welded_edge_uses(&m.extract_uniform(0).unwrap())
            .values()
            .all(|&u| u == 2);
        closed_seen += closed as usize;
        let base = m.base_triangle_count();
        for _ in 0..6 {
            let levels: Vec<u8> = (0..base)
                .map(|_| {
                    lcg = lcg
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1_442_695_040_888_963_407);
                    ((lcg >> 33) % 4) as u8
                })
                .collect();
            let a = m.extract_levels(&levels).unwrap();
            let uses = welded_edge_uses(&a);
            assert!(
                uses.values().all(|&u| u <= 2),
                "{}: an edge has more than two triangles",
                path.display()
            );
            if closed {
                assert!(
                    uses.values().all(|&u| u == 2),
                    "{} with levels {levels:?}: crack",
                    path.display()
                );
            }
            for n in a.normals.chunks_exact(3) {
                assert!((Vec3::from_slice(n).length() - 1.0).abs() < 1e-3);
            }
        }
    }
    assert!(closed_seen >= 3);
}
