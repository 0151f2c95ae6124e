//! Corpus sweeps: the corpus checks of `step_input.rs` and `fit_encoder.rs` on the larger
//! corpus models, too slow for `scripts/test.sh`. Built only with the `sweep` feature; run
//! them with `scripts/sweep.sh` (release build).

mod common;
mod decode_support;
mod fit_support;
mod step_support;
use common::corpus_dir;
use decode_support::check_decode_to_tolerance;
use fit_support::check_model;
use scode::pipeline::Effort;
use step_support::{
    check_decoded_analytic_faces_on_exact_surfaces, check_encodes_within_tolerance,
    check_step_path_no_larger_than_mesh_path,
};

/// `step_input.rs`' `corpus_subset_encodes_within_tolerance_of_fine_tessellation` on the
/// larger models.
#[test]
fn step_corpus_encodes_within_tolerance_of_fine_tessellation() {
    let Some(corpus) = corpus_dir() else { return };
    // A sphere corner between cylinder fillets (periodic faces cut along a seam, a pole); an
    // 18-solid assembly of planes and cylinders; rational B-spline strips and tori, whose
    // edge projection restarts between neighbours where it would stop off the surface.
    // Files whose fit does not meet the tolerance (an encoder limit, also on their mesh
    // twins) are in the `step_sweep` example's table only: bug27693 encodes all 110 faces
    // but its fine tessellation's vertices are 0.34 tol rms from the decoded surface.
    for file in ["block_fillet3.step", "trj2_as1-ec-214.stp", "linkrods.step"] {
        check_encodes_within_tolerance(&corpus, file);
    }
}

/// Issue #5: the STEP path knows the exact surfaces and the topology, so it should cost no
/// more than the mesh path (`<name>_fine.obj` with its sidecar) at the same tolerance
/// (`step_input.rs`' `step_path_no_larger_than_mesh_path` on the larger models).
#[test]
fn step_path_no_larger_than_mesh_path() {
    let Some(corpus) = corpus_dir() else { return };
    // At the highest effort: the STEP path's tessellations and fits are searched, as the
    // mesh path's are. The corpus tessellation's sphere facets sag up to 0.45 tol and the
    // mesh path (with the chord allowance, as the STEP path has) is not charged for them,
    // so the STEP path measures its
    // analytic faces against their exact surfaces and tessellates them more coarsely. trj4
    // is not here: its mesh path is held to the corpus facets, which are over 1.4 mm off
    // the exact surfaces in places, and the STEP path, held to the exact surfaces, is larger.
    for file in [
        "trj3_s1-ec-214.stp",
        "trj10_ap209-eb.stp",
        "block_fillet3.step",
        "screw.step",
        "bm2_ec_lever-A.stp",
        "abc_00000050.step",
        "occwl_example.stp",
    ] {
        check_step_path_no_larger_than_mesh_path(&corpus, file, Effort::Max);
    }
}

/// `step_input.rs`' `decoded_analytic_faces_stay_on_their_exact_surfaces` on the models
/// with spheres and tori.
#[test]
fn decoded_analytic_faces_stay_on_their_exact_surfaces() {
    let Some(corpus) = corpus_dir() else { return };
    for file in ["block_fillet3.step", "screw.step"] {
        check_decoded_analytic_faces_on_exact_surfaces(&corpus, file);
    }
}

/// `fit_encoder.rs`' `corpus_models_within_tolerance` on the larger models: fillets and
/// freeform faces; faces stored as their facets (bug33398: a plane ring thinner than its
/// outline's error, facets whose chord error is twice the tolerance); a plate whose planes'
/// thin slivers cross their outlines.
#[test]
fn fitted_corpus_models_within_tolerance() {
    let Some(dir) = corpus_dir() else { return };
    for (name, min_ratio) in [
        ("tess/trj10_ap209-eb_fine.obj", 8.0),
        ("tess/bm2_ec_lever-A_fine.obj", 6.0),
        ("tess/block_fillet3_fine.obj", 6.0),
        ("tess/bug33398_fine.obj", 3.0),
        ("tess/bug3883_xr2-ct-214_plate_fine.obj", 10.0),
    ] {
        check_model(&dir.join(name), min_ratio);
    }
}

/// `decode_accuracy.rs`' `corpus_models_decode_to_their_tolerance` on the larger models:
/// hundreds of faces, freeform surfaces, fillets and tori.
#[test]
fn larger_corpus_models_decode_to_their_tolerance() {
    let Some(dir) = corpus_dir() else { return };
    for name in ["Ventilator_fine", "bug33398_fine", "trj6_b1-ec-214_fine"] {
        check_decode_to_tolerance(&dir.join(format!("tess/{name}.obj")));
    }
}
