//! Round-trips every corpus triangle mesh (OBJ and OFF) through the codec in raw mode and
//! prints sizes. Run with `--nocapture` to see the table (bytes per section, bits per vertex).
//!
//! The OBJ/OFF readers here are deliberately minimal (v / f / g only) and local to this test:
//! the real readers live in `scode::io`.

mod common;
use common::corpus_dir;
use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use scode::codec::{decode, encode_with_map, inspect, EncodeOptions, Limits};
use scode::mesh::{edge_key, BoundarySurface, ControlMesh, PatchKind};

/// Marks groups whose CAD surface is a plane (crude scan of the `.faces.json` sidecar:
/// `"tag": N` followed by `"type": "Plane"`), sharp edges between groups, and corners where
/// three or more groups meet, so the tessellations exercise the CAD paths of the codec.
fn add_cad_attributes(m: &mut ControlMesh, json: Option<String>) {
    if let Some(j) = json {
        let mut planes = BTreeSet::new();
        let mut rest = j.as_str();
        while let Some(p) = rest.find("\"tag\":") {
            rest = &rest[p + 6..];
            let tag: String = rest
                .trim_start()
                .chars()
                .take_while(|c| c.is_ascii_digit())
                .collect();
            if let Some(t) = rest.find("\"type\":") {
                let ty = rest[t + 7..].trim_start();
                if ty.starts_with("\"Plane\"") {
                    planes.insert(format!("face_{tag}"));
                }
            }
        }
        for g in &mut m.groups {
            if planes.contains(&g.name) {
                g.patch = PatchKind::Boundary(BoundarySurface::Plane);
            }
        }
    }
    let mut edge_groups: BTreeMap<(u32, u32), Vec<u32>> = BTreeMap::new();
    let mut vertex_groups: Vec<BTreeSet<u32>> = vec![BTreeSet::new(); m.vertex_count()];
    for f in 0..m.face_count() {
        let face = m.face(f).to_vec();
        let g = m.face_groups[f];
        for i in 0..face.len() {
            edge_groups
                .entry(edge_key(face[i], face[(i + 1) % face.len()]))
                .or_default()
                .push(g);
            vertex_groups[face[i] as usize].insert(g);
        }
    }
    for (e, gs) in edge_groups {
        if gs.len() == 2 && gs[0] != gs[1] {
            m.sharp_edges.insert(e);
        }
    }
    for (v, gs) in vertex_groups.iter().enumerate() {
        if gs.len() >= 3 {
            m.corners.insert(v as u32);
        }
    }
}

fn cyclic_eq(a: &[u32], b: &[u32]) -> bool {
    a.len() == b.len() && (0..a.len()).any(|r| (0..a.len()).all(|i| a[(i + r) % a.len()] == b[i]))
}

fn round_trip(name: &str, m: &ControlMesh) -> usize {
    let opts = EncodeOptions::default();
    let t0 = std::time::Instant::now();
    let (bytes, map) = encode_with_map(m, &opts).unwrap_or_else(|e| panic!("{name}: {e}"));
    let t1 = std::time::Instant::now();
    let d = decode(&bytes, &Limits::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
    let t2 = std::time::Instant::now();
    let out = &d.mesh;
    assert_eq!(out.face_count(), m.face_count(), "{name}");
    assert_eq!(out.vertex_count(), m.vertex_count(), "{name}");
    for f in 0..m.face_count() {
        let expected: Vec<u32> = m.face(f).iter().map(|&v| map.vertex[v as usize]).collect();
        assert!(
            cyclic_eq(&expected, out.face(map.face[f] as usize)),
            "{name}: face {f}"
        );
        assert_eq!(
            out.face_groups[map.face[f] as usize],
            map.group[m.face_groups[f] as usize]
        );
    }
    for (g, grp) in m.groups.iter().enumerate() {
        assert_eq!(out.groups[map.group[g] as usize], *grp, "{name}: group {g}");
    }
    let sharp: BTreeSet<_> = m
        .sharp_edges
        .iter()
        .map(|&(a, b)| edge_key(map.vertex[a as usize], map.vertex[b as usize]))
        .collect();
    assert_eq!(sharp, out.sharp_edges, "{name}");
    let corners: BTreeSet<_> = m.corners.iter().map(|&c| map.vertex[c as usize]).collect();
    assert_eq!(corners, out.corners, "{name}");
    let step = d.header.quantization_step();
    for (v, p) in m.positions.iter().enumerate() {
        let e = (out.positions[map.vertex[v] as usize] - *p)
            .abs()
            .max_element();
        assert!(
            e <= step / 2.0 * (1.0 + 1e-9) + 1e-12,
            "{name}: vertex {v} off by {e}"
        );
    }
    let info = inspect(&bytes, &Limits::default()).unwrap();
    let secs: Vec<String> = info
        .sections
        .iter()
        .map(|s| format!("{}={}", s.name, s.stored_bytes))
        .collect();
    println!(
        "{name:<34} V={:>6} F={:>6} G={:>4} sharp={:>5} merged={:>3}: {:>7} B = {:>6.2} bpv  [{}]  enc {:.1} ms dec {:.1} ms",
        m.vertex_count(),
        m.face_count(),
        m.groups.len(),
        m.sharp_edges.len(),
        info.header.merged_vertex_count,
        bytes.len(),
        bytes.len() as f64 * 8.0 / m.vertex_count() as f64,
        secs.join(" "),
        (t1 - t0).as_secs_f64() * 1e3,
        (t2 - t1).as_secs_f64() * 1e3,
    );
    bytes.len()
}

#[test]
fn corpus_meshes_round_trip() {
    let Some(dir) = corpus_dir() else { return };
    let mut files: Vec<PathBuf> = Vec::new();
    for sub in ["meshes", "tess"] {
        let rd = std::fs::read_dir(dir.join(sub))
            .unwrap_or_else(|e| panic!("{}: {e}", dir.join(sub).display()));
        for e in rd.flatten() {
            let p = e.path();
            let n = p.file_name().unwrap().to_string_lossy().to_string();
            let wanted = (sub == "meshes" && (n.ends_with(".obj") || n.ends_with(".off")))
                || (sub == "tess" && n.ends_with("_coarse.obj"));
            if wanted {
                files.push(p);
            }
        }
    }
    files.sort();
    // CORPUS_FILTER=substring limits the run (for quick measurements).
    if let Ok(f) = std::env::var("CORPUS_FILTER") {
        files.retain(|p| p.to_string_lossy().contains(&f));
    }
    assert!(!files.is_empty(), "no corpus mesh in {}", dir.display());

    for p in files {
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let (mut m, _) = scode::io::read_mesh(&p).unwrap();
        m.validate().unwrap();
        if std::env::var("STRIP_GROUPS").is_ok() {
            m.groups.truncate(1);
            m.face_groups.iter_mut().for_each(|g| *g = 0);
        }
        let plain = round_trip(&name, &m);
        if name == "fandisk.obj" {
            // Issue target: at most 1.3x Draco 1.5 `-qp 10 -cl 10` (7,103 bytes).
            assert!(plain <= 9234, "fandisk takes {plain} bytes");
        }
        if name.ends_with("_coarse.obj") {
            let sidecar = p.with_file_name(name.replace("_coarse.obj", ".faces.json"));
            add_cad_attributes(&mut m, std::fs::read_to_string(sidecar).ok());
            round_trip(&format!("{name} +cad"), &m);
        }
    }
}
