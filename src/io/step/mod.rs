//! STEP (ISO 10303-21, AP203/AP214/AP242) B-rep input for the encoder.
//!
//! [`read_step`] reads the solids and shells of a STEP file with truck (truck-stepio for the
//! geometry, truck-meshalgo for the tessellation) and returns a [`StepModel`]: one triangle
//! mesh with one vertex pool for the whole model (watertight where the B-rep is), one group
//! per B-rep face, the B-rep vertices as corners, the B-rep edges as polylines in the pool,
//! each face's surface type with its exact axis, apex and radii, and the list of faces that
//! could not be read and why. The encoder takes the mesh and the surface types from here
//! instead of re-deriving them from triangles.
//!
//! What truck does not do is done here (crates.md, "STEP"):
//! * **Text pre-passes** ([`text::prepass`]): `.PCURVE_S1.` master flags and empty lists;
//!   PARABOLA curves, on which truck's face conversion hangs, rewritten as the quadratic
//!   B-splines they are over their edges ([`text::parabolas_to_bsplines`]).
//! * **Ids**: truck forgets STEP ids once it builds a shell, so the walk from shells to faces,
//!   edges and vertices is our own (mirroring `Table::to_compressed_shell`), and every face
//!   keeps its `ADVANCED_FACE #id`.
//! * **Nothing dropped silently**: a face whose surface or edge curve truck cannot convert,
//!   or whose tessellation fails, panics or hangs, becomes a [`SkippedFace`] naming the face
//!   id and the entity; the rest of the model is still read.
//! * **Hostile text** ([`check`]): nesting deeper than [`check::MAX_NESTING`], numbers that
//!   are not finite f64 values (or do not fit ruststep's integers) and points whose box
//!   has no finite diagonal are refused with their line and instance before ruststep parses
//!   the file; a syntax error names the line of the damaged instance.
//! * **Hangs and panics**: parsing runs in a watchdog thread ([`StepOptions::timeout`]), and
//!   each face is tessellated in its own watchdog thread ([`StepOptions::face_timeout`]),
//!   both under `catch_unwind`; all faces together get [`StepOptions::total_timeout`], so a
//!   read always ends. At a timeout the job's tessellation (ours and truck's) stops at its
//!   next surface or curve evaluation (`watch`); a job that cannot be stopped (the parse,
//!   truck's conversion of a face) is abandoned, and a read with more than one of those
//!   still running fails rather than start more threads.
//! * **Welding by construction**: each B-rep edge is polylined once (truck's curve
//!   polylining, trimmed to the edge's vertices) into a shared vertex pool, where boundary
//!   points at one position are one vertex. Each face is then triangulated by our own
//!   conforming tessellator (`conform`: spade CDT in the surface's parameters with the
//!   edge polylines as constraints, periodic faces cut along a seam whose copies share
//!   vertices, refined to the chordal tolerance), so neighbouring faces use the same
//!   vertices along their edge and the model is watertight; the CDT runs in a parameter
//!   plane stretched to the surface's lengths (a 500 mm cone's angle against its height:
//!   [`StepOptions::stretch_parameter_plane`]), and a face bounded by nothing but a
//!   VERTEX_LOOP (a whole sphere) is its surface's full parameter grid. Edge curves are
//!   trimmed to the vertices' nearest points on their polylines. A face it cannot do falls back
//!   to truck's tessellation snapped to the polylines; if that does not follow the face's
//!   edges either, the face is skipped and named rather than cracking the model. Where two
//!   faces meet at a knife edge and both close the same ear triangle on it, the ear is split
//!   in one of them so every edge keeps two faces.
//! * **Exact elementary surfaces** (`analytic`): planes, cylinders, cones, spheres and tori
//!   are evaluated and inverted in closed form from their STEP records (placement, radii,
//!   semi-angle in the file's plane-angle unit), not through truck's conversion, which
//!   misplaces some cones and spindle tori (minor radius larger than the major one); the
//!   face's exact axis and radii come from the record too. B-splines and the other
//!   surfaces use truck's surface (truck keeps the weights of rational B-splines).
//! * **Units**: truck ignores them; positions are converted to millimetres from the file's
//!   LENGTH_UNIT (as Open CASCADE and gmsh do), see [`StepModel::millimetres_per_unit`].
//!
//! Not supported (the message names the entity): assembly placements
//! (NEXT_ASSEMBLY_USAGE_OCCURRENCE with ITEM_DEFINED_TRANSFORMATION: the whole file is
//! refused, because its parts would land in the wrong place), tessellated-only files
//! (no ADVANCED_FACE), and the surfaces and curves truck-stepio 0.3 does not convert
//! (OFFSET_SURFACE, RECTANGULAR_TRIMMED_SURFACE, CURVE_BOUNDED_SURFACE, TRIMMED_CURVE,
//! COMPOSITE_CURVE, ...: those faces are skipped).

mod analytic;
mod brep;
pub mod check;
mod conform;
mod tessellate;
pub mod text;
mod watch;

use std::path::Path;
use std::time::Duration;

use crate::error::{Error, Result};
use crate::io::faces_json::SurfaceType;
use crate::mesh::{AnalyticSurface, Axis, ControlMesh, Tolerance};
use watch::{Cancel, Watched, Workers};

/// Options of [`read_step`].
#[derive(Clone, Debug, PartialEq)]
pub struct StepOptions {
    /// Chordal tolerance of the tessellation: in millimetres (the output unit), or relative
    /// to the model's bounding-box diagonal. Default: a quarter of the encoder's default
    /// tolerance ([`Tolerance::DEFAULT`]), so the tessellation's own chord error takes a
    /// small part of the error budget.
    pub chordal_tolerance: Tolerance,
    /// Faces on a plane, cylinder, cone, sphere or torus read from the record are
    /// tessellated at this multiple of the chordal tolerance, and so are the edges only such
    /// faces share (default 1: one chordal tolerance for all). The encoder measures those
    /// faces against their exact surface ([`crate::pipeline::step_exact_surfaces`]), so
    /// their facets need not be as fine as the others', which are measured against their
    /// facets alone; [`crate::pipeline::encode_step`] tries it besides 1.
    pub analytic_chordal_factor: f64,
    /// Triangulate each face in its parameter plane stretched to the surface's lengths
    /// (default true), so that its Delaunay triangles and chord refinement see the surface's
    /// shapes where its parameters are in different units (a cone's angle in radians against
    /// its height in millimetres); false triangulates in the raw parameters, which makes the
    /// smaller file on some models. [`crate::pipeline::encode_step`] tries both.
    pub stretch_parameter_plane: bool,
    /// Convert to millimetres using the file's LENGTH_UNIT (default true). When false, or when
    /// the file names no length unit, positions stay in file units.
    pub to_millimetres: bool,
    /// Longest time parsing the file may take.
    pub timeout: Duration,
    /// Longest time converting one face from STEP to truck, and then tessellating it, may
    /// take; a face over it is skipped.
    pub face_timeout: Duration,
    /// Longest time tessellating all faces may take (checked between faces, so the read
    /// ends at most about three `face_timeout`s later); over it the read fails naming how
    /// far it got. With `timeout` this bounds the whole read even when many faces hang.
    pub total_timeout: Duration,
}

impl Default for StepOptions {
    fn default() -> Self {
        StepOptions {
            chordal_tolerance: Tolerance::DEFAULT.scaled(0.25),
            analytic_chordal_factor: 1.0,
            stretch_parameter_plane: true,
            to_millimetres: true,
            timeout: Duration::from_secs(60),
            face_timeout: Duration::from_secs(10),
            total_timeout: Duration::from_secs(300),
        }
    }
}

/// The surface under one B-rep face, as the STEP file defines it (in output units).
///
/// It is kept beside the mesh (not only turned into a [`crate::mesh::PatchKind`]) because
/// spheres and tori also have exact parameters the encoder may use, and because `info`
/// shows the plan before anything is fitted.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceSurface {
    /// Id of the ADVANCED_FACE (or FACE_SURFACE) instance.
    pub face_id: u64,
    /// Id of its surface instance.
    pub surface_id: u64,
    /// Index into [`StepModel::bodies`].
    pub body: u32,
    /// The surface type, in the vocabulary of the corpus sidecars.
    pub surface: SurfaceType,
    /// STEP entity name of the surface (`CYLINDRICAL_SURFACE`, `B_SPLINE_SURFACE_WITH_KNOTS`,
    /// or a complex instance `(BOUNDED_SURFACE B_SPLINE_SURFACE ...)`).
    pub entity: String,
    /// The exact surface of a plane, cylinder, cone (its axis from the apex into the
    /// cone), sphere or torus face; `None` for other surfaces (and for a cone whose apex
    /// cannot be placed).
    pub exact: Option<AnalyticSurface>,
    /// A surface of revolution's axis.
    pub revolution_axis: Option<Axis>,
}

/// One body: a solid (MANIFOLD_SOLID_BREP, BREP_WITH_VOIDS; one per assembly instance) or a
/// free shell when the file has no solids. Bodies are the second level of grouping: with
/// several bodies, group names start with the body name, and each body's groups are
/// contiguous.
#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    /// `body<k>`, as used in group names.
    pub name: String,
    /// Id of the solid or shell instance.
    pub step_id: u64,
    /// Its entity name (`MANIFOLD_SOLID_BREP`, `CLOSED_SHELL`, ...).
    pub entity: String,
    /// Groups `first_group..first_group + group_count` belong to this body.
    pub first_group: u32,
    pub group_count: u32,
}

/// A B-rep edge as a polyline of pool vertices, from one B-rep vertex to the other.
#[cfg(feature = "internals")]
#[derive(Clone, Debug, PartialEq)]
pub struct BrepEdge {
    /// Id of the EDGE_CURVE instance.
    pub step_id: u64,
    /// Vertices of the mesh along the edge (first and last are corners).
    pub vertices: Vec<u32>,
    /// Groups (faces) bounded by this edge: two for an inner edge, one for a seam or an open
    /// boundary.
    pub groups: Vec<u32>,
}

/// A face that is not in the mesh, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct SkippedFace {
    /// Id of the face instance.
    pub face_id: u64,
    /// Name of the body (`body<k>`) it belongs to.
    pub body: String,
    /// The entity that stopped it (`OFFSET_SURFACE #52`, `TRIMMED_CURVE #80`, or the face's
    /// own entity when the tessellation failed).
    pub entity: String,
    pub reason: String,
}

impl std::fmt::Display for SkippedFace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "face #{} of {}: {}: {}",
            self.face_id, self.body, self.entity, self.reason
        )
    }
}

/// What [`read_step`] read.
#[derive(Clone, Debug, Default)]
pub struct StepModel {
    /// Triangles in one vertex pool, one group per face (`face_<k>` for the body's k-th face
    /// in file order, or `body<b>/face_<k>`
    /// when the file has several bodies); group-boundary
    /// edges are sharp, B-rep vertices are corners; analytic faces (plane, cylinder, cone)
    /// already carry their exact [`crate::mesh::BoundarySurface`] as the group's patch kind.
    pub mesh: ControlMesh,
    /// Surface of each group (same index).
    pub faces: Vec<FaceSurface>,
    #[cfg(feature = "internals")]
    pub bodies: Vec<Body>,
    #[cfg(feature = "internals")]
    pub edges: Vec<BrepEdge>,
    pub skipped: Vec<SkippedFace>,
    /// Chordal tolerance the faces were tessellated with (output units).
    pub chordal_tolerance: f64,
    /// Scale applied to the file's coordinates (`None`: no length unit found, file units kept).
    #[cfg(feature = "internals")]
    pub millimetres_per_unit: Option<f64>,
    /// What else the reader noticed (pre-pass rewrites, free shells left out, open edges...).
    pub notes: Vec<String>,
}

#[cfg(feature = "internals")]
impl StepModel {
    /// Number of faces by surface type name, in a fixed order.
    pub fn surface_histogram(&self) -> std::collections::BTreeMap<String, usize> {
        let mut h = std::collections::BTreeMap::new();
        for f in &self.faces {
            *h.entry(surface_name(&f.surface)).or_insert(0) += 1;
        }
        h
    }
}

/// Short name of a surface type for messages.
#[cfg(feature = "internals")]
pub fn surface_name(s: &SurfaceType) -> String {
    match s {
        SurfaceType::Plane => "plane".into(),
        SurfaceType::Cylinder => "cylinder".into(),
        SurfaceType::Cone => "cone".into(),
        SurfaceType::Sphere => "sphere".into(),
        SurfaceType::Torus => "torus".into(),
        SurfaceType::BSplineSurface => "B-spline".into(),
        SurfaceType::BezierSurface => "Bezier".into(),
        SurfaceType::SurfaceOfRevolution => "revolution".into(),
        SurfaceType::SurfaceOfExtrusion => "extrusion".into(),
        SurfaceType::OffsetSurface => "offset".into(),
        SurfaceType::Other(n) => n.clone(),
        SurfaceType::Unknown => "unknown".into(),
    }
}

/// True for `.step` / `.stp` (any case).
#[cfg(feature = "internals")]
pub fn is_step_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("step") || e.eq_ignore_ascii_case("stp"))
}

/// Reads the B-rep solids (or, without solids, the shells) of a STEP file. See the module
/// documentation for what is supported and how failures are reported.
#[cfg(feature = "internals")]
pub fn read_step(path: &Path, opts: &StepOptions) -> Result<StepModel> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_step_bytes(path, &bytes, opts)
}

/// [`read_step`] on bytes already in memory; `path` is only used in messages.
pub fn read_step_bytes(path: &Path, bytes: &[u8], opts: &StepOptions) -> Result<StepModel> {
    let parsed = parse_and_convert(path, bytes, opts)?;
    tessellate::tessellate(path, parsed, opts)
}

/// [`read_step`] once per entry of `tessellations`, parsing the file and converting its
/// faces once: the parse, the units and the conversion's timeouts are the first entry's,
/// each tessellation uses its own entry's chordal tolerances and timeouts. All models hold
/// the same faces, skipped or not, up to faces whose tessellation failed in one of them.
#[cfg(feature = "internals")]
pub fn read_step_tessellations(
    path: &Path,
    tessellations: &[StepOptions],
) -> Result<Vec<StepModel>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_step_tessellations_bytes(path, &bytes, tessellations)
}

/// [`read_step_tessellations`] on bytes already in memory; `path` is only used in messages.
pub fn read_step_tessellations_bytes(
    path: &Path,
    bytes: &[u8],
    tessellations: &[StepOptions],
) -> Result<Vec<StepModel>> {
    let Some(first) = tessellations.first() else {
        return Err(Error::Parameter(
            "read_step_tessellations: no tessellation asked for".into(),
        ));
    };
    let parsed = parse_and_convert(path, bytes, first)?;
    tessellations
        .iter()
        .map(|opts| tessellate::tessellate(path, parsed.clone(), opts))
        .collect()
}

/// The file's B-rep with every face converted to truck (what does not depend on the
/// tessellation options; `opts`' timeouts and units apply).
fn parse_and_convert(path: &Path, bytes: &[u8], opts: &StepOptions) -> Result<brep::Parsed> {
    let text = String::from_utf8_lossy(bytes).into_owned();
    if !text.trim_start().starts_with("ISO-10303-21") {
        return Err(Error::input(
            path,
            "not a STEP file: it does not start with `ISO-10303-21;`",
        ));
    }
    let owned_path = path.to_path_buf();
    let owned_opts = opts.clone();
    let workers = Workers::default();
    // ruststep's parse cannot poll a token: the text checks before it keep it linear in
    // the file's size, and past the timeout it is abandoned.
    let parsed = workers.run("scode-step-parse", opts.timeout, move |_: &Cancel| {
        brep::parse(&owned_path, &text, &owned_opts)
    });
    let parsed = match parsed {
        Watched::Done(r) => r?,
        Watched::Panicked(msg) => {
            return Err(Error::input(
                path,
                format!("the STEP reader (truck-stepio/ruststep) panicked: {msg}"),
            ))
        }
        Watched::TimedOut { .. } => {
            return Err(Error::input(
                path,
                format!(
                    "reading the B-rep did not finish within {:.0} s (truck can loop forever \
                     on some files); giving up",
                    opts.timeout.as_secs_f64()
                ),
            ))
        }
    };
    brep::convert(parsed, opts, workers)
}
