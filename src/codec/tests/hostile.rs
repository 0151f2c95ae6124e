//! Hostile files against the decoder's limits (`spec/format.md` §10). Each is made by a small
//! generator with the codec's own writers and coders, so CRCs and entropy coding are right and
//! it is the decoder's logic that must reject the file; each test asserts the rejection and
//! the decoder's own accounting (never wall time): at most 100 MB charged, the work within its
//! bound. `spec/vectors/limits/` holds small ones, one per rule of spec §10.

use super::super::bytes::{TAG_DEFLATED, TAG_SKIPPABLE};
use super::*;

const MB: u64 = 1 << 20;

/// Header counts of a hand-made file (raw mesh unless `level` is set).
#[derive(Clone, Copy, Default)]
struct Counts {
    level: Option<u8>,
    v: u64,
    f: u64,
    k: u64,
    g: u64,
    isolated: u64,
}

impl Counts {
    fn elements(&self) -> u64 {
        self.v + self.f + self.k + 1
    }
}

fn header(c: Counts) -> Vec<u8> {
    let mut flags = 0;
    if c.level.is_some() {
        flags |= FLAG_CONTROL_MESH;
    }
    if c.isolated > 0 {
        flags |= FLAG_ISOLATED;
    }
    let mut h = Vec::new();
    put_varint(&mut h, flags);
    h.extend(c.level);
    h.push(10);
    for n in [c.v, c.f, c.k, c.g] {
        put_varint(&mut h, n);
    }
    if c.isolated > 0 {
        put_varint(&mut h, c.isolated);
    }
    for _ in 0..4 {
        h.extend_from_slice(&1f32.to_le_bytes());
    }
    h
}

/// A file: the header of `c`, then `sections` (id, payload) framed as the encoder frames them.
fn file(c: Counts, sections: &[(u8, Vec<u8>)]) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    out.extend([FORMAT_VERSION_MAJOR, FORMAT_VERSION_MINOR]);
    put_section(&mut out, SEC_HEADER, &header(c), false, true);
    for (id, payload) in sections {
        put_section(&mut out, *id, payload, true, false);
    }
    out
}

/// Appends a section whose tag says deflated, claiming `raw_len` bytes, holding `stream`.
fn deflated_section(out: &mut Vec<u8>, tag: u8, raw_len: u64, stream: &[u8]) {
    let start = out.len();
    out.push(tag | TAG_DEFLATED);
    put_varint(out, stream.len() as u64);
    put_varint(out, raw_len);
    out.extend_from_slice(stream);
    let crc = crc32fast::hash(&out[start..]);
    out.extend_from_slice(&crc.to_le_bytes());
}

/// A connectivity payload: `count` labels range-coded as the encoder codes them, then the
/// group symbols `groups` writes into the same stream.
fn connectivity(
    count: u64,
    labels: impl Iterator<Item = Label>,
    groups: impl FnOnce(&mut ConnModels, &mut RangeEncoder),
) -> Vec<u8> {
    let mut payload = Vec::new();
    put_varint(&mut payload, count);
    let mut enc = RangeEncoder::new();
    let mut models = ConnModels::new(true);
    for l in labels {
        models.encode_label(&mut enc, l);
    }
    groups(&mut models, &mut enc);
    payload.extend(enc.finish());
    payload
}

fn empty_stream() -> Vec<u8> {
    RangeEncoder::new().finish()
}

/// `labels` of a file whose creases and geometry sections hold nothing (files rejected
/// before those are read).
fn labels_file(c: Counts, count: u64, labels: impl Iterator<Item = Label>) -> Vec<u8> {
    file(
        c,
        &[
            (SEC_CONNECTIVITY, connectivity(count, labels, |_, _| {})),
            (SEC_CREASES, empty_stream()),
            (SEC_GEOMETRY, empty_stream()),
        ],
    )
}

/// Decodes `bytes` with `limits` and checks that it is rejected with `LimitsExceeded` or
/// `Format` while the decoder's accounting stays small: at most 100 MB charged and the work
/// within its bound for the header counts `c`. Returns the error message.
fn assert_rejected(bytes: &[u8], limits: &Limits, c: Counts) -> String {
    let (result, usage) = decode_with_usage(bytes, limits);
    let e = match result {
        Ok(_) => panic!("a hostile file decoded ({usage:?})"),
        Err(e @ (Error::LimitsExceeded { .. } | Error::Format { .. })) => e.to_string(),
        Err(e) => panic!("wrong error kind: {e}"),
    };
    assert!(usage.memory <= 100 * MB, "{e}: {usage:?}");
    assert!(
        usage.work <= limits.max_work_per_element * c.elements(),
        "{e}: {usage:?}"
    );
    e
}

/// A triangle followed by a run of one label, then `E` (`count` labels in all): a run of one
/// label costs a few thousandths of a bit, so the count is huge for the bytes.
fn label_run(c: Counts, count: u64, run: Label) -> Vec<u8> {
    let labels = std::iter::once(Label::F(3))
        .chain(std::iter::repeat_n(run, count as usize - 2))
        .chain(std::iter::once(Label::E));
    labels_file(c, count, labels)
}

/// Forward labels whose reverse rebuild splits a boundary of about `2 m` half-edges in two
/// halves (`M`) and merges them back (`S`), `pairs` times: each pair costs about `1.5 m` walk
/// steps for a few bytes. A face of high degree makes the labels give the header's faces and
/// corners, so the rebuild runs.
fn merge_walk(m: u32, pairs: u32) -> (Counts, Vec<u8>) {
    let d = 4 * pairs + 2 * m + 1;
    let c = Counts {
        v: 3,
        f: 2,
        k: 3 + u64::from(d),
        g: 1,
        ..Counts::default()
    };
    let l = m + 1;
    let split = Label::M { i: 0, k: l / 2, l };
    let labels = [Label::F(3), Label::F(d)]
        .into_iter()
        .chain((0..pairs).flat_map(move |_| [Label::S, split]))
        .chain(std::iter::repeat_n(Label::R, m as usize))
        .chain(std::iter::once(Label::E));
    let count = 3 + 2 * u64::from(pairs) + u64::from(m);
    (c, labels_file(c, count, labels))
}

/// Forward labels whose rebuild inserts `pairs` suspended boundaries at the bottom of a stack
/// of `depth`: each insert moves the whole stack.
fn deep_inserts(depth: u32, pairs: u32) -> (Counts, Vec<u8>) {
    let d = 4 * pairs + 4 * depth - 3;
    let c = Counts {
        v: 3,
        f: 2,
        k: 3 + u64::from(d),
        g: 1,
        ..Counts::default()
    };
    let labels = [Label::F(3), Label::F(d)]
        .into_iter()
        .chain(std::iter::repeat_n(Label::S, (pairs + depth - 1) as usize))
        // Rebuilt in reverse: the last of these inserts at depth `depth - 1`, the first at
        // depth `depth + pairs - 2`.
        .chain((0..pairs).map(move |j| Label::M {
            i: depth + pairs - 2 - j,
            k: 0,
            l: 2,
        }))
        .chain(std::iter::repeat_n(Label::E, depth as usize));
    let count = 2 + 2 * u64::from(pairs) + 2 * u64::from(depth) - 1;
    (c, labels_file(c, count, labels))
}

/// A fan of `n` triangles around one vertex, groups alternating: every face names its group as
/// a vertex candidate (§6.5), which the decoder finds by walking all the way round the hub.
fn fan_vertex_groups(n: u32) -> (Counts, Vec<u8>) {
    let mut mesh = ControlMesh::new();
    mesh.push_vertex(DVec3::ZERO);
    for i in 0..=n {
        let a = f64::from(i) * 0.001;
        mesh.push_vertex(DVec3::new(a.cos(), a.sin(), 0.0));
    }
    for g in 0..2 {
        mesh.push_group(format!("g{g}"), PatchKind::Closed);
    }
    for i in 0..n {
        mesh.push_face(&[0, i + 1, i + 2], i % 2);
    }
    let he = HalfEdgeMesh::build(&mesh).unwrap();
    let tr = encode_traversal(&he);
    let rb = rebuild(&tr.labels, &mut Budget::unlimited()).unwrap();
    let c = Counts {
        v: u64::from(n) + 2,
        f: u64::from(n),
        k: 3 * u64::from(n),
        g: 2,
        ..Counts::default()
    };
    let groups = |models: &mut ConnModels, enc: &mut RangeEncoder| {
        let mut face_group = vec![NONE; rb.faces.len()];
        let (mut prev_real, mut cands, mut seen) = (None, Vec::new(), 0u32);
        for (i, rf) in rb.faces.iter().enumerate() {
            if rf.hole {
                continue;
            }
            group_candidates(&rb, i, &face_group, prev_real, &mut cands);
            let class = group_class(&rb, i, &face_group, &cands);
            // With one edge candidate, the other group is the first vertex candidate (the hub
            // touches faces of both); with two, the face takes the first edge candidate.
            let (sym, g) = match (seen, cands.len()) {
                (0 | 1, _) => (GroupSym::New, seen),
                (_, 1) => (GroupSym::Vertex(0), 1 - cands[0]),
                _ => (GroupSym::Candidate(0), cands[0]),
            };
            models.encode_group(enc, sym, class, seen);
            face_group[i] = g;
            seen = seen.max(face_group[i] + 1);
            prev_real = Some(i);
        }
    };
    let conn = connectivity(tr.labels.len() as u64, tr.labels.iter().copied(), groups);
    let bytes = file(
        c,
        &[
            (SEC_CONNECTIVITY, conn),
            (SEC_CREASES, empty_stream()),
            (SEC_GEOMETRY, empty_stream()),
        ],
    );
    (c, bytes)
}

/// A raw-mode file of `count` isolated vertices. With `streams`, the corner flags and the
/// zero residuals are range-coded as the encoder codes them (the file decodes where the memory
/// allows); without, the sections hold just enough bytes for the header's count to pass the
/// size checks (the decoder rejects it before reading them).
fn isolated_vertices(count: u64, streams: bool) -> (Counts, Vec<u8>) {
    let c = Counts {
        v: count,
        isolated: count,
        ..Counts::default()
    };
    let (creases, geometry) = if streams {
        let mut enc = RangeEncoder::new();
        let mut corner = BitModel::default();
        for _ in 0..count {
            enc.encode_bit(&mut corner, false);
        }
        let creases = enc.finish();
        // Every residual is 0 in one context (the first vertex sits at the grid's centre,
        // each next one at the previous).
        let mut enc = RangeEncoder::new();
        let mut residual = IntModel::default();
        for _ in 0..3 * count {
            residual.encode(&mut enc, 0);
        }
        (creases, enc.finish())
    } else {
        (empty_stream(), vec![0; (count * 15 / 363_000) as usize])
    };
    let bytes = file(
        c,
        &[
            (
                SEC_CONNECTIVITY,
                connectivity(0, std::iter::empty(), |_, _| {}),
            ),
            (SEC_CREASES, creases),
            (SEC_GEOMETRY, geometry),
        ],
    );
    (c, bytes)
}

/// One triangle as a control mesh whose header asks for `level` by default.
fn triangle_at_level(level: u8) -> Vec<u8> {
    let mut mesh = samples::from_faces(
        &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        &[vec![0, 1, 2]],
    );
    mesh.groups[0].patch = PatchKind::Closed;
    let opts = EncodeOptions {
        content: Content::ControlMesh {
            default_level: level,
        },
        ..EncodeOptions::default()
    };
    encode(&mesh, &opts).unwrap()
}

/// The sections of a genuine file (the cube), then unknown skippable sections that claim
/// `claim` bytes each once inflated and hold garbage: a decoder that inflated them would fail.
fn skippable_bombs(sections: u8, claim: u64) -> Vec<u8> {
    let mut out = encode(&samples::cube(), &EncodeOptions::default()).unwrap();
    let garbage = vec![0xA5u8; (claim / 1040) as usize];
    for id in 0..sections {
        deflated_section(&mut out, (7 + id) | TAG_SKIPPABLE, claim, &garbage);
    }
    out
}

/// The cube with its connectivity section replaced by one claiming `claim` inflated bytes.
fn connectivity_bomb(claim: u64, stream: &[u8]) -> Vec<u8> {
    let cube = encode(&samples::cube(), &EncodeOptions::default()).unwrap();
    let mut r = Reader::new(&cube, "file");
    r.bytes(6, "start").unwrap();
    read_section(&mut r, Some(0), true).unwrap();
    let mut out = cube[..r.pos()].to_vec();
    read_section(&mut r, None, true).unwrap();
    deflated_section(&mut out, SEC_CONNECTIVITY, claim, stream);
    out.extend_from_slice(&cube[r.pos()..]);
    out
}

/// The cube with `groups` groups (every face in the first), and a names section whose first
/// record is a stem of `stem` bytes and whose other records (a byte each) repeat it.
fn repeated_names(groups: u32, stem: usize) -> (Counts, Vec<u8>) {
    let cube = samples::cube();
    let bytes = encode(&cube, &EncodeOptions::default()).unwrap();
    let c = Counts {
        v: 8,
        f: 6,
        k: 24,
        g: u64::from(groups),
        ..Counts::default()
    };
    let mut header_bytes = header(c);
    header_bytes[0] |= FLAG_NAMES as u8;
    let mut out = MAGIC.to_vec();
    out.extend([FORMAT_VERSION_MAJOR, FORMAT_VERSION_MINOR]);
    put_section(&mut out, SEC_HEADER, &header_bytes, false, true);
    // The cube's labels, then group symbols for `groups` groups: the first face opens group
    // 0, every other one takes its first candidate (group 0 too). Its creases and geometry
    // then read as they do for one group.
    let he = HalfEdgeMesh::build(&cube).unwrap();
    let tr = encode_traversal(&he);
    let rb = rebuild(&tr.labels, &mut Budget::unlimited()).unwrap();
    let conn = connectivity(
        tr.labels.len() as u64,
        tr.labels.iter().copied(),
        |m, enc| {
            let face_group = vec![0u32; rb.faces.len()];
            let (mut cands, mut prev_real) = (Vec::new(), None);
            for (i, rf) in rb.faces.iter().enumerate() {
                if rf.hole {
                    continue;
                }
                group_candidates(&rb, i, &face_group, prev_real, &mut cands);
                let class = group_class(&rb, i, &face_group, &cands);
                let sym = match prev_real {
                    None => GroupSym::New,
                    Some(_) => GroupSym::Candidate(0),
                };
                m.encode_group(enc, sym, class, u32::from(prev_real.is_some()));
                prev_real = Some(i);
            }
        },
    );
    put_section(&mut out, SEC_CONNECTIVITY, &conn, true, false);
    let mut r = Reader::new(&bytes, "file");
    r.bytes(6, "start").unwrap();
    read_section(&mut r, Some(0), true).unwrap();
    while !r.is_empty() {
        let s = read_section(&mut r, None, true).unwrap();
        if s.id == SEC_CREASES || s.id == SEC_GEOMETRY {
            put_section(&mut out, s.id, &s.payload().unwrap(), true, false);
        }
    }
    let mut names = Vec::new();
    let mut enc = RangeEncoder::new();
    let mut hit = BitModel::default();
    for _ in 0..groups {
        enc.encode_bit(&mut hit, true);
    }
    let order = enc.finish();
    put_varint(&mut names, order.len() as u64);
    names.extend(order);
    put_varint(&mut names, (stem as u64) << 2);
    names.extend(std::iter::repeat_n(b'x', stem));
    put_varint(&mut names, 0);
    names.extend(std::iter::repeat_n(2u8, groups as usize - 1));
    put_section(&mut out, SEC_NAMES, &names, true, false);
    (c, out)
}

#[test]
fn a_run_of_one_label_is_rejected_before_its_arrays_exist() {
    // The header's counts alone need more than the budget: rejected before any label.
    let c = Counts {
        v: 3,
        f: 1,
        k: 180_000_000,
        g: 1,
        ..Counts::default()
    };
    let bytes = label_run(c, 1 << 26, Label::R);
    assert!(bytes.len() < 20_000, "{}", bytes.len());
    let e = assert_rejected(&bytes, &Limits::default(), c);
    assert!(e.contains("the header's counts need"), "{e}");
    // Counts within the budget: the labels are read (and charged), then fail the header's
    // face and corner counts before the rebuild allocates anything.
    let c = Counts { k: 3_000_000, ..c };
    for run in [
        Label::R,
        Label::L,
        Label::S,
        Label::E,
        Label::F(3),
        Label::H(3),
    ] {
        let e = assert_rejected(&label_run(c, c.k + c.f, run), &Limits::default(), c);
        assert!(e.contains("labels"), "{run:?}: {e}");
    }
}

#[test]
fn merge_walks_are_charged_to_the_work_bound() {
    let (c, bytes) = merge_walk(1 << 16, 2000);
    assert!(bytes.len() < 20_000, "{}", bytes.len());
    let e = assert_rejected(&bytes, &Limits::default(), c);
    assert!(e.contains("decode work"), "{e}");
    let (c, bytes) = deep_inserts(1 << 18, 4000);
    let e = assert_rejected(&bytes, &Limits::default(), c);
    assert!(e.contains("decode work"), "{e}");
}

#[test]
fn vertex_candidates_around_a_hub_are_charged_to_the_work_bound() {
    let (c, bytes) = fan_vertex_groups(50_000);
    let e = assert_rejected(&bytes, &Limits::default(), c);
    assert!(e.contains("decode work"), "{e}");
    // The same kind of file, small enough to stay within the bound, resolves its groups.
    let (c, bytes) = fan_vertex_groups(40);
    let (r, usage) = decode_with_usage(&bytes, &Limits::default());
    assert!(
        usage.work > 0 && usage.work <= Limits::default().max_work_per_element * c.elements(),
        "{usage:?}"
    );
    if let Err(e) = r {
        assert!(!e.to_string().contains("decode work"), "{e}");
    }
}

#[test]
fn unknown_skippable_sections_are_never_inflated() {
    let bytes = skippable_bombs(6, 1 << 30);
    let (decoded, usage) = decode_with_usage(&bytes, &Limits::default());
    let decoded = decoded.unwrap();
    assert_eq!(decoded.mesh.face_count(), 6);
    assert!(usage.memory < bytes.len() as u64 + MB, "{usage:?}");
}

#[test]
fn inflated_sections_are_charged_before_inflating() {
    // 1 GiB claimed: over the budget with the input, rejected before inflating (the stream is
    // not even zlib).
    let c = Counts::default();
    let bytes = connectivity_bomb(1 << 30, &vec![0; (1 << 30) / 1040]);
    let e = assert_rejected(&bytes, &Limits::default(), c);
    assert!(e.contains("inflated sections"), "{e}");
    // A real stream within the budget inflates, is charged, and the total counts: a budget
    // smaller than input + inflated bytes stops it.
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    std::io::Write::write_all(&mut z, &vec![0; 8 << 20]).unwrap();
    let stream = z.finish().unwrap();
    let bytes = connectivity_bomb(8 << 20, &stream);
    let (r, usage) = decode_with_usage(&bytes, &Limits::default());
    assert!(matches!(r, Err(Error::Format { .. })), "{r:?}");
    assert!((8 * MB..10 * MB).contains(&usage.memory), "{usage:?}");
    let small = Limits {
        max_memory: 8 * MB,
        ..Limits::default()
    };
    let e = assert_rejected(&bytes, &small, c);
    assert!(e.contains("inflated sections"), "{e}");
}

#[test]
fn default_levels_and_isolated_vertices_are_checked_at_the_header() {
    // Level 12 of one triangle: 16.7 M triangles, within `max_subdivided_faces`, so the control
    // mesh decodes (subdividing it is charged by whoever subdivides); level 14 is not.
    let bytes = triangle_at_level(12);
    assert!(bytes.len() < 100, "{}", bytes.len());
    decode(&bytes, &Limits::default()).unwrap();
    let c = Counts {
        v: 3,
        f: 1,
        k: 3,
        g: 1,
        ..Counts::default()
    };
    let e = assert_rejected(&triangle_at_level(14), &Limits::default(), c);
    assert!(e.contains("subdivided faces at the default level"), "{e}");
    let (c, bytes) = isolated_vertices(50_000_000, false);
    assert!(bytes.len() < 300, "{}", bytes.len());
    let e = assert_rejected(&bytes, &Limits::default(), c);
    assert!(e.contains("the header's counts need"), "{e}");
}

#[test]
fn isolated_vertices_decode_within_the_budget() {
    let (_, bytes) = isolated_vertices(10_000, true);
    let (d, usage) = decode_with_usage(&bytes, &Limits::default());
    assert_eq!(d.unwrap().mesh.vertex_count(), 10_000);
    assert!(usage.memory < MB, "{usage:?}");
}

#[test]
fn repeated_group_names_are_charged() {
    // 100,000 names of 100,000 bytes from a file of a few hundred bytes: 10 GB of names, stopped
    // by a budget of 64 MB.
    let (c, bytes) = repeated_names(100_000, 100_000);
    assert!(bytes.len() < 1_000, "{}", bytes.len());
    let limits = Limits {
        max_memory: 64 * MB,
        ..Limits::default()
    };
    let e = assert_rejected(&bytes, &limits, c);
    assert!(e.contains("group names"), "{e}");
    // The same construction with short names decodes.
    let (d, _) = decode_with_usage(&repeated_names(20, 4).1, &Limits::default());
    let mesh = d.unwrap().mesh;
    assert_eq!(mesh.groups.len(), 20);
    assert!(mesh.groups.iter().all(|g| g.name == "xxxx"));
}

#[test]
fn a_decode_releases_what_it_frees() {
    // Every array but the mesh is freed by the end of a decode: what stays charged is the
    // input and the mesh, and the peak lies above it. (No names: their charge is the stems'.)
    let mut part = samples::cad_part();
    for g in &mut part.groups {
        g.name.clear();
    }
    let bytes = encode(&part, &EncodeOptions::default()).unwrap();
    let (d, usage) = decode_with_usage(&bytes, &Limits::default());
    let mesh = d.unwrap().mesh;
    assert!(!mesh.sharp_edges.is_empty() && !mesh.corners.is_empty());
    let header = inspect(&bytes, &Limits::default()).unwrap().header;
    let held = bytes.len() as u64
        + mesh_bytes(&header)
        + mesh.sharp_edges.len() as u64 * SHARP_EDGE_BYTES
        + mesh.corners.len() as u64 * CORNER_BYTES;
    assert_eq!(usage.held, held, "{usage:?}");
    assert!(usage.memory > 2 * held, "{usage:?}");
}

/// Two faces of `n` corners each, glued along all their edges (a pillow).
fn pillow(n: u32) -> Vec<u8> {
    let mut mesh = ControlMesh::new();
    for i in 0..n {
        let a = f64::from(i) * std::f64::consts::TAU / f64::from(n);
        mesh.push_vertex(DVec3::new(a.cos(), a.sin(), 0.0));
    }
    let g = mesh.push_group("", PatchKind::Closed);
    let ring: Vec<u32> = (0..n).collect();
    mesh.push_face(&ring, g);
    mesh.push_face(&ring.iter().rev().copied().collect::<Vec<_>>(), g);
    encode(&mesh, &EncodeOptions::default()).unwrap()
}

#[test]
fn faces_of_high_degree_decode_in_linear_work() {
    // Each corner's predictions look 3 steps round its face, and validation finds repeated
    // vertices in one pass: nothing walks a whole face per corner.
    let (d, usage) = decode_with_usage(&pillow(200_000), &Limits::default());
    assert_eq!(d.unwrap().mesh.face_vertices.len(), 400_000);
    assert_eq!(usage.work, 0);
}

/// The vectors of `spec/vectors/limits/` (spec §11): file name, bytes, and the error a decoder
/// with the default limits gives (`LimitsExceeded` and the quantity, or `Format` and the
/// section and field).
fn limit_vectors() -> Vec<(&'static str, Vec<u8>, &'static str)> {
    let run = Counts {
        v: 3,
        f: 1,
        k: 3_000_000,
        g: 1,
        ..Counts::default()
    };
    vec![
        (
            "header_memory.scode",
            isolated_vertices(50_000_000, false).1,
            "LimitsExceeded decode memory the header's counts need (bytes)",
        ),
        (
            "default_level.scode",
            triangle_at_level(14),
            "LimitsExceeded subdivided faces at the default level",
        ),
        (
            "label_counts.scode",
            label_run(run, run.k + run.f, Label::R),
            "Format connectivity.labels",
        ),
        (
            "merge_walk.scode",
            merge_walk(1 << 16, 2000).1,
            "LimitsExceeded decode work (walk steps)",
        ),
        (
            "vertex_candidates.scode",
            fan_vertex_groups(50_000).1,
            "LimitsExceeded decode work (walk steps)",
        ),
        (
            "group_names.scode",
            repeated_names(100_000, 100_000).1,
            "LimitsExceeded decode memory for group names (bytes)",
        ),
    ]
}

fn limit_vector_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("spec/vectors/limits")
}

/// Writes `spec/vectors/limits/` and its `EXPECTED.txt`.
fn write_limit_vectors() {
    let dir = limit_vector_dir();
    std::fs::create_dir_all(&dir).unwrap();
    let mut expected = String::from(
        "# file  bytes  error with the default limits: LimitsExceeded + quantity, or Format + \
         section.field\n# Regenerate with `SCODE_WRITE_VECTORS=1 cargo test --release --lib \
         limit_vectors`; checked by tests/spec_vectors.rs.\n",
    );
    for (name, bytes, error) in limit_vectors() {
        std::fs::write(dir.join(name), &bytes).unwrap();
        expected += &format!("{name} {} {error}\n", bytes.len());
    }
    std::fs::write(dir.join("EXPECTED.txt"), expected).unwrap();
}

/// The stored vectors are what the generators make (with `SCODE_WRITE_VECTORS` set, when a
/// rule or the coders change deliberately, they are written first).
#[test]
fn limit_vectors_match_their_generators() {
    if std::env::var_os("SCODE_WRITE_VECTORS").is_some() {
        write_limit_vectors();
    }
    for (name, bytes, _) in limit_vectors() {
        let stored = std::fs::read(limit_vector_dir().join(name)).unwrap();
        assert!(
            stored == bytes,
            "{name} differs from its generator: `SCODE_WRITE_VECTORS=1 cargo test --release \
             --lib limit_vectors` writes it"
        );
        assert!(bytes.len() < 100_000, "{name}: {} bytes", bytes.len());
    }
}
