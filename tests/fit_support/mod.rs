//! The fitted-mesh check shared by `fit_encoder.rs` (small corpus models) and `sweep.rs`
//! (the larger ones).

use std::path::Path;

use scode::codec::{self, Content, EncodeOptions, Limits};
use scode::metrics::{hausdorff, DistanceOptions, SampleCount};
use scode::pipeline::{
    encode_fitted, measure_file_against_input, sidecar_hints, ModelEncodeOptions,
};
use scode::subdiv::{subdivide, SubdivOptions};

/// Every edge of the decoded triangle mesh has exactly two faces (the inputs are closed).
fn assert_watertight(mesh: &scode::ControlMesh, name: &str) {
    let mut count = std::collections::BTreeMap::new();
    for f in mesh.faces() {
        for k in 0..f.len() {
            let (a, b) = (f[k], f[(k + 1) % f.len()]);
            *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    let bad = count.values().filter(|&&c| c != 2).count();
    assert_eq!(bad, 0, "{name}: {bad} edges without exactly two faces");
}

/// `min_ratio`: how many times smaller than raw mode the fitted file must be.
pub fn check_model(path: &Path, min_ratio: f64) {
    let name = path.file_name().unwrap().to_string_lossy().to_string();
    let (input, _) = scode::io::read_mesh(path).unwrap();
    let hints = sidecar_hints(path, &input)
        .unwrap()
        .map(|(_, h)| h)
        .unwrap_or_default();
    let opts = ModelEncodeOptions::default();
    let (bytes, report) = encode_fitted(&input, &hints, &opts).unwrap();
    let tol = report.tolerance;
    assert!(
        report.within_tolerance,
        "{name}: not within tolerance: {:?}\n{:#?}",
        report.error, report.notes
    );
    // Decode exactly as a user would and measure independently of the encoder.
    let decoded = codec::decode(&bytes, &Limits::default()).unwrap();
    let Content::ControlMesh { default_level } = decoded.header.content else {
        panic!("{name}: fitted file must hold a control mesh");
    };
    let (surface, _) = subdivide(
        &decoded.mesh,
        u32::from(default_level),
        &SubdivOptions {
            limit: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert_watertight(&surface, &name);
    let dist = hausdorff(
        &surface,
        &input,
        &DistanceOptions {
            samples: SampleCount::Total(40_000),
            ..Default::default()
        },
    )
    .unwrap();
    // The tolerance bounds the plain distance to the input mesh, which this measures again
    // with random samples of its own (the vertices of both are sampled by both): a few
    // percent of slack for what other samples find between the encoder's.
    assert!(
        dist.max <= 1.03 * tol,
        "{name}: max {:.3e} vs tolerance {tol:.3e}",
        dist.max
    );
    // The symmetric RMS is a small fraction of the tolerance.
    assert!(
        dist.rms < 0.5 * tol,
        "{name}: rms {:.3e} vs tolerance {tol:.3e}",
        dist.rms
    );
    // The encoder's figures are the file's as `scode info --against` measures it: the
    // same vertices and random points; edge points at the tolerance's spacing rather than
    // the default's, so the max may differ by what one finds between the other's, and the
    // mean and RMS by a vertex counted on two faces where the fit split it.
    let (info, _) = measure_file_against_input(
        &bytes,
        &input,
        &Limits::default(),
        &DistanceOptions::default(),
        tol,
    )
    .unwrap();
    let e = &report.error;
    assert!(
        (e.max - info.max).abs() <= 0.02 * tol,
        "{name}: encoder max {:.4e}, info --against {:.4e}",
        e.max,
        info.max
    );
    for (what, fit, file) in [("rms", e.rms, info.rms), ("mean", e.mean, info.mean)] {
        assert!(
            (fit - file).abs() <= 1e-2 * file,
            "{name}: encoder {what} {fit:.5e}, info --against {file:.5e}"
        );
    }
    let raw = codec::encode(&input, &EncodeOptions::default()).unwrap();
    println!(
        "{name}: fitted {} B vs raw {} B, {} control vertices, max {:.3e} rms {:.3e} (tol {tol:.3e})",
        bytes.len(),
        raw.len(),
        report.control_vertices,
        dist.max,
        dist.rms
    );
    assert!(
        bytes.len() as f64 * min_ratio < raw.len() as f64,
        "{name}: fitted {} B is not {min_ratio}x smaller than raw {} B",
        bytes.len(),
        raw.len()
    );
}
