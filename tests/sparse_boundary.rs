//! Sparse output of boundary patches on a fitted model (spec/subdivision.md §8): the boss
//! plate (planes and one cylinder) decoded at levels 1-4 and as random mixed-level LOD is
//! watertight, and much smaller than the dense grid.

use std::collections::BTreeMap;
use std::path::Path;

use scode::codec::{self, Limits};
use scode::pipeline::{encode_fitted, ModelEncodeOptions};
use scode::subdiv::{subdivide, BoundaryPatchOutput, Refinement, SubdivOptions};

/// Every undirected edge has exactly two faces traversing it in opposite directions.
fn assert_closed(tris: impl Iterator<Item = [u32; 3]>, what: &str) {
    let mut directed: BTreeMap<(u32, u32), u32> = BTreeMap::new();
    for t in tris {
        assert!(
            t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
            "{what}: degenerate {t:?}"
        );
        for k in 0..3 {
            *directed.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    for (&(a, b), &c) in &directed {
        assert_eq!(c, 1, "{what}: directed edge ({a}, {b}) used {c} times");
        assert!(
            directed.contains_key(&(b, a)),
            "{what}: open edge ({a}, {b})"
        );
    }
}

#[test]
fn fitted_boss_plate_sparse_output_is_watertight() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus/boss_plate.obj");
    let (input, _) = scode::io::read_mesh(&path).unwrap();
    let (bytes, _) = encode_fitted(&input, &[], &ModelEncodeOptions::default()).unwrap();
    let mesh = codec::decode(&bytes, &Limits::default()).unwrap().mesh;
    assert!(mesh
        .groups
        .iter()
        .all(|g| matches!(g.patch, scode::mesh::PatchKind::Boundary(_))));
    // Plane triangles of the sparse output at the level before, by `limit`.
    let mut before = [0usize; 2];
    for level in 1..=4u32 {
        for limit in [false, true] {
            let opts = SubdivOptions {
                limit,
                ..Default::default()
            };
            let (sparse, _) = subdivide(&mesh, level, &opts).unwrap();
            sparse.validate().unwrap();
            let tris = |m: &scode::ControlMesh| {
                m.faces()
                    .map(|f| [f[0], f[1], f[2]])
                    .collect::<Vec<_>>()
                    .into_iter()
            };
            assert_closed(tris(&sparse), &format!("sparse level {level}"));
            let (dense, _) = subdivide(
                &mesh,
                level,
                &SubdivOptions {
                    boundary_patches: BoundaryPatchOutput::Dense,
                    ..opts
                },
            )
            .unwrap();
            assert_closed(tris(&dense), &format!("dense level {level}"));
            assert_eq!(dense.face_count(), mesh_triangles(&mesh) << (2 * level));
            // Plane patches grow about 2x per level (along their outlines) where their dense
            // grids grow 4x.
            let in_planes = |m: &scode::ControlMesh| {
                m.face_groups
                    .iter()
                    .filter(|&&g| {
                        matches!(
                            mesh.groups[g as usize].patch,
                            scode::mesh::PatchKind::Boundary(scode::mesh::BoundarySurface::Plane)
                        )
                    })
                    .count()
            };
            assert!(
                sparse.face_count() < dense.face_count(),
                "level {level}: sparse {} dense {}",
                sparse.face_count(),
                dense.face_count()
            );
            let was = &mut before[usize::from(limit)];
            assert!(
                level == 1 || 2 * in_planes(&sparse) <= 5 * *was,
                "level {level}: {} plane triangles after {was}",
                in_planes(&sparse)
            );
            assert!(
                level < 3 || 4 * in_planes(&sparse) < in_planes(&dense),
                "level {level}: plane triangles sparse {} dense {}",
                in_planes(&sparse),
                in_planes(&dense)
            );
            *was = in_planes(&sparse);
        }
    }
    let r = Refinement::new(&mesh, 4).unwrap();
    let p = r.positions(&mesh.positions).unwrap();
    let mut seed = 7u64;
    for round in 0..30 {
        let levels: Vec<u8> = (0..r.base_face_count())
            .map(|_| {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((seed >> 33) % 5) as u8
            })
            .collect();
        for mode in [BoundaryPatchOutput::Sparse, BoundaryPatchOutput::Dense] {
            let lod = r.extract_lod_with(&p, None, &levels, mode).unwrap();
            assert_closed(
                lod.triangles.iter().copied(),
                &format!("LOD round {round} {mode:?}"),
            );
        }
    }
}

fn mesh_triangles(m: &scode::ControlMesh) -> usize {
    m.faces().map(|f| f.len() - 2).sum()
}
