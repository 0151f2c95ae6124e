//! Test-only helpers: the corpus location and a minimal OBJ/OFF reader (v, f, g lines; OFF
//! header). `crate::io` replaces it at merge time.

use std::path::PathBuf;

use std::collections::BTreeMap;

use glam::DVec3;

use crate::mesh::{ControlMesh, PatchKind};

/// `../shared/corpus` next to the repository, or `/work/shared/corpus`; `None` if absent.
pub(crate) fn corpus_dir() -> Option<PathBuf> {
    let local = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus");
    [local, PathBuf::from("/work/shared/corpus")]
        .into_iter()
        .find(|p| p.join("MANIFEST.md").exists())
}

/// Reads an OBJ (v / f / g) or OFF file from the corpus; `None` (with a message) when the
/// corpus is missing.
pub(crate) fn load_corpus(rel: &str) -> Option<ControlMesh> {
    let Some(dir) = corpus_dir() else {
        eprintln!("corpus not found; skipping {rel}");
        return None;
    };
    let text = std::fs::read_to_string(dir.join(rel)).expect("read corpus file");
    Some(if rel.ends_with(".off") {
        parse_off(&text)
    } else {
        parse_obj(&text)
    })
}

pub(crate) fn parse_obj(text: &str) -> ControlMesh {
    let mut m = ControlMesh::new();
    let mut group: Option<u32> = None;
    let mut names: Vec<String> = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it.take(3).map(|s| s.parse().expect("coordinate")).collect();
                m.push_vertex(DVec3::new(c[0], c[1], c[2]));
            }
            Some("g") => {
                let name = it.collect::<Vec<_>>().join(" ");
                let idx = match names.iter().position(|n| *n == name) {
                    Some(i) => i as u32,
                    None => {
                        names.push(name.clone());
                        m.push_group(name, PatchKind::Closed)
                    }
                };
                group = Some(idx);
            }
            Some("f") => {
                let nv = m.positions.len() as i64;
                let vs: Vec<u32> = it
                    .map(|t| {
                        let i: i64 = t.split('/').next().unwrap().parse().expect("index");
                        (if i < 0 { nv + i } else { i - 1 }) as u32
                    })
                    .collect();
                let g = *group.get_or_insert_with(|| {
                    names.push("default".into());
                    m.push_group("default", PatchKind::Closed)
                });
                m.push_face(&vs, g);
            }
            _ => {}
        }
    }
    m
}

pub(crate) fn parse_off(text: &str) -> ControlMesh {
    let mut tokens = text
        .lines()
        .map(|l| l.split('#').next().unwrap())
        .flat_map(|l| l.split_whitespace());
    assert_eq!(tokens.next(), Some("OFF"));
    let mut num = || {
        tokens
            .next()
            .expect("token")
            .parse::<f64>()
            .expect("number")
    };
    let (nv, nf, _) = (num() as usize, num() as usize, num());
    let mut m = ControlMesh::new();
    let g = m.push_group("default", PatchKind::Closed);
    for _ in 0..nv {
        let (x, y, z) = (num(), num(), num());
        m.push_vertex(DVec3::new(x, y, z));
    }
    for _ in 0..nf {
        let k = num() as usize;
        let vs: Vec<u32> = (0..k).map(|_| num() as u32).collect();
        m.push_face(&vs, g);
    }
    m
}

/// Axis-aligned cube [0,1]^3, each side an n x n grid of quads split into triangles,
/// one group per side, outward orientation.
pub(crate) fn grid_cube(n: usize) -> ControlMesh {
    let mut m = ControlMesh::new();
    let mut index: BTreeMap<(i64, i64, i64), u32> = BTreeMap::new();
    let mut vid = |m: &mut ControlMesh, p: DVec3| {
        let key = (
            (p.x * 1e6).round() as i64,
            (p.y * 1e6).round() as i64,
            (p.z * 1e6).round() as i64,
        );
        *index.entry(key).or_insert_with(|| m.push_vertex(p))
    };
    // (origin, u, v) with u x v pointing outward.
    let sides = [
        (DVec3::ZERO, DVec3::Y, DVec3::X), // z = 0, normal -z
        (DVec3::Z, DVec3::X, DVec3::Y),    // z = 1
        (DVec3::ZERO, DVec3::X, DVec3::Z), // y = 0, normal -y
        (DVec3::Y, DVec3::Z, DVec3::X),    // y = 1
        (DVec3::ZERO, DVec3::Z, DVec3::Y), // x = 0
        (DVec3::X, DVec3::Y, DVec3::Z),    // x = 1
    ];
    for (s, (o, u, v)) in sides.iter().enumerate() {
        let g = m.push_group(format!("face_{s}"), PatchKind::Closed);
        for i in 0..n {
            for j in 0..n {
                let p = |a: usize, b: usize| {
                    *o + *u * (a as f64 / n as f64) + *v * (b as f64 / n as f64)
                };
                let a = vid(&mut m, p(i, j));
                let b = vid(&mut m, p(i + 1, j));
                let c = vid(&mut m, p(i + 1, j + 1));
                let d = vid(&mut m, p(i, j + 1));
                m.push_face(&[a, b, c], g);
                m.push_face(&[a, c, d], g);
            }
        }
    }
    m
}
