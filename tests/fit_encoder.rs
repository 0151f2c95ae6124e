//! End-to-end tests of the fitting encoder on real CAD models: fit, encode, decode, and
//! check what the decoder rebuilds (tolerance, watertightness, size against raw mode).

mod common;
mod fit_support;
use common::corpus_dir;
use fit_support::check_model;
use std::path::Path;

use scode::codec::{self, Limits};
use scode::fit::encoder::{FitReport, SurfaceHint};
use scode::metrics::DistanceReport;
use scode::pipeline::{encode_fitted, sidecar_hints, Effort, ModelEncodeOptions};
use scode::Tolerance;

#[test]
fn bundled_example_part() {
    // A 386-vertex part: raw mode is already small, the fit must still beat it.
    check_model(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus/boss_plate.obj"),
        1.2,
    );
}

#[test]
fn the_same_bytes_on_any_number_of_threads() {
    // The measurement and the searches run in parallel; their results are combined in a
    // fixed order, so the file does not depend on the thread count.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus/boss_plate.obj");
    let (input, _) = scode::io::read_mesh(&path).unwrap();
    let encode_on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                encode_fitted(&input, &[], &ModelEncodeOptions::default())
                    .unwrap()
                    .0
            })
    };
    let one = encode_on(1);
    assert_eq!(one, encode_on(3));
    assert_eq!(one, encode_on(2));
}

#[test]
fn the_mean_tolerance_is_checked_and_reported() {
    // `FitOptions::mean_tolerance`: rejected when not positive; a bound the fit cannot meet
    // (one ten-thousandth of the mean it gets) is reported as not met, with a note. That a
    // bound it can meet holds is `fandisk_at_the_seed_coders_operating_point`.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus/boss_plate.obj");
    let (input, _) = scode::io::read_mesh(&path).unwrap();
    let with_mean = |mean: Option<f64>| {
        let mut opts = ModelEncodeOptions::default();
        opts.fit.mean_tolerance = mean.map(Tolerance::Absolute);
        encode_fitted(&input, &[], &opts)
    };
    assert!(matches!(
        with_mean(Some(-1.0)),
        Err(scode::Error::Parameter(_))
    ));
    let (_, free) = with_mean(None).unwrap();
    assert!(free.within_tolerance, "{:?}", free.error);
    let (_, tight) = with_mean(Some(1e-4 * free.error.mean)).unwrap();
    assert!(!tight.within_tolerance);
    assert!(
        tight.notes.iter().any(|n| n.contains("mean tolerance")),
        "{:#?}",
        tight.notes
    );
}

#[test]
fn a_precision_the_caller_chose_is_kept() {
    // `ModelEncodeOptions::quantization_bits`: neither fewer bits nor a fraction of a bit
    // coarser (a larger grid box) than asked for. Without that rule the quarter-bit search
    // takes the screw at 14 bits 0.75 bit coarser.
    let Some(dir) = corpus_dir() else { return };
    let (input, _) = scode::io::read_mesh(&dir.join("tess/screw_fine.obj")).unwrap();
    let opts = ModelEncodeOptions {
        quantization_bits: Some(14),
        ..Default::default()
    };
    let (bytes, report) = encode_fitted(&input, &[], &opts).unwrap();
    assert!(report.within_tolerance, "{:?}", report.error);
    let decoded = codec::decode(&bytes, &Limits::default()).unwrap();
    let h = &decoded.header;
    assert_eq!(h.quantization_bits, 14);
    // The grid covers the control points and the input's box with a margin of 1/32 of its
    // extent on each side; a quarter bit coarser would make it 1.19 times larger.
    let (lo, hi) = decoded.mesh.bounding_box().unwrap();
    let (in_lo, in_hi) = input.bounding_box().unwrap();
    let extent = (hi - lo)
        .max_element()
        .max((in_hi - in_lo).max_element() * (1.0 + 2.0 / 32.0));
    assert!(
        h.bbox_extent <= extent * (1.0 + 1e-4) + h.quantization_step(),
        "grid box {} for control points and the input's box spanning {extent}",
        h.bbox_extent
    );
}

#[test]
fn corpus_models_within_tolerance() {
    let Some(dir) = corpus_dir() else { return };
    // Face-grouped CAD models with planes, cylinders, cones and tori; the ratio is a
    // regression guard against raw mode (Draco-class, 10 bits). The larger models are in
    // `sweep.rs`.
    for (name, min_ratio) in [
        ("tess/four_cone_fine.obj", 10.0),
        ("tess/tr8_bv1_ec_fine.obj", 20.0),
        ("tess/screw_fine.obj", 4.0),
    ] {
        check_model(&dir.join(name), min_ratio);
    }
}

#[test]
fn fandisk_at_the_seed_coders_operating_point() {
    // Issue #4: fandisk (no groups: segmented first) with mean error <= 1e-3 and max error
    // <= 1e-2 of the bounding-box diagonal must take under 1,000 bytes (the seed coder
    // takes 292 B at mean 0.887e-3, max 10.18e-3). Measured as `scode info --against` does.
    // The mean is bounded too (`FitOptions::mean_tolerance`): at this loose max tolerance the
    // quantisation search would otherwise coarsen the grid until the mean passes 1e-3.
    let Some(dir) = corpus_dir() else { return };
    let (input, _) = scode::io::read_mesh(&dir.join("meshes/fandisk.obj")).unwrap();
    let opts = ModelEncodeOptions {
        fit: scode::fit::encoder::FitOptions {
            tolerance: Tolerance::Relative(0.008),
            mean_tolerance: Some(Tolerance::Relative(1e-3)),
            ..Default::default()
        },
        ..Default::default()
    };
    let (bytes, _) = encode_fitted(&input, &[], &opts).unwrap();
    let rel = measured_as_info_does(&bytes, &input).relative();
    println!(
        "fandisk: {} B, mean {:.3e}, max {:.3e} of the diagonal",
        bytes.len(),
        rel.mean,
        rel.max
    );
    assert!(rel.mean <= 1e-3, "mean {:.3e} of the diagonal", rel.mean);
    assert!(rel.max <= 1e-2, "max {:.3e} of the diagonal", rel.max);
    assert!(bytes.len() < 1000, "{} bytes", bytes.len());
}

#[test]
fn the_file_decodes_to_the_surface_the_encoder_measured() {
    // fandisk has no groups: the segmenter's have no names, so the codec numbers them in
    // traversal order, and where two analytic patches meet the group order picks the frame
    // of their edge. A traversal start that numbers them otherwise decodes to another
    // surface, which the encoder did not measure: it must not be the one written.
    let Some(dir) = corpus_dir() else { return };
    let (input, _) = scode::io::read_mesh(&dir.join("meshes/fandisk.obj")).unwrap();
    let (bytes, report) = encode_fitted(&input, &[], &ModelEncodeOptions::default()).unwrap();
    let measured = measured_as_info_does(&bytes, &input);
    // Both sample the same surfaces, at other points.
    assert!(
        (measured.max - report.error.max).abs() <= 0.05 * report.error.max,
        "decoded file {:.4e} from the input, the encoder measured {:.4e}",
        measured.max,
        report.error.max
    );
}

/// A file's distance to its input, as `scode info --against` measures it.
fn measured_as_info_does(bytes: &[u8], input: &scode::ControlMesh) -> DistanceReport {
    let near = 1e-3 * input.diagonal();
    scode::pipeline::measure_file_against_input(
        bytes,
        input,
        &Limits::default(),
        &Default::default(),
        near,
    )
    .unwrap()
    .0
}

/// A face-grouped corpus model with its sidecar's surface hints; `None` without the corpus.
fn corpus_model(file: &str) -> Option<(scode::ControlMesh, Vec<SurfaceHint>)> {
    let dir = corpus_dir()?;
    let path = dir.join(file);
    let (input, _) = scode::io::read_mesh(&path).unwrap();
    let hints = sidecar_hints(&path, &input).unwrap().unwrap().1;
    Some((input, hints))
}

/// Bytes and report of a fitted encode, which must meet the tolerance.
fn fitted(
    model: &(scode::ControlMesh, Vec<SurfaceHint>),
    opts: &ModelEncodeOptions,
) -> (usize, FitReport) {
    let (bytes, report) = encode_fitted(&model.0, &model.1, opts).unwrap();
    assert!(report.within_tolerance, "{:?}", report.error);
    (bytes.len(), report)
}

#[test]
fn max_effort_is_no_larger_than_either_plane_treatment_alone() {
    // `Effort::Max`: plane patches kept on their faces make smaller files on most models,
    // decimated freely on some; at the highest effort small inputs get the smaller of the two
    // that meet the tolerance (decimated freely, a plane's triangles can span its holes).
    let Some(model) = corpus_model("tess/bug3883_xr2-ct-214_plate_fine.obj") else {
        return;
    };
    let size = |keep: bool, effort: Effort| {
        let mut opts = ModelEncodeOptions {
            effort,
            ..Default::default()
        };
        opts.fit.keep_planes_on_faces = keep;
        let (bytes, report) = encode_fitted(&model.0, &model.1, &opts).unwrap();
        (bytes.len(), report.within_tolerance)
    };
    let (kept, plain, max) = (
        size(true, Effort::Default),
        size(false, Effort::Default),
        size(true, Effort::Max),
    );
    println!("plate: planes kept on faces {kept:?}, decimated freely {plain:?}, max {max:?}");
    assert!(max.1, "{max:?}");
    let best = [kept, plain].into_iter().filter(|s| s.1).map(|s| s.0).min();
    assert_eq!(Some(max.0), best);
}

#[test]
fn max_effort_is_no_larger_than_either_closed_patch_refinement_alone() {
    // `Effort::Max`: the screw's torus patches fail in early rounds; refining them only where
    // they fail makes a smaller file on some models and a larger one on others, so the highest
    // effort fits small inputs both ways and keeps the smaller file.
    let Some(model) = corpus_model("tess/screw_fine.obj") else {
        return;
    };
    let size = |local: bool, effort: Effort| {
        let mut opts = ModelEncodeOptions {
            effort,
            ..Default::default()
        };
        opts.fit.local_refinement = local;
        opts.fit.keep_planes_on_faces = true;
        let (bytes, report) = fitted(&model, &opts);
        (bytes, report.closed_refinements)
    };
    let ((everywhere, refinements), (local, _)) =
        (size(false, Effort::Default), size(true, Effort::Default));
    let mut opts = ModelEncodeOptions {
        effort: Effort::Max,
        ..Default::default()
    };
    opts.fit.keep_planes_on_faces = true;
    let max = fitted(&model, &opts).0;
    // Max also tries plane patches decimated freely, so it may be smaller still.
    println!(
        "screw: closed patches refined everywhere {everywhere} B ({refinements} refinements), \
         near failures {local} B, max {max} B"
    );
    assert!(
        refinements > 0,
        "no closed patch of the screw fails, so the option changes nothing: pick another model"
    );
    assert!(max <= everywhere.min(local), "max {max} B");
}

#[test]
fn fast_effort_meets_the_tolerance_with_fewer_searches() {
    // `Effort::Fast` skips the relaxation round, the quarter-bit steps and the traversal
    // starts: the same tolerance, measured the same way, with fewer measurements and encodes.
    let Some(model) = corpus_model("tess/screw_fine.obj") else {
        return;
    };
    let run = |effort: Effort| {
        fitted(
            &model,
            &ModelEncodeOptions {
                effort,
                ..Default::default()
            },
        )
    };
    let ((fast, fast_report), (default, default_report)) =
        (run(Effort::Fast), run(Effort::Default));
    println!(
        "screw: fast {fast} B in {} rounds, default {default} B in {} rounds",
        fast_report.rounds, default_report.rounds
    );
    assert!(fast_report.rounds <= default_report.rounds);
    for note in &fast_report.notes {
        assert!(
            !note.contains("traversal started") && !note.contains("relax"),
            "{note}"
        );
        if let Some(rest) = note.strip_prefix("quantisation: ") {
            let bits: f64 = rest.split(' ').next().unwrap().parse().unwrap();
            assert_eq!(bits.fract(), 0.0, "{note}");
        }
    }
}

#[test]
fn relaxing_refined_closed_patches_makes_a_smaller_file_within_tolerance() {
    // `FitOptions::relax`: on the coarse tessellation of the screw the torus patches fail in
    // early rounds and end far within the tolerance after their last refinement; coarsening
    // them again by half a step keeps the model within tolerance in fewer bytes. At
    // `Effort::Max` the fit kept is the one whose closed patches are refined only where they
    // fail, which is where that happens. A coarse tessellation: held beyond its facets'
    // chord error (no smooth surface comes nearer to them than their sagitta).
    let Some(model) = corpus_model("tess/screw_coarse.obj") else {
        return;
    };
    let fit = |relax: bool| {
        let mut opts = ModelEncodeOptions {
            effort: Effort::Max,
            ..Default::default()
        };
        opts.fit.relax = relax;
        opts.fit.chord_allowance = true;
        fitted(&model, &opts)
    };
    let ((relaxed, report), (converged, _)) = (fit(true), fit(false));
    println!("screw (coarse): relaxed {relaxed} B, converged {converged} B");
    assert!(
        report.notes.iter().any(|n| n.contains("kept the relaxed")),
        "{:#?}",
        report.notes
    );
    assert!(
        relaxed < converged,
        "relaxed {relaxed} B, converged {converged} B"
    );
}

/// A sphere of radius 10 tessellated coarsely (15-degree facets sag 0.86 mm from it) in two
/// hemisphere faces, with the sphere given as their exact surface (as a STEP file gives it):
/// the closed patches are fitted onto the sphere itself, not onto the sagging facets, so the
/// decoded surface is not biased inwards. Fitted to the facets, its vertices' mean radial
/// deviation is about -0.13 mm; onto the sphere, about -0.04 mm.
#[test]
fn closed_patches_are_fitted_onto_their_exact_surfaces() {
    use scode::fit::encoder::ExactSurface;
    use scode::mesh::AnalyticSurface;
    use scode::mesh::PatchKind;
    use scode::pipeline::{decode_surface, Detail, SurfaceOptions};
    let (r, step) = (10.0f64, 15usize);
    let (rings, around) = (180 / step, 360 / step);
    let mut m = scode::ControlMesh::new();
    let north = m.push_group("north", PatchKind::Closed);
    let south = m.push_group("south", PatchKind::Closed);
    let at = |lat: f64, lon: f64| {
        let (lat, lon) = (lat.to_radians(), lon.to_radians());
        glam::DVec3::new(
            r * lat.cos() * lon.cos(),
            r * lat.cos() * lon.sin(),
            r * lat.sin(),
        )
    };
    // Vertices: the poles, then the rings from south to north.
    m.positions.push(at(-90.0, 0.0));
    m.positions.push(at(90.0, 0.0));
    for i in 1..rings {
        for j in 0..around {
            let lat = -90.0 + (i * step) as f64;
            m.positions.push(at(lat, (j * step) as f64));
        }
    }
    let ring = |i: usize, j: usize| (2 + (i - 1) * around + j % around) as u32;
    let group = |i: usize| if 2 * i < rings { south } else { north };
    for j in 0..around {
        m.push_face(&[0, ring(1, j + 1), ring(1, j)], south);
        m.push_face(&[1, ring(rings - 1, j), ring(rings - 1, j + 1)], north);
        for i in 1..rings - 1 {
            let (a, b) = (ring(i, j), ring(i, j + 1));
            let (c, d) = (ring(i + 1, j + 1), ring(i + 1, j));
            m.push_face(&[a, b, c], group(i));
            m.push_face(&[a, c, d], group(i));
        }
    }
    let sphere = ExactSurface::new(AnalyticSurface::Sphere {
        center: glam::DVec3::ZERO,
        radius: r,
    });
    let mut opts = ModelEncodeOptions::default();
    opts.fit.tolerance = Tolerance::Absolute(1.0);
    opts.fit.exact_surfaces = vec![sphere, sphere];
    let hints = [SurfaceHint::Freeform, SurfaceHint::Freeform];
    let (bytes, report) = encode_fitted(&m, &hints, &opts).unwrap();
    assert!(report.within_tolerance, "{:?}", report.error);
    let opts = SurfaceOptions {
        detail: Detail::DefaultLevel,
        ..Default::default()
    };
    let decoded = decode_surface(&bytes, &Limits::default(), &opts)
        .unwrap()
        .mesh;
    let radial: Vec<f64> = decoded.positions.iter().map(|p| p.length() - r).collect();
    let mean = radial.iter().sum::<f64>() / radial.len() as f64;
    let worst = radial.iter().fold(0.0f64, |w, d| w.max(d.abs()));
    println!(
        "{} decoded vertices: mean radial deviation {mean:.3}, worst {worst:.3}",
        radial.len()
    );
    assert!(worst <= 1.0, "{worst} from the sphere");
    assert!(mean.abs() <= 0.08, "mean radial deviation {mean}");
}

/// A model still out of tolerance when its rounds run out has its failing groups faceted
/// and measured in rounds beyond `max_rounds` until it holds: with one round allowed, a
/// cylinder of eight facets (which sag beyond the tolerance from any smooth surface through
/// their vertices) fails the first round, and its side is faceted and measured in a second.
#[test]
fn groups_failing_when_the_rounds_run_out_are_faceted_and_measured() {
    use std::fmt::Write as _;
    let n = 8;
    let mut obj = String::new();
    for z in [0.0, 2.0] {
        for i in 0..n {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            writeln!(obj, "v {} {} {z}", a.cos(), a.sin()).unwrap();
        }
    }
    writeln!(obj, "v 0 0 0\nv 0 0 2\ng side").unwrap();
    for i in 0..n {
        let (a, b) = (i + 1, (i + 1) % n + 1);
        writeln!(obj, "f {a} {b} {}\nf {a} {} {}", b + n, b + n, a + n).unwrap();
    }
    writeln!(obj, "g bottom").unwrap();
    for i in 0..n {
        writeln!(obj, "f {} {} {}", 2 * n + 1, (i + 1) % n + 1, i + 1).unwrap();
    }
    writeln!(obj, "g top").unwrap();
    for i in 0..n {
        writeln!(obj, "f {} {} {}", 2 * n + 2, i + 1 + n, (i + 1) % n + 1 + n).unwrap();
    }
    let (mesh, _) = scode::io::read_mesh_bytes(
        obj.as_bytes(),
        scode::io::MeshFormat::Obj,
        Path::new("cylinder.obj"),
    )
    .unwrap();
    let mut opts = ModelEncodeOptions::default();
    opts.fit.max_rounds = 1;
    let (_, report) = encode_fitted(&mesh, &[], &opts).unwrap();
    assert!(
        report.within_tolerance && report.faceted_groups >= 1 && report.rounds == 2,
        "{} rounds, {} faceted, {:?}\n{:#?}",
        report.rounds,
        report.faceted_groups,
        report.error,
        report.notes
    );
}
