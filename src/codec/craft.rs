//! Files made from a description with the codec's own writers and coders, for the
//! structure-aware fuzz target (feature `fuzzing`; not a stable interface).
//!
//! A fuzzer that mutates `.scode` bytes spends its time on CRCs and on range-coded streams
//! whose bits mean nothing once changed; one that describes a file (labels, group symbols,
//! header counts, sections) and has it written as the encoder writes reaches the decoder's
//! logic: every section's CRC is right and every label is the one described. [`build`]
//! starts from a genuine file of one of the sample meshes and replaces what the description
//! gives:
//! * the header's fields (counts, flags, level, bits, box), each kept, derived or set;
//! * the connectivity: labels range-coded with the connectivity models, then one group
//!   symbol per mesh face of the rebuilt connectivity in the context class the decoder
//!   computes while the described groups and the decoder's agree;
//! * any section, as raw bytes or as a range-coded stream of bits or integers (with one
//!   adaptive model: the decoder's models read other symbols from it, but every value is
//!   one an adaptive coder can produce), deflated or not, skippable or not;
//! and the header's counts follow the described labels unless set.

use super::bytes::{put_section, put_varint, read_section, Reader, TAG_DEFLATED};
use super::facefixer::{encode_traversal, rebuild, Label};
use super::rangecoder::{BitModel, IntModel, RangeEncoder};
use super::{
    decode, encode, group_candidates, group_class, samples, Budget, ConnModels, Content,
    EncodeOptions, GroupSym, Limits, FLAG_BOX_F64, FLAG_CONTROL_MESH, FLAG_ISOLATED, FLAG_MERGES,
    FORMAT_VERSION_MAJOR, FORMAT_VERSION_MINOR, MAGIC, SEC_CONNECTIVITY, SEC_HEADER,
};
use crate::mesh::topology::HalfEdgeMesh;
use crate::mesh::ControlMesh;

/// Work a description's rebuild may take per label before it is given up (then the group
/// symbols are coded without the rebuilt connectivity's context classes).
const REBUILD_WORK_PER_LABEL: u64 = 64;

/// A group symbol of a mesh face (spec §6.5).
#[derive(Clone, Copy, Debug)]
pub enum Group {
    Candidate(u8),
    New,
    Vertex(u8),
    Recent(u32),
}

/// What a section holds.
#[derive(Clone, Debug)]
pub enum Payload {
    Raw(Vec<u8>),
    /// Range-coded bits, one adaptive binary model.
    Bits(Vec<bool>),
    /// Range-coded integers, one adaptive integer model.
    Ints(Vec<u32>),
}

/// A section that replaces the base file's section of the same id, or is added after the
/// others when the base file has none.
#[derive(Clone, Debug)]
pub struct Section {
    /// Section id (0..64; 0, the header, is not replaced).
    pub id: u8,
    pub payload: Payload,
    /// Framed with the skippable bit.
    pub skippable: bool,
    /// Deflated with this claimed `raw_len` (`None`: stored, or deflated when smaller, as
    /// the encoder does). A claim that is not the true length is a hostile file.
    pub deflate_claim: Option<u64>,
}

/// Header fields; `None` keeps the base file's value or the one the labels give.
#[derive(Clone, Debug, Default)]
pub struct HeaderEdit {
    /// Flags XOR this.
    pub flags_xor: u64,
    pub default_level: Option<u8>,
    pub bits: Option<u8>,
    pub vertices: Option<u64>,
    pub faces: Option<u64>,
    pub corners: Option<u64>,
    pub groups: Option<u64>,
    pub isolated: Option<u64>,
    pub merges: Option<u64>,
    /// Box minimum and extent (stored as f32 unless the flags say f64).
    pub bbox: Option<[f64; 4]>,
}

/// A file to build (see the module documentation).
#[derive(Clone, Debug, Default)]
pub struct Description {
    /// The sample mesh the base file encodes (taken modulo the number of samples).
    pub base: u8,
    /// The base file stores a control mesh at this default level (else a raw mesh).
    pub control_level: Option<u8>,
    pub header: HeaderEdit,
    /// Labels replacing the base file's (`None`: keep its connectivity section).
    pub labels: Option<Vec<Label>>,
    /// Label count stored before the labels (`None`: their number).
    pub label_count: Option<u64>,
    /// Group symbols of the mesh faces in order, when the file has several groups.
    pub groups: Vec<Group>,
    pub sections: Vec<Section>,
}

fn sample(i: u8) -> ControlMesh {
    match i % 6 {
        0 => samples::tetrahedron(),
        1 => samples::cube(),
        2 => samples::open_box(),
        3 => samples::torus(4, 3),
        4 => samples::multi_group(),
        _ => samples::cad_part(),
    }
}

/// The labels made valid for the coders: degrees at least 3, `k < l`, values below 2^20.
fn coded(l: Label) -> Label {
    const MAX: u32 = 1 << 20;
    match l {
        Label::F(d) => Label::F(d.clamp(3, MAX)),
        Label::H(d) => Label::H(d.clamp(3, MAX)),
        Label::M { i, k, l } => {
            let l = l.clamp(2, MAX);
            Label::M {
                i: i.min(MAX),
                k: k % l,
                l,
            }
        }
        other => other,
    }
}

/// The connectivity payload of `labels`, their group symbols, and the counts they give
/// (vertices when the rebuild succeeds, faces, corners).
fn connectivity(d: &Description, labels: &[Label], groups: u64) -> (Vec<u8>, [Option<u64>; 3]) {
    let faces = labels.iter().filter(|l| matches!(l, Label::F(_))).count() as u64;
    let corners: u64 = labels
        .iter()
        .map(|l| match l {
            Label::F(d) => u64::from(*d),
            _ => 0,
        })
        .sum();
    let mut payload = Vec::new();
    put_varint(&mut payload, d.label_count.unwrap_or(labels.len() as u64));
    let mut enc = RangeEncoder::new();
    let mut models = ConnModels::new(true);
    for &l in labels {
        models.encode_label(&mut enc, l);
    }
    let mut budget = Budget::unlimited();
    budget.max_work = REBUILD_WORK_PER_LABEL * (labels.len() as u64 + 1);
    let rebuilt = rebuild(labels, &mut budget).ok();
    if groups > 1 {
        let mut syms = d.groups.iter().copied().cycle().take(faces as usize);
        match &rebuilt {
            Some(rb) => {
                // The groups as described, as far as a candidate or a new group says.
                let mut face_group = vec![0u32; rb.faces.len()];
                let (mut cands, mut prev_real, mut seen) = (Vec::new(), None, 0u32);
                for (i, rf) in rb.faces.iter().enumerate() {
                    if rf.hole {
                        continue;
                    }
                    group_candidates(rb, i, &face_group, prev_real, &mut cands);
                    let class = group_class(rb, i, &face_group, &cands);
                    let g = syms.next().unwrap_or(Group::New);
                    let (sym, group) = symbol(g, seen, &cands);
                    models.encode_group(&mut enc, sym, class, seen);
                    face_group[i] = group;
                    seen = seen.max(group + 1);
                    prev_real = Some(i);
                }
            }
            None => {
                let mut seen = 0;
                for g in syms {
                    let (sym, group) = symbol(g, seen, &[]);
                    models.encode_group(&mut enc, sym, 0, seen);
                    seen = seen.max(group + 1);
                }
            }
        }
    }
    payload.extend(enc.finish());
    let vertices = rebuilt.map(|rb| rb.vertex_count as u64);
    (payload, [vertices, Some(faces), Some(corners)])
}

/// The symbol to code for `g` and the group it names (as far as the description can tell).
fn symbol(g: Group, seen: u32, cands: &[u32]) -> (GroupSym, u32) {
    match g {
        Group::Candidate(i) => {
            let i = i % 3;
            (
                GroupSym::Candidate(i),
                cands.get(usize::from(i)).copied().unwrap_or(0),
            )
        }
        Group::Vertex(i) => (GroupSym::Vertex(i % 3), 0),
        Group::Recent(r) if seen > 0 => (GroupSym::Recent(r % seen), 0),
        Group::Recent(_) | Group::New => (GroupSym::New, seen),
    }
}

fn stream(p: &Payload) -> Vec<u8> {
    match p {
        Payload::Raw(b) => b.clone(),
        Payload::Bits(bits) => {
            let mut enc = RangeEncoder::new();
            let mut m = BitModel::default();
            for &b in bits {
                enc.encode_bit(&mut m, b);
            }
            enc.finish()
        }
        Payload::Ints(v) => {
            let mut enc = RangeEncoder::new();
            let mut m = IntModel::default();
            for &x in v {
                m.encode(&mut enc, x.min(1 << 24));
            }
            enc.finish()
        }
    }
}

/// Appends `s` framed as the description says, its CRC right.
fn put_described(out: &mut Vec<u8>, s: &Section) {
    let tag = (s.id & 0x3F) | if s.skippable { 0x40 } else { 0 };
    let payload = stream(&s.payload);
    match s.deflate_claim {
        None => put_section(out, tag, &payload, true, false),
        Some(claim) => {
            use std::io::Write;
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
            let deflated = z.write_all(&payload).ok().and_then(|()| z.finish().ok());
            let start = out.len();
            out.push(tag | TAG_DEFLATED);
            let deflated = deflated.unwrap_or_default();
            put_varint(out, deflated.len() as u64);
            put_varint(out, claim);
            out.extend_from_slice(&deflated);
            let crc = crc32fast::hash(&out[start..]);
            out.extend_from_slice(&crc.to_le_bytes());
        }
    }
}

/// The header payload: `e`'s edits over the base header and the counts the labels give;
/// and its `V + F + K`, which the work bound of spec §10.4 multiplies.
fn header(base: &super::Header, e: &HeaderEdit, from_labels: [Option<u64>; 3]) -> (Vec<u8>, u64) {
    let flags = base.flags ^ e.flags_xor;
    let mut h = Vec::new();
    put_varint(&mut h, flags);
    if flags & FLAG_CONTROL_MESH != 0 {
        let level = match base.content {
            Content::ControlMesh { default_level } => default_level,
            Content::RawMesh => 2,
        };
        h.push(e.default_level.unwrap_or(level));
    }
    h.push(e.bits.unwrap_or(base.quantization_bits));
    let pick = |edit: Option<u64>, labels: Option<u64>, base: u64| edit.or(labels).unwrap_or(base);
    let counts = [
        pick(e.vertices, from_labels[0], base.vertex_count),
        pick(e.faces, from_labels[1], base.face_count),
        pick(e.corners, from_labels[2], base.face_corner_count),
    ];
    for n in counts {
        put_varint(&mut h, n);
    }
    put_varint(&mut h, e.groups.unwrap_or(base.group_count));
    if flags & FLAG_ISOLATED != 0 {
        put_varint(&mut h, e.isolated.unwrap_or(base.isolated_vertex_count));
    }
    if flags & FLAG_MERGES != 0 {
        put_varint(&mut h, e.merges.unwrap_or(base.merged_vertex_count));
    }
    let b = base.bbox_min;
    for v in e.bbox.unwrap_or([b[0], b[1], b[2], base.bbox_extent]) {
        if flags & FLAG_BOX_F64 != 0 {
            h.extend_from_slice(&v.to_le_bytes());
        } else {
            h.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    let elements = counts.iter().fold(0u64, |a, &n| a.saturating_add(n));
    (h, elements)
}

/// The file `d` describes (see the module documentation), and the `V + F + K` of its header.
pub fn build(d: &Description) -> (Vec<u8>, u64) {
    let mesh = sample(d.base);
    let content = match d.control_level {
        Some(default_level) => Content::ControlMesh {
            default_level: default_level % 4,
        },
        None => Content::RawMesh,
    };
    let opts = EncodeOptions {
        content,
        ..EncodeOptions::default()
    };
    // The samples are valid meshes: their encoding and decoding cannot fail.
    let genuine = encode(&mesh, &opts).expect("a sample mesh encodes");
    let base = decode(&genuine, &Limits::default())
        .expect("a sample mesh decodes")
        .header;
    let mut sections = Vec::new();
    let mut r = Reader::new(&genuine, "file");
    let _ = r.bytes(6, "start");
    // The header's CRC covers the file from its start.
    let _ = read_section(&mut r, Some(0), true);
    while !r.is_empty() {
        let Ok(s) = read_section(&mut r, None, true) else {
            break;
        };
        if let Ok(p) = s.payload() {
            sections.push((s.id, p.into_owned()));
        }
    }
    let groups = d.header.groups.unwrap_or(base.group_count);
    let labels = d.labels.as_ref().map(|ls| {
        let ls: Vec<Label> = ls.iter().map(|&l| coded(l)).collect();
        connectivity(d, &ls, groups)
    });
    let from_labels = labels.as_ref().map_or([None; 3], |(_, counts)| *counts);
    let mut out = MAGIC.to_vec();
    out.extend([FORMAT_VERSION_MAJOR, FORMAT_VERSION_MINOR]);
    let (header_bytes, elements) = header(&base, &d.header, from_labels);
    put_section(&mut out, SEC_HEADER, &header_bytes, false, true);
    let replaced = |id: u8| d.sections.iter().find(|s| s.id == id && id != SEC_HEADER);
    for (id, payload) in &sections {
        match (replaced(*id), &labels) {
            (Some(s), _) => put_described(&mut out, s),
            (None, Some((conn, _))) if *id == SEC_CONNECTIVITY => {
                put_section(&mut out, *id, conn, true, false)
            }
            _ => put_section(&mut out, *id, payload, true, false),
        }
    }
    for s in &d.sections {
        if s.id != SEC_HEADER && !sections.iter().any(|(id, _)| *id == s.id) {
            put_described(&mut out, s);
        }
    }
    (out, elements)
}

/// A genuine file's labels (for seeds that start from real connectivity).
pub fn sample_labels(base: u8) -> Vec<Label> {
    let mesh = sample(base);
    let he = HalfEdgeMesh::build(&mesh).expect("a sample mesh is manifold");
    encode_traversal(&he).labels
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::decode_with_usage;
    use crate::error::Error;

    /// What the fuzz target checks: the decoder's accounting within spec §10's bounds.
    fn decode_within_bounds(bytes: &[u8], elements: u64) -> crate::Result<super::super::Decoded> {
        let limits = Limits::default();
        let (decoded, usage) = decode_with_usage(bytes, &limits);
        assert!(usage.memory <= limits.max_memory, "{usage:?}");
        assert!(
            usage.work <= limits.max_work_per_element * (elements + 1),
            "{usage:?}"
        );
        decoded
    }

    /// An empty description is the genuine file of its sample, for every sample and both
    /// contents: the fuzzer starts from files that decode.
    #[test]
    fn an_empty_description_is_a_genuine_file() {
        for base in 0..6 {
            for control_level in [None, Some(2)] {
                let d = Description {
                    base,
                    control_level,
                    ..Description::default()
                };
                let (bytes, elements) = build(&d);
                let decoded = decode_within_bounds(&bytes, elements).unwrap();
                assert_eq!(
                    decoded.header.vertex_count
                        + decoded.header.face_count
                        + decoded.header.face_corner_count,
                    elements
                );
                // The sample's own labels, described, give the same file.
                let relabelled = Description {
                    labels: Some(sample_labels(base)),
                    groups: vec![Group::Candidate(0)],
                    ..d
                };
                let (again, _) = build(&relabelled);
                if decoded.mesh.groups.len() == 1 {
                    assert_eq!(again, bytes, "base {base}");
                }
            }
        }
    }

    /// Described damage reaches the decoder's logic past the CRCs: a label run it must
    /// refuse for its counts, a header count that disagrees with the labels, a deflated
    /// section that lies about its length, all refused within the bounds.
    #[test]
    fn described_damage_is_refused_within_the_bounds() {
        let run = Description {
            base: 1,
            labels: Some(
                std::iter::once(Label::F(3))
                    .chain(std::iter::repeat_n(Label::R, 100_000))
                    .chain(std::iter::once(Label::E))
                    .collect(),
            ),
            ..Description::default()
        };
        let (bytes, elements) = build(&run);
        let e = decode_within_bounds(&bytes, elements).unwrap_err();
        assert!(
            matches!(e, Error::Format { .. } | Error::LimitsExceeded { .. }),
            "{e}"
        );
        let counts = Description {
            base: 1,
            header: HeaderEdit {
                faces: Some(7),
                ..HeaderEdit::default()
            },
            ..Description::default()
        };
        let (bytes, elements) = build(&counts);
        assert!(decode_within_bounds(&bytes, elements).is_err());
        let lying = Description {
            base: 1,
            sections: vec![Section {
                id: SEC_CONNECTIVITY,
                payload: Payload::Raw(vec![7; 100]),
                skippable: false,
                deflate_claim: Some(1 << 40),
            }],
            ..Description::default()
        };
        let (bytes, elements) = build(&lying);
        let e = decode_within_bounds(&bytes, elements).unwrap_err();
        assert!(
            matches!(e, Error::Format { .. } | Error::LimitsExceeded { .. }),
            "{e}"
        );
    }
}
