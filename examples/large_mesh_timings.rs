//! Times segmentation, curve-network extraction and the Hausdorff distance on the largest
//! corpus tessellation (trj4, a bearing assembly). Reports timings, asserts nothing; the
//! criterion benches in `cli/benches/` cover the codec and subdivision.
//!
//! Run: `cargo run --release --example large_mesh_timings` (`SCODE_CORPUS` overrides the
//! corpus folder).

use std::time::Instant;

use scode::fit::curves::build_curve_network;
use scode::fit::segment::{segment, SegmentOptions};
use scode::metrics::{hausdorff, DistanceOptions};

#[path = "../tests/common/mod.rs"]
mod common;

fn main() {
    let corpus = common::corpus_dir().expect("the corpus (set SCODE_CORPUS)");
    let read = |rel: &str| {
        scode::io::read_mesh(&corpus.join(rel))
            .unwrap_or_else(|e| panic!("{rel}: {e}"))
            .0
    };
    let name = "tess/trj4_pm2-ec-214_fine.obj";
    let fine = read(name);

    let t = Instant::now();
    let (segmented, rep) = segment(&fine, &SegmentOptions::default()).unwrap();
    let t_seg = t.elapsed();
    let t = Instant::now();
    let net = build_curve_network(&fine, &Default::default()).unwrap();
    let t_curves_true = t.elapsed();
    let t = Instant::now();
    let net2 = build_curve_network(&segmented, &Default::default()).unwrap();
    let t_curves_seg = t.elapsed();
    println!(
        "{name}: {} triangles; segment {t_seg:?} -> {}; curves on true groups {t_curves_true:?} \
         ({} corners, {} chains); curves on segmentation {t_curves_seg:?} ({} corners, {} chains)",
        fine.face_count(),
        rep.summary(),
        net.corners.len(),
        net.chains.len(),
        net2.corners.len(),
        net2.chains.len()
    );

    let coarse = read("tess/trj4_pm2-ec-214_coarse.obj");
    let t = Instant::now();
    let r = hausdorff(&coarse, &fine, &DistanceOptions::default()).unwrap();
    println!(
        "trj4 coarse ({} tris) vs fine ({} tris), {} + {} samples: {:?}; relative max {:.3e} rms {:.3e}",
        coarse.face_count(),
        fine.face_count(),
        r.samples_a,
        r.samples_b,
        t.elapsed(),
        r.relative().max,
        r.relative().rms
    );
}
