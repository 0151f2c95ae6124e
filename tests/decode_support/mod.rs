//! The check of a decode to the file's tolerance, shared by `decode_accuracy.rs` (small
//! corpus models) and `sweep.rs` (the larger ones), and the edge count `decode_max_edge.rs`
//! checks watertightness with. Each test binary uses a part of it.
#![allow(dead_code)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use scode::codec::Limits;
use scode::metrics::{hausdorff, DistanceOptions, SampleCount};
use scode::pipeline::{
    decode_surface, encode_fitted, sidecar_hints, Detail, ModelEncodeOptions, SurfaceOptions,
};
use scode::ControlMesh;

/// Edges used by one face, and edges used by more than two.
pub fn open_and_overused_edges(mesh: &ControlMesh) -> (usize, usize) {
    let mut count = BTreeMap::new();
    for f in mesh.faces() {
        for k in 0..f.len() {
            *count
                .entry(scode::mesh::edge_key(f[k], f[(k + 1) % f.len()]))
                .or_insert(0) += 1;
        }
    }
    (
        count.values().filter(|&&c| c == 1).count(),
        count.values().filter(|&&c| c > 2).count(),
    )
}

/// Encodes a face-grouped corpus model at the default tolerance, decodes it as `scode
/// decode` does by default (to the file's tolerance) and checks the conditions: at
/// most 1.5 times the input's triangles, within the tolerance of the uniform level-6 decode
/// both ways (the crate's metrics, from the vertices and area samples of each surface to the
/// other), no open edge where the uniform decode has none, every group kept.
pub fn check_decode_to_tolerance(path: &Path) {
    let name = path.file_name().unwrap().to_string_lossy().to_string();
    let (input, _) = scode::io::read_mesh(path).unwrap();
    let hints = sidecar_hints(path, &input)
        .unwrap()
        .map(|(_, h)| h)
        .unwrap_or_default();
    let (bytes, report) = encode_fitted(&input, &hints, &ModelEncodeOptions::default()).unwrap();
    let tol = report.tolerance;
    // The command line's budget: level 6 of a model of hundreds of faces takes gigabytes.
    let limits = Limits {
        max_memory: 4 << 30,
        ..Limits::default()
    };
    let decode = |detail| {
        let opts = SurfaceOptions {
            detail,
            ..Default::default()
        };
        let t0 = std::time::Instant::now();
        let s = decode_surface(&bytes, &limits, &opts).unwrap();
        (s, t0.elapsed())
    };
    let (accurate, took) = decode(Detail::FileTolerance);
    let (uniform, _) = decode(Detail::DefaultLevel);
    let (level6, _) = decode(Detail::Level(6));
    let a = accurate
        .accuracy
        .as_ref()
        .expect("a control mesh decodes to a tolerance");
    // The file does not store its tolerance: the decoder's default is the encoder's, against
    // the decoded surface's diagonal instead of the input's.
    assert!(
        (a.tolerance - tol).abs() <= 0.01 * tol,
        "{name}: decoded to {:.4e}, encoded for {tol:.4e}",
        a.tolerance
    );
    let (mesh, fine) = (&accurate.mesh, &level6.mesh);
    // By area, as the decoder's own measurement picks the levels: where a plane patch's
    // sparse fans cross its outline, the flipped triangles of a decode to a tolerance and
    // the fans of a uniform level cover the crossing differently, which the points along
    // thin triangles' edges see (abc_00000050: 1.18 tol) and which the level choice does
    // not cause.
    let d = hausdorff(
        mesh,
        fine,
        &DistanceOptions {
            samples: SampleCount::Total(200_000),
            include_vertices: true,
            edge_spacing: None,
            ..Default::default()
        },
    )
    .unwrap();
    println!(
        "{name}: input {} triangles, to the tolerance {} (levels {:?}), uniform level {} {}; \
         to level 6 max {:.4e} / {:.4e} ({:.2} tol; estimated {:.2} tol); tolerance {tol:.4e}; \
         decode {:.0} ms",
        input.face_count(),
        mesh.face_count(),
        a.triangles_per_level,
        uniform.level,
        uniform.mesh.face_count(),
        d.max_a_to_b,
        d.max_b_to_a,
        d.max / tol,
        a.bound / tol,
        took.as_secs_f64() * 1e3
    );
    assert!(
        mesh.face_count() as f64 <= 1.5 * input.face_count() as f64,
        "{name}: {} triangles for an input of {}",
        mesh.face_count(),
        input.face_count()
    );
    assert!(
        d.max <= tol,
        "{name}: {:.4e} from level 6 (output to it {:.4e}, it to the output {:.4e}) beyond \
         the tolerance {tol:.4e}",
        d.max,
        d.max_a_to_b,
        d.max_b_to_a
    );
    let (open, overused) = open_and_overused_edges(mesh);
    let (uniform_open, _) = open_and_overused_edges(&uniform.mesh);
    assert_eq!(overused, 0, "{name}: edges with more than two faces");
    if uniform_open == 0 {
        assert_eq!(
            open, 0,
            "{name}: open edges where the uniform decode has none"
        );
    }
    assert_eq!(mesh.groups, uniform.mesh.groups, "{name}");
    let groups = |m: &ControlMesh| m.face_groups.iter().copied().collect::<BTreeSet<u32>>();
    assert_eq!(groups(mesh), groups(&uniform.mesh), "{name}: groups lost");
    mesh.validate().unwrap();
}
