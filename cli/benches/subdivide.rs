//! Subdivision throughput: output triangles per second at levels 1-5 on corpus models, on
//! one core and on all cores (rayon pools), for (a) position evaluation on a prebuilt
//! topology (the encoder / viewer hot path), (b) topology + positions from scratch and
//! (c) a full decode (`subdivide`: topology, positions and the output mesh).
//!
//! Run: `cargo bench --bench subdivide` (wall time, rayon pools of 1 thread and of all
//! threads) and `cargo bench -p scode-cli --bench subdivide --no-default-features --features mimalloc`
//! (sequential build, measured in the thread's own CPU time (clock_gettime(CLOCK_THREAD_CPUTIME_ID)), which stays
//! meaningful on a loaded machine). SCODE_CORPUS overrides the corpus folder.

/// The `scode` binary's allocator (see the `mimalloc` feature); build the bench with
/// `-p scode-cli --no-default-features --features parallel` to measure the system allocator.
#[cfg(feature = "mimalloc")]
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use scode::subdiv::{Refinement, SubdivOptions};

#[path = "../../tests/common/mod.rs"]
mod common;
use common::corpus_dir;

/// CPU time of the calling thread (the sequential build runs everything on it).
#[cfg_attr(feature = "parallel", allow(dead_code))]
struct ThreadCpuTime;

#[cfg_attr(feature = "parallel", allow(dead_code))]
static WALL: WallTime = WallTime;

impl Measurement for ThreadCpuTime {
    type Intermediate = cpu_time::ThreadTime;
    type Value = std::time::Duration;
    fn start(&self) -> cpu_time::ThreadTime {
        cpu_time::ThreadTime::now()
    }
    fn end(&self, i: cpu_time::ThreadTime) -> std::time::Duration {
        i.elapsed()
    }
    fn add(&self, a: &Self::Value, b: &Self::Value) -> Self::Value {
        *a + *b
    }
    fn zero(&self) -> Self::Value {
        std::time::Duration::ZERO
    }
    fn to_f64(&self, v: &Self::Value) -> f64 {
        v.as_nanos() as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        WALL.formatter()
    }
}

/// Runs `f` in the rayon pool (parallel build) or directly on this thread (sequential build,
/// so that the thread's CPU time covers the work).
fn run<R: Send>(pool: &rayon::ThreadPool, f: impl FnOnce() -> R + Send) -> R {
    if cfg!(feature = "parallel") {
        pool.install(f)
    } else {
        f()
    }
}

fn bench_model<M: Measurement>(c: &mut Criterion<M>, name: &str, rel: &str, max_level: u32) {
    let Some(dir) = corpus_dir() else { return };
    let (mut mesh, _) =
        scode::io::read_mesh(&dir.join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"));
    // CAD-face boundaries are the control mesh's sharp edges.
    mesh.sharpen_group_boundaries();
    let all = if cfg!(feature = "parallel") {
        rayon::current_num_threads()
    } else {
        1
    };
    for threads in [1, all] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let label = if cfg!(feature = "parallel") {
            format!("{name}/{threads}thr")
        } else {
            format!("{name}/sequential-cpu")
        };
        let mut group = c.benchmark_group(label);
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
                    run(&pool, || {
                        r.positions_into(&mesh.positions, l, &mut out, &mut scratch)
                            .unwrap()
                    })
                })
            });
            group.bench_with_input(
                BenchmarkId::new("topology+positions", level),
                &level,
                |b, &l| {
                    b.iter(|| {
                        run(&pool, || {
                            let r = Refinement::new(&mesh, l).unwrap();
                            r.positions(&mesh.positions).unwrap()
                        })
                    })
                },
            );
            // What `scode decode` does without `--limit`: topology, positions and the output
            // mesh (groups, sharp edges, sparse boundary patches).
            group.bench_with_input(BenchmarkId::new("decode", level), &level, |b, &l| {
                b.iter(|| {
                    run(&pool, || {
                        scode::subdiv::subdivide(&mesh, l, &SubdivOptions::default())
                            .unwrap()
                            .0
                    })
                })
            });
            if level >= 3 {
                let p = r.positions(&mesh.positions).unwrap();
                group.bench_with_input(
                    BenchmarkId::new("limit+normals", level),
                    &level,
                    |b, &l| {
                        b.iter(|| {
                            run(&pool, || {
                                (
                                    r.limit_positions(&p, l).unwrap(),
                                    r.limit_normals(&p, l).unwrap(),
                                )
                            })
                        })
                    },
                );
            }
        }
        group.finish();
        if threads == all {
            break;
        }
    }
}

fn benches<M: Measurement>(c: &mut Criterion<M>) {
    bench_model(c, "plate", "tess/bug3883_xr2-ct-214_plate_coarse.obj", 5);
    bench_model(c, "fandisk", "meshes/fandisk.obj", 4);
}

#[cfg(feature = "parallel")]
criterion_group!(subdivide, benches);
#[cfg(not(feature = "parallel"))]
criterion_group! {
    name = subdivide;
    config = Criterion::default().with_measurement(ThreadCpuTime);
    targets = benches
}
criterion_main!(subdivide);
