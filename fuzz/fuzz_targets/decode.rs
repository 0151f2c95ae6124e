//! Arbitrary bytes into the decoder with checksums off (so the fuzzer gets past the CRCs) and
//! the command-line tool's default limits scaled down together by `SCALE` (counts, input size
//! and memory budget; the work bound is per element already), so an input costs what it would
//! cost a default decode at a sixteenth of the scale. Must never panic, and a decode that
//! fails must fail within its budget. A control mesh that decodes is then decoded to a
//! tolerance too, as `scode decode` does by default, on a small budget of triangles.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scode::codec::{decode_with_usage, inspect, Content, Limits};
use scode::subdiv::{subdivide_to_tolerance, AccuracyOptions};

const SCALE: u64 = 16;

fuzz_target!(|data: &[u8]| {
    let d = Limits::default();
    let limits = Limits {
        max_input_bytes: d.max_input_bytes / SCALE,
        max_vertices: d.max_vertices / SCALE,
        max_faces: d.max_faces / SCALE,
        max_face_corners: d.max_face_corners / SCALE,
        max_groups: d.max_groups / SCALE,
        max_subdivided_faces: d.max_subdivided_faces / SCALE,
        max_memory: d.max_memory / SCALE,
        verify_checksums: false,
        ..d
    };
    let (decoded, usage) = decode_with_usage(data, &limits);
    assert!(usage.memory <= limits.max_memory, "{usage:?}");
    if let Ok(d) = decoded {
        // Whatever decodes must be a valid mesh that matches its header.
        d.mesh.validate().expect("decoded mesh must be valid");
        assert_eq!(d.mesh.vertex_count() as u64, d.header.vertex_count);
        assert_eq!(d.mesh.face_count() as u64, d.header.face_count);
        let elements = d.header.vertex_count + d.header.face_count + d.header.face_corner_count;
        assert!(usage.work <= limits.max_work_per_element * (elements + 1));
        let info = inspect(data, &limits).expect("inspect agrees with decode");
        assert_eq!(info.total_bytes, data.len());
        if let Content::ControlMesh { default_level } = d.header.content {
            let opts = AccuracyOptions {
                max_level: u32::from(default_level).min(2),
                max_faces: 1 << 14,
                ..Default::default()
            };
            if let Ok(out) = subdivide_to_tolerance(&d.mesh, &opts) {
                out.mesh
                    .validate()
                    .expect("a surface decoded to a tolerance must be valid");
            }
        }
    }
});
