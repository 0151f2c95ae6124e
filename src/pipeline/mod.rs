//! The whole encoder: fitting (`fit`) plus the bitstream (`codec`). It lives above both so
//! that neither depends on the other; the fit measures its error on the control mesh exactly
//! as this module's codec round trip reconstructs it.

use std::path::Path;

use crate::codec::{self, Content, EncodeOptions, Limits};
use crate::error::{Error, Result};
use crate::fit::encoder::{fit_model, ExactSurface, FitOptions, FitReport, SurfaceHint};
use crate::io::faces_json::{self, SurfaceType};
use crate::mesh::{ControlMesh, Tolerance};
use glam::DVec3;

mod search;
pub use search::{
    encode_fitted, Effort, LOCAL_REFINEMENT_MAX_TRIANGLES, PLAIN_PLANES_MAX_TRIANGLES,
    TRAVERSAL_STARTS,
};
#[cfg(feature = "step")]
pub use search::{encode_step, StepTessellation, STEP_TESSELLATIONS};

/// Fitted control meshes are never quantised coarser than this.
const MIN_FITTED_BITS: u8 = 6;

/// `2^(k/4)` for k = 0..4, the grid step factors of a quarter bit coarser (literals, not
/// `powf`, so the stored box is the same on every platform's libm).
const QUARTER_BIT_SCALES: [f64; 4] = [
    1.0,
    1.189_207_115_002_721,
    std::f64::consts::SQRT_2,
    1.681_792_830_507_429,
];

/// The margin of the fitted models' quantisation grid around the input's box, as a fraction
/// of the box's largest extent on each side: control points of convex closed patches lie
/// outside the surface, and the grid covers them (a control point beyond the margin grows the
/// box for its round alone).
const GRID_MARGIN: f64 = 1.0 / 32.0;

/// Options of [`encode_fitted`] and [`encode_step`].
#[derive(Clone, Debug, PartialEq)]
pub struct ModelEncodeOptions {
    pub fit: FitOptions,
    /// Quantisation bits; default: the fewest that keep the quantisation error below a
    /// quarter of the tolerance.
    pub quantization_bits: Option<u8>,
    pub store_group_names: bool,
    /// How many alternatives the encoder fits and encodes to find a smaller file.
    pub effort: Effort,
}

impl Default for ModelEncodeOptions {
    fn default() -> Self {
        ModelEncodeOptions {
            fit: FitOptions::default(),
            quantization_bits: None,
            store_group_names: true,
            effort: Effort::Default,
        }
    }
}

/// What a surface type from a STEP file or a sidecar means for the fit.
pub fn hint_for(surface: &SurfaceType) -> SurfaceHint {
    match surface {
        SurfaceType::Plane => SurfaceHint::Plane,
        SurfaceType::Cylinder => SurfaceHint::Cylinder,
        SurfaceType::Cone => SurfaceHint::Cone,
        SurfaceType::Unknown => SurfaceHint::Unknown,
        _ => SurfaceHint::Freeform,
    }
}

/// Per-group surface hints of a STEP model: its exact surface types.
#[cfg(feature = "step")]
pub fn step_hints(model: &crate::io::step::StepModel) -> Vec<SurfaceHint> {
    model.faces.iter().map(|f| hint_for(&f.surface)).collect()
}

/// Per-group exact surfaces of a STEP model, for [`FitOptions::exact_surfaces`]: planes,
/// cylinders, cones, spheres and tori with the file's parameters; `None` for other surfaces
/// and for parameters the reader could not make sense of.
#[cfg(feature = "step")]
pub fn step_exact_surfaces(model: &crate::io::step::StepModel) -> Vec<Option<ExactSurface>> {
    model
        .faces
        .iter()
        .map(|f| f.exact.and_then(ExactSurface::new))
        .collect()
}

/// Chordal tolerance of the STEP tessellation, as a fraction of the encode tolerance: the
/// facets' own chord error takes a small part of the error budget of faces measured against
/// their facets alone (B-splines and other freeform surfaces).
#[cfg(feature = "step")]
pub const STEP_CHORD_FRACTION: f64 = 0.25;

/// The coarser chordal tolerance of [`encode_step`]'s analytic faces (and, at
/// [`Effort::Max`], of a tessellation of every face), as a fraction of the encode tolerance:
/// coarser facets give the fit fewer points to follow, and on the corpus 0.45 makes smaller
/// files than 0.25 on most models and than 0.55 or 0.7 on the small ones.
#[cfg(feature = "step")]
pub const STEP_COARSE_CHORD_FRACTION: f64 = 0.45;

/// Whether two tessellations hold the same faces: the same group names in the same order.
#[cfg(feature = "step")]
pub(crate) fn same_faces(a: &ControlMesh, b: &ControlMesh) -> bool {
    a.groups.len() == b.groups.len()
        && a.groups
            .iter()
            .zip(&b.groups)
            .all(|(x, y)| x.name == y.name)
}

/// STEP reading options with one chordal tolerance for all faces,
/// [`STEP_CHORD_FRACTION`] of the encode tolerance.
#[cfg(feature = "step")]
pub fn step_options_for(tolerance: Tolerance) -> crate::io::step::StepOptions {
    crate::io::step::StepOptions {
        chordal_tolerance: tolerance.scaled(STEP_CHORD_FRACTION),
        ..Default::default()
    }
}

/// Per-group surface hints from the `<name>.faces.json` sidecar next to `input`, matched by
/// group name; `None` when there is no sidecar.
pub fn sidecar_hints(
    input: &Path,
    mesh: &ControlMesh,
) -> Result<Option<(std::path::PathBuf, Vec<SurfaceHint>)>> {
    let Some(side) = faces_json::sidecar_path_for(input) else {
        return Ok(None);
    };
    let faces = faces_json::read_faces_json(&side)?;
    let hints = faces_json::face_info_for_groups(mesh, &faces)
        .iter()
        .map(|fi| fi.map_or(SurfaceHint::Unknown, |f| hint_for(&f.surface)))
        .collect();
    Ok(Some((side, hints)))
}

/// Bits per coordinate so that the Euclidean quantisation error `sqrt(3)/2 * R/(2^b - 1)`
/// stays below `fraction * tolerance` for a box of extent `extent`.
pub fn bits_for_tolerance(extent: f64, tolerance: f64, fraction: f64) -> u8 {
    let cells = 3f64.sqrt() / 2.0 * extent / (fraction * tolerance);
    let bits = (cells + 1.0).log2().ceil();
    if bits.is_finite() {
        bits.clamp(6.0, 24.0) as u8
    } else {
        24
    }
}

/// One fit and encode of [`encode_fitted`], at the effort's fit options, with the traversal
/// start searched as the effort says.
pub(crate) fn encode_fitted_once(
    input: &ControlMesh,
    hints: &[SurfaceHint],
    opts: &ModelEncodeOptions,
) -> Result<(Vec<u8>, FitReport)> {
    // Before the tolerance is resolved against the diagonal, so that the error names the
    // coordinates rather than an infinite tolerance.
    input.check_extent()?;
    let extent = input
        .bounding_box()
        .map(|(lo, hi)| (hi - lo).max_element())
        .unwrap_or(1.0);
    let tol = opts.fit.tolerance.resolve(input.diagonal());
    let bits = opts
        .quantization_bits
        .unwrap_or_else(|| bits_for_tolerance(extent, tol, 0.25));
    let mut fit_opts = opts.effort.fit_options(&opts.fit);
    if opts.quantization_bits.is_some() {
        // The caller chose the precision: keep it.
        fit_opts.max_coarser_bits = 0;
    }
    // One grid for every round and step of the fit: the input's box with a margin for
    // control points outside it (those of a convex closed patch lie outside its surface).
    // A round that changes a few faces then decodes the others bit-identically, and the
    // measurement keeps their results (see `fit::measure`).
    let grid_covers = input.bounding_box().map(|(lo, hi)| {
        let margin = DVec3::splat(GRID_MARGIN * (hi - lo).max_element());
        [lo - margin, hi + margin]
    });
    // `coarser` counts quarter bits: `coarser / 4` whole bits fewer, and the step times
    // `2^((coarser % 4) / 4)` (`EncodeOptions::step_scale`).
    let encode_opts = |level: u8, coarser: u8| EncodeOptions {
        quantization_bits: bits
            .saturating_sub(coarser / 4)
            .max(MIN_FITTED_BITS.min(bits)),
        content: Content::ControlMesh {
            default_level: level,
        },
        store_group_names: opts.store_group_names,
        step_scale: QUARTER_BIT_SCALES[usize::from(coarser % 4)],
        grid_covers,
    };
    // The codec numbers groups in its own traversal order; the fit attributes errors to
    // groups by the input's numbering, so give the decoded mesh the input's group order.
    let mut reconstruct =
        |control: &ControlMesh, level: u8, coarser: u8| -> Result<(ControlMesh, usize)> {
            let (bytes, map) = codec::encode_with_map(control, &encode_opts(level, coarser))?;
            let mut mesh = codec::decode(&bytes, &trusted_limits())?.mesh;
            let mut old_of_new = vec![0u32; mesh.groups.len()];
            for (old, &new) in map.group.iter().enumerate() {
                old_of_new[new as usize] = old as u32;
            }
            for g in &mut mesh.face_groups {
                *g = old_of_new[*g as usize];
            }
            let mut groups = mesh.groups.clone();
            for (old, &new) in map.group.iter().enumerate() {
                groups[old] = mesh.groups[new as usize].clone();
            }
            mesh.groups = groups;
            Ok((mesh, bytes.len()))
        };
    let outcome = fit_model(input, hints, &fit_opts, &mut reconstruct)?;
    let final_opts = encode_opts(outcome.default_level, outcome.coarser_quarter_bits);
    let bytes = codec::encode(&outcome.control, &final_opts)
        .map_err(|e| crate::fit::encoder::with_faces_involved(e, &outcome.control))?;
    let mut report = outcome.report;
    let bytes = search::smallest_traversal_start(
        &outcome.control,
        &final_opts,
        opts.effort.traversal_starts(),
        bytes,
        &mut report,
    );
    Ok((bytes, report))
}

/// The same control mesh with its face list rotated to begin at face `start` (positions,
/// groups, sharp edges and corners unchanged): the codec's traversal then starts there.
pub(crate) fn rotate_faces(mesh: &ControlMesh, start: usize) -> ControlMesh {
    let mut out = ControlMesh::new();
    out.positions = mesh.positions.clone();
    out.groups = mesh.groups.clone();
    out.sharp_edges = mesh.sharp_edges.clone();
    out.corners = mesh.corners.clone();
    let n = mesh.face_count();
    for i in 0..n {
        let f = (start + i) % n;
        out.push_face(mesh.face(f), mesh.face_groups[f]);
    }
    out
}

/// Limits for decoding the encoder's own output while fitting: only the format's count
/// limits apply, not the budgets that guard a decode of untrusted files.
fn trusted_limits() -> Limits {
    Limits {
        max_subdivided_faces: u64::MAX,
        max_memory: u64::MAX,
        max_work_per_element: u64::MAX,
        ..Limits::default()
    }
}

/// A `.scode` file decoded to a surface (see [`SurfaceOptions`]).
#[derive(Clone, Debug)]
pub struct DecodedSurface {
    /// Raw-mode files: the stored mesh; control-mesh files: the subdivided surface.
    pub mesh: ControlMesh,
    /// Limit normals, when the surface was projected to the limit.
    pub normals: Option<Vec<glam::DVec3>>,
    /// Subdivision level applied: the uniform level, or with `accuracy` the finest level a
    /// base triangle is shown at (0 for raw-mode files unless asked otherwise).
    pub level: u32,
    /// Whether positions are limit positions.
    pub limit: bool,
    pub content: Content,
    /// How a surface decoded to a tolerance came out (`None` for a uniform level and for
    /// raw-mode files, which are the stored surface itself).
    pub accuracy: Option<AccuracyReport>,
}

/// What decoding to a tolerance delivered.
#[derive(Clone, Debug, PartialEq)]
pub struct AccuracyReport {
    /// The tolerance in model units.
    pub tolerance: f64,
    /// The largest estimated distance between the output and the limit surface (see
    /// [`crate::subdiv::subdivide_to_tolerance`]); above `tolerance` only where a base
    /// triangle would need a level beyond `max_level`.
    pub bound: f64,
    /// The finest level a base triangle could be shown at.
    pub max_level: u32,
    /// Base triangles (control faces fan-triangulated) shown at each level `0..=max_level`.
    pub triangles_per_level: Vec<usize>,
}

/// How much detail a control mesh is decoded to.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Detail {
    /// Every base triangle at the coarsest level within the tolerance the file was encoded
    /// for of the limit surface ([`file_tolerance`]).
    #[default]
    FileTolerance,
    /// Every base triangle at the coarsest level within this distance of the limit surface
    /// (a relative tolerance is a fraction of the surface's bounding-box diagonal).
    Tolerance(Tolerance),
    /// One uniform level for the whole surface.
    Level(u32),
    /// The file's default level, uniform: the surface the encoder measured against its
    /// input, so what `scode info --against` and `scode report` measure.
    DefaultLevel,
}

/// How to turn a decoded `.scode` file into a surface. A raw-mode file stays as stored
/// (level 0, no limit) unless [`Detail::Level`] asks for a level; a control mesh is decoded
/// to the file's tolerance by default (`detail`) and always to limit positions unless
/// `limit` is `Some(false)`, which needs a uniform level.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfaceOptions {
    pub detail: Detail,
    pub limit: Option<bool>,
    /// How boundary patches are triangulated (sparse, as S-CODE, by default).
    pub boundary_patches: crate::subdiv::BoundaryPatchOutput,
}

/// The encoder's default tolerance, relative to the model's diagonal: without a tolerance of
/// its own, a decode to an accuracy uses it (capped by the file's grid, [`file_tolerance`]).
pub const DEFAULT_RELATIVE_TOLERANCE: f64 = 1e-3;

/// How many quantisation steps the tolerance of a fitted file is at most. The encoder picks
/// the fewest bits whose Euclidean quantisation error `sqrt(3)/2 step` is at most a quarter
/// of the tolerance `t` ([`bits_for_tolerance`]): the bit count rounds up, so the nominal
/// step over the model's extent `E` exceeds `t / (4 sqrt(3))`, and the grid's box is at
/// least the input's box widened by 1/32 of its extent on each side, so `step > (17/16) t /
/// (4 sqrt(3))`, i.e. `t < 6.53 step`; fitting may then coarsen the grid, which only makes
/// the step larger. A file whose grid the encoder chose this way was encoded for a
/// tolerance below this many steps.
pub const TOLERANCE_STEPS: f64 = 6.6;

/// The tolerance a decode to an accuracy uses by default: the file does not store the
/// tolerance it was encoded for, so it is [`DEFAULT_RELATIVE_TOLERANCE`] of the decoded
/// surface's diagonal (the encoder's default, relative to the input's diagonal, which the
/// surface matches), but never more than [`TOLERANCE_STEPS`] quantisation steps, a bound
/// the grid gives on the tolerance of a file encoded for a tighter one. Returns the relative
/// tolerance and the cap in model units.
pub fn file_tolerance(header: &codec::Header) -> (Tolerance, f64) {
    let cap = TOLERANCE_STEPS * header.quantization_step();
    let cap = if cap > 0.0 && cap.is_finite() {
        cap
    } else {
        f64::INFINITY
    };
    (Tolerance::Relative(DEFAULT_RELATIVE_TOLERANCE), cap)
}

/// Decodes `bytes` and builds the surface asked for (see [`SurfaceOptions`]). One
/// implementation for `scode decode`, `scode info --against` and `scode report`, so they all
/// measure the surfaces they name.
pub fn decode_surface(
    bytes: &[u8],
    limits: &Limits,
    opts: &SurfaceOptions,
) -> Result<DecodedSurface> {
    let (decoded, usage) = codec::decode_with_usage(bytes, limits);
    let decoded = decoded?;
    let content = decoded.header.content;
    let default_level = match content {
        Content::RawMesh => None,
        Content::ControlMesh { default_level } => Some(u32::from(default_level)),
    };
    let level = match (opts.detail, default_level) {
        (Detail::Level(l), _) => l,
        (_, None) => 0,
        (Detail::DefaultLevel, Some(l)) => l,
        (Detail::FileTolerance | Detail::Tolerance(_), Some(l)) => {
            if opts.limit == Some(false) {
                return Err(Error::Parameter(
                    "a decode to a tolerance measures against the limit surface: without limit \
                     positions, ask for a uniform level"
                        .into(),
                ));
            }
            return decode_to_tolerance(decoded, usage.held, l, limits, opts);
        }
    };
    let limit = opts.limit.unwrap_or(default_level.is_some());
    let (mesh, normals) = if level == 0 && !limit {
        (decoded.mesh, None)
    } else {
        // Before subdividing: the finest level's triangles (fan-triangulated faces times
        // 4^level) against the limits, and the memory they take on top of what the decode
        // still holds (the input and the control mesh) against the budget.
        check_subdivision(
            &decoded.mesh,
            level,
            crate::subdiv::MEMORY_PER_TRIANGLE,
            usage.held,
            limits,
        )?;
        let sopts = crate::subdiv::SubdivOptions {
            limit,
            boundary_patches: opts.boundary_patches,
            max_faces: limits.max_subdivided_faces,
            ..Default::default()
        };
        crate::subdiv::subdivide(&decoded.mesh, level, &sopts)?
    };
    Ok(DecodedSurface {
        mesh,
        normals,
        level,
        limit,
        content,
        accuracy: None,
    })
}

/// `Error::LimitsExceeded` unless `mesh`'s triangles at `level` (fan-triangulated faces
/// times 4^level) fit `max_subdivided_faces` and, at `per_triangle` bytes each, the memory
/// budget on top of the `held` bytes the decode still holds.
fn check_subdivision(
    mesh: &ControlMesh,
    level: u32,
    per_triangle: u64,
    held: u64,
    limits: &Limits,
) -> Result<()> {
    let triangles = (mesh.face_vertices.len() - 2 * mesh.face_count()) as u64;
    let finest = triangles.saturating_mul(
        1u64.checked_shl(level.saturating_mul(2))
            .unwrap_or(u64::MAX),
    );
    let memory = held.saturating_add(finest.saturating_mul(per_triangle));
    for (what, value, limit) in [
        ("subdivided faces", finest, limits.max_subdivided_faces),
        (
            "decode memory with subdivision (bytes)",
            memory,
            limits.max_memory,
        ),
    ] {
        if value > limit {
            return Err(Error::LimitsExceeded { what, value, limit });
        }
    }
    Ok(())
}

/// The decode to a tolerance of a control mesh whose default level is `default_level`.
///
/// The finest level shown is the file's default level: the encoder chose it so that the
/// surface meets the file's tolerance. A tighter tolerance gets one more level per factor 4
/// (a triangle's distance from a smooth surface shrinks with its size squared, 4 times per
/// level), estimated against the control mesh's diagonal; the measurement then picks the
/// levels actually shown.
fn decode_to_tolerance(
    decoded: codec::Decoded,
    held: u64,
    default_level: u32,
    limits: &Limits,
    opts: &SurfaceOptions,
) -> Result<DecodedSurface> {
    let content = decoded.header.content;
    let (file_relative, cap) = file_tolerance(&decoded.header);
    let tolerance = match opts.detail {
        Detail::Tolerance(t) => t,
        _ => file_relative,
    };
    let diagonal = decoded.mesh.diagonal();
    let file_t = file_relative.resolve(diagonal).min(cap);
    let asked = tolerance.resolve(diagonal);
    // The measurement refines one level beyond the finest shown.
    let deepest = crate::subdiv::MAX_LEVEL - 1;
    let mut max_level = default_level.min(deepest);
    if asked > 0.0 && asked < file_t {
        let extra = (file_t / asked).log(4.0).ceil();
        max_level = (f64::from(max_level) + extra).min(f64::from(deepest)) as u32;
    }
    check_subdivision(
        &decoded.mesh,
        max_level,
        crate::subdiv::MEMORY_PER_ACCURATE_TRIANGLE,
        held,
        limits,
    )?;
    let aopts = crate::subdiv::AccuracyOptions {
        tolerance,
        max_tolerance: if matches!(opts.detail, Detail::Tolerance(_)) {
            f64::INFINITY
        } else {
            cap
        },
        max_level,
        normals: true,
        max_faces: limits.max_subdivided_faces,
        boundary_patches: opts.boundary_patches,
    };
    let out = crate::subdiv::subdivide_to_tolerance(&decoded.mesh, &aopts)?;
    let mut triangles_per_level = vec![0; max_level as usize + 1];
    for &m in &out.levels {
        triangles_per_level[m as usize] += 1;
    }
    Ok(DecodedSurface {
        mesh: out.mesh,
        normals: out.normals,
        level: out.levels.iter().copied().max().unwrap_or(0).into(),
        limit: true,
        content,
        accuracy: Some(AccuracyReport {
            tolerance: out.tolerance,
            bound: out.bound,
            max_level,
            triangles_per_level,
        }),
    })
}
