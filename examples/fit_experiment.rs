//! Development driver: fit and encode the given meshes, print size and error.
//! `cargo run --release --example fit_experiment -- FILE... [--tol REL]`
use scode::fit::encoder::SurfaceHint;
use scode::pipeline::{encode_fitted, ModelEncodeOptions};

fn main() {
    let mut rel = 1e-3;
    let mut files = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if a == "--tol" {
            rel = args.next().unwrap().parse().unwrap();
        } else {
            files.push(a);
        }
    }
    for f in files {
        let path = std::path::Path::new(&f);
        let (mesh, _) = scode::io::read_mesh(path).unwrap();
        let hints: Vec<SurfaceHint> = match scode::io::faces_json::sidecar_path_for(path) {
            Some(side) => {
                let faces = scode::io::faces_json::read_faces_json(&side).unwrap();
                let infos = scode::io::faces_json::face_info_for_groups(&mesh, &faces);
                infos
                    .iter()
                    .map(|fi| match fi.map(|f| &f.surface) {
                        Some(scode::io::faces_json::SurfaceType::Plane) => SurfaceHint::Plane,
                        Some(scode::io::faces_json::SurfaceType::Cylinder) => SurfaceHint::Cylinder,
                        Some(scode::io::faces_json::SurfaceType::Cone) => SurfaceHint::Cone,
                        Some(scode::io::faces_json::SurfaceType::Unknown) | None => {
                            SurfaceHint::Unknown
                        }
                        Some(_) => SurfaceHint::Freeform,
                    })
                    .collect()
            }
            None => Vec::new(),
        };
        let mut opts = ModelEncodeOptions::default();
        opts.fit.tolerance = Some(rel * mesh.diagonal());
        let t = std::time::Instant::now();
        match encode_fitted(&mesh, &hints, &opts) {
            Ok((bytes, rep)) => {
                println!(
                    "{f}: {} B, {} ctrl verts, {} faces, level {}, max {:.3e} rms {:.3e} mean {:.3e} (rel max {:.2e} mean {:.2e}) ok={} rounds={} {:.2}s kinds={:?}",
                    bytes.len(), rep.control_vertices, rep.control_faces, rep.default_level,
                    rep.error.max, rep.error.rms, rep.error.mean,
                    rep.error.max / rep.diagonal, rep.error.mean / rep.diagonal,
                    rep.within_tolerance, rep.rounds, t.elapsed().as_secs_f64(), rep.patch_kinds
                );
                for n in &rep.notes {
                    println!("    {n}");
                }
            }
            Err(e) => println!("{f}: ERROR {e}"),
        }
    }
}
