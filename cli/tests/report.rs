//! `scode report` end to end on two small corpus models, quick mode, without the baselines
//! (a `--draco-dir` and a `--gltfpack-dir` that hold neither take the "missing baseline"
//! paths, so the test does not depend on them being installed).

#[path = "../../tests/common/mod.rs"]
mod common;

use std::path::PathBuf;
use std::process::Command;

#[test]
fn report_runs_without_draco_and_writes_tables_and_plots() {
    let Some(corpus) = common::corpus_dir() else {
        return;
    };
    let out = std::env::temp_dir().join(format!("scode-report-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let no_draco = out.join("no-draco-here");
    std::fs::create_dir_all(&no_draco).unwrap();
    let models: Vec<PathBuf> = ["tess/screw_coarse.obj", "tess/four_cone_coarse.obj"]
        .iter()
        .map(|m| corpus.join(m))
        .collect();
    let run = Command::new(env!("CARGO_BIN_EXE_scode"))
        .arg("report")
        .args(&models)
        // A STEP file: measured against its B-rep.
        .arg(corpus.join("step/screw.step"))
        .args(["--quick", "--jobs", "2", "--draco-dir"])
        .arg(&no_draco)
        .arg("--gltfpack-dir")
        .arg(&no_draco)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&run.stdout).to_string() + &String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{text}");
    assert!(text.contains("Draco not found"), "{text}");
    assert!(text.contains("gltfpack not found"), "{text}");

    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let first_table = md.lines().find(|l| l.starts_with('|')).unwrap();
    assert!(first_table.contains("scode setting"), "{first_table}");
    assert!(md.contains("Draco not found"), "{md}");
    assert!(md.contains("gltfpack not found"), "{md}");
    assert!(
        md.contains(
            "Errors are measured against the B-rep: 10 of 10 faces measured to their exact surface"
        ),
        "{md}"
    );
    assert!(md.contains("exact surface"), "{md}");
    assert!(
        md.contains("![tess_screw_coarse_obj") || md.contains("plots/"),
        "{md}"
    );

    // The CSV: one row per measured point, numbers parse, errors are sane fractions.
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header.join(","), scode_cli::report::CSV_HEADER);
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let measured: Vec<&Vec<&str>> = rows
        .iter()
        .filter(|r| !r[col("bytes")].is_empty())
        .collect();
    // Two meshes x (raw 10 bit + one tolerance), and the STEP part at that tolerance.
    assert_eq!(measured.len(), 5, "{csv}");
    for r in &measured {
        let bytes: u64 = r[col("bytes")].parse().unwrap();
        let bpv: f64 = r[col("bits_per_vertex")].parse().unwrap();
        let ratio: f64 = r[col("ratio_to_raw")].parse().unwrap();
        let max: f64 = r[col("max_error")].parse().unwrap();
        let rms: f64 = r[col("rms_error")].parse().unwrap();
        let enc: f64 = r[col("encode_ms")].parse().unwrap();
        let dec: f64 = r[col("decode_ms")].parse().unwrap();
        assert!(bytes > 0 && bpv > 0.0 && ratio > 1.0, "{r:?}");
        assert!(max > 0.0 && max < 0.05 && rms > 0.0 && rms <= max, "{r:?}");
        assert!(enc > 0.0 && dec > 0.0, "{r:?}");
        // No baseline: no equal-error pairing.
        assert_eq!(r[col("best_over_scode")], "");
        assert_eq!(r[col("draco_over_scode")], "");
        assert_eq!(r[col("gltfpack_over_scode")], "");
    }
    // Raw 10 bit: the quantisation error bound sqrt(3)/2 / 1023 of the largest extent.
    for r in measured.iter().filter(|r| r[col("setting")] == "10 bit") {
        let max: f64 = r[col("max_error")].parse().unwrap();
        assert!(max < 1e-3, "{r:?}");
    }
    let step_rows: Vec<&Vec<&str>> = rows.iter().filter(|r| r[0] == "screw.step").collect();
    assert_eq!(step_rows.len(), 1, "{csv}");
    assert_eq!(step_rows[0][col("setting")], "tol 2e-3", "{csv}");
    // The fit holds its tolerance against the exact surfaces, which the B-rep ruler
    // measures (sampling sees slightly less than the fit's own bound).
    let step_max: f64 = step_rows[0][col("max_error")].parse().unwrap();
    assert!(step_max > 1e-4 && step_max <= 2e-3, "{csv}");

    // A rerun with --resume keeps the models already written (their timings are the first
    // run's) and measures the one whose file is gone.
    let first_rows = |csv: &str, model: &str| -> Vec<String> {
        csv.lines()
            .filter(|l| l.starts_with(model))
            .map(str::to_string)
            .collect()
    };
    std::fs::remove_file(out.join("models/four_cone_coarse_obj.json")).unwrap();
    let rerun = Command::new(env!("CARGO_BIN_EXE_scode"))
        .arg("report")
        .args(&models)
        .arg(corpus.join("step/screw.step"))
        .args(["--quick", "--resume", "--draco-dir"])
        .arg(&no_draco)
        .arg("--gltfpack-dir")
        .arg(&no_draco)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(rerun.status.success(), "{rerun:?}");
    let csv2 = std::fs::read_to_string(out.join("results.csv")).unwrap();
    for kept in ["screw_coarse.obj", "screw.step"] {
        assert_eq!(first_rows(&csv, kept), first_rows(&csv2, kept), "{csv2}");
    }
    assert_eq!(first_rows(&csv2, "four_cone_coarse.obj").len(), 2, "{csv2}");
    assert!(out.join("models/four_cone_coarse_obj.json").is_file());

    for plot in ["corpus", "screw_coarse_obj", "four_cone_coarse_obj"] {
        for ext in ["png", "svg"] {
            let p = out.join("plots").join(format!("{plot}.{ext}"));
            let meta = std::fs::metadata(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            assert!(meta.len() > 1000, "{}", p.display());
        }
    }
    let _ = std::fs::remove_dir_all(&out);
}
