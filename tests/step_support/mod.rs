//! STEP-path checks shared by `step_input.rs` (small corpus models) and `sweep.rs` (the
//! larger ones).

use std::path::{Path, PathBuf};
use std::time::Instant;

use scode::codec::{self, Content, Limits};
use scode::metrics::{point_distances, TriangleSurface};
use scode::pipeline::{encode_fitted, encode_step, sidecar_hints, Effort, ModelEncodeOptions};
use scode::subdiv::{subdivide, SubdivOptions};
use scode::{ControlMesh, Tolerance};

/// The surface a `.scode` file decodes to (default level, limit positions), as `info
/// --against` measures it.
pub fn decoded_surface(bytes: &[u8]) -> ControlMesh {
    let decoded = codec::decode(bytes, &Limits::default()).expect("decode");
    let level = match decoded.header.content {
        Content::ControlMesh { default_level } => u32::from(default_level),
        Content::RawMesh => 0,
    };
    let (surface, _) = subdivide(
        &decoded.mesh,
        level,
        &SubdivOptions {
            limit: true,
            ..Default::default()
        },
    )
    .expect("subdivide");
    surface
}

/// Distances between a decoded surface and a reference tessellation.
pub struct Comparison {
    /// Reference vertices (on the exact B-rep surface) to the decoded surface.
    pub max_vertices: f64,
    pub rms_vertices: f64,
    /// Symmetric sampled Hausdorff distance (includes the reference's own chord error).
    pub hausdorff: f64,
    pub rms: f64,
}

pub fn compare(decoded: &ControlMesh, reference: &ControlMesh) -> Comparison {
    let tris = |m: &ControlMesh| -> Vec<[u32; 3]> {
        m.faces()
            .flat_map(|f| (1..f.len() - 1).map(move |i| [f[0], f[i], f[i + 1]]))
            .collect()
    };
    let surface = TriangleSurface::new(decoded.positions.clone(), tris(decoded)).unwrap();
    let d = point_distances(&reference.positions, &surface);
    let n = d.len().max(1) as f64;
    let h = scode::metrics::hausdorff(decoded, reference, &Default::default()).unwrap();
    Comparison {
        max_vertices: d.iter().copied().fold(0.0, f64::max),
        rms_vertices: (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
        hausdorff: h.max,
        rms: h.rms,
    }
}

pub fn fine_tessellation(corpus: &Path, stem: &str) -> Option<PathBuf> {
    let p = corpus.join("tess").join(format!("{stem}_fine.obj"));
    p.is_file().then_some(p)
}

/// Encodes `file` at 1e-3 of the diagonal of its fine tessellation and checks the decoded
/// surface against that tessellation: its vertices lie on the exact B-rep surface, so their
/// distance to the decoded surface is the codec's error (plus our own chord error, which
/// the fit allows for) and must stay within the tolerance.
pub fn check_encodes_within_tolerance(corpus: &Path, file: &str) {
    let path = corpus.join("step").join(file);
    let stem = Path::new(file).file_stem().unwrap().to_str().unwrap();
    let fine_path = fine_tessellation(corpus, stem).expect("fine tessellation");
    let (fine, _) = scode::io::read_mesh(&fine_path).unwrap();
    let tol = 1e-3 * fine.diagonal();
    let t0 = Instant::now();
    let mut opts = ModelEncodeOptions::default();
    opts.fit.tolerance = Tolerance::Absolute(tol);
    let (model, bytes, report) = encode_step(&path, &opts).unwrap();
    assert!(report.within_tolerance, "{file}: {:?}", report.error);
    let surface = decoded_surface(&bytes);
    let c = compare(&surface, &fine);
    eprintln!(
        "{file}: {} faces, {} skipped, {} bytes, tol {tol:.3e}: fine vertices -> decoded max \
         {:.3e} rms {:.3e}; hausdorff {:.3e} rms {:.3e}; within tolerance (fit): {} [{:.1} s]",
        model.faces.len(),
        model.skipped.len(),
        bytes.len(),
        c.max_vertices,
        c.rms_vertices,
        c.hausdorff,
        c.rms,
        report.within_tolerance,
        t0.elapsed().as_secs_f64()
    );
    assert!(model.skipped.is_empty(), "{file}: {:?}", model.skipped);
    assert!(
        (model.mesh.diagonal() - fine.diagonal()).abs() < 1e-2 * fine.diagonal(),
        "{file}: the STEP model and its tessellation differ in size (units?)"
    );
    assert!(
        c.max_vertices <= 1.5 * tol,
        "{file}: decoded surface is {:.3e} from the fine tessellation (tolerance {tol:.3e})",
        c.max_vertices
    );
    // The RMS is well below the largest distance unless the surface is off as a whole; a
    // model stored for its coarsest decode level keeps that level's chord error between
    // its triangles' corners, about a quarter of the tolerance on curved faces.
    assert!(
        c.rms_vertices <= tol / 3.0,
        "{file}: rms {:.3e}",
        c.rms_vertices
    );
    // The other way, from the decoded triangles to the tessellation: a decoded edge that
    // cuts through the solid (a belt quad's side across a curved face) shows here. The
    // tessellation's own chords lie inside curved faces that the decoded surface follows,
    // which this direction adds to the error; a quarter of the tolerance covers them.
    assert!(
        c.hausdorff <= 1.25 * tol,
        "{file}: the decoded surface is {:.3e} from the fine tessellation (tolerance {tol:.3e})",
        c.hausdorff
    );
}

/// Encodes corpus STEP `file` through the STEP path and its fine tessellation (with its
/// sidecar) through the mesh path, both at 1e-3 of the tessellation's diagonal and at
/// `effort`, and asserts that the STEP path needs no more control vertices and makes a file
/// no larger, up to the bytes that face order and triangulation move: the two readers list a
/// model's faces in different orders, and the decimation may split a plane's polygon by other
/// diagonals, which moves even files with the same control vertices by a few bytes, and
/// the bit per coordinate the STEP path's B-rep outlines may cost its quantisation.
pub fn check_step_path_no_larger_than_mesh_path(corpus: &Path, file: &str, effort: Effort) {
    let stem = Path::new(file).file_stem().unwrap().to_str().unwrap();
    let fine_path = fine_tessellation(corpus, stem).expect("fine tessellation");
    let (fine, _) = scode::io::read_mesh(&fine_path).unwrap();
    let tol = 1e-3 * fine.diagonal();
    let mut opts = ModelEncodeOptions {
        effort,
        ..Default::default()
    };
    opts.fit.tolerance = Tolerance::Absolute(tol);
    let (_, step_bytes, report) = encode_step(&corpus.join("step").join(file), &opts).unwrap();
    assert!(report.within_tolerance, "{file}: {:?}", report.error);
    let hints = sidecar_hints(&fine_path, &fine).unwrap().unwrap().1;
    // Both held to within the tolerance of the part: the STEP path of its B-rep, the mesh
    // path of a fine tessellation of it (the plain distance).
    let (mesh_bytes, mesh_report) = encode_fitted(&fine, &hints, &opts).unwrap();
    eprintln!(
        "{file} at effort {effort}: STEP path {} bytes, {} control vertices; mesh path {} bytes, {} control vertices",
        step_bytes.len(),
        report.control_vertices,
        mesh_bytes.len(),
        mesh_report.control_vertices
    );
    assert!(
        report.control_vertices <= mesh_report.control_vertices,
        "{file} at effort {effort}: STEP path {} control vertices, mesh path {}",
        report.control_vertices,
        mesh_report.control_vertices
    );
    // The STEP path holds decoded points beyond a face's outline to the facets plus their
    // chord, which may cost it one quantisation bit per coordinate over the mesh path.
    let order_slack = 2 + mesh_bytes.len() / 25 + (3 * report.control_vertices).div_ceil(8);
    assert!(
        step_bytes.len() <= mesh_bytes.len() + order_slack,
        "{file} at effort {effort}: STEP path {} bytes, mesh path {} bytes",
        step_bytes.len(),
        mesh_bytes.len()
    );
}

/// Encodes corpus STEP `file` at the default tolerance and asserts that the decoded vertices
/// away from face boundaries lie within 1.05 tolerance of their faces' exact surfaces.
/// Returns the encoded file.
pub fn check_decoded_analytic_faces_on_exact_surfaces(corpus: &Path, file: &str) -> Vec<u8> {
    let path = corpus.join("step").join(file);
    let (model, bytes, report) = encode_step(&path, &ModelEncodeOptions::default()).unwrap();
    assert!(report.within_tolerance, "{file}: {:?}", report.error);
    let exact = scode::pipeline::step_exact_surfaces(&model);
    let decoded = decoded_surface(&bytes);
    // Decoded groups keep the input's order.
    assert_eq!(decoded.groups.len(), exact.len());
    let mut groups_of: Vec<Vec<u32>> = vec![Vec::new(); decoded.vertex_count()];
    for (f, &g) in decoded.face_groups.iter().enumerate() {
        for &v in decoded.face(f) {
            groups_of[v as usize].push(g);
        }
    }
    let mut checked = 0usize;
    let mut worst = 0.0f64;
    for (v, gs) in groups_of.iter().enumerate() {
        let g = gs[0];
        if gs.iter().any(|&h| h != g) {
            continue;
        }
        if let Some(s) = &exact[g as usize] {
            worst = worst.max(s.distance(decoded.positions[v]) / report.tolerance);
            checked += 1;
        }
    }
    eprintln!("{file}: {checked} interior vertices, worst {worst:.3} tol");
    assert!(checked > 500, "{file}: {checked}");
    assert!(
        worst <= 1.05,
        "{file}: {worst:.3} tol from the exact surface"
    );
    bytes
}
