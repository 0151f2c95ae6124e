//! Decodes every frozen vector in `spec/vectors/` and compares the canonical hash of the
//! decoded mesh with `EXPECTED.txt`; every truncated prefix and every single-bit flip of each
//! vector must give an error (never a panic, never a silently different mesh).

use std::path::Path;

use scode::codec::bytes::{read_section, Reader};
use scode::codec::samples::canonical_hash;
use scode::codec::{decode, Limits};

/// The current version's vectors and the frozen version-1, 2 and 3 ones, which must
/// still decode.
fn vectors() -> Vec<(String, Vec<u8>, u64, usize, usize)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("spec/vectors");
    let mut all = vectors_in(&root);
    all.extend(vectors_in(&root.join("v1")));
    all.extend(vectors_in(&root.join("v2")));
    all.extend(vectors_in(&root.join("v3")));
    all
}

fn vectors_in(dir: &Path) -> Vec<(String, Vec<u8>, u64, usize, usize)> {
    let text = std::fs::read_to_string(dir.join("EXPECTED.txt")).expect("EXPECTED.txt");
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            let bytes = std::fs::read(dir.join(f[0])).expect("vector file");
            let name = format!("{}/{}", dir.display(), f[0]);
            assert_eq!(
                bytes.len(),
                f[4].parse::<usize>().unwrap(),
                "{}: size",
                f[0]
            );
            (
                name,
                bytes,
                u64::from_str_radix(f[1], 16).unwrap(),
                f[2].parse().unwrap(),
                f[3].parse().unwrap(),
            )
        })
        .collect()
}

#[test]
fn vectors_decode_to_expected_meshes() {
    let v = vectors();
    assert!(v.len() >= 19);
    for (name, bytes, hash, nv, nf) in v {
        let d = decode(&bytes, &Limits::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(d.mesh.vertex_count(), nv, "{name}");
        assert_eq!(d.mesh.face_count(), nf, "{name}");
        assert_eq!(
            canonical_hash(&d.mesh),
            hash,
            "{name}: decoded mesh differs"
        );
    }
}

/// Where the last section a decoder must read ends (unknown skippable sections follow).
fn end_of_known_sections(bytes: &[u8]) -> usize {
    let mut r = Reader::new(bytes, "file");
    r.bytes(6, "magic and version").unwrap();
    let mut end = 0;
    let mut first = true;
    while !r.is_empty() {
        let s = read_section(&mut r, first.then_some(0), true).unwrap();
        first = false;
        if !s.skippable {
            end = r.pos();
        }
    }
    end
}

#[test]
fn truncations_and_bit_flips_are_errors() {
    let lax = Limits {
        verify_checksums: false,
        ..Limits::default()
    };
    for (name, bytes, hash, _, _) in vectors() {
        // Skippable sections at the end may be cut off whole: what is left is a file without
        // them, which decodes to the same mesh.
        let known_end = end_of_known_sections(&bytes);
        for n in 0..bytes.len() {
            match decode(&bytes[..n], &Limits::default()) {
                Err(_) => {}
                Ok(d) => assert!(
                    n >= known_end && canonical_hash(&d.mesh) == hash,
                    "{name}: prefix {n}"
                ),
            }
            let _ = decode(&bytes[..n], &lax);
        }
        for i in 0..bytes.len() * 8 {
            let mut c = bytes.clone();
            c[i / 8] ^= 1 << (i % 8);
            assert!(
                decode(&c, &Limits::default()).is_err(),
                "{name}: bit {i} flip accepted"
            );
            // Without CRCs the flip may decode; it must never panic and must give a valid mesh.
            if let Ok(d) = decode(&c, &lax) {
                d.mesh.validate().unwrap();
                let _ = canonical_hash(&d.mesh) == hash;
            }
        }
    }
}

/// The vectors of `spec/vectors/limits/`, one per rule of spec §10: each must be refused with
/// the default limits, with the error `EXPECTED.txt` names.
#[test]
fn limit_vectors_are_refused_as_expected() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("spec/vectors/limits");
    let text = std::fs::read_to_string(dir.join("EXPECTED.txt")).expect("EXPECTED.txt");
    let mut count = 0;
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
    {
        let mut fields = line.splitn(4, ' ');
        let (name, size, kind, detail) = (
            fields.next().unwrap(),
            fields.next().unwrap().parse::<usize>().unwrap(),
            fields.next().unwrap(),
            fields.next().unwrap(),
        );
        let bytes = std::fs::read(dir.join(name)).expect("vector file");
        assert_eq!(bytes.len(), size, "{name}: size");
        match (kind, decode(&bytes, &Limits::default())) {
            ("LimitsExceeded", Err(scode::Error::LimitsExceeded { what, .. })) => {
                assert_eq!(what, detail, "{name}")
            }
            ("Format", Err(scode::Error::Format { section, field, .. })) => {
                assert_eq!(format!("{section}.{field}"), detail, "{name}")
            }
            (_, r) => panic!("{name}: expected {kind} {detail}, got {:?}", r.err()),
        }
        count += 1;
    }
    assert!(count >= 6);
}
