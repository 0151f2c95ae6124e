//! Regenerates the frozen test vectors in `spec/vectors/` and their expected hashes.
//!
//! `cargo run --example make_vectors` — only when the format changes deliberately; the normal
//! test suite (`tests/spec_vectors.rs`) only reads the files.

use std::fmt::Write as _;
use std::path::Path;

use scode::codec::bytes::{put_varint, TAG_DEFLATED, TAG_SKIPPABLE};
use scode::codec::samples::{self, canonical_hash};
use scode::codec::{decode, encode, Content, EncodeOptions, Limits};
use scode::mesh::ControlMesh;

/// The vectors: file stem, mesh, options.
fn vectors() -> Vec<(&'static str, ControlMesh, EncodeOptions)> {
    let raw = EncodeOptions::default();
    let control = |level, bits| EncodeOptions {
        quantization_bits: bits,
        content: Content::ControlMesh {
            default_level: level,
        },
        store_group_names: true,
        ..Default::default()
    };
    vec![
        ("tetrahedron", samples::tetrahedron(), raw.clone()),
        ("cube", samples::cube(), raw.clone()),
        ("open_box", samples::open_box(), raw.clone()),
        ("torus", samples::torus(8, 6), raw.clone()),
        ("multi_group", samples::multi_group(), control(3, 10)),
        ("cad_part", samples::cad_part(), control(4, 12)),
        ("turned_part", samples::turned_part(), control(3, 12)),
        ("rounded_part", samples::rounded_part(), control(3, 12)),
    ]
}

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("spec/vectors");
    std::fs::create_dir_all(&dir).expect("create spec/vectors");
    let mut expected = String::from(
        "# file  fnv64-of-canonical-decoded-mesh  vertices  faces  bytes\n\
         # Regenerate with `cargo run --example make_vectors`; checked by tests/spec_vectors.rs.\n",
    );
    for (name, mesh, opts) in vectors() {
        let bytes = encode(&mesh, &opts).expect("encode sample");
        let decoded = decode(&bytes, &Limits::default()).expect("decode sample");
        let file = format!("{name}.scode");
        std::fs::write(dir.join(&file), &bytes).expect("write vector");
        writeln!(
            expected,
            "{file} {:016x} {} {} {}",
            canonical_hash(&decoded.mesh),
            decoded.mesh.vertex_count(),
            decoded.mesh.face_count(),
            bytes.len()
        )
        .unwrap();
        println!("{file}: {} bytes", bytes.len());
    }
    // Spec §10: an unknown section with the skippable bit is skipped without inflating it. This
    // one says it is deflated but holds no zlib stream, so a decoder that inflated it would
    // fail; the file decodes to the cube.
    let mut bytes = encode(&samples::cube(), &EncodeOptions::default()).expect("encode cube");
    let start = bytes.len();
    let garbage = [0xA5u8; 16];
    bytes.push(7 | TAG_SKIPPABLE | TAG_DEFLATED);
    put_varint(&mut bytes, garbage.len() as u64);
    put_varint(&mut bytes, 1040 * garbage.len() as u64 + 64);
    bytes.extend_from_slice(&garbage);
    let crc = crc32fast::hash(&bytes[start..]);
    bytes.extend_from_slice(&crc.to_le_bytes());
    let decoded = decode(&bytes, &Limits::default()).expect("decode skippable_section");
    std::fs::write(dir.join("skippable_section.scode"), &bytes).expect("write vector");
    writeln!(
        expected,
        "skippable_section.scode {:016x} {} {} {}",
        canonical_hash(&decoded.mesh),
        decoded.mesh.vertex_count(),
        decoded.mesh.face_count(),
        bytes.len()
    )
    .unwrap();
    std::fs::write(dir.join("EXPECTED.txt"), expected).expect("write EXPECTED.txt");
}
