//! The library's documented entry points, re-exported at the crate root: [`encode`],
//! [`decode`] and [`inspect`] with their options and results. They take and return plain
//! arrays ([`Mesh`]) so that an embedder needs none of the internal types.

#[cfg(feature = "encoder")]
use std::path::Path;

use crate::codec;
use crate::error::Result;
use crate::mesh::{ControlMesh, Tolerance};
use crate::surface::{decode_surface, AccuracyReport, SurfaceOptions};

/// Decoder resource limits (re-exported from the codec; see `spec/format.md` §10).
pub use crate::codec::Limits;

/// A triangle mesh whose triangles are grouped by CAD face: the input of [`encode`] and the
/// output of [`decode`].
///
/// `groups` is empty or holds one group index per triangle; `group_names` is empty or holds
/// one name per group (a name may be empty). Sharp edges are vertex pairs, in either order
/// on input and as `[min, max]` on output; the edges between two groups are sharp whether
/// listed or not.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions in model units.
    pub positions: Vec<[f64; 3]>,
    /// Vertex indices of each triangle, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    /// Group (CAD face) of each triangle; empty for an ungrouped mesh.
    pub groups: Vec<u32>,
    /// Name of each group; empty for unnamed groups.
    pub group_names: Vec<String>,
    /// Sharp (crease) edges as vertex pairs.
    pub sharp_edges: Vec<[u32; 2]>,
}

impl Mesh {
    /// Number of groups: of `group_names`, or one more than the largest group index (1 for
    /// an ungrouped mesh with triangles).
    pub fn group_count(&self) -> usize {
        let used = self
            .groups
            .iter()
            .max()
            .map_or(usize::from(!self.triangles.is_empty()), |&g| g as usize + 1);
        used.max(self.group_names.len())
    }

    /// The mesh with polygons fan-triangulated (a triangle keeps its face's group), sharp
    /// edges as `[min, max]` pairs.
    pub(crate) fn from_control(mesh: &ControlMesh) -> Mesh {
        let mut triangles = Vec::with_capacity(mesh.face_vertices.len());
        let mut groups = Vec::with_capacity(mesh.face_vertices.len());
        for (f, face) in mesh.faces().enumerate() {
            for k in 1..face.len() - 1 {
                triangles.push([face[0], face[k], face[k + 1]]);
                groups.push(mesh.face_groups[f]);
            }
        }
        Mesh {
            positions: mesh.positions.iter().map(|p| p.to_array()).collect(),
            triangles,
            groups,
            group_names: mesh.groups.iter().map(|g| g.name.clone()).collect(),
            sharp_edges: mesh.sharp_edges.iter().map(|&(a, b)| [a, b]).collect(),
        }
    }

    /// `Error::Parameter` unless every index is in range and the group arrays agree.
    #[cfg(feature = "encoder")]
    fn check(&self) -> Result<()> {
        let nv = self.positions.len();
        let bad = |what: String| Err(crate::Error::Parameter(what));
        if u32::try_from(nv).is_err() {
            return bad(format!("{nv} vertices: at most 2^32 are supported"));
        }
        if let Some((t, tri)) = self
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v as usize >= nv))
        {
            return bad(format!(
                "triangle {t} ({tri:?}) references a vertex beyond the {nv} vertices"
            ));
        }
        if !self.groups.is_empty() && self.groups.len() != self.triangles.len() {
            return bad(format!(
                "{} group indices for {} triangles (give one per triangle, or none)",
                self.groups.len(),
                self.triangles.len()
            ));
        }
        if !self.group_names.is_empty() {
            if let Some(&g) = self
                .groups
                .iter()
                .find(|&&g| g as usize >= self.group_names.len())
            {
                return bad(format!(
                    "group {g} has no name: {} group names given",
                    self.group_names.len()
                ));
            }
        }
        if let Some(e) = self
            .sharp_edges
            .iter()
            .find(|e| e.iter().any(|&v| v as usize >= nv) || e[0] == e[1])
        {
            return bad(format!(
                "sharp edge {e:?} is not an edge between two vertices"
            ));
        }
        Ok(())
    }

    /// The mesh as the readers produce a file's: welded, repaired, empty groups and
    /// unreferenced vertices dropped (see the `io` module documentation).
    #[cfg(feature = "encoder")]
    fn to_control(&self) -> Result<ControlMesh> {
        use crate::io::repair::{finish, RawMesh};
        self.check()?;
        let mut raw = RawMesh::new();
        raw.positions = self
            .positions
            .iter()
            .map(|&p| glam::DVec3::from(p))
            .collect();
        let groups = self.group_count().max(1);
        raw.group_names = (0..groups)
            .map(|g| self.group_names.get(g).cloned().unwrap_or_default())
            .collect();
        for (t, tri) in self.triangles.iter().enumerate() {
            raw.push_face(tri, self.groups.get(t).copied().unwrap_or(0));
        }
        raw.input_faces = self.triangles.len();
        raw.sharp_edges = self.sharp_edges.clone();
        let (mut mesh, _) = finish(raw, crate::io::MeshFormat::Obj, Path::new("mesh"))?;
        mesh.sharpen_group_boundaries();
        Ok(mesh)
    }
}

/// A mesh file format [`encode`] reads (re-exported from the readers).
#[cfg(feature = "encoder")]
pub use crate::io::MeshFormat;

/// How hard the encoder searches for a smaller file (re-exported from the pipeline).
#[cfg(feature = "encoder")]
pub use crate::pipeline::Effort;

/// What a fitted file's error is measured against (re-exported from the fit).
#[cfg(feature = "encoder")]
pub use crate::fit::encoder::Reference;

/// What [`encode`] compresses.
#[cfg(feature = "encoder")]
#[derive(Clone, Copy, Debug)]
#[non_exhaustive]
pub enum Input<'a> {
    /// A triangle mesh with face groups.
    Mesh(&'a Mesh),
    /// A mesh file in memory: OBJ (`g` groups), PLY, STL, OFF or glTF binary (groups from
    /// primitives or `_FEATURE_ID_0`).
    MeshFile { bytes: &'a [u8], format: MeshFormat },
    /// A STEP (ISO 10303-21) file in memory: its B-rep faces are tessellated to the
    /// tolerance and fitted with their surface types. Lengths come out in millimetres.
    #[cfg(feature = "step")]
    Step(&'a [u8]),
}

/// Options of [`encode`].
#[cfg(feature = "encoder")]
#[derive(Clone, Debug, PartialEq)]
pub struct EncodeOptions {
    /// Largest distance the decoded surface may be from the input (default: 1e-3 of the
    /// bounding-box diagonal): the plain distance to an input mesh (unless
    /// `chord_allowance`), the distance to the B-rep for STEP input.
    pub tolerance: Tolerance,
    /// Hold the tolerance beyond the input mesh's own chord error (each facet's estimated
    /// distance from the CAD surface it tessellates) instead of to the mesh itself: for
    /// coarse tessellations of smooth parts, whose facets a smooth surface cannot come nearer
    /// to than their sagitta. Default false. STEP input is always measured against its B-rep.
    pub chord_allowance: bool,
    /// The bytes of a mesh input's face sidecar (`<name>.faces.json`: each CAD face's
    /// surface type, matched to the group of the same name, `face_<tag>`): groups on planes,
    /// cylinders and cones are then fitted as such instead of by the shape of their
    /// triangles, which fits some faces a guess cannot (the `scode` command reads the
    /// sidecar next to its input by itself). Ignored for STEP input, which has its own
    /// surface types, and in raw mode. Default `None`.
    pub faces_json: Option<Vec<u8>>,
    /// Default [`Effort::Default`].
    pub effort: Effort,
    /// Store the group names (default true).
    pub store_group_names: bool,
    /// `Some(bits)`: store the input mesh itself (raw mode, no fit) with positions quantised
    /// to `bits` bits per coordinate (4..=24); `tolerance` and `effort` do not apply.
    pub raw_bits: Option<u8>,
}

#[cfg(feature = "encoder")]
impl Default for EncodeOptions {
    fn default() -> Self {
        EncodeOptions {
            tolerance: Tolerance::DEFAULT,
            chord_allowance: false,
            faces_json: None,
            effort: Effort::Default,
            store_group_names: true,
            raw_bits: None,
        }
    }
}

/// The result of [`encode`].
#[cfg(feature = "encoder")]
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct Encoded {
    /// The `.scode` file.
    pub bytes: Vec<u8>,
    /// Vertices, triangles (polygons fan-split) and groups of the input as read.
    pub input_vertices: usize,
    pub input_triangles: usize,
    pub input_groups: usize,
    /// Fitted files: the tolerance in model units.
    pub tolerance: Option<f64>,
    /// Fitted files: the largest distance between the decoded surface (default level, limit
    /// positions) and the input, in model units.
    pub max_error: Option<f64>,
    /// Fitted files: what `max_error` and the tolerance were measured against.
    pub reference: Option<Reference>,
    /// Whether the fit met the tolerance against `reference`; always true for raw mode.
    pub within_tolerance: bool,
    /// STEP input: B-rep faces that could not be read or tessellated, left out of the file.
    pub skipped_faces: usize,
    /// What the reader and the fit noted (choices made, parts skipped), one line each.
    pub notes: Vec<String>,
}

/// Encodes `input` to a `.scode` file.
///
/// ```
/// // A unit cube, two triangles per side, each side its own CAD face.
/// let positions = (0..8)
///     .map(|i| [(i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2 & 1) as f64])
///     .collect();
/// let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
/// let mut mesh = scode::Mesh { positions, ..Default::default() };
/// for (side, q) in quads.iter().enumerate() {
///     mesh.triangles.extend([[q[0], q[1], q[2]], [q[0], q[2], q[3]]]);
///     mesh.groups.extend([side as u32; 2]);
///     mesh.group_names.push(format!("side{side}"));
/// }
/// let encoded = scode::encode(scode::Input::Mesh(&mesh), &scode::EncodeOptions::default())?;
/// assert!(encoded.within_tolerance);
///
/// let surface = scode::decode(&encoded.bytes, &scode::DecodeOptions::default())?;
/// assert_eq!(surface.mesh.group_names, mesh.group_names);
/// assert!(surface.mesh.positions.iter().flatten().all(|c| (-1e-3..=1.001).contains(c)));
/// # Ok::<(), scode::Error>(())
/// ```
#[cfg(feature = "encoder")]
pub fn encode(input: Input<'_>, opts: &EncodeOptions) -> Result<Encoded> {
    use crate::pipeline::{encode_fitted, ModelEncodeOptions};
    let mut model_opts = ModelEncodeOptions {
        store_group_names: opts.store_group_names,
        effort: opts.effort,
        ..Default::default()
    };
    model_opts.fit.tolerance = opts.tolerance;
    model_opts.fit.chord_allowance = opts.chord_allowance;
    let mut notes = Vec::new();
    let (mesh, fitted, skipped_faces) = match input {
        Input::Mesh(m) => (m.to_control()?, None, 0),
        Input::MeshFile { bytes, format } => {
            let name = format!("<{} file>", format.name());
            let (mesh, report) = crate::io::read_mesh_bytes(bytes, format, Path::new(&name))?;
            notes.extend(report.repairs);
            (mesh, None, 0)
        }
        #[cfg(feature = "step")]
        Input::Step(bytes) => {
            let name = Path::new("<STEP file>");
            if opts.raw_bits.is_some() {
                let sopts = crate::pipeline::step_options_for(opts.tolerance);
                let model = crate::io::step::read_step_bytes(name, bytes, &sopts)?;
                notes.extend(model.notes);
                (model.mesh, None, model.skipped.len())
            } else {
                let (model, bytes, fit) =
                    crate::pipeline::encode_step_bytes(name, bytes, &model_opts)?;
                notes.extend(model.notes);
                (model.mesh, Some((bytes, fit)), model.skipped.len())
            }
        }
    };
    let (bytes, fit) = match (opts.raw_bits, fitted) {
        (Some(bits), _) => {
            let copts = codec::EncodeOptions {
                quantization_bits: bits,
                content: codec::Content::RawMesh,
                store_group_names: opts.store_group_names,
                ..Default::default()
            };
            (codec::encode(&mesh, &copts)?, None)
        }
        (None, Some((bytes, fit))) => (bytes, Some(fit)),
        (None, None) => {
            let hints = match &opts.faces_json {
                Some(json) => crate::pipeline::sidecar_hints_from_bytes(
                    json,
                    Path::new("<faces.json>"),
                    &mesh,
                )?,
                None => Vec::new(),
            };
            let (bytes, fit) = encode_fitted(&mesh, &hints, &model_opts)?;
            (bytes, Some(fit))
        }
    };
    if let Some(fit) = &fit {
        notes.extend(fit.notes.iter().cloned());
    }
    Ok(Encoded {
        bytes,
        input_vertices: mesh.vertex_count(),
        input_triangles: mesh.face_vertices.len() - 2 * mesh.face_count(),
        input_groups: mesh.groups.len(),
        tolerance: fit.as_ref().map(|f| f.tolerance),
        max_error: fit.as_ref().map(|f| f.error.max),
        reference: fit.as_ref().map(|f| f.reference),
        within_tolerance: fit.as_ref().is_none_or(|f| f.within_tolerance),
        skipped_faces,
        notes,
    })
}

/// How much detail [`decode`] produces (re-exported from the decoder).
pub use crate::surface::Detail as DecodeDetail;

/// Options of [`decode`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DecodeOptions {
    /// Default: every part of the surface subdivided to the coarsest level within the
    /// tolerance the file was encoded for ([`DecodeDetail::FileTolerance`]).
    pub detail: DecodeDetail,
    /// Limit positions (and normals): `None` is true for a control mesh and false for a
    /// raw-mode file; `Some(false)` needs a uniform level ([`DecodeDetail::Level`]).
    pub limit: Option<bool>,
    /// Resource limits for untrusted files (default [`Limits::default`]).
    pub limits: Limits,
    /// The longest edge of the output in model units, for solvers that need an element
    /// size: longer edges are split at their midpoints, the same way for both faces beside
    /// them, so the surface stays watertight and keeps its groups, sharp edges and corners.
    /// `None` (the default) splits nothing.
    pub max_edge: Option<f64>,
    /// With `max_edge`: the smallest angle (degrees, up to 30) of the triangles inside plane
    /// patches, which are triangulated anew by constrained Delaunay refinement inside their
    /// outlines (feature `remesh`, on by default); curved patches keep the split triangles.
    pub min_angle: Option<f64>,
}

impl DecodeOptions {
    /// A uniform subdivision level for the whole surface.
    pub fn level(level: u32) -> Self {
        DecodeOptions {
            detail: DecodeDetail::Level(level),
            ..Default::default()
        }
    }

    /// Every part at the coarsest level within `tolerance` of the limit surface.
    pub fn tolerance(tolerance: Tolerance) -> Self {
        DecodeOptions {
            detail: DecodeDetail::Tolerance(tolerance),
            ..Default::default()
        }
    }

    /// These options with no output edge longer than `max_edge` (model units). The surface
    /// does not move: new vertices lie on the edges they split, so the decode's accuracy
    /// holds.
    ///
    /// ```
    /// let opts = scode::DecodeOptions::default().max_edge(0.5);
    /// assert_eq!(opts.max_edge, Some(0.5));
    /// ```
    pub fn max_edge(self, max_edge: f64) -> Self {
        DecodeOptions {
            max_edge: Some(max_edge),
            ..self
        }
    }

    /// These options with plane patches refined to no angle under `min_angle` degrees (up
    /// to 30); needs [`DecodeOptions::max_edge`].
    ///
    /// ```
    /// let opts = scode::DecodeOptions::default().max_edge(0.5).min_angle(25.0);
    /// assert_eq!(opts.min_angle, Some(25.0));
    /// ```
    pub fn min_angle(self, min_angle: f64) -> Self {
        DecodeOptions {
            min_angle: Some(min_angle),
            ..self
        }
    }
}

/// A decoded surface: the result of [`decode`].
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct Surface {
    /// The triangles, each with its CAD face (group) and the group names; sharp edges are
    /// the creases of the surface (CAD-face boundaries among them).
    pub mesh: Mesh,
    /// Unit normals of the limit surface per vertex, when decoded to limit positions.
    pub normals: Option<Vec<[f64; 3]>>,
    /// The finest subdivision level in the output (0 for a raw-mode file).
    pub level: u32,
    /// Whether positions lie on the limit surface.
    pub limit: bool,
    /// Decoded to a tolerance: the tolerance in model units and the largest estimated
    /// distance of the output from the limit surface.
    pub tolerance: Option<(f64, f64)>,
}

/// Decodes a `.scode` file to a triangle surface. Malformed or hostile input is an
/// [`Error`](crate::Error) (never a panic), and a file whose decode would exceed `opts.limits` is
/// [`Error::LimitsExceeded`](crate::Error::LimitsExceeded).
///
/// ```
/// let err = scode::decode(b"not a scode file", &scode::DecodeOptions::default()).unwrap_err();
/// assert!(matches!(err, scode::Error::Format { .. }));
/// ```
pub fn decode(bytes: &[u8], opts: &DecodeOptions) -> Result<Surface> {
    let sopts = SurfaceOptions {
        detail: opts.detail,
        limit: opts.limit,
        max_edge: opts.max_edge,
        min_angle: opts.min_angle,
        ..Default::default()
    };
    let s = decode_surface(bytes, &opts.limits, &sopts)?;
    Ok(Surface {
        mesh: Mesh::from_control(&s.mesh),
        normals: s.normals.map(|n| n.iter().map(|v| v.to_array()).collect()),
        level: s.level,
        limit: s.limit,
        tolerance: s.accuracy.map(
            |AccuracyReport {
                 tolerance, bound, ..
             }| (tolerance, bound),
        ),
    })
}

/// What [`inspect`] reports about a `.scode` file.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct Info {
    /// Format version (major, minor).
    pub version: (u8, u8),
    /// `Some(level)` for a control mesh (the level the encoder measured its error at),
    /// `None` for a raw-mode file.
    pub default_level: Option<u32>,
    /// Vertices, faces and groups of the stored mesh.
    pub vertices: u64,
    pub faces: u64,
    pub groups: u64,
    pub group_names: Vec<String>,
    pub sharp_edges: usize,
    /// Bits per coordinate of the position grid.
    pub quantization_bits: u8,
    /// The grid's cube: minimum corner and edge length, in model units.
    pub bbox_min: [f64; 3],
    pub bbox_extent: f64,
    /// Size of the file and of each section (name, bytes stored).
    pub bytes: usize,
    pub sections: Vec<(&'static str, usize)>,
}

/// Reads a `.scode` file's header and sections (with the default [`Limits`]) without
/// subdividing it.
///
/// ```
/// assert!(scode::inspect(&[0u8; 8]).is_err());
/// ```
pub fn inspect(bytes: &[u8]) -> Result<Info> {
    let info = codec::inspect(bytes, &Limits::default())?;
    let h = info.header;
    Ok(Info {
        version: (h.version_major, h.version_minor),
        default_level: match h.content {
            codec::Content::RawMesh => None,
            codec::Content::ControlMesh { default_level } => Some(default_level.into()),
        },
        vertices: h.vertex_count,
        faces: h.face_count,
        groups: h.group_count,
        group_names: info.group_names,
        sharp_edges: info.sharp_edge_count,
        quantization_bits: h.quantization_bits,
        bbox_min: h.bbox_min,
        bbox_extent: h.bbox_extent,
        bytes: info.total_bytes,
        sections: info
            .sections
            .iter()
            .map(|s| (s.name, s.stored_bytes))
            .collect(),
    })
}

#[cfg(all(test, feature = "encoder"))]
mod tests {
    use super::*;
    use crate::Error;

    fn tetrahedron() -> Mesh {
        Mesh {
            positions: vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            groups: vec![0, 1, 2, 3],
            group_names: ["a", "b", "c", "d"].map(String::from).to_vec(),
            sharp_edges: vec![],
        }
    }

    #[test]
    fn raw_round_trip_keeps_groups_and_names() {
        let mesh = tetrahedron();
        let opts = EncodeOptions {
            raw_bits: Some(12),
            ..Default::default()
        };
        let enc = encode(Input::Mesh(&mesh), &opts).unwrap();
        assert_eq!((enc.input_vertices, enc.input_triangles), (4, 4));
        let s = decode(&enc.bytes, &DecodeOptions::default()).unwrap();
        assert_eq!(s.level, 0);
        assert_eq!(s.mesh.triangles.len(), 4);
        assert_eq!(s.mesh.group_names, mesh.group_names);
        // Every edge separates two groups, so every edge is sharp.
        assert_eq!(s.mesh.sharp_edges.len(), 6);
        let info = inspect(&enc.bytes).unwrap();
        assert_eq!((info.vertices, info.faces, info.groups), (4, 4, 4));
        assert_eq!(info.default_level, None);
        assert_eq!(info.bytes, enc.bytes.len());
    }

    #[test]
    fn bad_meshes_are_parameter_errors() {
        let mut m = tetrahedron();
        m.triangles[1][2] = 9;
        let e = encode(Input::Mesh(&m), &EncodeOptions::default()).unwrap_err();
        assert!(matches!(e, Error::Parameter(_)), "{e}");
        let mut m = tetrahedron();
        m.groups.pop();
        assert!(matches!(
            encode(Input::Mesh(&m), &EncodeOptions::default()),
            Err(Error::Parameter(_))
        ));
        let mut m = tetrahedron();
        m.group_names.pop();
        assert!(matches!(
            encode(Input::Mesh(&m), &EncodeOptions::default()),
            Err(Error::Parameter(_))
        ));
    }

    #[test]
    fn polygons_are_fan_triangulated_with_their_group() {
        let mut c = ControlMesh::new();
        for p in [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
            c.push_vertex(glam::DVec3::from(p));
        }
        let g = c.push_group("q", Default::default());
        c.push_face(&[0, 1, 2, 3], g);
        c.set_sharp(3, 0);
        let m = Mesh::from_control(&c);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.groups, vec![0, 0]);
        assert_eq!(m.sharp_edges, vec![[0, 3]]);
        assert_eq!(m.group_count(), 1);
    }
}
