//! End-to-end: corpus models through every writer and back via the public `scode::io` API.

mod common;
use common::corpus_dir;
use std::path::Path;

use scode::io::{read_mesh, read_mesh_bytes, write_mesh, write_mesh_to, MeshFormat};

#[test]
fn corpus_models_survive_every_format() {
    let Some(dir) = corpus_dir() else { return };
    for file in [
        "tess/screw_coarse.obj",
        "abc/abc_00007974_5.obj",
        "meshes/block.off",
    ] {
        let (mesh, _) = read_mesh(&dir.join(file)).unwrap();

        // Exact formats: OBJ and PLY give back the identical mesh.
        for format in [MeshFormat::Obj, MeshFormat::Ply] {
            let mut bytes = Vec::new();
            write_mesh_to(&mut bytes, format, &mesh, None).unwrap();
            let (back, report) = read_mesh_bytes(&bytes, format, Path::new(file)).unwrap();
            assert_eq!(back, mesh, "{file} via {format}");
            assert!(report.unchanged(), "{file} via {format}: {report}");
        }

        // f32 formats: same triangles; glb keeps the groups, STL has one.
        let rounded: Vec<_> = mesh
            .positions
            .iter()
            .map(|p| p.as_vec3().as_dvec3())
            .collect();
        for format in [MeshFormat::Glb, MeshFormat::Stl] {
            let mut bytes = Vec::new();
            write_mesh_to(&mut bytes, format, &mesh, None).unwrap();
            let (back, _) = read_mesh_bytes(&bytes, format, Path::new(file)).unwrap();
            assert_eq!(back.face_count(), mesh.face_count(), "{file} via {format}");
            // Same triangles as position triples (STL renumbers vertices by first use).
            let triangles = |m: &scode::ControlMesh, pos: &[glam::DVec3]| {
                let mut t: Vec<[[u64; 3]; 3]> = m
                    .faces()
                    .map(|f| [0, 1, 2].map(|k| pos[f[k] as usize].to_array().map(f64::to_bits)))
                    .collect();
                t.sort_unstable();
                t
            };
            assert!(
                triangles(&back, &back.positions) == triangles(&mesh, &rounded),
                "{file} via {format}: triangles differ"
            );
            if format == MeshFormat::Glb {
                assert!(
                    back.positions == rounded,
                    "{file} via glb: positions differ"
                );
                assert_eq!(back.face_vertices, mesh.face_vertices, "{file} via glb");
                assert_eq!(back.face_groups, mesh.face_groups, "{file} via glb");
                let names = |m: &scode::ControlMesh| {
                    m.groups.iter().map(|g| g.name.clone()).collect::<Vec<_>>()
                };
                assert_eq!(names(&back), names(&mesh));
            } else {
                assert_eq!(back.groups.len(), 1);
            }
        }
    }
}

#[test]
fn write_mesh_picks_the_format_from_the_extension() {
    let Some(dir) = corpus_dir() else { return };
    let (mesh, _) = read_mesh(&dir.join("tess/four_cone_coarse.obj")).unwrap();
    let out = std::env::temp_dir().join(format!("scode-io-e2e-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    for ext in ["obj", "PLY", "stl", "glb", "gltf", "off"] {
        let path = out.join(format!("four_cone.{ext}"));
        write_mesh(&path, &mesh, None).unwrap();
        let (back, _) = read_mesh(&path).unwrap();
        assert_eq!(back.face_count(), mesh.face_count(), "{ext}");
    }
    assert!(write_mesh(&out.join("x.step"), &mesh, None).is_err());
    std::fs::remove_dir_all(&out).unwrap();
}
