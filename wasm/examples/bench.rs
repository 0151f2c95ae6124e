//! Native timing of the viewer engine (the same code the page runs as WebAssembly):
//! `cargo run --release --example bench -- file.scode [triangles]` decodes, refines to the first
//! level with at least `triangles` (default 1e6) triangles and extracts the WebGL arrays.
use std::time::Instant;

use scode_wasm::engine::Model;

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: bench file.scode [triangles]");
    let want: f64 = args
        .next()
        .map_or(1e6, |s| s.parse().expect("triangle count"));
    let bytes = std::fs::read(&path).expect("read file");
    for run in 0..3 {
        let t0 = Instant::now();
        let mut m = Model::decode(&bytes).expect("decode");
        let t1 = Instant::now();
        let base = m.base_triangle_count() as f64;
        let mut level = 0;
        while base * 4f64.powi(level as i32) < want {
            level += 1;
        }
        m.refine(level).expect("refine");
        let t2 = Instant::now();
        let a = m.extract_uniform(level).expect("extract");
        let t3 = Instant::now();
        let levels: Vec<u8> = (0..m.base_triangle_count())
            .map(|k| (k % (level as usize + 1)) as u8)
            .collect();
        let b = m.extract_levels(&levels).expect("lod");
        let t4 = Instant::now();
        let b2 = m.extract_levels(&levels).expect("lod");
        let t5 = Instant::now();
        let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
        println!(
            "run {run}: level {level}, {} triangles: decode {:.1} ms, refine {:.1} ms, arrays {:.1} ms, total {:.1} ms; mixed-level LOD {} triangles first {:.1} ms, again {:.1} ms",
            a.triangle_count(),
            ms(t0, t1),
            ms(t1, t2),
            ms(t2, t3),
            ms(t0, t3),
            b.triangle_count(),
            ms(t3, t4),
            ms(t4, t5),
        );
        assert_eq!(b.triangle_count(), b2.triangle_count());
    }
}
