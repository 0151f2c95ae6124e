//! Test-only helpers: the corpus location and a minimal OBJ/OFF reader (v, f, g lines; OFF
//! header). `crate::io` replaces it at merge time.

use std::path::PathBuf;

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
