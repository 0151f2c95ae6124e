//! Arbitrary bytes into the decoder with checksums off (so the fuzzer gets past the CRCs) and
//! modest limits (so forged counts cannot make one input take seconds). Must never panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scode::codec::{decode, inspect, Limits};

fuzz_target!(|data: &[u8]| {
    let limits = Limits {
        max_vertices: 200_000,
        max_faces: 400_000,
        max_face_corners: 1_200_000,
        max_groups: 10_000,
        verify_checksums: false,
        ..Limits::default()
    };
    if let Ok(d) = decode(data, &limits) {
        // Whatever decodes must be a valid mesh that matches its header.
        d.mesh.validate().expect("decoded mesh must be valid");
        assert_eq!(d.mesh.vertex_count() as u64, d.header.vertex_count);
        assert_eq!(d.mesh.face_count() as u64, d.header.face_count);
        let info = inspect(data, &limits).expect("inspect agrees with decode");
        assert_eq!(info.total_bytes, data.len());
    }
});
