//! Encode and decode times on two corpus models: the fitting encoder (tolerance 1e-3 of the
//! diagonal, the default), raw mode at 10 bits, and decoding (bitstream only, and to the
//! surface a viewer shows: subdivision to the file's default level plus limit projection).
//! Subdivision alone is benchmarked in `cli/benches/subdivide.rs`.
//!
//! Run: `cargo bench --bench codec` (SCODE_CORPUS overrides the corpus folder). The fitting
//! encoder takes seconds per model, so its group uses criterion's minimum of 10 samples.

/// The `scode` binary's allocator (see the `mimalloc` feature); build the bench with
/// `-p scode-cli --no-default-features --features parallel` to measure the system allocator.
#[cfg(feature = "mimalloc")]
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use std::path::Path;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use scode::codec::{self, Content, EncodeOptions, Limits};
use scode::pipeline::{
    decode_surface, encode_fitted, sidecar_hints, Detail, ModelEncodeOptions, SurfaceOptions,
};

#[path = "../../tests/common/mod.rs"]
mod common;
use common::corpus_dir;

/// Two small-to-medium CAD tessellations with sidecars: a part with cones and planes and
/// one with fillets (cylinders) and a sphere.
const MODELS: [(&str, &str); 2] = [
    ("four_cone_fine", "tess/four_cone_fine.obj"),
    ("block_fillet3_coarse", "tess/block_fillet3_coarse.obj"),
];

fn bench_codec(c: &mut Criterion) {
    let Some(corpus) = corpus_dir() else { return };
    for (name, rel) in MODELS {
        let path: &Path = &corpus.join(rel);
        let (mesh, _) =
            scode::io::read_mesh(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let hints = sidecar_hints(path, &mesh)
            .ok()
            .flatten()
            .map(|(_, h)| h)
            .unwrap_or_default();
        let nv = mesh.vertex_count() as u64;
        let fitted_opts = ModelEncodeOptions::default();
        let raw_opts = EncodeOptions {
            quantization_bits: 10,
            content: Content::RawMesh,
            store_group_names: true,
            ..Default::default()
        };

        let mut g = c.benchmark_group("encode");
        g.throughput(Throughput::Elements(nv));
        g.sample_size(10);
        g.measurement_time(Duration::from_secs(20));
        g.bench_function(BenchmarkId::new("fitted_1e-3", name), |b| {
            b.iter(|| encode_fitted(&mesh, &hints, &fitted_opts).expect("fit"))
        });
        g.bench_function(BenchmarkId::new("raw_10bit", name), |b| {
            b.iter(|| codec::encode(&mesh, &raw_opts).expect("encode"))
        });
        g.finish();

        let (fitted, _) = encode_fitted(&mesh, &hints, &fitted_opts).expect("fit");
        let raw = codec::encode(&mesh, &raw_opts).expect("encode");
        let mut g = c.benchmark_group("decode");
        g.throughput(Throughput::Elements(nv));
        g.bench_function(BenchmarkId::new("raw_10bit", name), |b| {
            b.iter(|| codec::decode(&raw, &Limits::default()).expect("decode"))
        });
        g.bench_function(BenchmarkId::new("fitted_bitstream", name), |b| {
            b.iter(|| codec::decode(&fitted, &Limits::default()).expect("decode"))
        });
        g.bench_function(BenchmarkId::new("fitted_surface", name), |b| {
            b.iter(|| {
                decode_surface(
                    &fitted,
                    &Limits::default(),
                    &SurfaceOptions {
                        detail: Detail::DefaultLevel,
                        ..Default::default()
                    },
                )
                .expect("decode")
            })
        });
        g.finish();
    }
}

criterion_group!(benches, bench_codec);
criterion_main!(benches);
