//! The `scode` binary end to end: encode (fitted and raw), info, decode, subdivide, errors.

use std::path::{Path, PathBuf};
use std::process::Command;

fn scode(args: &[&str]) -> (bool, String) {
    let (status, text) = scode_status(args);
    (status == 0, text)
}

/// The exit status of `scode args` (-1 when killed by a signal) and its stdout + stderr.
fn scode_status(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_scode"))
        .args(args)
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.code().unwrap_or(-1), text)
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("scode-cli-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// The repository's root, above this package (`cli/`): the example model, spec vectors and
/// test data.
fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn example() -> String {
    repo()
        .join("corpus/boss_plate.obj")
        .to_string_lossy()
        .into_owned()
}

#[test]
fn encode_info_decode_roundtrip() {
    let fitted = tmp("boss.scode");
    let (ok, text) = scode(&["encode", &example(), fitted.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(
        text.contains("vs the input mesh:") && text.contains("met") && !text.contains("NOT met"),
        "{text}"
    );
    let (ok, text) = scode(&["info", fitted.to_str().unwrap(), "--against", &example()]);
    assert!(ok, "{text}");
    assert!(
        text.contains("control mesh (default decode level"),
        "{text}"
    );
    assert!(text.contains("symmetric: max"), "{text}");
    // Where the farthest samples are, each a point inside the part's box.
    let farthest = text
        .lines()
        .find(|l| l.trim_start().starts_with("farthest: decoded point ("))
        .unwrap_or_else(|| panic!("{text}"));
    let coords: Vec<f64> = farthest
        .split(['(', ')', ','])
        .filter_map(|t| t.trim().parse().ok())
        .collect();
    assert_eq!(coords.len(), 6, "{farthest}");
    assert!(coords.iter().all(|c| c.is_finite()), "{farthest}");
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
    // By default to the file's tolerance: few triangles on a plate of planes and a cylinder.
    assert!(
        text.contains("tolerance") && text.contains("estimated distance to the limit surface"),
        "{text}"
    );
    let (decoded, _) = scode::io::read_mesh(&out).unwrap();
    assert_eq!(decoded.groups.len(), 8);
    let uniform = tmp("boss_decoded_uniform.obj");
    let (ok, text) = scode(&[
        "decode",
        "--level",
        "4",
        fitted.to_str().unwrap(),
        "-o",
        uniform.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    assert!(text.contains("(level 4;"), "{text}");
    let (uniform, _) = scode::io::read_mesh(&uniform).unwrap();
    // sparse boundary patches by default
    assert!(
        uniform.face_count() > 500,
        "level 4 has {} faces",
        uniform.face_count()
    );
    assert!(
        decoded.face_count() < uniform.face_count(),
        "to the tolerance {} faces, level 4 {}",
        decoded.face_count(),
        uniform.face_count()
    );
    // The plate's flat rectangular sides come out as two triangles each.
    for (g, group) in decoded.groups.iter().enumerate() {
        let n = decoded
            .face_groups
            .iter()
            .filter(|&&x| x as usize == g)
            .count();
        if group.name.starts_with("side_") {
            assert_eq!(n, 2, "{}: {n} triangles", group.name);
        }
    }
    let dense = tmp("boss_decoded_dense.obj");
    let (ok, text) = scode(&[
        "decode",
        "--dense-boundary",
        "--level",
        "4",
        fitted.to_str().unwrap(),
        "-o",
        dense.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    let (dense, _) = scode::io::read_mesh(&dense).unwrap();
    // The planes (seven of the eight faces) come out as a few triangles each instead of
    // their full level-4 grids; the cylinder is subdivided either way.
    assert!(
        dense.face_count() > 2 * uniform.face_count(),
        "dense {} vs sparse {} faces",
        dense.face_count(),
        uniform.face_count()
    );
    // A looser tolerance takes fewer triangles, a tighter one more; relative to the diagonal
    // with --relative.
    let faces_at = |args: &[&str]| {
        let out = tmp("boss_decoded_tol.obj");
        let mut all = vec!["decode"];
        all.extend_from_slice(args);
        all.extend([fitted.to_str().unwrap(), out.to_str().unwrap()]);
        let (ok, text) = scode(&all);
        assert!(ok, "{text}");
        scode::io::read_mesh(&out).unwrap().0.face_count()
    };
    let loose = faces_at(&["--tolerance", "0.02", "--relative"]);
    let tight = faces_at(&["--tolerance", "0.0002", "--relative"]);
    assert!(
        loose <= decoded.face_count() && decoded.face_count() <= tight && loose < tight,
        "{loose} / {} / {tight}",
        decoded.face_count()
    );
    for bad in [
        vec!["--tolerance", "0.1", "--level", "2"],
        vec!["--relative"],
        vec!["--tolerance", "-1"],
        vec!["--tolerance", "0.1", "--no-limit"],
    ] {
        let mut all = vec!["decode"];
        all.extend(bad.iter().copied());
        all.extend([fitted.to_str().unwrap(), out.to_str().unwrap()]);
        let (status, text) = scode_status(&all);
        assert_eq!(status, 1, "{bad:?}: {text}");
    }

    let raw = tmp("boss_raw.scode");
    let (ok, text) = scode(&["encode", "--raw", &example(), "-o", raw.to_str().unwrap()]);
    assert!(ok, "{text}");
    let back = tmp("boss_raw.ply");
    let (ok, text) = scode(&["decode", raw.to_str().unwrap(), back.to_str().unwrap()]);
    assert!(ok, "{text}");
    let (mesh, _) = scode::io::read_mesh(&back).unwrap();
    assert_eq!(mesh.face_count(), 768);
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
    // A missed tolerance writes the file and exits with status 5.
    std::fs::remove_file(out).unwrap();
    let (status, text) = scode_status(&[
        "encode",
        &example(),
        out,
        "--mean-tolerance",
        "1e-9",
        "--relative",
    ]);
    assert_eq!(status, 5, "{text}");
    assert!(mean_line(&text).contains("NOT met: the mean is"), "{text}");
    assert!(text.contains("scode: error: tolerance NOT met"), "{text}");
    assert!(Path::new(out).is_file());
    let (status, text) = scode_status(&[
        "encode",
        "--raw",
        &example(),
        out,
        "--mean-tolerance",
        "0.1",
    ]);
    assert_eq!(status, 1, "{text}");
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

/// A closed cylinder of radius 1 and height 2 tessellated coarsely (eight facets around, a
/// sagitta of 0.076 against a default tolerance of 0.0035), one OBJ group per CAD face.
fn coarse_cylinder_obj() -> String {
    use std::fmt::Write as _;
    let n = 8;
    let mut s = String::new();
    for z in [0.0, 2.0] {
        for i in 0..n {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            writeln!(s, "v {} {} {z}", a.cos(), a.sin()).unwrap();
        }
    }
    writeln!(s, "v 0 0 0\nv 0 0 2").unwrap();
    let (bottom_centre, top_centre) = (2 * n + 1, 2 * n + 2);
    s.push_str("g side\n");
    for i in 0..n {
        let (a, b) = (i + 1, (i + 1) % n + 1);
        writeln!(s, "f {a} {b} {}\nf {a} {} {}", b + n, b + n, a + n).unwrap();
    }
    s.push_str("g bottom\n");
    for i in 0..n {
        writeln!(s, "f {bottom_centre} {} {}", (i + 1) % n + 1, i + 1).unwrap();
    }
    s.push_str("g top\n");
    for i in 0..n {
        writeln!(s, "f {top_centre} {} {}", i + 1 + n, (i + 1) % n + 1 + n).unwrap();
    }
    s
}

/// The tolerance bounds the plain distance to the input mesh: a coarse tessellation of a
/// smooth part is met by storing the faces no smooth patch comes near enough to as their
/// facets (said, and measured by `info --against`); `--chord-allowance` holds it beyond the
/// facets' chord error instead, with smooth patches in fewer bytes; a precision too coarse
/// for the tolerance misses it (status 5, the file written, the message naming the
/// reference and the option).
#[test]
fn the_tolerance_is_held_to_the_input_mesh_unless_the_chord_error_is_allowed() {
    let input = tmp("coarse_cylinder.obj");
    std::fs::write(&input, coarse_cylinder_obj()).unwrap();
    let out = tmp("coarse_cylinder.scode");
    let _ = std::fs::remove_file(&out);
    let (status, text) = scode_status(&["encode", input.to_str().unwrap(), out.to_str().unwrap()]);
    assert_eq!(status, 0, "{text}");
    assert!(
        text.contains("vs the input mesh:")
            && text.contains(" met")
            && text.contains("stored as its input facets")
            && text.contains("--chord-allowance"),
        "{text}"
    );
    let against = |out: &Path| -> f64 {
        let (ok, text) = scode(&[
            "info",
            out.to_str().unwrap(),
            "--against",
            input.to_str().unwrap(),
        ]);
        assert!(ok, "{text}");
        text.split("symmetric: max ")
            .nth(1)
            .and_then(|t| t.split_whitespace().next())
            .and_then(|t| t.trim_end_matches(',').parse().ok())
            .unwrap_or_else(|| panic!("{text}"))
    };
    // The default tolerance, 1e-3 of the diagonal (sqrt(12)).
    let faceted_max = against(&out);
    assert!(
        faceted_max <= 1e-3 * 12f64.sqrt(),
        "info --against measures {faceted_max}"
    );
    let faceted_bytes = std::fs::metadata(&out).unwrap().len();
    let (status, text) = scode_status(&[
        "encode",
        "--chord-allowance",
        input.to_str().unwrap(),
        out.to_str().unwrap(),
    ]);
    assert_eq!(status, 0, "{text}");
    assert!(
        text.contains("vs the input mesh beyond its facets' chord error:")
            && text.contains(" met")
            && !text.contains("input facets"),
        "{text}"
    );
    let smooth_bytes = std::fs::metadata(&out).unwrap().len();
    assert!(
        smooth_bytes < faceted_bytes,
        "{smooth_bytes} vs {faceted_bytes} bytes"
    );
    std::fs::remove_file(&out).unwrap();
    let (status, text) = scode_status(&[
        "encode",
        "--bits",
        "4",
        input.to_str().unwrap(),
        out.to_str().unwrap(),
    ]);
    assert_eq!(status, 5, "{text}");
    assert!(
        text.contains("NOT met") && text.contains("--chord-allowance") && out.exists(),
        "{text}"
    );
    let (status, text) = scode_status(&[
        "encode",
        "--raw",
        "--chord-allowance",
        input.to_str().unwrap(),
        out.to_str().unwrap(),
    ]);
    assert_eq!(status, 1, "{text}");
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
    let file = repo().join("spec/vectors/cad_part.scode");
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

/// `scode --help` lists the exit statuses, and each kind of failure exits with its own.
#[test]
fn exit_statuses_are_listed_and_used() {
    let (status, text) = scode_status(&["--help"]);
    assert_eq!(status, 0, "{text}");
    for line in [
        "Exit status:",
        "1  usage",
        "2  input or I/O",
        "5  encode: tolerance",
    ] {
        assert!(text.contains(line), "{line}: {text}");
    }
    let (status, text) = scode_status(&["encode", "--no-such-option", &example()]);
    assert_eq!(status, 1, "{text}");
    let (status, text) = scode_status(&["decode", "/nonexistent/x.scode", "out.obj"]);
    assert_eq!(status, 2, "{text}");
    let garbage = tmp("status-garbage.scode");
    std::fs::write(&garbage, b"not an scode file at all").unwrap();
    let (status, text) = scode_status(&["decode", garbage.to_str().unwrap(), "out.obj"]);
    assert_eq!(status, 3, "{text}");
    let (status, text) = scode_status(&[
        "decode",
        "--max-bytes",
        "4",
        garbage.to_str().unwrap(),
        "out.obj",
    ]);
    assert_eq!(status, 4, "{text}");
}

/// A dense sphere (a UV grid of `n x n` quads, poles fanned), as OBJ text: a fitted encode of
/// it takes far longer than a fraction of a second.
fn dense_sphere_obj(n: u32) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    writeln!(s, "v 0 0 1").unwrap();
    for i in 1..n {
        let th = std::f64::consts::PI * f64::from(i) / f64::from(n);
        for j in 0..n {
            let ph = 2.0 * std::f64::consts::PI * f64::from(j) / f64::from(n);
            writeln!(
                s,
                "v {} {} {}",
                th.sin() * ph.cos(),
                th.sin() * ph.sin(),
                th.cos()
            )
            .unwrap();
        }
    }
    writeln!(s, "v 0 0 -1").unwrap();
    let ring = |i: u32, j: u32| 2 + (i - 1) * n + j % n;
    let south = 2 + (n - 1) * n;
    for j in 0..n {
        writeln!(s, "f 1 {} {}", ring(1, j), ring(1, j + 1)).unwrap();
        writeln!(s, "f {south} {} {}", ring(n - 1, j + 1), ring(n - 1, j)).unwrap();
    }
    for i in 1..n - 1 {
        for j in 0..n {
            let (a, b) = (ring(i, j), ring(i, j + 1));
            let (c, d) = (ring(i + 1, j + 1), ring(i + 1, j));
            writeln!(s, "f {a} {d} {c} {b}").unwrap();
        }
    }
    s
}

/// An encode of a 180k-triangle sphere with `budget` (an option and its value) over it ends
/// with status 4 and a message holding `says` and "not written", writes nothing and leaves
/// the input as it was; with `roomy` it finishes; each of `bad` is a usage error.
fn check_encode_budget(budget: &str, tight: &str, says: &str, roomy: &str, bad: &[&str]) {
    let input = tmp(&format!("dense_sphere{budget}.obj"));
    std::fs::write(&input, dense_sphere_obj(300)).unwrap();
    let before = std::fs::read(&input).unwrap();
    let out = tmp(&format!("dense_sphere{budget}.scode"));
    let _ = std::fs::remove_file(&out);
    let (input, out_path) = (input.to_str().unwrap(), out.to_str().unwrap());
    let (status, text) = scode_status(&["encode", budget, tight, input, out_path]);
    assert_eq!(status, 4, "{text}");
    assert!(
        text.contains(says) && text.contains("not written"),
        "{text}"
    );
    assert!(!out.exists(), "an encode over its budget wrote {out_path}");
    assert_eq!(std::fs::read(input).unwrap(), before);
    let (status, text) = scode_status(&["encode", "--raw", budget, roomy, input, out_path]);
    assert_eq!(status, 0, "{text}");
    assert!(out.exists());
    for value in bad {
        let (status, text) = scode_status(&["encode", budget, value, input, out_path]);
        assert_eq!(status, 1, "{value}: {text}");
    }
}

/// `encode --max-seconds`: the whole encode's time.
#[test]
fn max_seconds_bounds_the_whole_encode() {
    check_encode_budget(
        "--max-seconds",
        "0.3",
        "did not finish within 0.3 s (--max-seconds)",
        "600",
        &["0", "-1", "nan", "inf", "soon"],
    );
}

/// `encode --max-memory`: the whole encode's resident memory (a 180k-triangle fit holds far
/// more than 16 MiB).
#[test]
fn max_memory_bounds_the_whole_encode() {
    check_encode_budget(
        "--max-memory",
        "16M",
        "needed more than 16 MiB of memory (--max-memory 16777216",
        "8G",
        &["0", "-1", "2T", "lots", "1.5G"],
    );
}

/// An OS error is printed once, after the path it is about.
#[test]
fn os_errors_are_printed_once() {
    let (status, text) = scode_status(&["encode", "/nonexistent/in.obj", "out.scode"]);
    assert_eq!(status, 2, "{text}");
    let os = std::fs::read("/nonexistent/in.obj")
        .unwrap_err()
        .to_string();
    assert_eq!(text.matches(&os).count(), 1, "{text}");
    assert!(text.contains("/nonexistent/in.obj"), "{text}");
}

/// `scode encode x.obj x.obj` (and through another path, a symbolic or a hard link) is
/// refused before anything is read or written, and the input stays as it was; an output
/// whose extension names another format than the bytes written is refused too.
#[test]
fn the_output_may_not_be_the_input_or_another_format() {
    let input = tmp("self.obj");
    std::fs::copy(example(), &input).unwrap();
    let before = std::fs::read(&input).unwrap();
    let dotted = input
        .parent()
        .unwrap()
        .join("../")
        .join(input.parent().unwrap().file_name().unwrap())
        .join("self.obj");
    let mut aliases = vec![input.clone(), dotted];
    #[cfg(unix)]
    {
        let link = tmp("self-link.scode");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&input, &link).unwrap();
        let hard = tmp("self-hard.scode");
        let _ = std::fs::remove_file(&hard);
        std::fs::hard_link(&input, &hard).unwrap();
        aliases.extend([link, hard]);
    }
    for out in &aliases {
        for raw in [false, true] {
            let mut args = vec!["encode", input.to_str().unwrap(), out.to_str().unwrap()];
            if raw {
                args.insert(1, "--raw");
            }
            let (status, text) = scode_status(&args);
            assert_eq!(status, 1, "{out:?}: {text}");
            assert!(text.contains("is the input file"), "{text}");
        }
    }
    let (status, text) = scode_status(&[
        "segment",
        input.to_str().unwrap(),
        "-o",
        input.to_str().unwrap(),
    ]);
    assert_eq!(status, 1, "{text}");
    assert_eq!(
        std::fs::read(&input).unwrap(),
        before,
        "the input was changed"
    );

    // .scode bytes under a mesh extension, a mesh under .scode.
    let wrong = tmp("encoded.obj");
    let (status, text) = scode_status(&[
        "encode",
        "--raw",
        input.to_str().unwrap(),
        "-o",
        wrong.to_str().unwrap(),
    ]);
    assert_eq!(status, 1, "{text}");
    assert!(text.contains("must end in .scode"), "{text}");
    assert!(!wrong.exists());
    let encoded = tmp("encoded.scode");
    let (ok, text) = scode(&[
        "encode",
        "--raw",
        input.to_str().unwrap(),
        encoded.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    let mesh_as_scode = tmp("decoded.scode");
    let (status, text) = scode_status(&[
        "decode",
        encoded.to_str().unwrap(),
        mesh_as_scode.to_str().unwrap(),
    ]);
    assert_eq!(status, 1, "{text}");
    assert!(text.contains("writes a mesh"), "{text}");
    assert!(!mesh_as_scode.exists());
    let (status, text) = scode_status(&[
        "decode",
        encoded.to_str().unwrap(),
        encoded.to_str().unwrap(),
    ]);
    assert_eq!(status, 1, "{text}");
}

/// A STEP file with a face the reader cannot read is not encoded (status 6, nothing
/// written) unless `--allow-skipped` lets the rest be encoded.
#[test]
fn skipped_step_faces_need_allow_skipped() {
    let step = repo().join("tests/data/cube_offset_face.step");
    let step = step.to_str().unwrap();
    for raw in [false, true] {
        let out = tmp(&format!("cube-raw-{raw}.scode"));
        let _ = std::fs::remove_file(&out);
        let mut args = vec!["encode", step, out.to_str().unwrap()];
        if raw {
            args.push("--raw");
        }
        let (status, text) = scode_status(&args);
        assert_eq!(status, 6, "{text}");
        assert!(
            text.contains("OFFSET_SURFACE") && text.contains("--allow-skipped"),
            "{text}"
        );
        assert!(!out.exists(), "{text}");
        args.push("--allow-skipped");
        let (status, text) = scode_status(&args);
        assert_eq!(status, 0, "{text}");
        assert!(text.contains("1 faces skipped"), "{text}");
        assert!(out.is_file());
    }
}

/// A STEP file with 50 000 nested parentheses is an input error (status 2) naming the
/// line, not a stack overflow that aborts the process.
#[test]
fn deeply_nested_step_is_an_input_error() {
    let text = std::fs::read_to_string(repo().join("tests/data/cube_offset_face.step")).unwrap();
    let deep = text.replace(
        "#1 = CARTESIAN_POINT('',(0.0,0.0,0.0));",
        &format!(
            "#1 = CARTESIAN_POINT('',{}0.0{});",
            "(".repeat(50_000),
            ")".repeat(50_000)
        ),
    );
    let input = tmp("deep.step");
    std::fs::write(&input, deep).unwrap();
    for args in [
        vec!["info", input.to_str().unwrap()],
        vec!["encode", input.to_str().unwrap(), "deep.scode"],
    ] {
        let (status, text) = scode_status(&args);
        assert_eq!(status, 2, "{text}");
        assert!(
            text.contains("#1 = CARTESIAN_POINT: parentheses nested deeper"),
            "{text}"
        );
    }
}

/// Coordinates near f64::MAX are refused when the file is read (status 2, the file and the
/// vertices' lines named), by the fitted and the raw path alike, instead of encoding a file
/// the decoder refuses or an infinite tolerance.
#[test]
fn coordinates_whose_box_overflows_are_an_input_error() {
    let input = tmp("huge.obj");
    std::fs::write(&input, "v 0 0 0\nv 1.7e308 0 0\nv -1.7e308 1 0\nf 1 2 3\n").unwrap();
    for raw in [false, true] {
        let out = tmp(&format!("huge-{raw}.scode"));
        let mut args = vec!["encode", input.to_str().unwrap(), out.to_str().unwrap()];
        if raw {
            args.push("--raw");
        }
        let (status, text) = scode_status(&args);
        assert_eq!(status, 2, "{text}");
        assert!(
            text.contains("huge.obj: coordinates too large") && text.contains("(line 3)"),
            "{text}"
        );
        assert!(!out.exists());
    }
}

/// A `.gltf` whose buffer names a file outside its folder is refused (status 2, the URI
/// named), and nothing of that file reaches an output.
#[test]
fn gltf_buffers_outside_the_folder_are_refused() {
    let dir = tmp("gltf-upload");
    std::fs::create_dir_all(&dir).unwrap();
    for uri in [
        "/etc/passwd",
        "../../../../../../etc/passwd",
        "%2E%2E/secret.bin",
    ] {
        let gltf = dir.join("evil.gltf");
        std::fs::write(
            &gltf,
            format!(
                r#"{{"asset":{{"version":"2.0"}},
                "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
                "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
                    "min":[0,0,0],"max":[1,1,1]}}],
                "bufferViews":[{{"buffer":0,"byteLength":36}}],
                "buffers":[{{"uri":"{uri}","byteLength":36}}]}}"#
            ),
        )
        .unwrap();
        let out = tmp("evil.scode");
        let _ = std::fs::remove_file(&out);
        for args in [
            vec!["info", gltf.to_str().unwrap()],
            vec![
                "encode",
                "--raw",
                gltf.to_str().unwrap(),
                out.to_str().unwrap(),
            ],
        ] {
            let (status, text) = scode_status(&args);
            assert_eq!(status, 2, "{text}");
            assert!(
                text.contains(&format!("buffer URI `{uri}` refused")),
                "{text}"
            );
            assert!(!out.exists());
        }
    }
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
    // Level 13 of one triangle is 67 M triangles: more than the command line's 1 GiB budget,
    // refused before subdividing; any level asked for is checked the same way, and so is a
    // decode to a tolerance (by default, and charged for the finest level it may show).
    let file = triangle_at_level(13);
    let out = tmp("level13.obj");
    let (ok, text) = scode(&[
        "decode",
        "--level",
        "13",
        file.to_str().unwrap(),
        out.to_str().unwrap(),
    ]);
    assert!(!ok, "{text}");
    assert!(
        text.contains("limit exceeded: decode memory with subdivision"),
        "{text}"
    );
    assert!(text.contains("--max-memory raises it"), "{text}");
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
    let part = repo().join("spec/vectors/cad_part.scode");
    let part = part.to_str().unwrap();
    let (ok, text) = scode(&["info", "--max-work-per-element", "0", part]);
    assert!(!ok, "{text}");
    assert!(text.contains("limit exceeded: decode work"), "{text}");
    let (ok, text) = scode(&["info", part]);
    assert!(ok, "{text}");
}
