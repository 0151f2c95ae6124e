//! The memory a subdivision to a tolerance allocates, from exact element counts, so that a
//! decoder charges it against its budget before it is allocated ([`super::accuracy`]).
//!
//! Two charges, each made before its arrays exist. The *measurement* (before the
//! refinement is built): the connectivity of levels `0..n` (level `n` is read through level
//! `n - 1`), the lazily evaluated positions of levels `1..=n` and limit points and normals
//! of level `n` at their full size (they are allocated zeroed, so untouched pages are only
//! address space, but any of them may be touched), the evaluation queues and the per base
//! triangle and per base edge measurements. The *output* (once the levels are chosen, before
//! the extraction): the triangles and vertices the chosen levels show, through the
//! extraction, the triangle mesh made from it and the flips of plane patches. The output is
//! charged for what is shown, so a model whose triangles mostly stay coarse is charged little
//! for it; a model shown at the finest level everywhere is charged all of it.
//!
//! The per-element bytes are those of the arrays, with growth by doubling where an array is
//! filled by pushing; they are fixed numbers, not the sizes of a platform's types, so whether
//! a decode fits a budget is the same everywhere.

use crate::mesh::{edge_key, ControlMesh};

use super::lazy::{PAGE, QUEUE_LIMIT};
use super::masks::eclass;
use super::topology::{Level, NONE};

/// Vertex, edge and triangle counts of levels `0..=n` of the refinement of `mesh` (faces
/// fan-triangulated): every edge is split in two and adds a vertex, every triangle adds
/// three inner edges and becomes four.
pub(crate) fn level_counts(mesh: &ControlMesh, n: u32) -> Vec<[u64; 3]> {
    let mut keys: Vec<(u32, u32)> = Vec::with_capacity(mesh.face_vertices.len());
    let (mut diagonals, mut tri) = (0u64, 0u64);
    for f in mesh.faces() {
        for i in 0..f.len() {
            keys.push(edge_key(f[i], f[(i + 1) % f.len()]));
        }
        diagonals += f.len().saturating_sub(3) as u64;
        tri += f.len().saturating_sub(2) as u64;
    }
    keys.sort_unstable();
    keys.dedup();
    let mut c = [
        mesh.positions.len() as u64,
        (keys.len() as u64).saturating_add(diagonals),
        tri,
    ];
    let mut out = vec![c];
    for _ in 0..n {
        let [nv, ne, nf] = c;
        c = [
            nv.saturating_add(ne),
            ne.saturating_mul(2).saturating_add(nf.saturating_mul(3)),
            nf.saturating_mul(4),
        ];
        out.push(c);
    }
    out
}

/// `Σ count × bytes`, saturating.
fn bytes(terms: &[(u64, u64)]) -> u64 {
    terms
        .iter()
        .fold(0u64, |a, &(n, b)| a.saturating_add(n.saturating_mul(b)))
}

/// Bytes of one level's connectivity per vertex, edge and triangle (`topology::Level`): a
/// vertex's class, frame and ring offset, and one more ring entry at a boundary vertex
/// (11); an edge's ends, faces, class and frame and its two ring entries (27); a triangle's
/// corners and edges (24).
const LEVEL_BYTES: [u64; 3] = [11, 27, 24];
/// Bytes per edge of the finest level built while the next level's rings are made (their
/// offsets, one level at a time).
const RING_SCRATCH_PER_EDGE: u64 = 4;

/// Bytes charged per base triangle for its measurements (two errors per level, 192), its
/// level, the lists of triangles measured and checked and their results, the sparse plan,
/// the belt pairing (its partner and, while it is made, rungs and marks: 26) and level 0's
/// construction (its corners by vertex, 24); and per base edge for its chains' two errors
/// per level (16 per level) and plan.
const MEASURE_PER_BASE_TRIANGLE: u64 = 400;
const MEASURE_PER_BASE_EDGE_LEVEL: u64 = 16;
const MEASURE_PER_BASE_EDGE: u64 = 16;

/// The memory of the measurement of a subdivision to level `n` with level counts `c`
/// ([`level_counts`]).
pub(crate) fn measurement_bytes(c: &[[u64; 3]], n: u32) -> u64 {
    let n = n as usize;
    let mut terms = Vec::new();
    let built = &c[..n.max(1)];
    for &[nv, ne, nf] in built {
        terms.extend([
            (nv, LEVEL_BYTES[0]),
            (ne, LEVEL_BYTES[1]),
            (nf, LEVEL_BYTES[2]),
        ]);
    }
    terms.push((built[built.len() - 1][1], RING_SCRATCH_PER_EDGE));
    // The page tables of the positions of levels 0..=n (their pages are charged as they
    // are written) and a bit each; the queue of the positions to evaluate of each level
    // below n (each vertex at most once, in a vector grown by doubling; level n's are the
    // queued vertices below).
    for (j, &[nv, _, _]) in c[..=n.max(1)].iter().enumerate() {
        let queue = if j < n.max(1) { nv } else { 0 };
        terms.extend([(nv.div_ceil(PAGE), 16), (nv.div_ceil(8), 1), (queue, 8)]);
    }
    // The page tables of the limit points and normals of level n, with their bits; the
    // vertices queued for them and the vertices their masks read, run once past
    // `QUEUE_LIMIT` entries (so at most that many and one ring more, of at most a level-0
    // vertex's edges; grown by doubling).
    let [nv, _, _] = c[n.max(1)];
    let [_, ne0, nf0] = c[0];
    terms.extend([
        (nv.div_ceil(PAGE), 32),
        (nv.div_ceil(4), 1),
        (QUEUE_LIMIT as u64, 8),
        (ne0, 8),
    ]);
    terms.extend([
        (nf0, MEASURE_PER_BASE_TRIANGLE),
        (ne0, MEASURE_PER_BASE_EDGE),
        (ne0, MEASURE_PER_BASE_EDGE_LEVEL * (n as u64 + 1)),
    ]);
    bytes(&terms)
}

/// Bytes per output triangle: the extraction's triangles and groups (16, grown by doubling:
/// 32), the triangle mesh's corners, offsets and groups (20), the flips' copy of the
/// triangles and the corners made from it (24), their map of plane edges and stack (about
/// 60 per triangle: one and a half edges of 24 bytes in a hash table at most 7/8 full, and
/// their stack).
const OUTPUT_PER_TRIANGLE: u64 = 136;
/// Bytes per output vertex: the extraction's moved vertices (32, grown by doubling: 64),
/// used ids (4, grown by doubling: 8), positions and normals (48), and the triangle mesh's
/// positions (24).
const OUTPUT_PER_VERTEX: u64 = 144;
/// Bytes per output sharp edge (a key in an ordered set, with its share of a tree node).
const OUTPUT_PER_SHARP_EDGE: u64 = 48;

/// The memory of a decode to the file's own tolerance of a control mesh whose default level
/// is `level`, as an encoder estimates it before choosing that level: the measurement to
/// level `level + 1` ([`default_top_level`]) and the output of every base triangle at
/// `level`. The output is the estimate's assumption: the encoder measured the model within
/// its tolerance at `level`, so the decode shows few triangles finer than that and most
/// coarser.
#[cfg(feature = "encoder")]
pub(crate) fn default_decode_bytes(mesh: &ControlMesh, level: u32) -> u64 {
    let n = default_top_level(level);
    let c = level_counts(mesh, n.max(1));
    let [nv, _, nf] = c[level as usize];
    measurement_bytes(&c, n.max(1))
        .saturating_add(bytes(&[(nf, OUTPUT_PER_TRIANGLE), (nv, OUTPUT_PER_VERTEX)]))
}

/// The finest level a decode to the file's own tolerance refines to, for a file whose
/// default level is `default_level`: one more, whose triangles leave a quarter of the chord
/// error that the default level's triangles stand off the limit surface by.
pub(crate) fn default_top_level(default_level: u32) -> u32 {
    (default_level + 1).min(super::MAX_LEVEL - 1)
}

/// The memory of the output of a subdivision whose base triangles (level-0 triangles of
/// `l0`) are shown at `levels`, the finest level shown having `nv_top` vertices (the
/// extraction marks and numbers them in arrays of that length).
pub(crate) fn output_bytes(l0: &Level, levels: &[u8], nv_top: usize) -> u64 {
    // The base vertices, the vertices inside every base triangle at its level, and along
    // every base edge those of the finer side.
    let (mut tris, mut verts) = (0u64, l0.nv as u64);
    for &m in levels {
        let s = 1u64 << m;
        tris += s * s;
        verts += (s - 1) * s.saturating_sub(2) / 2;
    }
    // A coarser triangle next to a finer one is fanned through the finer side's vertices,
    // round a new centroid vertex at most; along a sharp base edge the finer side's chain is
    // a run of sharp edges.
    let (mut fans, mut sharp) = (0u64, 0u64);
    for e in 0..l0.ne() {
        let [a, b] = l0.edge_faces[e];
        let la = levels[a as usize];
        let lb = if b == NONE { la } else { levels[b as usize] };
        let fine = 1u64 << la.max(lb);
        verts += fine - 1;
        if la != lb {
            fans += fine;
        }
        if l0.eclass[e] & eclass::SHARP != 0 {
            sharp += fine;
        }
    }
    bytes(&[
        (
            tris.saturating_add(fans.saturating_mul(2)),
            OUTPUT_PER_TRIANGLE,
        ),
        (verts.saturating_add(fans), OUTPUT_PER_VERTEX),
        (sharp, OUTPUT_PER_SHARP_EDGE),
        // The extraction's bits over the finest level's vertices and its map from them.
        (nv_top as u64, 5),
    ])
}
