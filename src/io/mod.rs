//! Mesh file readers and writers, with input welding, repair and validation.
//!
//! Every reader produces the same two things: a [`ControlMesh`] (one group per CAD face where
//! the format can say so, shared vertices welded, sharp edges and corners where the format can
//! carry them) and a [`ReadReport`] that says what was done to the input. Nothing is repaired
//! silently: each change is counted in the report and described in [`ReadReport::repairs`].
//!
//! | format | read | write | groups | sharp edges / corners |
//! |---|---|---|---|---|
//! | OBJ  | polygons, `o`/`g`, `l`, `p` | yes (f64 exact) | `g` | `l` / `p` elements ([`obj`]) |
//! | PLY  | ascii, binary LE/BE | binary LE (f64 positions) | face `group` property (+ names in comments) | `sharp_edge` element / vertex `corner` ([`ply`]) |
//! | STL  | ascii, binary | binary, fan-triangulated | one group | no |
//! | glTF / glb | triangles, strips, fans; 8/16-bit quantised | glb or self-contained gltf, fan-triangulated, one primitive per body (f32 or quantised positions) | feature ids (`EXT_mesh_features`, names in `EXT_structural_metadata`), else one per primitive ([`gltf`]) | line primitives / no |
//! | OFF  | polygons | yes | one group | no |
//!
//! # What every reader does after parsing (see [`repair`])
//! 1. **Non-finite coordinates** (NaN, inf), **coordinates whose bounding box has no finite
//!    diagonal** (near 1e154 and beyond: every distance the encoder measures would be
//!    infinite) and **out-of-range indices** are errors naming the file and the line (text
//!    formats) or element (binary formats).
//! 2. **Weld** vertices with identical f64 coordinates (`-0.0 == 0.0`) where the stored mesh
//!    is open (vertices on boundary edges, or used by no face); the first occurrence keeps its
//!    place, so the result is deterministic. Coincident vertices inside closed surfaces
//!    (touching solids of an assembly) are kept apart and counted ([`weld`]).
//! 3. **Degenerate faces**: repeated vertices (after welding) are removed from a face, keeping
//!    the first occurrence; a face left with fewer than 3 distinct vertices is dropped.
//! 4. **Empty groups** (declared but without faces, or emptied by step 3) are dropped.
//! 5. **Unreferenced vertices** are removed (vertex order is otherwise kept). Corners on
//!    removed vertices, and sharp edges that are not an edge of any face (after welding),
//!    are dropped.
//! 6. Counted but **not** changed: zero-area faces, boundary and non-manifold edges.
//!
//! A file with no faces left is an error.
//!
//! Other mesh sources (e.g. a future STEP tessellator) can get the same treatment by filling
//! a [`repair::RawMesh`] and calling [`repair::finish`].

use std::fmt;
use std::path::Path;

#[cfg(feature = "internals")]
use glam::DVec3;

use crate::error::{Error, Result};
use crate::mesh::ControlMesh;

pub mod faces_json;
pub mod gltf;
pub mod obj;
pub mod off;
pub mod ply;
pub mod repair;
#[cfg(feature = "step")]
pub mod step;
pub mod stl;
pub mod weld;

#[cfg(feature = "internals")]
pub use faces_json::{
    face_info_for_groups, read_faces_json, sidecar_path_for, FaceInfo, SurfaceType,
};

/// The mesh file formats scode reads and writes, chosen by file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MeshFormat {
    Obj,
    Ply,
    Stl,
    /// Binary glTF (one file with a BIN chunk).
    Glb,
    /// JSON glTF with external `.bin` buffers or `data:` URIs (written with a `data:` URI).
    Gltf,
    Off,
}

/// Extensions accepted by [`MeshFormat::from_path`], for messages.
const SUPPORTED_EXTENSIONS: &str = ".obj, .ply, .stl, .glb, .gltf, .off";

impl MeshFormat {
    /// Every format, in a fixed order.
    pub const ALL: [MeshFormat; 6] = [
        MeshFormat::Obj,
        MeshFormat::Off,
        MeshFormat::Ply,
        MeshFormat::Stl,
        MeshFormat::Glb,
        MeshFormat::Gltf,
    ];

    /// Picks the format from the file extension (case-insensitive).
    pub fn from_path(path: &Path) -> Result<MeshFormat> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("obj") => Ok(MeshFormat::Obj),
            Some("ply") => Ok(MeshFormat::Ply),
            Some("stl") => Ok(MeshFormat::Stl),
            Some("glb") => Ok(MeshFormat::Glb),
            Some("gltf") => Ok(MeshFormat::Gltf),
            Some("off") => Ok(MeshFormat::Off),
            Some(other) => Err(Error::input(
                path,
                format!(
                    "unsupported mesh file extension `.{other}`; supported: {SUPPORTED_EXTENSIONS}"
                ),
            )),
            None => Err(Error::input(
                path,
                format!("mesh file has no extension; supported: {SUPPORTED_EXTENSIONS}"),
            )),
        }
    }

    /// Lower-case name, as used in messages (`"obj"`, `"glb"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            MeshFormat::Obj => "obj",
            MeshFormat::Ply => "ply",
            MeshFormat::Stl => "stl",
            MeshFormat::Glb => "glb",
            MeshFormat::Gltf => "gltf",
            MeshFormat::Off => "off",
        }
    }
}

impl fmt::Display for MeshFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What the reader did to the input, so `scode info`/`encode` can say so (never silent
/// repairs). Counts refer to the file as stored: for STL, whose triangles carry their own
/// corner coordinates, `input_vertices` is three per triangle and most of them get welded.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadReport {
    pub format: MeshFormat,
    /// Vertex records in the file.
    pub input_vertices: usize,
    /// Face records in the file (polygons, or triangles for STL/glTF).
    pub input_faces: usize,
    /// Vertices merged into an earlier vertex with identical coordinates.
    pub welded_vertices: usize,
    /// Vertices with the same coordinates as another vertex that were deliberately not
    /// welded: both lie inside closed surfaces (e.g. solids of an assembly touching at a
    /// point or edge), where merging would create non-manifold edges. See [`weld`].
    pub coincident_vertices_kept: usize,
    /// Vertices no face uses (after welding and repair), removed.
    pub unreferenced_vertices: usize,
    /// Faces dropped because fewer than 3 distinct vertices remained.
    pub dropped_degenerate_faces: usize,
    /// Faces kept after removing repeated vertices.
    pub repaired_faces: usize,
    /// Groups dropped because they had no faces.
    pub dropped_empty_groups: usize,
    /// Sharp edges dropped: not an edge of any face (after welding), or collapsed by welding.
    pub dropped_sharp_edges: usize,
    /// Corners dropped: their vertex is used by no face.
    pub dropped_corners: usize,
    /// Faces whose area is below `1e-12 × (longest edge)²`; kept.
    pub zero_area_faces: usize,
    /// Edges with exactly one incident face; kept.
    pub boundary_edges: usize,
    /// Edges with more than two incident faces; kept (the codec handles them).
    pub nonmanifold_edges: usize,
    /// Human-readable notes, one per kind of repair or ignored content.
    pub repairs: Vec<String>,
}

impl ReadReport {
    /// An all-zero report for `format`.
    pub fn new(format: MeshFormat) -> Self {
        ReadReport {
            format,
            input_vertices: 0,
            input_faces: 0,
            welded_vertices: 0,
            coincident_vertices_kept: 0,
            unreferenced_vertices: 0,
            dropped_degenerate_faces: 0,
            repaired_faces: 0,
            dropped_empty_groups: 0,
            dropped_sharp_edges: 0,
            dropped_corners: 0,
            zero_area_faces: 0,
            boundary_edges: 0,
            nonmanifold_edges: 0,
            repairs: Vec::new(),
        }
    }

    /// True when the mesh was used exactly as stored: nothing welded, removed or repaired.
    /// (STL input is never "as stored": its vertices are always welded.) Informational notes
    /// in `repairs` (ignored statements, vertices kept apart) do not count as changes.
    #[cfg(feature = "internals")]
    pub fn unchanged(&self) -> bool {
        self.welded_vertices == 0
            && self.unreferenced_vertices == 0
            && self.dropped_degenerate_faces == 0
            && self.repaired_faces == 0
            && self.dropped_empty_groups == 0
            && self.dropped_sharp_edges == 0
            && self.dropped_corners == 0
    }
}

impl fmt::Display for ReadReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{}: {} vertices, {} faces in the file",
            self.format, self.input_vertices, self.input_faces
        )?;
        let counts = [
            (self.welded_vertices, "duplicate vertices welded"),
            (
                self.coincident_vertices_kept,
                "coincident vertices kept apart (closed surfaces)",
            ),
            (self.unreferenced_vertices, "unreferenced vertices removed"),
            (self.dropped_degenerate_faces, "degenerate faces dropped"),
            (self.repaired_faces, "faces with repeated vertices repaired"),
            (self.dropped_empty_groups, "empty groups dropped"),
            (self.dropped_sharp_edges, "sharp edges dropped"),
            (self.dropped_corners, "corners dropped"),
            (self.zero_area_faces, "zero-area faces (kept)"),
            (self.boundary_edges, "boundary edges"),
            (self.nonmanifold_edges, "non-manifold edges (kept)"),
        ];
        for (n, what) in counts {
            if n > 0 {
                writeln!(f, "  {n} {what}")?;
            }
        }
        for note in &self.repairs {
            writeln!(f, "  note: {note}")?;
        }
        Ok(())
    }
}

/// Options of the mesh readers ([`read_mesh_with`], [`read_mesh_bytes_with`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReadOptions {
    /// Whether a `.gltf` file may name external buffer files (default true). They are only
    /// read from the glTF file's folder or below it (absolute paths, `..` and links out of
    /// the folder are refused either way); false refuses every external file, leaving
    /// `data:` URIs and GLB chunks, for files from untrusted sources whose folder holds
    /// files of others, or bytes read from memory whose name is no real folder.
    pub external_files: bool,
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions {
            external_files: true,
        }
    }
}

/// Reads a mesh file with the default [`ReadOptions`]; the format comes from the extension.
#[cfg(feature = "internals")]
pub fn read_mesh(path: &Path) -> Result<(ControlMesh, ReadReport)> {
    read_mesh_with(path, &ReadOptions::default())
}

/// Reads a mesh file; the format comes from the extension.
#[cfg(feature = "internals")]
pub fn read_mesh_with(path: &Path, opts: &ReadOptions) -> Result<(ControlMesh, ReadReport)> {
    let format = MeshFormat::from_path(path)?;
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_mesh_bytes_with(&bytes, format, path, opts)
}

/// Reads a mesh from memory with the default [`ReadOptions`]. `name_for_errors` names the
/// source in errors and, for `.gltf`, its folder holds the external buffer files.
pub fn read_mesh_bytes(
    bytes: &[u8],
    format: MeshFormat,
    name_for_errors: &Path,
) -> Result<(ControlMesh, ReadReport)> {
    read_mesh_bytes_with(bytes, format, name_for_errors, &ReadOptions::default())
}

/// [`read_mesh_bytes`] with `opts`.
pub fn read_mesh_bytes_with(
    bytes: &[u8],
    format: MeshFormat,
    name_for_errors: &Path,
    opts: &ReadOptions,
) -> Result<(ControlMesh, ReadReport)> {
    let raw = match format {
        MeshFormat::Obj => obj::parse(bytes, name_for_errors)?,
        MeshFormat::Off => off::parse(bytes, name_for_errors)?,
        MeshFormat::Ply => ply::parse(bytes, name_for_errors)?,
        MeshFormat::Stl => stl::parse(bytes, name_for_errors)?,
        MeshFormat::Glb | MeshFormat::Gltf => gltf::parse_with(bytes, name_for_errors, opts)?,
    };
    repair::finish(raw, format, name_for_errors)
}

/// Options of the mesh writers ([`write_mesh_with`], [`write_mesh_to_with`]).
#[cfg(feature = "internals")]
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WriteOptions {
    /// glTF only (other formats refuse it): positions as normalized 16-bit integers under a
    /// node transform and normals as normalized 8-bit integers (`KHR_mesh_quantization`,
    /// then a required extension). Positions keep about 1.5e-5 of the half extent.
    pub quantize: bool,
}

/// Writes a mesh file with the default [`WriteOptions`]; the format comes from the
/// extension. `normals`: optional per-vertex normals (written as `vn` in OBJ, normal
/// attribute in PLY/glb, ignored for STL which has per-face normals computed from geometry,
/// and for OFF).
#[cfg(feature = "internals")]
pub fn write_mesh(path: &Path, mesh: &ControlMesh, normals: Option<&[DVec3]>) -> Result<()> {
    write_mesh_with(path, mesh, normals, &WriteOptions::default())
}

/// [`write_mesh`] with `opts`.
#[cfg(feature = "internals")]
pub fn write_mesh_with(
    path: &Path,
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
    opts: &WriteOptions,
) -> Result<()> {
    let format = MeshFormat::from_path(path)?;
    // Checked before the file is created, so a refused mesh leaves no file behind.
    check_writable(format, mesh, normals, opts)?;
    // The writers stream into the file through their own buffer: no copy of the whole
    // output is ever held in memory.
    let mut file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    if let Err(e) = write_checked(&mut file, format, mesh, normals, opts) {
        // A half-written file must not pass for a mesh.
        drop(file);
        let _ = std::fs::remove_file(path);
        return Err(match e {
            Error::Io { source, .. } => Error::io(path, source),
            other => other,
        });
    }
    Ok(())
}

/// Writes a mesh in `format` to `writer` with the default [`WriteOptions`]. The mesh must
/// pass [`ControlMesh::validate`]; `normals`, when given, must have one entry per vertex.
#[cfg(feature = "internals")]
pub fn write_mesh_to(
    writer: &mut dyn std::io::Write,
    format: MeshFormat,
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
) -> Result<()> {
    write_mesh_to_with(writer, format, mesh, normals, &WriteOptions::default())
}

/// [`write_mesh_to`] with `opts`.
#[cfg(feature = "internals")]
pub fn write_mesh_to_with(
    writer: &mut dyn std::io::Write,
    format: MeshFormat,
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
    opts: &WriteOptions,
) -> Result<()> {
    check_writable(format, mesh, normals, opts)?;
    write_checked(writer, format, mesh, normals, opts)
}

/// Refuses what no writer can write: quantization outside glTF, an invalid mesh, a normal
/// count that is not the vertex count.
#[cfg(feature = "internals")]
fn check_writable(
    format: MeshFormat,
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
    opts: &WriteOptions,
) -> Result<()> {
    if opts.quantize && !matches!(format, MeshFormat::Glb | MeshFormat::Gltf) {
        return Err(Error::Parameter(format!(
            "quantization is a glTF option; {format} output cannot be quantized"
        )));
    }
    mesh.validate()?;
    if let Some(n) = normals {
        if n.len() != mesh.vertex_count() {
            return Err(Error::Parameter(format!(
                "{} normals given for {} vertices",
                n.len(),
                mesh.vertex_count()
            )));
        }
    }
    Ok(())
}

/// Runs the writer of `format` on a mesh [`check_writable`] accepted.
#[cfg(feature = "internals")]
fn write_checked(
    writer: &mut dyn std::io::Write,
    format: MeshFormat,
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
    opts: &WriteOptions,
) -> Result<()> {
    let result = match format {
        MeshFormat::Obj => obj::write(writer, mesh, normals),
        MeshFormat::Off => off::write(writer, mesh),
        MeshFormat::Ply => ply::write(writer, mesh, normals),
        MeshFormat::Stl => stl::write(writer, mesh),
        MeshFormat::Glb => gltf::write_glb(writer, mesh, normals, opts),
        MeshFormat::Gltf => gltf::write_gltf(writer, mesh, normals, opts),
    };
    result.map_err(|e| Error::io(format!("<{format} output>"), e))
}

/// The writers' output buffer: large enough that each write reaches the file in few system
/// calls, since decoded meshes run to hundreds of megabytes.
#[cfg(feature = "internals")]
pub(crate) fn buffered(
    out: &mut dyn std::io::Write,
) -> std::io::BufWriter<&mut dyn std::io::Write> {
    std::io::BufWriter::with_capacity(1 << 20, out)
}

/// `mask[v]` is true for the corner vertices `v` of `mesh`: a lookup per vertex that does
/// not search the set.
#[cfg(feature = "internals")]
pub(crate) fn corner_mask(mesh: &ControlMesh) -> Vec<bool> {
    let mut mask = vec![false; mesh.vertex_count()];
    for &c in &mesh.corners {
        if let Some(m) = mask.get_mut(c as usize) {
            *m = true;
        }
    }
    mask
}

/// Triangulates face `f` as a fan from its first vertex (used by the STL and glb writers,
/// which only store triangles).
#[cfg(feature = "internals")]
pub(crate) fn fan_triangles(face: &[u32]) -> impl Iterator<Item = [u32; 3]> + '_ {
    (1..face.len().saturating_sub(1)).map(move |i| [face[0], face[i], face[i + 1]])
}

#[cfg(test)]
pub(crate) mod test_support {
    use std::path::PathBuf;

    /// The shared corpus: `<repo>/../shared/corpus`, falling back to `/work/shared/corpus`.
    pub fn corpus_dir() -> Option<PathBuf> {
        let candidates = [
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus"),
            PathBuf::from("/work/shared/corpus"),
        ];
        let found = candidates
            .into_iter()
            .find(|p| p.join("MANIFEST.md").is_file());
        if found.is_none() {
            eprintln!("corpus not found; skipping corpus test");
        }
        found
    }

    /// Reads a corpus mesh (by path relative to the corpus) with the real readers; `None`
    /// (with a message) when the corpus is missing.
    pub fn load_corpus(rel: &str) -> Option<crate::mesh::ControlMesh> {
        let dir = corpus_dir()?;
        let (mesh, _) = super::read_mesh(&dir.join(rel)).expect("corpus mesh reads");
        Some(mesh)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_from_extension() {
        assert_eq!(
            MeshFormat::from_path(Path::new("a/b.OBJ")).unwrap(),
            MeshFormat::Obj
        );
        assert_eq!(
            MeshFormat::from_path(Path::new("x.Glb")).unwrap(),
            MeshFormat::Glb
        );
        assert_eq!(
            MeshFormat::from_path(Path::new("x.off")).unwrap(),
            MeshFormat::Off
        );
        let err = MeshFormat::from_path(Path::new("x.step"))
            .unwrap_err()
            .to_string();
        assert!(err.contains(".step") && err.contains(".obj"), "{err}");
        assert!(MeshFormat::from_path(Path::new("noext")).is_err());
    }

    #[test]
    fn fan_triangulation() {
        let t: Vec<_> = fan_triangles(&[4, 5, 6, 7, 8]).collect();
        assert_eq!(t, vec![[4, 5, 6], [4, 6, 7], [4, 7, 8]]);
        assert_eq!(fan_triangles(&[1, 2, 3]).count(), 1);
    }

    #[test]
    fn empty_input_is_an_error_for_every_format() {
        for format in MeshFormat::ALL {
            let err = read_mesh_bytes(b"", format, Path::new("empty.x")).unwrap_err();
            assert!(matches!(err, Error::Input { .. }), "{format}: {err}");
        }
    }

    /// Corrupted files (random byte flips, truncations) of every format give `Ok` or `Err`,
    /// never a panic. Deterministic: a fixed LCG picks the corruptions.
    #[test]
    fn corrupted_files_never_panic() {
        use crate::mesh::PatchKind;
        let mut mesh = ControlMesh::new();
        for i in 0..12 {
            let a = i as f64 * 0.5;
            mesh.push_vertex(DVec3::new(a.cos(), a.sin(), (i % 3) as f64));
        }
        let g0 = mesh.push_group("face_1", PatchKind::default());
        let g1 = mesh.push_group("face_2", PatchKind::default());
        for i in 0..10u32 {
            mesh.push_face(&[i, i + 1, i + 2], if i < 5 { g0 } else { g1 });
        }
        mesh.push_face(&[0, 3, 6, 9], g1);
        mesh.set_sharp(0, 1);
        mesh.corners.insert(2);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as usize
        };
        for format in MeshFormat::ALL {
            let mut clean = Vec::new();
            write_mesh_to(&mut clean, format, &mesh, None).unwrap();
            read_mesh_bytes(&clean, format, Path::new("clean")).unwrap();
            for round in 0..400 {
                let mut bytes = clean.clone();
                match round % 4 {
                    0 => bytes.truncate(next() % clean.len()),
                    1 => {
                        let i = next() % bytes.len();
                        bytes[i] = next() as u8;
                    }
                    2 => {
                        for _ in 0..8 {
                            let i = next() % bytes.len();
                            bytes[i] ^= 1 << (next() % 8);
                        }
                    }
                    _ => {
                        let i = next() % bytes.len();
                        let digits = b"0123456789-.e ";
                        bytes[i] = digits[next() % digits.len()];
                    }
                }
                if let Ok((m, _)) = read_mesh_bytes(&bytes, format, Path::new("corrupt")) {
                    m.validate().unwrap();
                }
            }
        }
    }

    mod proptests {
        use super::*;
        use crate::mesh::PatchKind;
        use proptest::prelude::*;

        /// Random valid meshes: distinct positions with arbitrary finite bits (subnormals,
        /// large, negative zero) up to 1e150, beyond which a box's diagonal can overflow
        /// and the readers refuse the file, polygons of 3-5 distinct vertices, every vertex
        /// used, every group used, sharp edges on face edges, arbitrary corners.
        fn mesh_strategy() -> impl Strategy<Value = ControlMesh> {
            let coord = prop_oneof![
                any::<f64>().prop_filter("finite, box diagonal finite", |c| c.is_finite()
                    && c.abs() <= 1e150),
                Just(-0.0),
                Just(f64::MIN_POSITIVE / 8.0),
            ];
            (4usize..10)
                .prop_flat_map(move |nv| {
                    let positions = prop::collection::vec((coord.clone(), coord.clone()), nv);
                    let face = prop::sample::subsequence(
                        (0..nv as u32).collect::<Vec<_>>(),
                        3..=5.min(nv),
                    )
                    .prop_shuffle();
                    let faces = prop::collection::vec(face, 1..8);
                    (positions, faces, 1usize..4, any::<u64>())
                })
                .prop_map(|(xy, faces, ng, bits)| {
                    let ng = ng.min(faces.len());
                    // Keep used vertices only, in index order.
                    let mut used = vec![u32::MAX; xy.len()];
                    for f in &faces {
                        for &v in f {
                            used[v as usize] = 0;
                        }
                    }
                    let mut m = ControlMesh::new();
                    for (i, &(x, z)) in xy.iter().enumerate() {
                        if used[i] == 0 {
                            used[i] = m.push_vertex(DVec3::new(x, i as f64, z));
                        }
                    }
                    for g in 0..ng {
                        m.push_group(format!("group {g}"), PatchKind::default());
                    }
                    for (i, f) in faces.iter().enumerate() {
                        let f: Vec<u32> = f.iter().map(|&v| used[v as usize]).collect();
                        m.push_face(&f, (i % ng) as u32);
                    }
                    for f in 0..m.face_count() {
                        let face = m.face(f).to_vec();
                        if bits >> (f % 64) & 1 == 1 {
                            m.set_sharp(face[0], face[1]);
                        }
                    }
                    for v in 0..m.vertex_count() as u32 {
                        if bits >> (32 + v % 32) & 1 == 1 {
                            m.corners.insert(v);
                        }
                    }
                    m
                })
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(64))]
            #[test]
            fn obj_and_ply_round_trip_exactly(mesh in mesh_strategy()) {
                for format in [MeshFormat::Obj, MeshFormat::Ply] {
                    let mut bytes = Vec::new();
                    write_mesh_to(&mut bytes, format, &mesh, None).unwrap();
                    let (back, report) =
                        read_mesh_bytes(&bytes, format, Path::new("p")).unwrap();
                    prop_assert!(report.unchanged(), "{}: {}", format, report);
                    prop_assert_eq!(back.positions.len(), mesh.positions.len());
                    for (a, b) in back.positions.iter().zip(&mesh.positions) {
                        prop_assert_eq!(
                            a.to_array().map(f64::to_bits),
                            b.to_array().map(f64::to_bits)
                        );
                    }
                    prop_assert_eq!(&back, &mesh);
                }
            }

            #[test]
            fn off_round_trips_faces(mesh in mesh_strategy()) {
                let mut bytes = Vec::new();
                write_mesh_to(&mut bytes, MeshFormat::Off, &mesh, None).unwrap();
                let (back, _) = read_mesh_bytes(&bytes, MeshFormat::Off, Path::new("p")).unwrap();
                prop_assert_eq!(&back.positions, &mesh.positions);
                prop_assert_eq!(&back.face_vertices, &mesh.face_vertices);
            }
        }
    }
}
