//! The `.scode` bitstream (writes version 4, reads 1 to 4): encoder, decoder and inspector.
//! The byte-exact definition is `spec/format.md`; this module follows it section by section.
//!
//! Layout of a file: 4-byte magic `SCOD`, major and minor version bytes, then sections
//! (`header`, `connectivity`, optional `patches`, `creases`, `geometry`, optional `fixups`,
//! optional `names`), each framed as tag, length, payload (stored or zlib) and CRC-32.
//!
//! Connectivity is Face Fixer ([`facefixer`]) under an adaptive range coder ([`rangecoder`]);
//! face groups ride along with the F labels; sharp edges and corner tags are context-coded in
//! label / geometry order; positions are quantised to a cube and predicted ([`geometry`]);
//! patch kinds and axes have their own module ([`patches`]), as do group names ([`names`]).
//!
//! Decoded meshes are renumbered: vertices in geometry order, faces in traversal order (each
//! face's cycle may start at a different corner), groups by first appearance. [`encode_with_map`]
//! returns the renumbering so callers and tests can compare exactly.

pub mod bytes;
#[cfg(any(test, feature = "fuzzing"))]
#[doc(hidden)]
pub mod craft;
pub mod facefixer;
pub mod geometry;
mod names;
mod patches;
pub mod rangecoder;
mod ranks;
#[cfg(feature = "internals")]
pub mod samples;

#[cfg(any(feature = "encoder", feature = "internals"))]
use std::collections::BTreeSet;

use glam::DVec3;

use self::bytes::{read_section, RawSection, Reader};
use self::facefixer::{rebuild, Label, Rebuilt};
use self::geometry::{ArcAxes, GeomDecoder, Quantizer};
use self::rangecoder::{bits_for, BitModel, FreqModel, IntModel, RangeDecoder};
use crate::error::{Error, Result};
use crate::mesh::topology::NONE;
use crate::mesh::{edge_key, BoundarySurface, ControlMesh, Group, PatchKind};
#[cfg(any(feature = "encoder", feature = "internals"))]
use {
    self::bytes::{put_section, put_varint},
    self::facefixer::encode_traversal,
    self::geometry::GeomEncoder,
    self::rangecoder::RangeEncoder,
    crate::mesh::topology::{cut_non_manifold, HalfEdgeMesh},
};

pub const FORMAT_VERSION_MAJOR: u8 = 4;
#[cfg(any(feature = "encoder", feature = "internals"))]
pub const FORMAT_VERSION_MINOR: u8 = 0;
/// First four bytes of every `.scode` file.
pub const MAGIC: [u8; 4] = *b"SCOD";

/// What the stored mesh is: the final surface (raw mode) or a control mesh to subdivide.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Content {
    RawMesh,
    ControlMesh { default_level: u8 },
}

/// Encoder settings.
#[cfg(any(feature = "encoder", feature = "internals"))]
#[derive(Clone, Debug, PartialEq)]
pub struct EncodeOptions {
    /// Bits per coordinate of the position grid, 4..=24 (default 10).
    pub quantization_bits: u8,
    pub content: Content,
    /// Store group names (OBJ `g` names) in the optional `names` section (default true).
    pub store_group_names: bool,
    /// Grid step as a multiple of the smallest one that covers the positions with
    /// `quantization_bits` bits (default 1, at most 2^24): the stored box extent is the
    /// positions' extent times this, so a step between two whole bit counts (e.g. `sqrt 2`
    /// for half a bit coarser) needs no format support. Positions use grid values
    /// `0..=(2^bits - 1) / step_scale` only.
    pub step_scale: f64,
    /// A box (min, max corners) the position grid covers besides the positions (default
    /// none). An encoder that encodes variations of one model, such as the fit's rounds,
    /// gives them one box so that one grid quantises them all: parts that did not change
    /// quantise to the same points.
    pub grid_covers: Option<[glam::DVec3; 2]>,
}

#[cfg(any(feature = "encoder", feature = "internals"))]
impl Default for EncodeOptions {
    fn default() -> Self {
        EncodeOptions {
            quantization_bits: 10,
            content: Content::RawMesh,
            store_group_names: true,
            step_scale: 1.0,
            grid_covers: None,
        }
    }
}

/// Decoder resource limits. Every count read from a file is checked against these before
/// anything is allocated for it, and the memory and work a file can cost are bounded
/// (`spec/format.md` §10).
#[derive(Clone, Debug, PartialEq)]
pub struct Limits {
    /// Largest accepted file, and largest inflated section (default 1 GiB).
    pub max_input_bytes: u64,
    /// Default 50 million.
    pub max_vertices: u64,
    /// Default 100 million.
    pub max_faces: u64,
    /// Sum of face degrees (default 400 million).
    pub max_face_corners: u64,
    /// Default 1 million.
    pub max_groups: u64,
    /// Triangles after subdivision: a control mesh's fan-triangulated faces times 4^level, at
    /// the header's default level and at any level a caller decodes to (default 200 million).
    pub max_subdivided_faces: u64,
    /// Memory budget of one decode in bytes: the input, inflated sections and every array
    /// whose size the file decides (subdivision output included, when the caller subdivides)
    /// are charged against it before they are allocated and released when they are freed;
    /// what is live at once must fit. Default 1 GiB (the command-line tool's too): a raw
    /// triangle mesh peaks at about 150 bytes per triangle (7 million triangles fit). A
    /// subdivided surface adds 200 bytes per triangle of a uniform level, so a caller that
    /// subdivides large CAD models uniformly to their default level needs more (840 faces at
    /// level 5: 2.2 GB); a decode to a tolerance is charged for its measurement and for the
    /// output of the levels it chooses (a fine tessellation of 100,000 faces: 1.06 GB).
    pub max_memory: u64,
    /// Work bound: steps of the decoder's walks whose length the file decides (merge labels'
    /// boundary walks, candidate searches), at most this many per vertex, face and face
    /// corner of the header: a decode takes at most `max_work_per_element x (V + F + K + 1)`
    /// steps. The memory budget bounds the counts a header may claim (at least 25 bytes are
    /// charged per element, so 42 million elements per GiB): with the defaults a file costs at
    /// most about 256 x 42 million = 1.1e10 steps (4.3e10 per 4 GiB of budget). Default 256: genuine meshes of few handles count far below 1 per element, a
    /// voxel lattice of 45^3 cells (30,000 tunnels) 127; lattices of more tunnels need more.
    pub max_work_per_element: u64,
    /// Verify section CRCs (default true; the fuzz target turns it off).
    pub verify_checksums: bool,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_input_bytes: 1 << 30,
            max_vertices: 50_000_000,
            max_faces: 100_000_000,
            max_face_corners: 400_000_000,
            max_groups: 1_000_000,
            max_subdivided_faces: 200_000_000,
            max_memory: 1 << 30,
            max_work_per_element: 256,
            verify_checksums: true,
        }
    }
}

/// What one decode charged against its [`Limits`] (see [`decode_with_usage`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Usage {
    /// Peak of the bytes charged against `max_memory` and not yet released: what the decode
    /// held at most at one time.
    pub memory: u64,
    /// Bytes still charged when the decode ended: the input and the decoded mesh, which the
    /// caller holds (what a caller that subdivides adds to).
    pub held: u64,
    /// Walk steps charged against the work bound.
    pub work: u64,
}

/// The running account of a decode: allocation sites charge their bytes before allocating
/// and release them when the arrays are freed, so the live total is checked against the
/// budget (its peak is what a decode needs); walks whose length the file decides charge
/// their steps. Either beyond its limit is `Error::LimitsExceeded`. The encoder runs the
/// shared code with an unlimited budget.
pub(crate) struct Budget {
    max_memory: u64,
    max_work: u64,
    pub usage: Usage,
}

impl Budget {
    pub fn new(max_memory: u64) -> Self {
        Budget {
            max_memory,
            max_work: u64::MAX,
            usage: Usage::default(),
        }
    }

    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn unlimited() -> Self {
        Self::new(u64::MAX)
    }

    /// Charges `bytes` of memory for `what` (named in the error) on top of what is live.
    pub fn charge(&mut self, what: &'static str, bytes: u64) -> Result<()> {
        let live = self.usage.held.saturating_add(bytes);
        limit(what, live, self.max_memory)?;
        self.usage.held = live;
        self.usage.memory = self.usage.memory.max(live);
        Ok(())
    }

    /// Releases `bytes` charged earlier, when their arrays are freed.
    pub fn release(&mut self, bytes: u64) {
        self.usage.held = self.usage.held.saturating_sub(bytes);
    }

    pub fn work(&mut self, steps: u64) -> Result<()> {
        let total = self.usage.work.saturating_add(steps);
        limit("decode work (walk steps)", total, self.max_work)?;
        self.usage.work = total;
        Ok(())
    }
}

/// The decoded `header` section.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    pub version_major: u8,
    pub version_minor: u8,
    /// Raw flag bits (`spec/format.md` §5).
    pub flags: u64,
    pub content: Content,
    pub quantization_bits: u8,
    /// Minimum corner of the quantisation cube.
    pub bbox_min: [f64; 3],
    /// Edge length of the quantisation cube.
    pub bbox_extent: f64,
    /// Vertices of the decoded mesh.
    pub vertex_count: u64,
    pub face_count: u64,
    /// Sum of the face degrees.
    pub face_corner_count: u64,
    pub group_count: u64,
    /// Vertices used by no face (stored after the others).
    pub isolated_vertex_count: u64,
    /// Vertex copies the encoder made to cut non-manifold places apart, re-merged on decode.
    pub merged_vertex_count: u64,
}

impl Header {
    /// Grid step of the position quantisation (0 for a degenerate box).
    pub fn quantization_step(&self) -> f64 {
        self.bbox_extent / ((1u64 << self.quantization_bits) - 1) as f64
    }
}

/// Size of one section in a file.
#[derive(Clone, Debug, PartialEq)]
pub struct SectionInfo {
    pub name: &'static str,
    /// Bytes in the file, framing (tag, lengths, CRC) included.
    pub stored_bytes: usize,
    /// Payload bytes after inflation.
    pub raw_bytes: usize,
}

/// What `inspect` reports about a file.
#[derive(Clone, Debug, PartialEq)]
pub struct FileInfo {
    pub header: Header,
    pub sections: Vec<SectionInfo>,
    pub total_bytes: usize,
    pub sharp_edge_count: usize,
    /// Number of corner vertices.
    pub corner_count: usize,
    pub group_names: Vec<String>,
    pub patch_kinds: Vec<PatchKind>,
    pub component_count: usize,
    pub label_count: usize,
    /// Of the connectivity section, the bits that code face groups (information content of
    /// the group symbols as decoded); the rest codes the Face Fixer labels.
    pub group_bits: f64,
}

/// A decoded file.
#[derive(Clone, Debug, PartialEq)]
pub struct Decoded {
    pub header: Header,
    pub mesh: ControlMesh,
}

/// How the encoder renumbered the mesh: the decoded mesh has vertex `vertex[v]` where the
/// input had `v`, face `face[f]` for input face `f` (its cycle possibly rotated), and group
/// `group[g]` for input group `g`.
#[cfg(any(feature = "encoder", feature = "internals"))]
#[derive(Clone, Debug, PartialEq)]
pub struct EncodeMap {
    pub vertex: Vec<u32>,
    pub face: Vec<u32>,
    pub group: Vec<u32>,
}

// Section ids, in the order they must appear.
const SEC_HEADER: u8 = 0;
const SEC_CONNECTIVITY: u8 = 1;
const SEC_PATCHES: u8 = 2;
const SEC_CREASES: u8 = 3;
const SEC_GEOMETRY: u8 = 4;
const SEC_FIXUPS: u8 = 5;
const SEC_NAMES: u8 = 6;

fn section_name(id: u8) -> &'static str {
    match id {
        SEC_HEADER => "header",
        SEC_CONNECTIVITY => "connectivity",
        SEC_PATCHES => "patches",
        SEC_CREASES => "creases",
        SEC_GEOMETRY => "geometry",
        SEC_FIXUPS => "fixups",
        SEC_NAMES => "names",
        _ => "unknown",
    }
}

// Header flag bits.
const FLAG_CONTROL_MESH: u64 = 1;
const FLAG_BOX_F64: u64 = 2;
const FLAG_ISOLATED: u64 = 4;
const FLAG_MERGES: u64 = 8;
/// The optional sections present, so a file cut at a section boundary is detected.
const FLAG_PATCHES: u64 = 16;
const FLAG_NAMES: u64 = 32;
const KNOWN_FLAGS: u64 = 63;

/// What a file's version allows. All version gating lives here: the encoder writes the
/// current version, the decoder reads every version listed here.
struct Features {
    /// Known header flag bits.
    known_flags: u64,
    /// Geometry: vertices on creases are predicted along them (§8.2, version 2).
    crease_prediction: bool,
    /// Names: stored in input group order with the coded->input group order, stem + number
    /// coded (§9.2, version 2); version 1 stores plain names in coded order.
    names_in_input_order: bool,
    /// Geometry: crease vertices next to cylinders and cones are predicted on circles round
    /// the axis (§8.2, versions 3 and 4).
    arc_prediction: bool,
    /// Patches: range-coded, directions by reference, cylinder origins with two coordinates
    /// (§9 *Patches*, versions 3 and 4); versions 1 and 2 store bytes.
    coded_patches: bool,
    /// Connectivity: group symbols with vertex candidates and recency ranks (§6.5,
    /// version 3).
    groups_v3: bool,
    /// Patches: the size of the kind alphabet; version 4 adds spheres and tori.
    patch_kinds: usize,
}

/// Whether this build reads versions 1 and 2 (feature `legacy-formats`, on by default; the
/// WebAssembly viewer leaves it out to stay within its size budget). Code that only those
/// versions need is behind `LEGACY &&`, so builds without it drop that code.
const LEGACY: bool = cfg!(feature = "legacy-formats");

fn features_for(major: u8, _minor: u8) -> Result<Features> {
    // Minor versions may only add skippable sections; every decoder of a major version reads
    // the flags it knows and rejects the others.
    match major {
        1 | 2 if !LEGACY => Err(Error::format(
            "header",
            "version",
            format!(
                "version {major} files are read by builds with the `legacy-formats` feature \
                 (the scode command-line tool); this one reads version {FORMAT_VERSION_MAJOR}"
            ),
        )),
        1 => Ok(Features {
            known_flags: KNOWN_FLAGS,
            crease_prediction: false,
            names_in_input_order: false,
            arc_prediction: false,
            coded_patches: false,
            groups_v3: false,
            patch_kinds: patches::KINDS_V3,
        }),
        2 => Ok(Features {
            known_flags: KNOWN_FLAGS,
            crease_prediction: true,
            names_in_input_order: true,
            arc_prediction: false,
            coded_patches: false,
            groups_v3: false,
            patch_kinds: patches::KINDS_V3,
        }),
        3 | 4 => Ok(Features {
            known_flags: KNOWN_FLAGS,
            crease_prediction: true,
            names_in_input_order: true,
            arc_prediction: true,
            coded_patches: true,
            groups_v3: true,
            patch_kinds: if major == 3 {
                patches::KINDS_V3
            } else {
                patches::KINDS
            },
        }),
        _ => Err(Error::format(
            "header",
            "version",
            format!("unsupported major version {major} (this decoder reads versions 1.x to {FORMAT_VERSION_MAJOR}.x)"),
        )),
    }
}

// ------------------------------------------------------------------------------------------
// Label and group-symbol models (spec §6.3)

const LABEL_SYMBOLS: usize = 10;
const LABEL_CONTEXT_NONE: usize = LABEL_SYMBOLS;
const LABEL_CONTEXTS: usize = (LABEL_SYMBOLS + 1) * (LABEL_SYMBOLS + 1);
const SYM_F3: usize = 0;
const SYM_F4: usize = 1;
const SYM_F5: usize = 2;
const SYM_FX: usize = 3;
const SYM_R: usize = 4;
const SYM_L: usize = 5;
const SYM_S: usize = 6;
const SYM_E: usize = 7;
const SYM_H: usize = 8;
#[cfg(any(feature = "encoder", feature = "internals"))]
const SYM_M: usize = 9;

/// Initial counts of every label context (a fixed prior: F3/F4/R common, the rest rare), so
/// tiny meshes pay less learning cost than with all-ones counts.
const LABEL_PRIOR: [u32; LABEL_SYMBOLS] = [4, 4, 1, 1, 4, 1, 1, 1, 1, 1];

/// Group of a mesh face, relative to the groups of its already-decoded neighbours
/// (spec §6.5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum GroupSym {
    /// The `i`-th distinct group among the candidates (`i < GROUP_CANDIDATES`).
    Candidate(u8),
    /// The next group id not used so far.
    New,
    /// Versions 1-2: an already used group id, given explicitly.
    Explicit(u32),
    /// Version 3: the `i`-th distinct group among the faces around the face's vertices.
    Vertex(u8),
    /// Version 3: an already used group, by how many groups were used since (0 = the most
    /// recently used one). A face that re-enters a CAD face usually does so near where it
    /// left it.
    Recent(u32),
}

/// Candidate symbols; the alphabet is these plus `New` and `Explicit` (versions 1-2) and the
/// vertex candidates (version 3).
const GROUP_CANDIDATES: usize = 3;
const GROUP_SYMBOLS: usize = GROUP_CANDIDATES + 2;
const GROUP_SYMBOLS_V3: usize = GROUP_SYMBOLS + GROUP_CANDIDATES;
/// Version-3 group contexts (before the previous symbol): at most one candidate; two with
/// as many edges to each, more to the first, more to the second; three.
const GROUP_CLASSES_V3: usize = 5;

struct ConnModels {
    labels: Vec<FreqModel>,
    face_degree: IntModel,
    hole_degree: IntModel,
    m_depth: IntModel,
    m_length: IntModel,
    groups: Vec<FreqModel>,
    /// Version 3: group symbols 0..8 with the context classes; else the version-1 alphabet.
    groups_v3: bool,
    recent: IntModel,
    prev: [usize; 2],
    prev_group: usize,
    /// Bits spent on face groups while decoding (for `inspect`; not part of the format).
    group_bits: f64,
}

impl ConnModels {
    fn new(groups_v3: bool) -> Self {
        let (symbols, classes) = if groups_v3 {
            (GROUP_SYMBOLS_V3, GROUP_CLASSES_V3)
        } else {
            (GROUP_SYMBOLS, 3)
        };
        ConnModels {
            labels: vec![FreqModel::with_counts(&LABEL_PRIOR); LABEL_CONTEXTS],
            face_degree: IntModel::default(),
            hole_degree: IntModel::default(),
            m_depth: IntModel::default(),
            m_length: IntModel::default(),
            groups: vec![FreqModel::new(symbols); classes * (symbols + 1)],
            groups_v3,
            recent: IntModel::default(),
            prev: [LABEL_CONTEXT_NONE; 2],
            prev_group: symbols,
            group_bits: 0.0,
        }
    }

    fn ctx(&self) -> usize {
        self.prev[0] * (LABEL_SYMBOLS + 1) + self.prev[1]
    }

    fn push(&mut self, s: usize) {
        self.prev = [self.prev[1], s];
    }

    #[cfg(any(feature = "encoder", feature = "internals"))]
    fn encode_label(&mut self, enc: &mut RangeEncoder, l: Label) {
        let s = match l {
            Label::F(3) => SYM_F3,
            Label::F(4) => SYM_F4,
            Label::F(5) => SYM_F5,
            Label::F(_) => SYM_FX,
            Label::R => SYM_R,
            Label::L => SYM_L,
            Label::S => SYM_S,
            Label::E => SYM_E,
            Label::H(_) => SYM_H,
            Label::M { .. } => SYM_M,
        };
        let c = self.ctx();
        self.labels[c].encode(enc, s);
        self.push(s);
        match l {
            Label::F(d) if d >= 6 => self.face_degree.encode(enc, d - 6),
            Label::H(d) => self.hole_degree.encode(enc, d - 3),
            Label::M { i, k, l } => {
                self.m_depth.encode(enc, i);
                self.m_length.encode(enc, l - 2);
                encode_below(enc, k, l);
            }
            _ => {}
        }
    }

    fn decode_label(&mut self, dec: &mut RangeDecoder, max_degree: u32) -> Result<Label> {
        let c = self.ctx();
        let s = self.labels[c].decode(dec)?;
        self.push(s);
        let max_extra = max_degree.saturating_sub(3);
        Ok(match s {
            SYM_F3 => Label::F(3),
            SYM_F4 => Label::F(4),
            SYM_F5 => Label::F(5),
            SYM_FX => Label::F(6 + self.face_degree.decode(dec, max_extra, "face_degree")?),
            SYM_R => Label::R,
            SYM_L => Label::L,
            SYM_S => Label::S,
            SYM_E => Label::E,
            SYM_H => Label::H(3 + self.hole_degree.decode(dec, max_extra, "hole_degree")?),
            _ => {
                let i = self.m_depth.decode(dec, max_degree, "merge_depth")?;
                let l = 2 + self.m_length.decode(dec, max_extra, "merge_length")?;
                let k = decode_below(dec, l)?;
                if k >= l {
                    return Err(Error::format(
                        "connectivity",
                        "merge_offset",
                        format!("offset {k} not below the boundary length {l}"),
                    ));
                }
                Label::M { i, k, l }
            }
        })
    }

    /// Context: class (versions 1-2: number of candidates 0-1, 2, 3+; version 3:
    /// [`group_class`]) x previous group symbol.
    fn group_ctx(&self, class: usize) -> usize {
        let symbols = if self.groups_v3 {
            GROUP_SYMBOLS_V3
        } else {
            GROUP_SYMBOLS
        };
        class * (symbols + 1) + self.prev_group
    }

    /// Encodes a version-3 group symbol (`seen` groups used so far). The encoder never makes
    /// `Explicit` (versions 1-2 only).
    #[cfg(any(feature = "encoder", feature = "internals"))]
    fn encode_group(&mut self, enc: &mut RangeEncoder, g: GroupSym, class: usize, seen: u32) {
        debug_assert!(!matches!(g, GroupSym::Explicit(_)));
        let s = match g {
            GroupSym::Candidate(i) => usize::from(i),
            GroupSym::New => GROUP_CANDIDATES,
            GroupSym::Recent(_) | GroupSym::Explicit(_) => GROUP_CANDIDATES + 1,
            GroupSym::Vertex(i) => GROUP_SYMBOLS + usize::from(i),
        };
        let c = self.group_ctx(class);
        self.groups[c].encode(enc, s);
        self.prev_group = s;
        if let GroupSym::Recent(r) = g {
            debug_assert!(r < seen);
            self.recent.encode(enc, r);
        }
    }

    /// Decodes a group symbol; `class` as in [`Self::group_ctx`]. With `MEASURE` (`inspect`)
    /// the bits the group symbols take are added up; a plain decode leaves that code out.
    fn decode_group<const MEASURE: bool>(
        &mut self,
        dec: &mut RangeDecoder,
        seen: u32,
        class: usize,
    ) -> Result<GroupSym> {
        let c = self.group_ctx(class);
        let s = if MEASURE {
            let (s, cost) = self.groups[c].decode_with_cost(dec)?;
            self.group_bits += cost;
            s
        } else {
            self.groups[c].decode(dec)?
        };
        self.prev_group = s;
        let no_groups = || {
            Error::format(
                "connectivity",
                "group_id",
                "an already used group, but no group is used yet",
            )
        };
        Ok(match s {
            i if i < GROUP_CANDIDATES => GroupSym::Candidate(i as u8),
            GROUP_CANDIDATES => GroupSym::New,
            i if i > GROUP_CANDIDATES + 1 => GroupSym::Vertex((i - GROUP_SYMBOLS) as u8),
            _ if self.groups_v3 => {
                let max = seen.checked_sub(1).ok_or_else(no_groups)?;
                let before = MEASURE.then(|| self.recent.clone());
                let r = self.recent.decode(dec, max, "group_rank")?;
                self.group_bits += before.map_or(0.0, |b| b.cost(r));
                GroupSym::Recent(r)
            }
            _ if LEGACY => {
                self.group_bits += f64::from(bits_for(u64::from(seen)));
                let id = decode_below(dec, seen)?;
                if id >= seen {
                    return Err(Error::format(
                        "connectivity",
                        "group_id",
                        format!("explicit group {id} but only {seen} groups seen so far"),
                    ));
                }
                GroupSym::Explicit(id)
            }
            _ => {
                return Err(Error::format(
                    "connectivity",
                    "group",
                    "symbol of an older version",
                ))
            }
        })
    }
}

/// The edges in label order (spec §7): the one edge each label after the first owns, as the
/// half-edge the traversal recorded for it.
fn label_edges(label_edge: &[u32]) -> Vec<u32> {
    label_edge.iter().copied().filter(|&h| h != NONE).collect()
}

/// A value below `bound` in `bits_for(bound)` direct bits, high part (above 16 bits) first
/// (spec §4.3; used for merge offsets, §6.2, and explicit group ids, §6.5).
#[cfg(any(feature = "encoder", feature = "internals"))]
fn encode_below(enc: &mut RangeEncoder, v: u32, bound: u32) {
    let b = bits_for(u64::from(bound));
    enc.encode_direct(v >> 16.min(b), b.saturating_sub(16));
    enc.encode_direct(v & 0xFFFF, b.min(16));
}

/// Reads what [`encode_below`] wrote; the caller checks the value against its bound and
/// names the field.
fn decode_below(dec: &mut RangeDecoder, bound: u32) -> Result<u32> {
    let b = bits_for(u64::from(bound));
    let hi = dec.decode_direct(b.saturating_sub(16))?;
    let lo = dec.decode_direct(b.min(16))?;
    Ok((hi << 16.min(b)) | lo)
}

/// Candidate groups of mesh face `f` (spec §6.4): the distinct groups of the mesh faces
/// across its edges that precede it in encoding order, in the order of its half-edges from
/// the entry half-edge; when there are none, the group of the previous mesh face. Returns
/// the work done (comparisons, at most degree x candidates), which the decoder charges.
fn group_candidates(
    rb: &Rebuilt,
    f: usize,
    face_group: &[u32],
    prev_real: Option<usize>,
    out: &mut Vec<u32>,
) -> u64 {
    out.clear();
    let rf = rb.faces[f];
    let mut h = rf.first;
    for _ in 0..rf.degree {
        let k = rb.face[rb.twin[h as usize] as usize] as usize;
        if k < f && !rb.faces[k].hole && !out.contains(&face_group[k]) {
            out.push(face_group[k]);
        }
        h = rb.next[h as usize];
    }
    if out.is_empty() {
        if let Some(p) = prev_real {
            out.push(face_group[p]);
        }
    }
    u64::from(rf.degree) * (out.len() as u64 + 1)
}

/// Version-3 context class of a face with candidate list `cands` (spec §6.5): 0 for at most
/// one candidate, 4 for three or more; with two, 1, 2 or 3 as the face has as many, more or
/// fewer edges to earlier faces of the first candidate's group than of the second's.
fn group_class(rb: &Rebuilt, f: usize, face_group: &[u32], cands: &[u32]) -> usize {
    match cands.len() {
        0 | 1 => 0,
        2 => {
            let (mut n0, mut n1) = (0u32, 0u32);
            let rf = rb.faces[f];
            let mut h = rf.first;
            for _ in 0..rf.degree {
                let k = rb.face[rb.twin[h as usize] as usize] as usize;
                if k < f && !rb.faces[k].hole {
                    n0 += u32::from(face_group[k] == cands[0]);
                    n1 += u32::from(face_group[k] == cands[1]);
                }
                h = rb.next[h as usize];
            }
            match n0.cmp(&n1) {
                std::cmp::Ordering::Equal => 1,
                std::cmp::Ordering::Greater => 2,
                std::cmp::Ordering::Less => 3,
            }
        }
        _ => 4,
    }
}

/// Version-3 vertex candidates of mesh face `f` (spec §6.5): for the face's vertices in
/// cycle order from the entry half-edge, the faces around each vertex in rotation order
/// (from its first outgoing half-edge, `next = twin(prev(h))`); the groups of those that are
/// earlier mesh faces, each once, not among the edge candidates `cands`; at most
/// `GROUP_CANDIDATES`. Returns the work done (rotation steps times the comparisons of each),
/// which the decoder charges: around a vertex of high valence the walk is long.
fn vertex_candidates(
    rb: &Rebuilt,
    f: usize,
    face_group: &[u32],
    cands: &[u32],
    out: &mut Vec<u32>,
) -> u64 {
    out.clear();
    let rf = rb.faces[f];
    let mut h = rf.first;
    let mut steps = 0u64;
    'vertices: for _ in 0..rf.degree {
        let start = rb.vertex_out[rb.vertex[h as usize] as usize];
        let mut e = start;
        for _ in 0..rb.next.len() {
            steps += 1;
            let k = rb.face[e as usize] as usize;
            if k < f && !rb.faces[k].hole {
                let g = face_group[k];
                if !cands.contains(&g) && !out.contains(&g) {
                    out.push(g);
                    if out.len() == GROUP_CANDIDATES {
                        break 'vertices;
                    }
                }
            }
            e = rb.twin[rb.prev[e as usize] as usize];
            if e == start {
                break;
            }
        }
        h = rb.next[h as usize];
    }
    steps * (cands.len() as u64 + 1)
}

/// Recency order of the groups used so far (version 3, §6.5): each used group's last face,
/// flagged in a Fenwick tree over faces, so the rank "groups used since" and its inverse are
/// O(log n).
struct Recency {
    last_face: Vec<u32>,
    flags: ranks::Flags,
    used: u32,
}

impl Recency {
    fn new(groups: usize, faces: usize) -> Self {
        Recency {
            last_face: vec![NONE; groups],
            flags: ranks::Flags::none(faces),
            used: 0,
        }
    }

    /// Number of groups used since group `g` was (`g` used before).
    #[cfg(any(feature = "encoder", feature = "internals"))]
    fn rank_of(&self, g: u32) -> u32 {
        self.used - 1 - self.flags.rank(self.last_face[g as usize] as usize)
    }

    /// The face whose group has recency rank `r` (`r < used`).
    fn face_of(&self, r: u32) -> usize {
        self.flags.select(self.used - 1 - r)
    }

    fn assign(&mut self, g: u32, face: usize) {
        match self.last_face[g as usize] {
            NONE => self.used += 1,
            last => self.flags.take(last as usize),
        }
        self.flags.put(face);
        self.last_face[g as usize] = face as u32;
    }
}

// ------------------------------------------------------------------------------------------
// Crease coding (spec §7)

trait BitCoder {
    fn bit(&mut self, model: &mut BitModel, slot: &mut bool) -> Result<()>;
}

#[cfg(any(feature = "encoder", feature = "internals"))]
impl BitCoder for RangeEncoder {
    fn bit(&mut self, model: &mut BitModel, slot: &mut bool) -> Result<()> {
        self.encode_bit(model, *slot);
        Ok(())
    }
}

impl BitCoder for RangeDecoder<'_> {
    fn bit(&mut self, model: &mut BitModel, slot: &mut bool) -> Result<()> {
        *slot = self.decode_bit(model)?;
        Ok(())
    }
}

/// Codes the sharp flag of every edge (label order) and the corner flag of every coded
/// vertex. `sharp[j]` is indexed by edge number (label order), `corner` by coded vertex.
/// Returns per half-edge whether its edge is a crease (sharp or on the mesh boundary), which
/// the corner contexts and the geometry predictions (§8.2) both use.
fn code_creases(
    rb: &Rebuilt,
    edges: &[u32],
    face_group: &[u32],
    sharp: &mut [bool],
    corner: &mut [bool],
    coder: &mut impl BitCoder,
) -> Result<Vec<bool>> {
    let mut sharp_models = [BitModel::default(); 13];
    let mut count = vec![0u8; corner.len()];
    for (j, &h) in edges.iter().enumerate() {
        let t = rb.twin[h as usize];
        let (a, b) = (
            rb.vertex[h as usize] as usize,
            rb.vertex[t as usize] as usize,
        );
        let ctx = if rb.is_hole(h) || rb.is_hole(t) {
            12
        } else {
            let (ca, cb) = (count[a].min(2) as usize, count[b].min(2) as usize);
            let (lo, hi) = (ca.min(cb), ca.max(cb));
            let pair = lo * 3 + hi - lo * (lo + 1) / 2;
            let same = face_group[rb.face[h as usize] as usize]
                == face_group[rb.face[t as usize] as usize];
            pair * 2 + usize::from(same)
        };
        coder.bit(&mut sharp_models[ctx], &mut sharp[j])?;
        if sharp[j] {
            count[a] = count[a].saturating_add(1);
            count[b] = count[b].saturating_add(1);
        }
    }
    let mut crease = vec![false; rb.next.len()];
    let mut crease_degree = vec![0u8; corner.len()];
    for (j, &h) in edges.iter().enumerate() {
        let t = rb.twin[h as usize];
        if sharp[j] || rb.is_hole(h) || rb.is_hole(t) {
            crease[h as usize] = true;
            crease[t as usize] = true;
            for v in [rb.vertex[h as usize], rb.vertex[t as usize]] {
                crease_degree[v as usize] = crease_degree[v as usize].saturating_add(1);
            }
        }
    }
    let mut corner_models = [BitModel::default(); 4];
    for (v, c) in corner.iter_mut().enumerate() {
        coder.bit(&mut corner_models[crease_degree[v].min(3) as usize], c)?;
    }
    Ok(crease)
}

#[cfg(any(feature = "encoder", feature = "internals"))]
fn zigzag64(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

fn unzigzag64(u: u64) -> i64 {
    ((u >> 1) as i64) ^ -((u & 1) as i64)
}

// ------------------------------------------------------------------------------------------
// Encoder

/// Encodes a mesh. See [`encode_with_map`].
#[cfg(any(feature = "encoder", feature = "internals"))]
pub fn encode(mesh: &ControlMesh, opts: &EncodeOptions) -> Result<Vec<u8>> {
    encode_with_map(mesh, opts).map(|(b, _)| b)
}

/// Encodes a mesh and returns the bytes plus the renumbering the decoder will see.
///
/// Raw meshes (`Content::RawMesh`) with non-manifold edges or vertices are cut apart and
/// re-merged by the decoder (`fixups` section); a non-manifold control mesh is an error.
/// Every sharp edge must be an edge of the mesh.
#[cfg(any(feature = "encoder", feature = "internals"))]
pub fn encode_with_map(mesh: &ControlMesh, opts: &EncodeOptions) -> Result<(Vec<u8>, EncodeMap)> {
    check_encode_input(mesh, opts)?;
    let bits = opts.quantization_bits;
    let raw = opts.content == Content::RawMesh;
    let (cut, source, he) = manifold_half_edges(mesh, raw)?;
    let work = cut.as_ref().unwrap_or(mesh);
    let tr = encode_traversal(&he);
    let rb = rebuild(&tr.labels, &mut Budget::unlimited())
        .map_err(|e| internal_error(&e.to_string()))?;
    if rb.faces.len() != tr.faces.len() {
        return Err(internal_error("face count mismatch"));
    }

    let coded = number_coded_vertices(&rb, &tr.faces, &he, work.vertex_count())?;
    let orig_of_coded: Vec<u32> = coded.to_work.iter().map(|&w| source[w as usize]).collect();
    let (rep_of_orig, merges) = merges_of_copies(&orig_of_coded, mesh.vertex_count());
    let final_of_coded = final_numbering(coded.to_work.len(), &merges);
    let groups = code_groups(mesh, &rb, &coded.face_source);
    let group_count = mesh.groups.len() as u64;
    let conn = connectivity_section(&tr.labels, &groups.syms, group_count);

    // Patches section.
    let quant = encode_quantizer(mesh, opts)?;
    let (patches, group_axes) = patches::encode(&groups.coded_order, &quant)?;

    // Creases section.
    let edges = label_edges(&rb.label_edge);
    let mut sharp = sharp_edge_flags(mesh, &rb, &edges, &orig_of_coded)?;
    let mut corner: Vec<bool> = orig_of_coded
        .iter()
        .map(|o| mesh.corners.contains(o))
        .collect();
    let mut creases_enc = RangeEncoder::new();
    let crease_he = code_creases(
        &rb,
        &edges,
        &groups.face_group,
        &mut sharp,
        &mut corner,
        &mut creases_enc,
    )?;
    let creases = creases_enc.finish();

    // Geometry section.
    let q: Vec<[i32; 3]> = coded
        .to_work
        .iter()
        .map(|&w| quant.quantize(work.positions[w as usize]))
        .collect();
    let geometry = geometry_section(&rb, &groups, &group_axes, &crease_he, bits, q)?;

    let store_names =
        opts.store_group_names && groups.coded_order.iter().any(|g| !g.name.is_empty());
    let header = HeaderFields {
        content: opts.content,
        bits,
        isolated: coded.isolated,
        merges: merges.len() as u64,
        quant: &quant,
        patches: patches.is_some(),
        names: store_names,
    }
    .section(mesh);

    let mut out = Vec::new();
    out.extend_from_slice(&MAGIC);
    out.push(FORMAT_VERSION_MAJOR);
    out.push(FORMAT_VERSION_MINOR);
    put_section(&mut out, SEC_HEADER, &header, false, true);
    put_section(&mut out, SEC_CONNECTIVITY, &conn, true, false);
    if let Some(p) = patches {
        put_section(&mut out, SEC_PATCHES, &p, true, false);
    }
    put_section(&mut out, SEC_CREASES, &creases, true, false);
    put_section(&mut out, SEC_GEOMETRY, &geometry, true, false);
    if !merges.is_empty() {
        put_section(&mut out, SEC_FIXUPS, &fixups_section(&merges), true, false);
    }
    if store_names {
        let payload = names_section(mesh, &groups.group_new);
        put_section(&mut out, SEC_NAMES, &payload, true, false);
    }

    let vertex: Vec<u32> = (0..mesh.vertex_count())
        .map(|v| final_of_coded[rep_of_orig[v] as usize])
        .collect();
    let face = mesh_face_numbering(mesh, &rb, &coded.face_source);
    // With names stored, the decoder restores the input's group order.
    let group = if store_names {
        (0..mesh.groups.len() as u32).collect()
    } else {
        groups.group_new
    };
    Ok((
        out,
        EncodeMap {
            vertex,
            face,
            group,
        },
    ))
}

/// The checks [`encode_with_map`] makes before any work: the options' ranges, and a valid
/// mesh with a finite extent whose faces have groups.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn check_encode_input(mesh: &ControlMesh, opts: &EncodeOptions) -> Result<()> {
    let bits = opts.quantization_bits;
    if !(4..=24).contains(&bits) {
        return Err(Error::Parameter(format!(
            "quantization bits must be in 4..=24, got {bits}"
        )));
    }
    if !(1.0..=f64::from(1u32 << 24)).contains(&opts.step_scale) {
        return Err(Error::Parameter(format!(
            "the grid step scale must be in 1..=2^24, got {}",
            opts.step_scale
        )));
    }
    if let Some([lo, hi]) = opts.grid_covers {
        if !(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all()) {
            return Err(Error::Parameter(format!(
                "the grid's box must be finite with min <= max, got {lo} .. {hi}"
            )));
        }
    }
    mesh.validate()?;
    mesh.check_extent()?;
    if mesh.face_count() > 0 && mesh.groups.is_empty() {
        return Err(Error::Mesh("faces but no groups".into()));
    }
    Ok(())
}

/// The half-edge structure the encoder traverses. A non-manifold raw mesh (`raw`) is cut
/// apart first: then also the cut mesh and the input vertex of each of its vertices, else
/// `None` and the identity.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn manifold_half_edges(
    mesh: &ControlMesh,
    raw: bool,
) -> Result<(Option<ControlMesh>, Vec<u32>, HalfEdgeMesh)> {
    match HalfEdgeMesh::build(mesh) {
        Ok(he) => Ok((None, (0..mesh.vertex_count() as u32).collect(), he)),
        Err(e) if raw => {
            let (c, s) = cut_non_manifold(mesh)?;
            let he = HalfEdgeMesh::build(&c).map_err(|e2| {
                Error::Mesh(format!("{e}; cutting the mesh apart did not help: {e2}"))
            })?;
            Ok((Some(c), s, he))
        }
        Err(e) => Err(Error::Mesh(format!("control mesh is not manifold: {e}"))),
    }
}

/// An error for an encoder invariant that does not hold (a bug, not a bad input).
#[cfg(any(feature = "encoder", feature = "internals"))]
fn internal_error(what: &str) -> Error {
    Error::Mesh(format!("internal encoder error: {what}"))
}

/// How the rebuilt (coded) structure maps onto the mesh the encoder traversed.
#[cfg(any(feature = "encoder", feature = "internals"))]
struct CodedVertices {
    /// Traversed-mesh vertex of every coded vertex: the traversal's vertices in their coded
    /// order, then those the traversal does not reach.
    to_work: Vec<u32>,
    /// Traversed-mesh face of every rebuilt face.
    face_source: Vec<u32>,
    /// Number of vertices the traversal does not reach.
    isolated: u64,
}

/// Maps the rebuilt vertices and faces to those of `he` (mesh of `nw` vertices), whose
/// traversal entered face `tr_faces[i]` for rebuilt face `i`; the vertices no face reaches
/// are numbered after the others.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn number_coded_vertices(
    rb: &Rebuilt,
    tr_faces: &[(u32, u32)],
    he: &HalfEdgeMesh,
    nw: usize,
) -> Result<CodedVertices> {
    let mut coded_to_work = vec![NONE; nw];
    let mut work_to_coded = vec![NONE; nw];
    let mut rebuilt_face_source = vec![NONE; rb.faces.len()];
    for (i, rf) in rb.faces.iter().enumerate() {
        let (f, entry) = tr_faces[i];
        rebuilt_face_source[i] = f;
        let (mut hr, mut ho) = (rf.first, entry);
        for _ in 0..rf.degree {
            let (c, w) = (rb.vertex[hr as usize], he.origin[ho as usize]);
            if coded_to_work[c as usize] == NONE && work_to_coded[w as usize] == NONE {
                coded_to_work[c as usize] = w;
                work_to_coded[w as usize] = c;
            } else if coded_to_work[c as usize] != w {
                return Err(internal_error("vertex mapping mismatch"));
            }
            hr = rb.next[hr as usize];
            ho = he.next[ho as usize];
        }
    }
    let traversal_vertices = rb.vertex_count;
    let mut isolated = 0u64;
    let mut next_coded = traversal_vertices as u32;
    for (w, wc) in work_to_coded.iter_mut().enumerate() {
        if *wc == NONE {
            *wc = next_coded;
            coded_to_work[next_coded as usize] = w as u32;
            next_coded += 1;
            isolated += 1;
        }
    }
    Ok(CodedVertices {
        to_work: coded_to_work,
        face_source: rebuilt_face_source,
        isolated,
    })
}

/// Merges: every coded copy of an input vertex merges into the lowest coded copy. Returns
/// that representative for each of the `input_vertices` input vertices, and the
/// `(copy, representative)` pairs, copies ascending.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn merges_of_copies(orig_of_coded: &[u32], input_vertices: usize) -> (Vec<u32>, Vec<(u32, u32)>) {
    let mut rep_of_orig = vec![NONE; input_vertices];
    for (c, &o) in orig_of_coded.iter().enumerate() {
        if rep_of_orig[o as usize] == NONE {
            rep_of_orig[o as usize] = c as u32;
        }
    }
    let merges: Vec<(u32, u32)> = orig_of_coded
        .iter()
        .enumerate()
        .filter(|&(c, &o)| rep_of_orig[o as usize] != c as u32)
        .map(|(c, &o)| (c as u32, rep_of_orig[o as usize]))
        .collect();
    (rep_of_orig, merges)
}

/// The groups as the connectivity section codes them (spec §6.5).
#[cfg(any(feature = "encoder", feature = "internals"))]
struct GroupCoding {
    /// Coded id of every input group: by first appearance in encoding order, unused groups
    /// at the end.
    group_new: Vec<u32>,
    /// Coded group of every rebuilt face (`NONE` for holes).
    face_group: Vec<u32>,
    /// Per mesh face in encoding order: its group's symbol, context class, and the number of
    /// groups seen before it.
    syms: Vec<(GroupSym, usize, u32)>,
    /// The input's groups in coded order.
    coded_order: Vec<Group>,
}

/// Numbers the groups by first appearance in encoding order and finds the symbol that codes
/// each mesh face's group (`face_source`: the input face of each rebuilt face).
#[cfg(any(feature = "encoder", feature = "internals"))]
fn code_groups(mesh: &ControlMesh, rb: &Rebuilt, face_source: &[u32]) -> GroupCoding {
    let mut group_new = vec![NONE; mesh.groups.len()];
    let mut next_group = 0u32;
    let mut face_group_new = vec![NONE; rb.faces.len()];
    let mut group_syms = Vec::new();
    let mut prev_real = None;
    let (mut cands, mut vcands) = (Vec::new(), Vec::new());
    let mut recency = Recency::new(mesh.groups.len(), rb.faces.len());
    for (i, rf) in rb.faces.iter().enumerate() {
        if rf.hole {
            continue;
        }
        let og = mesh.face_groups[face_source[i] as usize] as usize;
        group_candidates(rb, i, &face_group_new, prev_real, &mut cands);
        let class = group_class(rb, i, &face_group_new, &cands);
        let seen = next_group;
        let sym = if group_new[og] == NONE {
            group_new[og] = next_group;
            next_group += 1;
            GroupSym::New
        } else {
            let g = group_new[og];
            match cands.iter().take(GROUP_CANDIDATES).position(|&c| c == g) {
                Some(c) => GroupSym::Candidate(c as u8),
                None => {
                    vertex_candidates(rb, i, &face_group_new, &cands, &mut vcands);
                    match vcands.iter().position(|&c| c == g) {
                        Some(c) => GroupSym::Vertex(c as u8),
                        None => GroupSym::Recent(recency.rank_of(g)),
                    }
                }
            }
        };
        group_syms.push((sym, class, seen));
        face_group_new[i] = group_new[og];
        recency.assign(group_new[og], i);
        prev_real = Some(i);
    }
    for g in group_new.iter_mut().filter(|g| **g == NONE) {
        *g = next_group;
        next_group += 1;
    }
    let mut groups_new_order = vec![Group::default(); mesh.groups.len()];
    for (og, &ng) in group_new.iter().enumerate() {
        groups_new_order[ng as usize] = mesh.groups[og].clone();
    }
    GroupCoding {
        group_new,
        face_group: face_group_new,
        syms: group_syms,
        coded_order: groups_new_order,
    }
}

/// The connectivity section: the label count, then the labels and (with more than one
/// group) the group symbols, range coded.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn connectivity_section(
    labels: &[Label],
    group_syms: &[(GroupSym, usize, u32)],
    group_count: u64,
) -> Vec<u8> {
    let mut conn = Vec::new();
    put_varint(&mut conn, labels.len() as u64);
    let mut enc = RangeEncoder::new();
    let mut models = ConnModels::new(true);
    for &l in labels {
        models.encode_label(&mut enc, l);
    }
    if group_count > 1 {
        for &(sym, class, seen) in group_syms {
            models.encode_group(&mut enc, sym, class, seen);
        }
    }
    conn.extend_from_slice(&enc.finish());
    conn
}

/// The quantisation grid over the mesh's positions (and the box `opts.grid_covers`, when
/// given). Fails when the grid's box overflows f64.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn encode_quantizer(mesh: &ControlMesh, opts: &EncodeOptions) -> Result<Quantizer> {
    let bits = opts.quantization_bits;
    let quant = match opts.grid_covers {
        None => Quantizer::for_positions(&mesh.positions, bits, opts.step_scale),
        Some(corners) => {
            let mut covered = mesh.positions.clone();
            covered.extend(corners);
            Quantizer::for_positions(&covered, bits, opts.step_scale)
        }
    };
    if !quant.extent.is_finite() {
        // A finite diagonal leaves room for this only through `step_scale` or `grid_covers`.
        return Err(Error::Parameter(format!(
            "the quantisation grid's box overflows f64: the vertices' extent {:e} times the \
             step scale {} (with the box the grid must cover) is not finite",
            mesh.bounding_box()
                .map_or(0.0, |(lo, hi)| (hi - lo).max_element()),
            opts.step_scale
        )));
    }
    Ok(quant)
}

/// The sharp flag of every edge (label order: `edges`), from the mesh's sharp edges between
/// input vertices. Fails when a sharp edge is not an edge of the mesh.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn sharp_edge_flags(
    mesh: &ControlMesh,
    rb: &Rebuilt,
    edges: &[u32],
    orig_of_coded: &[u32],
) -> Result<Vec<bool>> {
    let mut sharp = vec![false; edges.len()];
    let mut matched = BTreeSet::new();
    for (j, &h) in edges.iter().enumerate() {
        let t = rb.twin[h as usize];
        let key = edge_key(
            orig_of_coded[rb.vertex[h as usize] as usize],
            orig_of_coded[rb.vertex[t as usize] as usize],
        );
        if mesh.sharp_edges.contains(&key) {
            sharp[j] = true;
            matched.insert(key);
        }
    }
    if matched.len() != mesh.sharp_edges.len() {
        let missing = mesh.sharp_edges.iter().find(|k| !matched.contains(k));
        return Err(Error::Mesh(format!(
            "sharp edge {missing:?} is not an edge of the mesh"
        )));
    }
    Ok(sharp)
}

/// The geometry section: the grid points `q` of the coded vertices, walked as the current
/// version does (predictions along the creases `crease_he`, arcs round the groups' axes).
#[cfg(any(feature = "encoder", feature = "internals"))]
fn geometry_section(
    rb: &Rebuilt,
    groups: &GroupCoding,
    group_axes: &[Option<geometry::GridAxis>],
    crease_he: &[bool],
    bits: u8,
    mut q: Vec<[i32; 3]>,
) -> Result<Vec<u8>> {
    let kinds: Vec<PatchKind> = groups.coded_order.iter().map(|g| g.patch).collect();
    let face_plane_group = plane_groups_of_faces(&groups.face_group, &kinds);
    let (face_axis, axes) = patches::face_axes(&groups.face_group, group_axes);
    let mut geom_enc = RangeEncoder::new();
    let mut ge = GeomEncoder::new(&mut geom_enc);
    geometry::walk(
        rb,
        &face_plane_group,
        groups.coded_order.len(),
        bits,
        Some(crease_he),
        (!axes.is_empty()).then_some(&ArcAxes {
            face_axis: &face_axis,
            axes: &axes,
        }),
        &mut q,
        &mut ge,
    )?;
    Ok(geom_enc.finish())
}

/// What the header section records besides the mesh's own counts.
#[cfg(any(feature = "encoder", feature = "internals"))]
struct HeaderFields<'a> {
    content: Content,
    bits: u8,
    /// Vertices the traversal does not reach.
    isolated: u64,
    /// Number of `(copy, representative)` merges.
    merges: u64,
    quant: &'a Quantizer,
    /// Whether the file has a patches section / a names section.
    patches: bool,
    names: bool,
}

#[cfg(any(feature = "encoder", feature = "internals"))]
impl HeaderFields<'_> {
    /// The header's flag bits.
    fn flags(&self) -> u64 {
        let mut flags = 0u64;
        if let Content::ControlMesh { .. } = self.content {
            flags |= FLAG_CONTROL_MESH;
        }
        if !self.quant.as_f32 {
            flags |= FLAG_BOX_F64;
        }
        if self.isolated > 0 {
            flags |= FLAG_ISOLATED;
        }
        if self.merges > 0 {
            flags |= FLAG_MERGES;
        }
        if self.patches {
            flags |= FLAG_PATCHES;
        }
        if self.names {
            flags |= FLAG_NAMES;
        }
        flags
    }

    /// The header section's payload for `mesh` (spec §5).
    fn section(&self, mesh: &ControlMesh) -> Vec<u8> {
        let mut header = Vec::new();
        put_varint(&mut header, self.flags());
        if let Content::ControlMesh { default_level } = self.content {
            header.push(default_level);
        }
        header.push(self.bits);
        put_varint(&mut header, mesh.vertex_count() as u64);
        put_varint(&mut header, mesh.face_count() as u64);
        put_varint(&mut header, mesh.face_vertices.len() as u64);
        put_varint(&mut header, mesh.groups.len() as u64);
        if self.isolated > 0 {
            put_varint(&mut header, self.isolated);
        }
        if self.merges > 0 {
            put_varint(&mut header, self.merges);
        }
        let quant = self.quant;
        for v in quant.min.iter().chain(std::iter::once(&quant.extent)) {
            if quant.as_f32 {
                header.extend_from_slice(&(*v as f32).to_le_bytes());
            } else {
                header.extend_from_slice(&v.to_le_bytes());
            }
        }
        header
    }
}

/// The fixups section: per merge, the gap from the previous copy and how far back its
/// representative is.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn fixups_section(merges: &[(u32, u32)]) -> Vec<u8> {
    let mut fx = Vec::new();
    let mut prev: i64 = -1;
    for &(d, r) in merges {
        put_varint(&mut fx, (i64::from(d) - prev - 1) as u64);
        put_varint(&mut fx, u64::from(d - r - 1));
        prev = i64::from(d);
    }
    fx
}

/// The names section: the input's group names, and the input group of every coded group
/// (`group_new`: the coded id of every input group).
#[cfg(any(feature = "encoder", feature = "internals"))]
fn names_section(mesh: &ControlMesh, group_new: &[u32]) -> Vec<u8> {
    let input_names: Vec<&str> = mesh.groups.iter().map(|g| g.name.as_str()).collect();
    let mut input_of_coded = vec![0u32; group_new.len()];
    for (og, &ng) in group_new.iter().enumerate() {
        input_of_coded[ng as usize] = og as u32;
    }
    names::write(&input_names, &input_of_coded)
}

/// The decoded id of every input face: the mesh faces numbered in encoding order
/// (`face_source`: the input face of each rebuilt face).
#[cfg(any(feature = "encoder", feature = "internals"))]
fn mesh_face_numbering(mesh: &ControlMesh, rb: &Rebuilt, face_source: &[u32]) -> Vec<u32> {
    let mut face = vec![NONE; mesh.face_count()];
    let mut next_face = 0u32;
    for (i, rf) in rb.faces.iter().enumerate() {
        if !rf.hole {
            face[face_source[i] as usize] = next_face;
            next_face += 1;
        }
    }
    face
}

/// Final vertex id of every coded vertex after the merges (`(copy, representative)` pairs,
/// copies ascending, representatives not themselves copies).
fn final_numbering(coded_count: usize, merges: &[(u32, u32)]) -> Vec<u32> {
    let mut removed = vec![NONE; coded_count];
    for &(d, r) in merges {
        removed[d as usize] = r;
    }
    let mut fin = vec![NONE; coded_count];
    let mut next = 0u32;
    for c in 0..coded_count {
        if removed[c] == NONE {
            fin[c] = next;
            next += 1;
        }
    }
    for c in 0..coded_count {
        if removed[c] != NONE {
            fin[c] = fin[removed[c] as usize];
        }
    }
    fin
}

fn plane_groups_of_faces(face_group: &[u32], kinds: &[PatchKind]) -> Vec<u32> {
    face_group
        .iter()
        .map(|&g| match kinds.get(g as usize) {
            Some(PatchKind::Boundary(BoundarySurface::Plane)) => g,
            _ => NONE,
        })
        .collect()
}

// ------------------------------------------------------------------------------------------
// Decoder

/// Decodes a file. Every malformed input gives `Error::Format` or `Error::LimitsExceeded`.
#[cfg(any(feature = "encoder", feature = "internals"))]
pub fn decode(bytes: &[u8], limits: &Limits) -> Result<Decoded> {
    decode_full::<false>(bytes, limits, &mut Budget::new(limits.max_memory)).map(|(d, _)| d)
}

/// Decodes a file and reports what the decode charged against `limits` (also when it
/// fails): the bytes charged against `max_memory` and the walk steps against the work bound.
pub fn decode_with_usage(bytes: &[u8], limits: &Limits) -> (Result<Decoded>, Usage) {
    let mut budget = Budget::new(limits.max_memory);
    let decoded = decode_full::<false>(bytes, limits, &mut budget).map(|(d, _)| d);
    (decoded, budget.usage)
}

/// Header, section sizes and summary counts of a file (decodes it fully).
pub fn inspect(bytes: &[u8], limits: &Limits) -> Result<FileInfo> {
    let (Decoded { header, mesh }, summary) =
        decode_full::<true>(bytes, limits, &mut Budget::new(limits.max_memory))?;
    Ok(FileInfo {
        header,
        sections: summary.sections,
        total_bytes: bytes.len(),
        sharp_edge_count: mesh.sharp_edges.len(),
        corner_count: mesh.corners.len(),
        patch_kinds: mesh.groups.iter().map(|g| g.patch).collect(),
        group_names: mesh.groups.into_iter().map(|g| g.name).collect(),
        component_count: summary.component_count,
        label_count: summary.label_count,
        group_bits: summary.group_bits,
    })
}

fn limit(what: &'static str, value: u64, max: u64) -> Result<()> {
    if value > max {
        return Err(Error::LimitsExceeded {
            what,
            value,
            limit: max,
        });
    }
    Ok(())
}

fn parse_header(
    payload: &[u8],
    major: u8,
    minor: u8,
    limits: &Limits,
) -> Result<(Header, Quantizer)> {
    let features = features_for(major, minor)?;
    let mut r = Reader::new(payload, "header");
    let flags = r.varint("flags")?;
    if flags & !features.known_flags != 0 {
        return Err(r.err(
            "flags",
            format!("unknown flag bits {:#x}", flags & !features.known_flags),
        ));
    }
    let content = if flags & FLAG_CONTROL_MESH != 0 {
        Content::ControlMesh {
            default_level: r.u8("default_level")?,
        }
    } else {
        Content::RawMesh
    };
    let bits = r.u8("quantization_bits")?;
    if !(4..=24).contains(&bits) {
        return Err(r.err("quantization_bits", format!("{bits} is outside 4..=24")));
    }
    let vertex_count = r.varint("vertex_count")?;
    limit("vertex count", vertex_count, limits.max_vertices)?;
    let face_count = r.varint("face_count")?;
    limit("face count", face_count, limits.max_faces)?;
    let corners = r.varint("face_corner_count")?;
    limit("face corner count", corners, limits.max_face_corners)?;
    if corners < 3 * face_count || corners > u64::from(u32::MAX / 4) {
        return Err(r.err(
            "face_corner_count",
            format!("{corners} corners cannot form {face_count} faces"),
        ));
    }
    let group_count = r.varint("group_count")?;
    limit("group count", group_count, limits.max_groups)?;
    if face_count > 0 && group_count == 0 {
        return Err(r.err("group_count", "faces without groups"));
    }
    let isolated = if flags & FLAG_ISOLATED != 0 {
        r.varint_max("isolated_vertex_count", vertex_count)?
    } else {
        0
    };
    let merges = if flags & FLAG_MERGES != 0 {
        r.varint_max("merged_vertex_count", corners)?
    } else {
        0
    };
    let mut vals = [0.0f64; 4];
    for v in &mut vals {
        *v = if flags & FLAG_BOX_F64 != 0 {
            r.f64("bbox")?
        } else {
            f64::from(r.f32("bbox")?)
        };
    }
    if vals.iter().any(|v| !v.is_finite()) || vals[3] < 0.0 {
        return Err(r.err(
            "bbox",
            "bounding box is not finite or has a negative extent",
        ));
    }
    r.expect_end()?;
    if let Content::ControlMesh { default_level } = content {
        // The triangles a decode at the default level makes: the fan-triangulated faces
        // (K - 2F) times 4^level.
        let scale = 1u64
            .checked_shl(2 * u32::from(default_level))
            .unwrap_or(u64::MAX);
        limit(
            "subdivided faces at the default level",
            (corners - 2 * face_count).saturating_mul(scale),
            limits.max_subdivided_faces,
        )?;
    }
    let header = Header {
        version_major: major,
        version_minor: minor,
        flags,
        content,
        quantization_bits: bits,
        bbox_min: [vals[0], vals[1], vals[2]],
        bbox_extent: vals[3],
        vertex_count,
        face_count,
        face_corner_count: corners,
        group_count,
        isolated_vertex_count: isolated,
        merged_vertex_count: merges,
    };
    let quant = Quantizer {
        min: header.bbox_min,
        extent: header.bbox_extent,
        bits,
        as_f32: flags & FLAG_BOX_F64 == 0,
    };
    Ok((header, quant))
}

// Bytes the decoder allocates per element, charged against `Limits::max_memory` before the
// arrays exist and released when they are freed (`spec/format.md` §10.3); the rebuild charges
// its own arrays (`facefixer::rebuild`). Fixed numbers (the sizes on 64-bit targets, checked
// when compiling) rather than `size_of`, so whether a file fits a budget does not depend on
// the platform.
/// Per label: the label itself, from the label count until the rebuild is done.
const LABEL_BYTES: u64 = 16;
/// Held from the rebuild to the assembled mesh, per label: its edge and sharp flag.
const LABEL_ARRAY_BYTES: u64 = 4 + 1;
/// Per rebuilt face (holes included): its group and recency flag.
const FACE_BYTES: u64 = 4 + 4;
/// Per coded vertex: corner flag and two crease counts, grid point, merge flag, merge record
/// and the two numberings of the fixups.
const CODED_VERTEX_BYTES: u64 = 3 + 12 + 1 + 8 + 8;
/// Per output vertex: the validation's stamp.
const VERTEX_STAMP_BYTES: u64 = 4;
/// Per group: patch kind decoded and reordered (2 x 64), grid axis (56) and axis list entry
/// (48), plane state (112), the group record and its name (88 + 24), another name slot (24),
/// and six u32 arrays (plane stamp, axis index, recency, name order, its rank flags, input
/// order).
const GROUP_BYTES: u64 = 2 * 64 + 56 + 48 + 112 + 88 + 24 + 24 + 6 * 4;
/// The crease flags and the geometry walk, per half-edge (crease flag), per rebuilt face
/// (plane group and axis) and per coded vertex (known flag, level, and the level buckets:
/// each vertex enters each of 6 buckets at most once, and a bucket's capacity is at most
/// twice its entries).
const GEOMETRY_HALF_EDGE_BYTES: u64 = 1;
const GEOMETRY_FACE_BYTES: u64 = 4 + 4;
const GEOMETRY_VERTEX_BYTES: u64 = 1 + 1 + 6 * 4 * 2;
/// The output mesh: per vertex its position, per face its offset and group, per corner its
/// vertex; the entries of the sets of sharp edges and corners (B-tree nodes, amortised).
const MESH_VERTEX_BYTES: u64 = 24;
const MESH_FACE_BYTES: u64 = 8 + 4;
const MESH_CORNER_BYTES: u64 = 4;
const SHARP_EDGE_BYTES: u64 = 16;
const CORNER_BYTES: u64 = 8;

// No charge is below the size of what it stands for (on any target).
const _: () = {
    use std::mem::size_of;
    assert!(size_of::<Label>() as u64 <= LABEL_BYTES);
    assert!(size_of::<PatchKind>() <= 64);
    assert!(size_of::<Option<geometry::GridAxis>>() <= 56);
    assert!(size_of::<geometry::GridAxis>() <= 48);
    assert!(size_of::<Group>() <= 88 && size_of::<String>() <= 24);
    assert!(size_of::<usize>() as u64 + 4 <= MESH_FACE_BYTES);
    assert!(size_of::<DVec3>() as u64 <= MESH_VERTEX_BYTES);
};

/// Bytes held from the rebuild to the assembled mesh for `labels` labels and `faces` rebuilt
/// faces of a file with header `h`. Labels and faces are below 2^32 (§5 bounds K); vertex and
/// group counts only by the caller's limits.
fn decode_array_bytes(h: &Header, labels: u64, faces: u64) -> u64 {
    let coded = h.vertex_count.saturating_add(h.merged_vertex_count);
    (labels * LABEL_ARRAY_BYTES + faces * FACE_BYTES)
        .saturating_add(coded.saturating_mul(CODED_VERTEX_BYTES))
        .saturating_add(h.vertex_count.saturating_mul(VERTEX_STAMP_BYTES))
        .saturating_add(h.group_count.saturating_mul(GROUP_BYTES))
}

/// Bytes of the crease flags and the geometry walk (from the creases to the end of the
/// geometry).
fn geometry_bytes(h: &Header, half_edges: u64, faces: u64) -> u64 {
    let coded = h.vertex_count.saturating_add(h.merged_vertex_count);
    (half_edges * GEOMETRY_HALF_EDGE_BYTES + faces * GEOMETRY_FACE_BYTES)
        .saturating_add(coded.saturating_mul(GEOMETRY_VERTEX_BYTES))
}

/// Bytes of the output mesh the header describes (sets of sharp edges and corners apart).
fn mesh_bytes(h: &Header) -> u64 {
    ((h.face_count + 1) * MESH_FACE_BYTES + h.face_corner_count * MESH_CORNER_BYTES)
        .saturating_add(h.vertex_count.saturating_mul(MESH_VERTEX_BYTES))
}

/// A known section's payload, inflated after its raw length is checked and charged.
fn section_payload<'a>(
    s: &RawSection<'a>,
    limits: &Limits,
    budget: &mut Budget,
) -> Result<std::borrow::Cow<'a, [u8]>> {
    if let Some(n) = s.raw_len {
        limit("inflated section bytes", n, limits.max_input_bytes)?;
        budget.charge("decode memory for inflated sections (bytes)", n)?;
    }
    s.payload()
}

/// Drops a payload and releases its charge (a stored payload borrows the input: nothing to
/// release).
fn drop_payload(p: std::borrow::Cow<[u8]>, budget: &mut Budget) {
    if let std::borrow::Cow::Owned(v) = p {
        budget.release(v.len() as u64);
    }
}

/// The sections of a file after its header, framed and CRC-checked but not inflated, by id;
/// unknown skippable sections are skipped (never inflated).
type Sections<'a> = [Option<RawSection<'a>>; 7];

/// The connectivity section (spec §6): the labels, the rebuilt connectivity and every mesh
/// face's group. Returns the label count, the rebuilt connectivity, the face groups and the
/// bits the group symbols took (with `MEASURE`).
fn decode_connectivity<const MEASURE: bool>(
    conn: &[u8],
    header: &Header,
    groups_v3: bool,
    budget: &mut Budget,
) -> Result<(usize, Rebuilt, Vec<u32>, f64)> {
    let mut cr = Reader::new(conn, "connectivity");
    let label_count = cr.varint_max("label_count", header.face_corner_count + header.face_count)?;
    // Each label is one frequency-model symbol: at least log2(8216 / 8207) bits (9 other
    // symbols keep a count >= 1 out of a total <= 8192 + 24), i.e. < 6,400 labels per byte.
    let coded = cr.rest();
    if label_count > (coded.len() as u64 + 5) * 6_400 {
        return Err(Error::format(
            "connectivity",
            "label_count",
            format!(
                "{label_count} labels cannot fit in {} coded bytes",
                coded.len()
            ),
        ));
    }
    let mut dec = RangeDecoder::new(coded, "connectivity")?;
    let mut models = ConnModels::new(groups_v3);
    budget.charge(
        "decode memory for connectivity labels (bytes)",
        label_count * LABEL_BYTES,
    )?;
    let mut labels: Vec<Label> = Vec::with_capacity(label_count as usize);
    let (mut faces, mut corners) = (0u64, 0u64);
    let max_degree = header.face_corner_count.min(u64::from(u32::MAX / 2)) as u32;
    for _ in 0..label_count {
        let l = models.decode_label(&mut dec, max_degree.max(3))?;
        if let Label::F(d) = l {
            faces += 1;
            corners += u64::from(d);
        }
        labels.push(l);
    }
    // The mesh faces and their corners must be the header's before the rebuild is charged
    // and run.
    if faces != header.face_count || corners != header.face_corner_count {
        return Err(Error::format(
            "connectivity",
            "labels",
            format!(
                "labels give {faces} faces / {corners} corners, header says {} / {}",
                header.face_count, header.face_corner_count
            ),
        ));
    }
    let rb = rebuild(&labels, budget)?;
    drop(labels);
    budget.release(label_count * LABEL_BYTES);
    let traversal_vertices =
        header.vertex_count + header.merged_vertex_count - header.isolated_vertex_count;
    if rb.vertex_count as u64 != traversal_vertices {
        return Err(Error::format(
            "connectivity",
            "labels",
            format!(
                "labels give {} vertices, header implies {traversal_vertices}",
                rb.vertex_count
            ),
        ));
    }
    budget.charge(
        "decode memory for connectivity and geometry arrays (bytes)",
        decode_array_bytes(header, label_count, rb.faces.len() as u64),
    )?;
    let face_group = decode_groups::<MEASURE>(
        &mut dec,
        &mut models,
        &rb,
        header.group_count as usize,
        groups_v3,
        budget,
    )?;
    dec.finish()?;
    Ok((label_count as usize, rb, face_group, models.group_bits))
}

/// Resolves the group of every mesh face in encoding order (spec §6.5).
fn decode_groups<const MEASURE: bool>(
    dec: &mut RangeDecoder,
    models: &mut ConnModels,
    rb: &Rebuilt,
    group_count: usize,
    groups_v3: bool,
    budget: &mut Budget,
) -> Result<Vec<u32>> {
    let mut face_group = vec![NONE; rb.faces.len()];
    let mut next_group = 0u32;
    let mut prev_real = None;
    let (mut cands, mut vcands) = (Vec::new(), Vec::new());
    let mut recency =
        (groups_v3 && group_count > 1).then(|| Recency::new(group_count, rb.faces.len()));
    for i in 0..rb.faces.len() {
        if rb.faces[i].hole {
            continue;
        }
        let g = if group_count <= 1 {
            0
        } else {
            budget.work(group_candidates(rb, i, &face_group, prev_real, &mut cands))?;
            let class = if groups_v3 {
                group_class(rb, i, &face_group, &cands)
            } else {
                cands.len().clamp(1, 3) - 1
            };
            let missing = |what: &str, c: u8, n: usize| {
                Error::format(
                    "connectivity",
                    "group",
                    format!("face {i} refers to {what} candidate group {c} of {n}"),
                )
            };
            match models.decode_group::<MEASURE>(dec, next_group, class)? {
                GroupSym::New => {
                    next_group += 1;
                    next_group - 1
                }
                GroupSym::Explicit(id) => id,
                GroupSym::Candidate(c) => *cands
                    .get(usize::from(c))
                    .ok_or_else(|| missing("edge", c, cands.len()))?,
                GroupSym::Vertex(c) => {
                    budget.work(vertex_candidates(rb, i, &face_group, &cands, &mut vcands))?;
                    *vcands
                        .get(usize::from(c))
                        .ok_or_else(|| missing("vertex", c, vcands.len()))?
                }
                GroupSym::Recent(r) => match &recency {
                    Some(rc) if r < rc.used => face_group[rc.face_of(r)],
                    _ => {
                        return Err(Error::format(
                            "connectivity",
                            "group_rank",
                            format!("rank {r} among the groups used so far"),
                        ))
                    }
                },
            }
        };
        if g as usize >= group_count {
            return Err(Error::format(
                "connectivity",
                "group",
                format!("group {g} of {group_count}"),
            ));
        }
        face_group[i] = g;
        if let Some(rc) = &mut recency {
            rc.assign(g, i);
        }
        prev_real = Some(i);
    }
    Ok(face_group)
}

/// The `(copy, representative)` merges of the `fixups` section (spec §9).
fn decode_fixups(
    payload: Option<&[u8]>,
    merged: u64,
    coded_count: usize,
) -> Result<Vec<(u32, u32)>> {
    let mut merges = Vec::new();
    match (payload, merged) {
        (None, 0) => {}
        (Some(p), m) if m > 0 => {
            let mut fr = Reader::new(p, "fixups");
            let mut prev: u64 = 0;
            let mut is_copy = vec![false; coded_count];
            for i in 0..m {
                let gap = fr.varint("copy")?;
                let d = if i == 0 {
                    gap
                } else {
                    prev.saturating_add(gap).saturating_add(1)
                };
                if d >= coded_count as u64 {
                    return Err(fr.err("copy", format!("vertex {d} does not exist")));
                }
                let back = fr.varint("representative")?;
                if back >= d {
                    return Err(fr.err("representative", "must precede the copy"));
                }
                let rep = d - back - 1;
                if is_copy[rep as usize] {
                    return Err(fr.err("representative", "is itself a copy"));
                }
                is_copy[d as usize] = true;
                merges.push((d as u32, rep as u32));
                prev = d;
            }
            fr.expect_end()?;
        }
        _ => {
            return Err(Error::format(
                "fixups",
                "section",
                "section presence does not match the header's merged vertex count",
            ))
        }
    }
    Ok(merges)
}

/// The start of a decode: magic and version, the header (its counts checked against the
/// limits, and the memory any file with them needs against the budget, before any work),
/// and the framing of the other sections.
fn read_file<'a, const MEASURE: bool>(
    bytes: &'a [u8],
    limits: &Limits,
    budget: &mut Budget,
    sections_info: &mut Vec<SectionInfo>,
) -> Result<(Features, Header, Quantizer, Sections<'a>)> {
    limit("input bytes", bytes.len() as u64, limits.max_input_bytes)?;
    // The caller holds the input for the whole decode.
    budget.charge("decode memory for the input (bytes)", bytes.len() as u64)?;
    let mut r = Reader::new(bytes, "file");
    let magic = r.bytes(4, "magic")?;
    if magic != MAGIC {
        return Err(Error::format(
            "file",
            "magic",
            "not an .scode file (bad magic bytes)",
        ));
    }
    let major = r.u8("version_major")?;
    let minor = r.u8("version_minor")?;
    let features = features_for(major, minor)?;
    let verify = limits.verify_checksums;

    let hs = read_section(&mut r, Some(0), verify)?;
    if hs.id != SEC_HEADER {
        return Err(Error::format(
            "file",
            "section",
            "the first section must be the header",
        ));
    }
    if MEASURE {
        sections_info.push(SectionInfo {
            name: "header",
            stored_bytes: hs.stored_bytes + 6,
            raw_bytes: hs.payload_len() as usize,
        });
    }
    let header_payload = section_payload(&hs, limits, budget)?;
    let (header, quant) = parse_header(&header_payload, major, minor, limits)?;
    drop_payload(header_payload, budget);
    // What any file with these counts holds at least while its geometry is decoded (a label
    // per two corners, a half-edge per corner, no hole), before any work.
    let (k, f) = (header.face_corner_count, header.face_count);
    limit(
        "decode memory the header's counts need (bytes)",
        budget
            .usage
            .held
            .saturating_add(facefixer::rebuilt_bytes(k / 2, k, f, 0))
            .saturating_add(decode_array_bytes(&header, k / 2, f))
            .saturating_add(geometry_bytes(&header, k, f)),
        limits.max_memory,
    )?;
    budget.max_work = limits.max_work_per_element.saturating_mul(
        header
            .vertex_count
            .saturating_add(header.face_count + k + 1),
    );
    // The other sections, in increasing id order, framed and CRC-checked but not inflated;
    // unknown skippable ones are skipped (never inflated).
    let mut sections: Sections<'a> = Default::default();
    let mut last_id = SEC_HEADER;
    while !r.is_empty() {
        let s = read_section(&mut r, None, verify)?;
        if s.id <= last_id {
            return Err(Error::format(
                "file",
                "section",
                format!("section {} out of order or repeated", s.id),
            ));
        }
        last_id = s.id;
        if s.id as usize >= sections.len() {
            if s.skippable {
                continue;
            }
            return Err(Error::format(
                "file",
                "section",
                format!("unknown section id {}", s.id),
            ));
        }
        if MEASURE {
            sections_info.push(SectionInfo {
                name: section_name(s.id),
                stored_bytes: s.stored_bytes,
                raw_bytes: s.payload_len() as usize,
            });
        }
        let id = s.id as usize;
        sections[id] = Some(s);
    }
    // Optional sections are present exactly when their flag is set, required ones always.
    for (id, flag) in [
        (SEC_CONNECTIVITY, 0),
        (SEC_PATCHES, FLAG_PATCHES),
        (SEC_CREASES, 0),
        (SEC_GEOMETRY, 0),
        (SEC_FIXUPS, FLAG_MERGES),
        (SEC_NAMES, FLAG_NAMES),
    ] {
        if sections[id as usize].is_some() != (flag == 0 || header.flags & flag != 0) {
            return Err(Error::format(
                section_name(id),
                "section",
                "section missing or present against the header",
            ));
        }
    }
    Ok((features, header, quant, sections))
}

/// What [`inspect`] reports besides the decoded mesh.
struct Summary {
    sections: Vec<SectionInfo>,
    component_count: usize,
    label_count: usize,
    group_bits: f64,
}

fn decode_full<const MEASURE: bool>(
    bytes: &[u8],
    limits: &Limits,
    budget: &mut Budget,
) -> Result<(Decoded, Summary)> {
    let mut sections_info = Vec::new();
    let file = FileDecode::read::<MEASURE>(bytes, limits, budget, &mut sections_info)?;
    file.check_isolated_vertices_fit()?;
    let header = &file.header;

    // Connectivity.
    let conn = file.payload(SEC_CONNECTIVITY, budget)?.unwrap_or_default();
    let (label_count, rb, mut face_group, group_bits) =
        decode_connectivity::<MEASURE>(&conn, header, file.features.groups_v3, budget)?;
    drop_payload(conn, budget);
    // Released when the mesh is assembled.
    let arrays = rb.bytes + decode_array_bytes(header, label_count as u64, rb.faces.len() as u64);

    let (patch_kinds, grid_axes) = file.patches(budget)?;

    // Creases, and the geometry walk's arrays (released after the geometry).
    let walk_bytes = geometry_bytes(header, rb.next.len() as u64, rb.faces.len() as u64);
    budget.charge("decode memory for the geometry walk (bytes)", walk_bytes)?;
    let edges = label_edges(&rb.label_edge);
    let mut sharp = vec![false; edges.len()];
    let mut corner = vec![false; file.coded_count];
    let crease_he = file.creases(&rb, &edges, &face_group, &mut sharp, &mut corner, budget)?;
    let q = file.geometry(
        &rb,
        &face_group,
        &patch_kinds,
        &grid_axes,
        &crease_he,
        budget,
    )?;
    drop(crease_he);
    budget.release(walk_bytes);

    // Fixups.
    let fixups = file.payload(SEC_FIXUPS, budget)?;
    let merges = decode_fixups(
        fixups.as_deref(),
        header.merged_vertex_count,
        file.coded_count,
    )?;
    if let Some(p) = fixups {
        drop_payload(p, budget);
    }
    let final_of_coded = final_numbering(file.coded_count, &merges);

    let (names, patch_kinds) = file.names_and_group_order(&mut face_group, patch_kinds, budget)?;
    let mesh = file.assemble(
        &rb,
        CodedContent {
            q,
            final_of_coded,
            face_group,
            names,
            patch_kinds,
            edges,
            sharp,
            corner,
        },
        budget,
    )?;
    // The input and the mesh stay charged: the caller holds them.
    budget.release(arrays);

    let summary = Summary {
        sections: sections_info,
        component_count: if MEASURE {
            rb.faces.iter().filter(|f| f.start).count()
        } else {
            0
        },
        label_count,
        group_bits,
    };
    Ok((
        Decoded {
            header: file.header,
            mesh,
        },
        summary,
    ))
}

/// A file being decoded: what [`read_file`] found in it, and the limits it is decoded within.
struct FileDecode<'a, 'l> {
    features: Features,
    header: Header,
    quant: Quantizer,
    sections: Sections<'a>,
    limits: &'l Limits,
    /// Coded vertices: the output vertices and the merged copies.
    coded_count: usize,
}

/// What the sections after the connectivity decode to, in coded numbering, for
/// [`FileDecode::assemble`].
struct CodedContent {
    /// Grid point of every coded vertex.
    q: Vec<[i32; 3]>,
    /// Output vertex of every coded vertex (after the merges).
    final_of_coded: Vec<u32>,
    /// Group of every rebuilt face (in the input's group order).
    face_group: Vec<u32>,
    /// Name and patch kind of every group.
    names: Vec<String>,
    patch_kinds: Vec<PatchKind>,
    /// Every edge's half-edge (label order) and sharp flag.
    edges: Vec<u32>,
    sharp: Vec<bool>,
    /// Corner flag of every coded vertex.
    corner: Vec<bool>,
}

impl<'a, 'l> FileDecode<'a, 'l> {
    /// Reads the file's start ([`read_file`]) and checks that its coded vertex count fits.
    fn read<const MEASURE: bool>(
        bytes: &'a [u8],
        limits: &'l Limits,
        budget: &mut Budget,
        sections_info: &mut Vec<SectionInfo>,
    ) -> Result<Self> {
        let (features, header, quant, sections) =
            read_file::<MEASURE>(bytes, limits, budget, sections_info)?;
        let coded_count = header
            .vertex_count
            .checked_add(header.merged_vertex_count)
            .ok_or_else(|| Error::format("header", "merged_vertex_count", "overflow"))?
            as usize;
        Ok(FileDecode {
            features,
            header,
            quant,
            sections,
            limits,
            coded_count,
        })
    }

    /// Section `id`'s payload if the file has it, inflated after its raw length is checked
    /// and charged ([`section_payload`]).
    fn payload(&self, id: u8, budget: &mut Budget) -> Result<Option<std::borrow::Cow<'a, [u8]>>> {
        match &self.sections[id as usize] {
            Some(s) => section_payload(s, self.limits, budget).map(Some),
            None => Ok(None),
        }
    }

    /// Isolated vertices cost at least 15 adaptive bits each in the geometry section: bounds
    /// their number by its size before per-vertex arrays are allocated.
    fn check_isolated_vertices_fit(&self) -> Result<()> {
        let geometry_len = self.sections[SEC_GEOMETRY as usize]
            .as_ref()
            .map_or(0, |s| s.payload_len()) as usize;
        let isolated = self.header.isolated_vertex_count;
        if isolated.saturating_mul(15) > rangecoder::max_symbols(geometry_len) {
            return Err(Error::format(
                "geometry",
                "isolated_vertex_count",
                format!("{isolated} isolated vertices cannot fit in {geometry_len} coded bytes"),
            ));
        }
        Ok(())
    }

    /// The patches section: each group's patch kind and grid axis (closed patches without
    /// axes when the file has no such section).
    fn patches(&self, budget: &mut Budget) -> Result<patches::DecodedPatches> {
        let group_count = self.header.group_count as usize;
        Ok(match self.payload(SEC_PATCHES, budget)? {
            Some(p) => {
                let decoded = if LEGACY && !self.features.coded_patches {
                    patches::decode_v1(&p, group_count, &self.quant)?
                } else {
                    patches::decode(&p, group_count, &self.quant, self.features.patch_kinds)?
                };
                drop_payload(p, budget);
                decoded
            }
            None => (
                vec![PatchKind::Closed; group_count],
                vec![None; group_count],
            ),
        })
    }

    /// The creases section: fills the sharp flag of every edge and the corner flag of every
    /// coded vertex, and returns per half-edge whether its edge is a crease.
    fn creases(
        &self,
        rb: &Rebuilt,
        edges: &[u32],
        face_group: &[u32],
        sharp: &mut [bool],
        corner: &mut [bool],
        budget: &mut Budget,
    ) -> Result<Vec<bool>> {
        let creases = self.payload(SEC_CREASES, budget)?.unwrap_or_default();
        let mut d = RangeDecoder::new(&creases, "creases")?;
        let crease = code_creases(rb, edges, face_group, sharp, corner, &mut d)?;
        d.finish()?;
        drop_payload(creases, budget);
        Ok(crease)
    }

    /// The geometry section: the grid point of every coded vertex, walked with the
    /// predictions the file's version has (along the creases `crease_he`, on circles round
    /// the groups' `grid_axes`).
    fn geometry(
        &self,
        rb: &Rebuilt,
        face_group: &[u32],
        patch_kinds: &[PatchKind],
        grid_axes: &[Option<geometry::GridAxis>],
        crease_he: &[bool],
        budget: &mut Budget,
    ) -> Result<Vec<[i32; 3]>> {
        let features = &self.features;
        let mut q = vec![[0i32; 3]; self.coded_count];
        let face_plane_group = plane_groups_of_faces(face_group, patch_kinds);
        let (face_axis, axes) = patches::face_axes(face_group, grid_axes);
        let arcs = ArcAxes {
            face_axis: &face_axis,
            axes: &axes,
        };
        let geometry = self.payload(SEC_GEOMETRY, budget)?.unwrap_or_default();
        let mut d = RangeDecoder::new(&geometry, "geometry")?;
        let mut gd = GeomDecoder::new(&mut d, self.quant.max_q(), budget);
        geometry::walk(
            rb,
            &face_plane_group,
            self.header.group_count as usize,
            self.quant.bits,
            features.crease_prediction.then_some(crease_he),
            (features.arc_prediction && !axes.is_empty()).then_some(&arcs),
            &mut q,
            &mut gd,
        )?;
        d.finish()?;
        drop_payload(geometry, budget);
        Ok(q)
    }

    /// The names section's group names, and (version 2 on) the input's group order: coded
    /// group `c` becomes group `input_of_coded[c]`, in `face_group` and in the patch kinds
    /// returned.
    fn names_and_group_order(
        &self,
        face_group: &mut [u32],
        patch_kinds: Vec<PatchKind>,
        budget: &mut Budget,
    ) -> Result<(Vec<String>, Vec<PatchKind>)> {
        let group_count = self.header.group_count as usize;
        let mut names = vec![String::new(); group_count];
        let mut input_of_coded: Option<Vec<u32>> = None;
        if let Some(p) = self.payload(SEC_NAMES, budget)? {
            if LEGACY && !self.features.names_in_input_order {
                names = names::read_v1(&p, group_count)?;
            } else {
                let (n, order) = names::read(&p, group_count, budget)?;
                names = n;
                input_of_coded = Some(order);
            }
            drop_payload(p, budget);
        }
        let mut patch_kinds = patch_kinds;
        if let Some(order) = &input_of_coded {
            for g in face_group.iter_mut() {
                if let Some(&o) = order.get(*g as usize) {
                    *g = o;
                }
            }
            let mut kinds = vec![PatchKind::Closed; group_count];
            for (c, &o) in order.iter().enumerate() {
                kinds[o as usize] = patch_kinds[c];
            }
            patch_kinds = kinds;
        }
        Ok((names, patch_kinds))
    }

    /// The decoded mesh (charged first): positions, the mesh faces in encoding order with
    /// their groups, the groups, sharp edges and corners, all in output numbering; it must
    /// be valid.
    fn assemble(
        &self,
        rb: &Rebuilt,
        content: CodedContent,
        budget: &mut Budget,
    ) -> Result<ControlMesh> {
        let header = &self.header;
        let CodedContent {
            q,
            final_of_coded,
            face_group,
            names,
            patch_kinds,
            edges,
            sharp,
            corner,
        } = content;
        let nf = header.face_count as usize;
        let sharp_count = sharp.iter().filter(|&&s| s).count() as u64;
        let corner_count = corner.iter().filter(|&&c| c).count() as u64;
        budget.charge(
            "decode memory for the decoded mesh (bytes)",
            mesh_bytes(header) + sharp_count * SHARP_EDGE_BYTES + corner_count * CORNER_BYTES,
        )?;
        let mut mesh = ControlMesh::new();
        let final_count = header.vertex_count as usize;
        mesh.positions = vec![DVec3::ZERO; final_count];
        for c in 0..self.coded_count {
            mesh.positions[final_of_coded[c] as usize] = self.quant.dequantize(q[c]);
        }
        mesh.face_vertices
            .reserve(header.face_corner_count as usize);
        mesh.face_offsets.reserve(nf);
        mesh.face_groups.reserve(nf);
        let mut buf = Vec::new();
        for (i, rf) in rb.faces.iter().enumerate() {
            if rf.hole {
                continue;
            }
            buf.clear();
            buf.extend(rb.face_vertices(i).map(|v| final_of_coded[v as usize]));
            mesh.push_face(&buf, face_group[i]);
        }
        mesh.groups = names
            .into_iter()
            .zip(&patch_kinds)
            .map(|(name, &patch)| Group { name, patch })
            .collect();
        for (j, &h) in edges.iter().enumerate() {
            if sharp[j] {
                let t = rb.twin[h as usize];
                mesh.sharp_edges.insert(edge_key(
                    final_of_coded[rb.vertex[h as usize] as usize],
                    final_of_coded[rb.vertex[t as usize] as usize],
                ));
            }
        }
        for (c, &is) in corner.iter().enumerate() {
            if is {
                mesh.corners.insert(final_of_coded[c]);
            }
        }
        mesh.validate().map_err(|e| {
            Error::format("fixups", "merges", format!("decoded mesh is invalid: {e}"))
        })?;
        Ok(mesh)
    }
}

#[cfg(test)]
mod tests;
