//! What every reader target checks, shared by the targets of the mesh readers and STEP.
//!
//! A target of a reader must not pass vacuously (a reader that refused every input would
//! fuzz nothing but its first error path): `fuzz/run.sh` first runs each target on its
//! seeds (valid files of the format) with `SCODE_FUZZ_SEEDS=1`, under which a read that
//! fails is a crash, then fuzzes from those seeds.
#![allow(dead_code)]

use std::path::Path;

use scode::io::{read_mesh_bytes_with, write_mesh_to, MeshFormat, ReadOptions};
use scode::{ControlMesh, Error};

/// True when the inputs are seeds that must read (see the module documentation).
pub fn seeds_must_read() -> bool {
    std::env::var_os("SCODE_FUZZ_SEEDS").is_some_and(|v| v == "1")
}

/// A read error must be a typed input error naming the source, never a panic; a seed must
/// read.
pub fn check_error(err: &Error, name: &Path) {
    if seeds_must_read() {
        panic!("a seed failed to read: {err}");
    }
    match err {
        Error::Input { path, detail } => {
            assert_eq!(path, name, "{err}");
            assert!(!detail.is_empty());
        }
        other => panic!("a reader returned a non-input error: {other:?}"),
    }
}

/// What every mesh a reader returns must satisfy: a valid mesh with finite coordinates
/// whose bounding box has a finite diagonal (the readers refuse the others).
pub fn check_mesh(mesh: &ControlMesh) {
    mesh.validate()
        .expect("a mesh a reader returns must be valid");
    assert!(
        mesh.face_count() > 0,
        "a reader returned a mesh without faces"
    );
    let mut lo = glam::DVec3::splat(f64::INFINITY);
    let mut hi = glam::DVec3::splat(f64::NEG_INFINITY);
    for p in &mesh.positions {
        assert!(p.is_finite(), "non-finite position {p}");
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    assert!((hi - lo).length().is_finite(), "box diagonal overflows");
}

/// Reads `data` as `format` the way `scode encode` does (the same entry point, default
/// options, except that no external file may be read: the bytes have no folder), checks
/// the result and, for the formats that store f64 exactly (OBJ, PLY, OFF), that a mesh the
/// reader left unchanged writes and reads back exactly. (A repaired mesh may be repaired
/// again, or even lose every face: coincident vertices are kept apart inside closed
/// surfaces, and the faces the repair drops can open those surfaces, so the repair is not
/// idempotent.)
pub fn read_mesh_target(data: &[u8], format: MeshFormat) {
    let name = Path::new("fuzz-input");
    let opts = ReadOptions {
        external_files: false,
    };
    let (mesh, report) = match read_mesh_bytes_with(data, format, name, &opts) {
        Ok(read) => read,
        Err(e) => return check_error(&e, name),
    };
    check_mesh(&mesh);
    assert_eq!(report.format, format);
    let exact = matches!(format, MeshFormat::Obj | MeshFormat::Ply | MeshFormat::Off);
    if exact && report.unchanged() {
        let mut bytes = Vec::new();
        write_mesh_to(&mut bytes, format, &mesh, None).expect("a mesh read writes");
        let (back, again) = read_mesh_bytes_with(&bytes, format, name, &opts)
            .unwrap_or_else(|e| panic!("a mesh read and written does not read back: {e}"));
        assert!(again.unchanged(), "reading back repaired: {again}");
        assert_eq!(back.positions, mesh.positions);
        assert_eq!(back.face_vertices, mesh.face_vertices);
        assert_eq!(back.face_offsets, mesh.face_offsets);
        if format != MeshFormat::Off {
            // OFF has no groups, sharp edges or corners.
            assert_eq!(back, mesh);
        }
    }
}
