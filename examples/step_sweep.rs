//! Every corpus STEP file through the STEP path, as a Markdown table: what encodes (or the
//! error naming the entity), faces by surface type, skipped faces, bytes, the decoded
//! surface's distance to the corpus' fine tessellation, and the mesh path's bytes
//! (`<name>_fine.obj` with its sidecar) at the same tolerance.
//!
//! Run: `cargo run --release --example step_sweep [-- FILE...]` (all of `<corpus>/step`
//! without arguments; `SCODE_CORPUS` overrides the corpus folder). It takes many minutes.
//! Each file runs in its own process (this program with `--one FILE`): a face whose
//! tessellation hangs leaves a thread behind that only the end of the process stops.

use std::path::{Path, PathBuf};
use std::time::Instant;

use scode::codec::{self, Content, Limits};
use scode::io::step::StepModel;
use scode::metrics::{point_distances, TriangleSurface};
use scode::pipeline::{encode_fitted, encode_step, sidecar_hints, ModelEncodeOptions};
use scode::subdiv::{subdivide, SubdivOptions};
use scode::{ControlMesh, Tolerance};

#[path = "../tests/common/mod.rs"]
mod common;

fn main() {
    let corpus = common::corpus_dir().expect("the corpus (set SCODE_CORPUS)");
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let [flag, file] = args.as_slice() {
        if flag == "--one" {
            row(&corpus, Path::new(file));
            return;
        }
    }
    let mut files: Vec<PathBuf> = if args.is_empty() {
        std::fs::read_dir(corpus.join("step"))
            .expect("<corpus>/step")
            .map(|e| e.unwrap().path())
            .collect()
    } else {
        args.iter().map(PathBuf::from).collect()
    };
    files.sort();
    println!(
        "| file | result | faces by type | skipped | bytes (STEP) | max / rms vs fine (vertices) | hausdorff / rms | bytes (fine.obj) | read+encode s |"
    );
    println!("|---|---|---|---|---:|---|---|---:|---:|");
    for path in files {
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .arg("--one")
            .arg(&path)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        let rows: Vec<&str> = text.lines().filter(|l| l.starts_with("| ")).collect();
        if rows.is_empty() {
            println!(
                "| {} | crashed: {} | | | | | | | |",
                path.display(),
                out.status
            );
        }
        for r in rows {
            println!("{r}");
        }
    }
}

/// Prints the table row of one STEP file.
fn row(corpus: &Path, path: &Path) {
    let name = path.file_name().unwrap().to_string_lossy().to_string();
    let stem = path.file_stem().unwrap().to_string_lossy().to_string();
    let fine = Some(corpus.join("tess").join(format!("{stem}_fine.obj")))
        .filter(|p| p.is_file())
        .map(|p| {
            let (m, _) = scode::io::read_mesh(&p).unwrap();
            (p, m)
        });
    let tol = fine.as_ref().map(|(_, m)| 1e-3 * m.diagonal());
    let t0 = Instant::now();
    let mut opts = ModelEncodeOptions::default();
    if let Some(t) = tol {
        opts.fit.tolerance = Tolerance::Absolute(t);
    }
    let result = encode_step(path, &opts);
    let secs = t0.elapsed().as_secs_f64();
    let (model, bytes, report): (StepModel, Vec<u8>, _) = match result {
        Ok(r) => r,
        Err(e) => {
            println!("| {name} | fails: {e} | | | | | | | {secs:.1} |");
            return;
        }
    };
    let hist: Vec<String> = model
        .surface_histogram()
        .iter()
        .map(|(k, n)| format!("{n} {k}"))
        .collect();
    let skipped: Vec<String> = model.skipped.iter().map(|s| s.to_string()).collect();
    let (cmp, hausdorff, mesh_bytes) = match &fine {
        Some((fine_path, fine_mesh)) => {
            let decoded = decoded_surface(&bytes);
            let (max, rms) = vertex_distances(&decoded, fine_mesh);
            let h = scode::metrics::hausdorff(&decoded, fine_mesh, &Default::default()).unwrap();
            let hints = sidecar_hints(fine_path, fine_mesh)
                .unwrap()
                .map(|(_, h)| h)
                .unwrap_or_default();
            let mb = encode_fitted(fine_mesh, &hints, &opts)
                .map(|(b, _)| b.len().to_string())
                .unwrap_or_else(|e| format!("fails: {e}"));
            (
                format!("{max:.2e} / {rms:.2e} (tol {:.2e})", tol.unwrap_or(0.0)),
                format!("{:.2e} / {:.2e}", h.max, h.rms),
                mb,
            )
        }
        None => ("no fine tessellation".into(), String::new(), String::new()),
    };
    println!(
        "| {name} | encodes{} | {} | {} | {} | {cmp} | {hausdorff} | {mesh_bytes} | {secs:.1} |",
        if report.within_tolerance {
            ""
        } else {
            " (fit tolerance NOT met)"
        },
        hist.join(", "),
        if skipped.is_empty() {
            "0".to_string()
        } else {
            skipped.join("; ")
        },
        bytes.len(),
    );
}

/// The surface a `.scode` file decodes to (default level, limit positions), as `info
/// --against` measures it.
fn decoded_surface(bytes: &[u8]) -> ControlMesh {
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

/// Largest and RMS distance of the reference's vertices (on the exact B-rep surface) to the
/// decoded surface.
fn vertex_distances(decoded: &ControlMesh, reference: &ControlMesh) -> (f64, f64) {
    let tris: Vec<[u32; 3]> = decoded
        .faces()
        .flat_map(|f| (1..f.len() - 1).map(move |i| [f[0], f[i], f[i + 1]]))
        .collect();
    let surface = TriangleSurface::new(decoded.positions.clone(), tris).unwrap();
    let d = point_distances(&reference.positions, &surface);
    let n = d.len().max(1) as f64;
    (
        d.iter().copied().fold(0.0, f64::max),
        (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
    )
}
