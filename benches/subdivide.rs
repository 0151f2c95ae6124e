//! Subdivision throughput: output triangles per second at levels 1-5 on corpus models, on
//! one core and on all cores (rayon pools), for (a) position evaluation on a prebuilt
//! topology (the encoder / viewer hot path) and (b) topology + positions from scratch.
//!
//! Run: `cargo bench --bench subdivide` (set SCODE_CORPUS to override the corpus folder).

use std::collections::BTreeMap;
use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::DVec3;
use scode::mesh::{edge_key, ControlMesh, PatchKind};
use scode::subdiv::Refinement;

fn corpus_dir() -> Option<PathBuf> {
    if let Ok(p) = std::env::var("SCODE_CORPUS") {
        return Some(PathBuf::from(p));
    }
    let local = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus");
    if local.is_dir() {
        return Some(local);
    }
    let abs = PathBuf::from("/work/shared/corpus");
    abs.is_dir().then_some(abs)
}

/// Minimal OBJ reader (v / f / g); edges between groups become sharp. Copy of the test
/// helper, to be replaced by `scode::io` at merge.
fn parse_obj(text: &str) -> ControlMesh {
    let mut m = ControlMesh::new();
    let mut group_ids: BTreeMap<String, u32> = BTreeMap::new();
    let mut current = None;
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it.take(3).map(|s| s.parse().unwrap()).collect();
                m.push_vertex(DVec3::new(c[0], c[1], c[2]));
            }
            Some("g") => {
                let name = it.next().unwrap_or("").to_string();
                let next = group_ids.len() as u32;
                let id = *group_ids.entry(name.clone()).or_insert(next);
                if id == next {
                    m.push_group(name, PatchKind::Closed);
                }
                current = Some(id);
            }
            Some("f") => {
                let idx: Vec<u32> = it
                    .map(|s| s.split('/').next().unwrap().parse::<u32>().unwrap() - 1)
                    .collect();
                let g = *current.get_or_insert_with(|| m.push_group("default", PatchKind::Closed));
                m.push_face(&idx, g);
            }
            _ => {}
        }
    }
    let mut edge_group: BTreeMap<(u32, u32), u32> = BTreeMap::new();
    let mut sharp = Vec::new();
    for f in 0..m.face_count() {
        let face = m.face(f).to_vec();
        let g = m.face_groups[f];
        for i in 0..face.len() {
            let k = edge_key(face[i], face[(i + 1) % face.len()]);
            match edge_group.get(&k) {
                Some(&g2) if g2 != g => sharp.push(k),
                Some(_) => {}
                None => {
                    edge_group.insert(k, g);
                }
            }
        }
    }
    for (a, b) in sharp {
        m.set_sharp(a, b);
    }
    m
}

fn bench_model(c: &mut Criterion, name: &str, rel: &str, max_level: u32) {
    let Some(dir) = corpus_dir() else {
        eprintln!("corpus not found, skipping");
        return;
    };
    let Ok(text) = std::fs::read_to_string(dir.join(rel)) else {
        eprintln!("{rel} not found, skipping");
        return;
    };
    let mesh = parse_obj(&text);
    let all = rayon::current_num_threads();
    for threads in [1, all] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let mut group = c.benchmark_group(format!("{name}/{threads}thr"));
        group.sample_size(10);
        group.warm_up_time(std::time::Duration::from_millis(300));
        group.measurement_time(std::time::Duration::from_secs(2));
        for level in 1..=max_level {
            let r = Refinement::new(&mesh, level).unwrap();
            let tris = r.level(level).face_count() as u64;
            group.throughput(Throughput::Elements(tris));
            let (mut out, mut scratch) = (Vec::new(), Vec::new());
            group.bench_with_input(BenchmarkId::new("positions", level), &level, |b, &l| {
                b.iter(|| {
                    pool.install(|| r.positions_into(&mesh.positions, l, &mut out, &mut scratch).unwrap())
                })
            });
            group.bench_with_input(BenchmarkId::new("topology+positions", level), &level, |b, &l| {
                b.iter(|| {
                    pool.install(|| {
                        let r = Refinement::new(&mesh, l).unwrap();
                        r.positions(&mesh.positions).unwrap()
                    })
                })
            });
            if level >= 3 {
                let p = r.positions(&mesh.positions).unwrap();
                group.bench_with_input(BenchmarkId::new("limit+normals", level), &level, |b, &l| {
                    b.iter(|| pool.install(|| (r.limit_positions(&p, l).unwrap(), r.limit_normals(&p, l).unwrap())))
                });
            }
        }
        group.finish();
        if threads == all {
            break;
        }
    }
}

fn benches(c: &mut Criterion) {
    bench_model(c, "plate", "tess/bug3883_xr2-ct-214_plate_coarse.obj", 5);
    bench_model(c, "fandisk", "meshes/fandisk.obj", 4);
}

criterion_group!(subdivide, benches);
criterion_main!(subdivide);
