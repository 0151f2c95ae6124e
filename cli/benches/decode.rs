//! Full decode throughput of fitted files: bitstream, subdivision topology, positions and the
//! output arrays (`decode_surface` at a uniform level), in output triangles per second on
//! one thread, at levels 4 and 5 on three corpus models. `level` leaves level positions (what
//! `scode decode --level N --no-limit` computes), `limit` projects to the limit surface with
//! normals (what `scode decode --level N` computes).
//!
//! Run: `cargo bench --bench decode` (SCODE_CORPUS overrides the corpus folder). Each model
//! is fitted once first (the encoder's default tolerance), which takes seconds.

/// The `scode` binary's allocator (see the `mimalloc` feature).
#[cfg(feature = "mimalloc")]
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use scode::codec::Limits;
use scode::pipeline::{
    decode_surface, encode_fitted, sidecar_hints, Detail, ModelEncodeOptions, SurfaceOptions,
};

#[path = "../../tests/common/mod.rs"]
mod common;
use common::corpus_dir;

/// A STEP tessellation with every surface type (422 faces), a plate of planes and cylinders
/// and an ungrouped freeform mesh.
const MODELS: [(&str, &str); 3] = [
    ("bug33398_fine", "tess/bug33398_fine.obj"),
    ("plate_fine", "tess/bug3883_xr2-ct-214_plate_fine.obj"),
    ("fandisk", "meshes/fandisk.obj"),
];

fn bench_decode(c: &mut Criterion) {
    let Some(corpus) = corpus_dir() else { return };
    // One core: the figure the decoder is held to, independent of the machine's load.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("thread pool");
    for (name, rel) in MODELS {
        let path = corpus.join(rel);
        let (mesh, _) =
            scode::io::read_mesh(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let hints = sidecar_hints(&path, &mesh)
            .ok()
            .flatten()
            .map(|(_, h)| h)
            .unwrap_or_default();
        let (bytes, _) = encode_fitted(&mesh, &hints, &ModelEncodeOptions::default()).expect("fit");
        let mut g = c.benchmark_group(format!("decode/{name}"));
        g.sample_size(10);
        g.warm_up_time(Duration::from_millis(500));
        g.measurement_time(Duration::from_secs(3));
        for level in [4, 5] {
            for (label, limit) in [("level", false), ("limit", true)] {
                let opts = SurfaceOptions {
                    detail: Detail::Level(level),
                    limit: Some(limit),
                    ..Default::default()
                };
                let decode = || decode_surface(&bytes, &Limits::default(), &opts).expect("decode");
                let out = pool.install(decode).mesh;
                // Fan-triangulated faces: what a triangle writer emits.
                let triangles = (out.face_vertices.len() - 2 * out.face_count()) as u64;
                g.throughput(Throughput::Elements(triangles));
                g.bench_function(BenchmarkId::new(label, level), |b| {
                    b.iter(|| pool.install(decode))
                });
            }
        }
        g.finish();
    }
}

criterion_group!(benches, bench_decode);
criterion_main!(benches);
