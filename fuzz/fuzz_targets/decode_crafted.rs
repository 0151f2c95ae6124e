//! Structure-aware decode: the fuzzer's bytes describe a file (header fields, labels, group
//! symbols, sections; [`scode::codec::craft`]) that is written with the codec's own writers
//! and coders, so every CRC is right and every label is the one described, and the decoder's
//! logic is what gets fuzzed. The file is decoded with the command-line tool's default
//! limits (checksums on), and the decoder's own accounting must stay within the bounds of
//! `spec/format.md` §10: the memory charged within `max_memory`, the input charged, the
//! work within `max_work_per_element x (V + F + K + 1)`; whatever decodes is a valid mesh
//! that matches its header.
#![no_main]

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use scode::codec::craft::{self, Description, Group, HeaderEdit, Payload, Section};
use scode::codec::facefixer::Label;
use scode::codec::{decode_with_usage, Limits};

#[derive(Arbitrary, Debug)]
enum LabelIn {
    F(u8),
    FBig(u32),
    H(u16),
    R,
    L,
    S,
    E,
    M { i: u16, k: u16, l: u16 },
}

impl LabelIn {
    fn label(&self) -> Label {
        match *self {
            LabelIn::F(d) => Label::F(u32::from(d)),
            LabelIn::FBig(d) => Label::F(d),
            LabelIn::H(d) => Label::H(u32::from(d)),
            LabelIn::R => Label::R,
            LabelIn::L => Label::L,
            LabelIn::S => Label::S,
            LabelIn::E => Label::E,
            LabelIn::M { i, k, l } => Label::M {
                i: u32::from(i),
                k: u32::from(k),
                l: u32::from(l),
            },
        }
    }
}

#[derive(Arbitrary, Debug)]
enum GroupIn {
    Candidate(u8),
    New,
    Vertex(u8),
    Recent(u32),
}

#[derive(Arbitrary, Debug)]
enum PayloadIn {
    Raw(Vec<u8>),
    Bits(Vec<bool>),
    Ints(Vec<u32>),
}

#[derive(Arbitrary, Debug)]
struct SectionIn {
    id: u8,
    payload: PayloadIn,
    skippable: bool,
    deflate_claim: Option<u32>,
}

#[derive(Arbitrary, Debug)]
struct HeaderIn {
    flags_xor: u8,
    default_level: Option<u8>,
    bits: Option<u8>,
    counts: [Option<u32>; 6],
    big_counts: Option<(u8, u64)>,
    bbox: Option<[f32; 4]>,
}

#[derive(Arbitrary, Debug)]
struct LabelsIn {
    /// Start from the base mesh's own labels (else from none).
    from_base: bool,
    /// Labels replaced by position (modulo the count).
    replace: Vec<(u16, LabelIn)>,
    /// Labels inserted by position.
    insert: Vec<(u16, LabelIn)>,
    append: Vec<LabelIn>,
    /// A run of one label appended `n` times (cheap in bits, long in labels).
    run: Option<(LabelIn, u16)>,
    count: Option<u32>,
}

#[derive(Arbitrary, Debug)]
struct Input {
    base: u8,
    control_level: Option<u8>,
    header: Option<HeaderIn>,
    labels: Option<LabelsIn>,
    groups: Vec<GroupIn>,
    sections: Vec<SectionIn>,
}

fn labels(base: u8, l: &LabelsIn) -> Vec<Label> {
    let mut out = if l.from_base {
        craft::sample_labels(base)
    } else {
        Vec::new()
    };
    for (i, x) in &l.replace {
        if !out.is_empty() {
            let n = out.len();
            out[usize::from(*i) % n] = x.label();
        }
    }
    for (i, x) in &l.insert {
        let at = usize::from(*i) % (out.len() + 1);
        out.insert(at, x.label());
    }
    out.extend(l.append.iter().map(LabelIn::label));
    if let Some((x, n)) = &l.run {
        out.extend(std::iter::repeat_n(x.label(), usize::from(*n)));
    }
    out
}

fn description(inp: &Input) -> Description {
    let header = inp.header.as_ref().map_or_else(HeaderEdit::default, |h| {
        let mut c = h.counts.map(|c| c.map(u64::from));
        if let Some((which, n)) = h.big_counts {
            c[usize::from(which) % 6] = Some(n);
        }
        HeaderEdit {
            flags_xor: u64::from(h.flags_xor),
            default_level: h.default_level,
            bits: h.bits,
            vertices: c[0],
            faces: c[1],
            corners: c[2],
            groups: c[3],
            isolated: c[4],
            merges: c[5],
            bbox: h.bbox.map(|b| b.map(f64::from)),
        }
    });
    Description {
        base: inp.base,
        control_level: inp.control_level,
        header,
        labels: inp.labels.as_ref().map(|l| labels(inp.base, l)),
        label_count: inp.labels.as_ref().and_then(|l| l.count).map(u64::from),
        groups: inp
            .groups
            .iter()
            .map(|g| match *g {
                GroupIn::Candidate(i) => Group::Candidate(i),
                GroupIn::New => Group::New,
                GroupIn::Vertex(i) => Group::Vertex(i),
                GroupIn::Recent(r) => Group::Recent(r),
            })
            .collect(),
        sections: inp
            .sections
            .iter()
            .map(|s| Section {
                id: s.id % 64,
                payload: match &s.payload {
                    PayloadIn::Raw(b) => Payload::Raw(b.clone()),
                    PayloadIn::Bits(b) => Payload::Bits(b.clone()),
                    PayloadIn::Ints(v) => Payload::Ints(v.clone()),
                },
                skippable: s.skippable,
                deflate_claim: s.deflate_claim.map(u64::from),
            })
            .collect(),
    }
}

fuzz_target!(|inp: Input| {
    let (bytes, elements) = craft::build(&description(&inp));
    let limits = Limits::default();
    let (decoded, usage) = decode_with_usage(&bytes, &limits);
    assert!(usage.memory <= limits.max_memory, "{usage:?}");
    assert!(
        usage.work
            <= limits
                .max_work_per_element
                .saturating_mul(elements.saturating_add(1)),
        "{usage:?}, V + F + K = {elements}"
    );
    match decoded {
        Ok(d) => {
            // The input is charged, and so is the mesh the caller now holds.
            assert!(usage.held >= bytes.len() as u64, "{usage:?}");
            d.mesh.validate().expect("decoded mesh must be valid");
            assert_eq!(d.mesh.vertex_count() as u64, d.header.vertex_count);
            assert_eq!(d.mesh.face_count() as u64, d.header.face_count);
            assert_eq!(
                d.mesh.face_vertices.len() as u64,
                d.header.face_corner_count
            );
        }
        Err(e) => {
            // A decoder failure is one of the decoder's typed errors.
            assert!(
                matches!(
                    e,
                    scode::Error::Format { .. } | scode::Error::LimitsExceeded { .. }
                ),
                "{e:?}"
            );
            assert!(
                usage.memory >= bytes.len() as u64 || usage.memory == 0,
                "{usage:?}"
            );
        }
    }
});
