//! Segments corpus meshes (`scode::fit::segment`) and prints what it finds: the regions with
//! their surface kinds, sizes and fit residuals and, on face-grouped meshes, how the regions
//! match the true CAD faces (purity: triangles in the majority true face of their region;
//! completeness: triangles in the majority region of their true face).
//!
//! Run: `cargo run --release --example segment_corpus [-- [--grouped] [--normal-angle DEG]
//! [MESH...]]`, MESH relative to the corpus (`SCODE_CORPUS` overrides its folder). Without
//! meshes: four_cone, fandisk, block and rocker-arm; `--grouped` takes every face-grouped
//! tessellation (`tess/*_coarse.obj`, `tess/*_cadexport.obj`) and two ABC models instead and
//! prints one line per mesh.

use std::collections::BTreeMap;
use std::time::Instant;

use scode::fit::segment::{segment, SegmentOptions, SegmentReport};

#[path = "../tests/common/mod.rs"]
mod common;

fn main() {
    let corpus = common::corpus_dir().expect("the corpus (set SCODE_CORPUS)");
    let mut grouped = false;
    let mut opts = SegmentOptions::default();
    let mut names: Vec<String> = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--grouped" => grouped = true,
            "--normal-angle" => {
                opts.normal_angle_deg = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .expect("--normal-angle DEG");
            }
            _ => names.push(a),
        }
    }
    if names.is_empty() && grouped {
        names = std::fs::read_dir(corpus.join("tess"))
            .expect("<corpus>/tess")
            .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().to_string()))
            .filter(|n| n.ends_with("_coarse.obj") || n.ends_with("_cadexport.obj"))
            .map(|n| format!("tess/{n}"))
            .collect();
        names.sort();
        names.push("abc/abc_00000006.obj".into());
        names.push("abc/abc_00007974_5.obj".into());
    } else if names.is_empty() {
        names = [
            "tess/four_cone_coarse.obj",
            "meshes/fandisk.obj",
            "meshes/block.off",
            "meshes/rocker-arm.obj",
        ]
        .map(String::from)
        .to_vec();
    }
    for name in names {
        let (m, _) =
            scode::io::read_mesh(&corpus.join(&name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        let t = Instant::now();
        let (out, rep) = segment(&m, &opts).unwrap_or_else(|e| panic!("{name}: {e}"));
        let dt = t.elapsed();
        if grouped {
            let (purity, completeness) = agreement(&m.face_groups, &out.face_groups);
            println!(
                "{name}: true {} faces, {} smooth comps -> {}; purity {purity:.3}, completeness \
                 {completeness:.3} ({dt:?})",
                m.groups.len(),
                rep.smooth_components,
                rep.summary(),
            );
            continue;
        }
        println!(
            "{name} ({dt:?}) tol {:.3e}: {}",
            rep.tolerance,
            describe(&rep)
        );
        if m.groups.len() > 1 {
            for g in 0..out.groups.len() {
                let mut h = BTreeMap::new();
                for f in 0..m.face_count() {
                    if out.face_groups[f] == g as u32 {
                        *h.entry(m.groups[m.face_groups[f] as usize].name.clone())
                            .or_insert(0) += 1;
                    }
                }
                println!("  region {g}: {h:?}");
            }
        }
    }
}

/// The summary line and one line per region.
fn describe(report: &SegmentReport) -> String {
    let mut s = report.summary();
    for (i, r) in report.regions.iter().enumerate() {
        s += &format!(
            "\n  face_{i}: {:?} {} tris, max res {:.2e}",
            r.kind,
            r.triangles,
            r.residuals.map(|r| r.max).unwrap_or(f64::NAN)
        );
    }
    s
}

/// Purity and completeness of the regions (`found`, per triangle) against the true faces.
fn agreement(truth: &[u32], found: &[u32]) -> (f64, f64) {
    let mut joint: BTreeMap<(u32, u32), usize> = BTreeMap::new();
    for (&r, &t) in found.iter().zip(truth) {
        *joint.entry((r, t)).or_insert(0) += 1;
    }
    let mut best_r: BTreeMap<u32, usize> = BTreeMap::new();
    let mut best_t: BTreeMap<u32, usize> = BTreeMap::new();
    for (&(r, t), &c) in &joint {
        let e = best_r.entry(r).or_insert(0);
        *e = (*e).max(c);
        let e = best_t.entry(t).or_insert(0);
        *e = (*e).max(c);
    }
    let n = truth.len().max(1) as f64;
    (
        best_r.values().sum::<usize>() as f64 / n,
        best_t.values().sum::<usize>() as f64 / n,
    )
}
