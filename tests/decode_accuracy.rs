//! Decoding to an accuracy (`scode decode`'s default): on face-grouped corpus models the
//! output has at most 1.5 times the input's triangles, lies within the file's tolerance of
//! the uniform level-6 decode, is watertight and keeps the groups; and the decode options
//! mean what they say.

mod common;
mod decode_support;
use common::corpus_dir;
use decode_support::check_decode_to_tolerance;
use std::path::Path;

use scode::codec::{self, EncodeOptions, Limits};
use scode::pipeline::{decode_surface, encode_fitted, Detail, ModelEncodeOptions, SurfaceOptions};
use scode::Tolerance;

#[test]
fn corpus_models_decode_to_their_tolerance() {
    let Some(dir) = corpus_dir() else { return };
    // Planes, cylinders and cones (belts, dense cone groups, plates with holes), tori and
    // spheres (closed patches), fillets; the larger models are in `sweep.rs`.
    for name in [
        "four_cone_fine",
        "screw_fine",
        "bug3883_xr2-ct-214_plate_fine",
        "block_fillet3_fine",
        "bm2_ec_lever-A_fine",
        "abc_00000050_fine",
    ] {
        check_decode_to_tolerance(&dir.join(format!("tess/{name}.obj")));
    }
}

fn boss_plate() -> (scode::ControlMesh, Vec<u8>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus/boss_plate.obj");
    let (input, _) = scode::io::read_mesh(&path).unwrap();
    let (bytes, _) = encode_fitted(&input, &[], &ModelEncodeOptions::default()).unwrap();
    (input, bytes)
}

#[test]
fn decode_options_mean_what_they_say() {
    let (input, bytes) = boss_plate();
    let limits = Limits::default();
    let decode = |detail, limit| {
        let opts = SurfaceOptions {
            detail,
            limit,
            ..Default::default()
        };
        decode_surface(&bytes, &limits, &opts)
    };
    let default = decode(Detail::FileTolerance, None).unwrap();
    let a = default.accuracy.clone().unwrap();
    assert!(default.limit && default.normals.is_some());
    assert!(a.bound <= a.tolerance, "{a:?}");
    assert_eq!(a.triangles_per_level.len() as u32, a.max_level + 1);
    assert_eq!(
        default.level as usize,
        a.triangles_per_level.iter().rposition(|&n| n > 0).unwrap()
    );
    // A tolerance given in model units, and one relative to the diagonal.
    let diagonal = input.diagonal();
    let absolute = decode(Detail::Tolerance(Tolerance::Absolute(a.tolerance)), None).unwrap();
    assert_eq!(absolute.mesh, default.mesh);
    let tight = decode(Detail::Tolerance(Tolerance::Relative(1e-4)), None).unwrap();
    let t = tight.accuracy.unwrap();
    assert!((t.tolerance - 1e-4 * diagonal).abs() < 1e-2 * t.tolerance);
    // Finer than the file's: up to a level more per factor 4.
    assert!(t.max_level > a.max_level);
    assert!(tight.mesh.face_count() > default.mesh.face_count());
    // A uniform level is the subdivided surface, as before.
    let uniform = decode(Detail::Level(2), None).unwrap();
    assert!(uniform.accuracy.is_none() && uniform.level == 2);
    let control = codec::decode(&bytes, &limits).unwrap().mesh;
    let (want, _) = scode::subdiv::subdivide(
        &control,
        2,
        &scode::subdiv::SubdivOptions {
            limit: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(uniform.mesh, want);
    // Level positions are not the limit surface a tolerance is measured against.
    assert!(matches!(
        decode(Detail::FileTolerance, Some(false)),
        Err(scode::Error::Parameter(_))
    ));
    assert!(decode(Detail::DefaultLevel, Some(false)).is_ok());
    // The memory budget covers the refinement one level below the finest level shown.
    let small = Limits {
        max_memory: 100_000,
        ..Limits::default()
    };
    assert!(matches!(
        decode_surface(&bytes, &small, &SurfaceOptions::default()),
        Err(scode::Error::LimitsExceeded { .. })
    ));
    // A raw-mode file is its own surface at any tolerance.
    let raw = codec::encode(&input, &EncodeOptions::default()).unwrap();
    let opts = SurfaceOptions {
        detail: Detail::Tolerance(Tolerance::Relative(1e-5)),
        ..Default::default()
    };
    let stored = decode_surface(&raw, &limits, &opts).unwrap();
    assert!(stored.accuracy.is_none());
    assert_eq!(stored.mesh, codec::decode(&raw, &limits).unwrap().mesh);
}
