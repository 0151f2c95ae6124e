//! Prints the section sizes of the spec vectors: `cargo run --example inspect_vectors`.

use scode::codec::{inspect, Limits};

fn main() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("spec/vectors");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("spec/vectors")
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "scode"))
        .collect();
    files.sort();
    for p in files {
        let bytes = std::fs::read(&p).expect("read vector");
        match inspect(&bytes, &Limits::default()) {
            Ok(info) => {
                let secs: Vec<String> = info
                    .sections
                    .iter()
                    .map(|s| format!("{}={}/{}", s.name, s.stored_bytes, s.raw_bytes))
                    .collect();
                println!(
                    "{:<20} {:>5} B  V={} F={} labels={}  [{}]",
                    p.file_name().unwrap_or_default().to_string_lossy(),
                    info.total_bytes,
                    info.header.vertex_count,
                    info.header.face_count,
                    info.label_count,
                    secs.join(" ")
                );
            }
            Err(e) => println!("{}: {e}", p.display()),
        }
    }
}
