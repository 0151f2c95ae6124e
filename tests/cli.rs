//! The `scode` binary end to end: encode (fitted and raw), info, decode, subdivide, errors.

use std::path::{Path, PathBuf};
use std::process::Command;

fn scode(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_scode"))
        .args(args)
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("scode-cli-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn example() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus/boss_plate.obj")
        .to_string_lossy()
        .into_owned()
}

#[test]
fn encode_info_decode_roundtrip() {
    let fitted = tmp("boss.scode");
    let (ok, text) = scode(&["encode", &example(), fitted.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(text.contains("met"), "{text}");
    let (ok, text) = scode(&["info", fitted.to_str().unwrap(), "--against", &example()]);
    assert!(ok, "{text}");
    assert!(
        text.contains("control mesh (default decode level"),
        "{text}"
    );
    assert!(text.contains("symmetric: max"), "{text}");
    assert!(
        text.contains("grid box min") && text.contains(", step "),
        "{text}"
    );
    let out = tmp("boss_decoded.obj");
    let (ok, text) = scode(&[
        "decode",
        fitted.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    let (decoded, _) = scode::io::read_mesh(&out).unwrap();
    // the boss plate is all planes and one cylinder: sparse boundary patches by default
    assert!(
        decoded.face_count() > 500,
        "decoded surface has {} faces",
        decoded.face_count()
    );
    assert_eq!(decoded.groups.len(), 8);
    let dense = tmp("boss_decoded_dense.obj");
    let (ok, text) = scode(&[
        "decode",
        "--dense-boundary",
        fitted.to_str().unwrap(),
        "-o",
        dense.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    let (dense, _) = scode::io::read_mesh(&dense).unwrap();
    assert!(
        dense.face_count() > 4 * decoded.face_count(),
        "dense {} vs sparse {} faces",
        dense.face_count(),
        decoded.face_count()
    );

    let raw = tmp("boss_raw.scode");
    let (ok, text) = scode(&["encode", "--raw", &example(), "-o", raw.to_str().unwrap()]);
    assert!(ok, "{text}");
    let back = tmp("boss_raw.ply");
    let (ok, text) = scode(&["decode", raw.to_str().unwrap(), back.to_str().unwrap()]);
    assert!(ok, "{text}");
    let (mesh, _) = scode::io::read_mesh(&back).unwrap();
    assert_eq!(mesh.face_count(), 288);
    assert_eq!(mesh.groups.len(), 8);
}

#[test]
fn the_mean_tolerance_is_reported() {
    let out = tmp("boss_mean.scode");
    let out = out.to_str().unwrap();
    let (ok, text) = scode(&[
        "encode",
        &example(),
        out,
        "--mean-tolerance",
        "0.5",
        "--relative",
    ]);
    assert!(ok, "{text}");
    let mean_line = |text: &str| {
        text.lines()
            .find(|l| l.starts_with("mean tolerance"))
            .unwrap_or_default()
            .to_string()
    };
    assert!(mean_line(&text).ends_with(" met"), "{text}");
    let (ok, text) = scode(&[
        "encode",
        &example(),
        out,
        "--mean-tolerance",
        "1e-9",
        "--relative",
    ]);
    assert!(ok, "{text}");
    assert!(mean_line(&text).contains("NOT met: the mean is"), "{text}");
    let (ok, text) = scode(&[
        "encode",
        "--raw",
        &example(),
        out,
        "--mean-tolerance",
        "0.1",
    ]);
    assert!(!ok, "{text}");
    assert!(text.contains("--mean-tolerance"), "{text}");
}

#[test]
fn subdivide_a_hand_made_control_mesh() {
    let control = tmp("tetra.obj");
    std::fs::write(
        &control,
        "v 1 1 1\nv 1 -1 -1\nv -1 1 -1\nv -1 -1 1\nf 1 2 3\nf 1 4 2\nf 1 3 4\nf 2 4 3\nl 1 2\n",
    )
    .unwrap();
    let out = tmp("tetra_l3.obj");
    let (ok, text) = scode(&[
        "subdivide",
        control.to_str().unwrap(),
        "--level",
        "3",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    let (mesh, _) = scode::io::read_mesh(&out).unwrap();
    assert_eq!(mesh.face_count(), 4 * 64);
    assert_eq!(
        mesh.sharp_edges.len(),
        8,
        "the sharp edge splits into 2^3 sharp edges"
    );
}

#[test]
fn errors_name_the_file_and_cause() {
    let (ok, text) = scode(&["decode", "/nonexistent/x.scode", "out.obj"]);
    assert!(!ok);
    assert!(text.contains("/nonexistent/x.scode"), "{text}");
    let garbage = tmp("garbage.scode");
    std::fs::write(&garbage, b"not an scode file at all").unwrap();
    let (ok, text) = scode(&["decode", garbage.to_str().unwrap(), "out.obj"]);
    assert!(!ok);
    assert!(
        text.contains("garbage.scode") && text.contains("section"),
        "{text}"
    );
    let (ok, text) = scode(&["encode", &example()]);
    assert!(!ok);
    assert!(text.contains("no output file"), "{text}");
    let (ok, text) = scode(&["encode", &example(), "a.scode", "-o", "b.scode"]);
    assert!(!ok);
    assert!(text.contains("two different outputs"), "{text}");
}

#[test]
fn every_effort_meets_the_tolerance_and_an_unknown_one_is_refused() {
    let mut sizes = Vec::new();
    for effort in ["fast", "default", "max"] {
        let out = tmp(&format!("boss-{effort}.scode"));
        let (ok, text) = scode(&[
            "encode",
            "--effort",
            effort,
            &example(),
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{effort}: {text}");
        assert!(
            text.contains("met") && !text.contains("NOT met"),
            "{effort}: {text}"
        );
        sizes.push(std::fs::metadata(&out).unwrap().len());
    }
    // `max` keeps the smallest of several fits, the default's among them.
    assert!(sizes[2] <= sizes[1], "{sizes:?}");
    let (ok, text) = scode(&["encode", "--effort", "most", &example(), "x.scode"]);
    assert!(!ok);
    assert!(text.contains("unknown effort 'most'"), "{text}");
}

/// `scode info | head` closes stdout early: the command ends quietly instead of panicking
/// on the failed write (std's `println!` panics on a closed pipe).
#[test]
fn a_closed_stdout_is_no_panic() {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("spec/vectors/cad_part.scode");
    let mut child = Command::new(env!("CARGO_BIN_EXE_scode"))
        .args(["info", "--groups", file.to_str().unwrap()])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Close the read end before the child writes anything.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{:?}: {stderr}", out.status);
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// One triangle as a control mesh whose header asks for subdivision level `level`.
fn triangle_at_level(level: u8) -> PathBuf {
    let mut mesh = scode::ControlMesh::new();
    for p in [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        mesh.push_vertex(p.into());
    }
    let g = mesh.push_group("", scode::mesh::PatchKind::Closed);
    mesh.push_face(&[0, 1, 2], g);
    let opts = scode::codec::EncodeOptions {
        content: scode::codec::Content::ControlMesh {
            default_level: level,
        },
        ..Default::default()
    };
    let path = tmp(&format!("triangle_level{level}.scode"));
    std::fs::write(&path, scode::codec::encode(&mesh, &opts).unwrap()).unwrap();
    path
}

#[test]
fn decoding_is_refused_beyond_the_memory_budget() {
    // Level 13 of one triangle is 67 M triangles: more than the command line's 4 GiB budget,
    // refused before subdividing; a level asked for on the command line is checked the same
    // way.
    let file = triangle_at_level(13);
    let out = tmp("level13.obj");
    let (ok, text) = scode(&["decode", file.to_str().unwrap(), out.to_str().unwrap()]);
    assert!(!ok, "{text}");
    assert!(
        text.contains("limit exceeded: decode memory with subdivision"),
        "{text}"
    );
    assert!(!out.exists());
    let (ok, text) = scode(&[
        "decode",
        "--level",
        "3",
        file.to_str().unwrap(),
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    assert!(text.contains("64 faces"), "{text}");
    // --max-memory sets the budget.
    let (ok, text) = scode(&[
        "decode",
        "--max-memory",
        "1000",
        file.to_str().unwrap(),
        out.to_str().unwrap(),
    ]);
    assert!(!ok, "{text}");
    assert!(text.contains("limit exceeded: decode memory"), "{text}");
    let (ok, text) = scode(&["info", "--max-memory", "1000", file.to_str().unwrap()]);
    assert!(!ok, "{text}");
    assert!(text.contains("limit exceeded: decode memory"), "{text}");
}

#[test]
fn a_file_over_max_bytes_is_refused_before_it_is_read() {
    // A sparse 2 GiB file: refused from its size, never read (reading it would take 2 GiB).
    let file = tmp("huge.scode");
    std::fs::File::create(&file)
        .unwrap()
        .set_len(2 << 30)
        .unwrap();
    let out = tmp("huge.obj");
    for args in [vec!["--max-bytes", "1000"], vec![]] {
        let mut all = vec!["decode"];
        all.extend(args);
        all.extend([file.to_str().unwrap(), out.to_str().unwrap()]);
        let (ok, text) = scode(&all);
        assert!(!ok, "{text}");
        assert!(
            text.contains("limit exceeded: input bytes = 2147483648"),
            "{text}"
        );
    }
    std::fs::remove_file(&file).unwrap();
}

#[test]
fn max_work_per_element_sets_the_work_bound() {
    // The CAD part's group candidates take a few walk steps: none are allowed here.
    let part = Path::new(env!("CARGO_MANIFEST_DIR")).join("spec/vectors/cad_part.scode");
    let part = part.to_str().unwrap();
    let (ok, text) = scode(&["info", "--max-work-per-element", "0", part]);
    assert!(!ok, "{text}");
    assert!(text.contains("limit exceeded: decode work"), "{text}");
    let (ok, text) = scode(&["info", part]);
    assert!(ok, "{text}");
}
