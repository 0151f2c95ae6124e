//! The whole encoder: fitting (`fit`) plus the bitstream (`codec`). It lives above both so
//! that neither depends on the other; the fit measures its error on the control mesh exactly
//! as this module's codec round trip reconstructs it.

use std::path::Path;

use crate::codec::{self, Content, EncodeOptions, Limits};
use crate::error::Result;
use crate::fit::encoder::{fit_model, ExactSurface, FitOptions, FitReport, SurfaceHint};
#[cfg(feature = "step")]
use crate::fit::primitives::Primitive;
use crate::io::faces_json::{self, SurfaceType};
use crate::mesh::ControlMesh;

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

/// Options of [`encode_fitted`].
#[derive(Clone, Debug, PartialEq)]
pub struct ModelEncodeOptions {
    pub fit: FitOptions,
    /// Quantisation bits; default: the fewest that keep the quantisation error below a
    /// quarter of the tolerance.
    pub quantization_bits: Option<u8>,
    pub store_group_names: bool,
    /// Also fit with [`FitOptions::local_refinement`] and keep the smaller file (the first
    /// on a tie), for inputs of at most [`LOCAL_REFINEMENT_MAX_TRIANGLES`] faces (default
    /// on): the two refinements win on different models, and a second fit of a small model
    /// is cheap. STEP block_fillet3: 563 -> 490 bytes, its sphere corner failing only at its
    /// three corners; meshes: screw 467 -> 446, block_fillet3 468 -> 460, the other small
    /// corpus meshes unchanged.
    pub try_local_refinement: bool,
    /// Also fit without [`FitOptions::keep_planes_on_faces`] and keep the smaller file, for
    /// inputs of at most [`PLAIN_PLANES_MAX_TRIANGLES`] faces (default on): keeping plane
    /// patches on their faces wins on most models but not all (plate: 498 bytes with it, 448
    /// without), and a second fit of a small model takes a second or two.
    pub try_plain_planes: bool,
    /// Also encode the fitted control mesh with its face list rotated to start at this many
    /// evenly spaced faces and keep the smallest file (0 or 1: the fit's order only). The
    /// codec's traversal starts at the first face, and where it starts moves the file by a
    /// few percent either way (trj10's STEP fit: 497..523 bytes over 16 starts, block_fillet3:
    /// 518..540) while the control mesh, and so the decoded surface, is the same. Default
    /// [`DEFAULT_START_FACES`]: about a millisecond per start per thousand control faces.
    pub try_start_faces: usize,
}

/// Traversal starts tried by default (see [`ModelEncodeOptions::try_start_faces`]).
pub const DEFAULT_START_FACES: usize = 16;

/// Largest input (faces) [`ModelEncodeOptions::try_local_refinement`] fits twice.
pub const LOCAL_REFINEMENT_MAX_TRIANGLES: usize = 20_000;

/// Largest input (faces) [`ModelEncodeOptions::try_plain_planes`] fits twice.
pub const PLAIN_PLANES_MAX_TRIANGLES: usize = 25_000;

impl Default for ModelEncodeOptions {
    fn default() -> Self {
        ModelEncodeOptions {
            fit: FitOptions::default(),
            quantization_bits: None,
            store_group_names: true,
            try_local_refinement: true,
            try_plain_planes: true,
            try_start_faces: DEFAULT_START_FACES,
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
        .map(|f| {
            let axis = f.axis?;
            let s = match f.surface {
                SurfaceType::Plane => Primitive::Plane {
                    point: axis.origin,
                    normal: axis.direction,
                },
                SurfaceType::Cylinder => Primitive::Cylinder {
                    axis,
                    radius: f.radius?,
                },
                SurfaceType::Cone => Primitive::Cone {
                    axis,
                    half_angle: f.half_angle?,
                },
                SurfaceType::Sphere => Primitive::Sphere {
                    center: axis.origin,
                    radius: f.radius?,
                },
                SurfaceType::Torus => Primitive::Torus {
                    axis,
                    major_radius: f.radius?,
                    minor_radius: f.minor_radius?,
                },
                _ => return None,
            };
            ExactSurface::new(s)
        })
        .collect()
}

/// Chordal tolerance of the STEP tessellation, as a fraction of the encode tolerance: the
/// facets' own chord error takes a small part of the error budget of faces measured against
/// their facets alone (B-splines and other freeform surfaces).
#[cfg(feature = "step")]
pub const STEP_CHORD_FRACTION: f64 = 0.25;

/// The coarser chordal tolerance [`encode_step`] also tries, as a fraction of the encode
/// tolerance (session 9, corpus: at 0.45 the files were smaller than at 0.25 on 8 of 14
/// encoded files; 0.55 and 0.7 were larger again on the small models tried).
#[cfg(feature = "step")]
pub const STEP_COARSE_CHORD_FRACTION: f64 = 0.45;

/// Reads a STEP file with its tessellation tied to the encode tolerance, fits it with the
/// B-rep's surface types and its faces' exact surfaces, and encodes it. `tolerance` is in
/// millimetres (the model's output unit) or, with `relative`, a fraction of the
/// bounding-box diagonal; `None` is 1e-3 of the diagonal. `opts.fit.mean_tolerance` is in
/// the same units (scaled with `relative` too).
///
/// Which tessellation fits best varies by model (and not smoothly), so five are fitted
/// and the best file is kept, all held to the same standard:
/// 1. every face at [`STEP_CHORD_FRACTION`] of the tolerance;
/// 2. faces on planes, cylinders, cones, spheres and tori (and the edges only they share)
///    at [`STEP_COARSE_CHORD_FRACTION`]: those are measured against their exact surfaces,
///    so their facets' chord error is no allowance the fit may spend;
/// 3. every face at [`STEP_COARSE_CHORD_FRACTION`], measured against tessellation 1 (which
///    has the same faces) rather than against itself, so B-spline faces too are held to
///    the fine facets ([`FitOptions::reference`]);
/// 4. and 5. as 1 and 2, but each face triangulated in its raw parameter plane instead of
///    the plane stretched to the surface's lengths
///    ([`crate::io::step::StepOptions::stretch_parameter_plane`]): on some models the
///    stretched triangles fit into more bytes (session 11: linkrods, block_fillet3).
///
/// The file is parsed and its faces converted once ([`crate::io::step::read_step_tessellations`]).
/// Best is: fewer skipped faces, then the tolerance met, then fewer bytes. A tessellation
/// equal to an earlier one is not fitted again (a model of planes only), nor is 3 when its
/// faces differ from 1's (a face skipped in one of them). When a fit fails the others'
/// files are kept; when all fail, the first error is returned. The chosen model's notes
/// say which tessellation it was.
#[cfg(feature = "step")]
pub fn encode_step(
    path: &Path,
    tolerance: Option<f64>,
    relative: bool,
    opts: &ModelEncodeOptions,
) -> Result<(crate::io::step::StepModel, Vec<u8>, FitReport)> {
    use crate::io::step::{read_step_tessellations, StepModel};
    let coarse = STEP_COARSE_CHORD_FRACTION / STEP_CHORD_FRACTION;
    // (what, chord factor, analytic faces' chord factor, measured against tessellation 1,
    // parameter plane stretched). The fitted bytes depend on the input triangles in ways no
    // rule predicts well, so a few tessellations are fitted and the smallest file is kept.
    let variants: [(&str, f64, f64, bool, bool); 5] = [
        ("every face at the chordal tolerance", 1.0, 1.0, false, true),
        (
            "analytic faces at a coarser chord, measured against their exact surfaces",
            1.0,
            coarse,
            false,
            true,
        ),
        (
            "every face at a coarser chord, measured against the finer tessellation",
            coarse,
            1.0,
            true,
            true,
        ),
        (
            "every face at the chordal tolerance, triangulated in its raw parameter plane",
            1.0,
            1.0,
            false,
            false,
        ),
        (
            "analytic faces at a coarser chord, triangulated in their raw parameter planes",
            1.0,
            coarse,
            false,
            false,
        ),
    ];
    let step_opts: Vec<_> = variants
        .iter()
        .map(|&(_, chord_factor, analytic_factor, _, stretch)| {
            let mut o = step_options_for(tolerance, relative);
            if let Some(c) = &mut o.chordal_tolerance {
                *c *= chord_factor;
            }
            o.relative_chordal_tolerance *= chord_factor;
            o.analytic_chordal_factor = analytic_factor;
            o.stretch_parameter_plane = stretch;
            o
        })
        .collect();
    // One parse and one conversion of the faces (truck's conversion timeouts are waited
    // for once), five tessellations.
    let models = read_step_tessellations(path, &step_opts)?;
    let mut best: Option<(StepModel, Vec<u8>, FitReport)> = None;
    let mut first_error = None;
    let mut fitted_meshes: Vec<ControlMesh> = Vec::new();
    // Tessellation 1's mesh, the reference of 3.
    let mut fine: Option<ControlMesh> = None;
    for ((what, _, _, against_fine, _), mut model) in variants.into_iter().zip(models) {
        if fitted_meshes.contains(&model.mesh) {
            continue;
        }
        let reference = match (against_fine, &fine) {
            (false, _) => None,
            (true, Some(f)) if same_faces(f, &model.mesh) => Some(f.clone()),
            (true, _) => continue,
        };
        let mut opts = opts.clone();
        let scale = |t: f64| {
            if relative {
                t * model.mesh.diagonal()
            } else {
                t
            }
        };
        opts.fit.tolerance = tolerance.map(scale);
        opts.fit.mean_tolerance = opts.fit.mean_tolerance.map(scale);
        opts.fit.exact_surfaces = step_exact_surfaces(&model);
        opts.fit.reference = reference;
        let fitted = encode_fitted(&model.mesh, &step_hints(&model), &opts);
        if fine.is_none() {
            fine = Some(model.mesh.clone());
        }
        fitted_meshes.push(model.mesh.clone());
        match fitted {
            Ok((bytes, report)) => {
                let key = |m: &StepModel, b: &[u8], r: &FitReport| {
                    (m.skipped.len(), !r.within_tolerance, b.len())
                };
                let better = match &best {
                    None => true,
                    Some((m, b, r)) => key(&model, &bytes, &report) < key(m, b, r),
                };
                if better {
                    model.notes.push(format!(
                        "encoded from the tessellation with {what} ({} bytes)",
                        bytes.len()
                    ));
                    best = Some((model, bytes, report));
                }
            }
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    match (best, first_error) {
        (Some(b), _) => Ok(b),
        (None, Some(e)) => Err(e),
        (None, None) => Err(crate::error::Error::Parameter(
            "no STEP tessellation was fitted".into(),
        )),
    }
}

/// Whether two tessellations hold the same faces: the same group names in the same order.
#[cfg(feature = "step")]
fn same_faces(a: &ControlMesh, b: &ControlMesh) -> bool {
    a.groups.len() == b.groups.len()
        && a.groups
            .iter()
            .zip(&b.groups)
            .all(|(x, y)| x.name == y.name)
}

/// STEP reading options with one chordal tolerance for all faces,
/// [`STEP_CHORD_FRACTION`] of the encode tolerance.
#[cfg(feature = "step")]
pub fn step_options_for(tolerance: Option<f64>, relative: bool) -> crate::io::step::StepOptions {
    let mut o = crate::io::step::StepOptions::default();
    match (tolerance, relative) {
        (Some(t), false) => o.chordal_tolerance = Some(STEP_CHORD_FRACTION * t),
        (Some(t), true) => o.relative_chordal_tolerance = STEP_CHORD_FRACTION * t,
        (None, _) => o.relative_chordal_tolerance = STEP_CHORD_FRACTION * 1e-3,
    }
    o
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

/// Fits `input` and encodes the control mesh. Returns the `.scode` bytes and what the fit did.
///
/// Besides the fit `opts` asks for, small inputs are also fitted the other ways the options
/// allow ([`ModelEncodeOptions::try_plain_planes`], [`ModelEncodeOptions::try_local_refinement`])
/// and the smallest file is kept (the first on a tie; a fit within tolerance beats one that
/// is not).
pub fn encode_fitted(
    input: &ControlMesh,
    hints: &[SurfaceHint],
    opts: &ModelEncodeOptions,
) -> Result<(Vec<u8>, FitReport)> {
    // The other fits: every combination of the two alternatives that apply. A fit with
    // local refinement is the same as the one without it when no closed patch failed there
    // (`FitReport::closed_refinements`), so it is skipped then: most small models have no
    // failing closed patch, and each skipped fit saves a whole fit's time.
    let plain = opts.try_plain_planes
        && opts.fit.keep_planes_on_faces
        && input.face_count() <= PLAIN_PLANES_MAX_TRIANGLES;
    let local = opts.try_local_refinement
        && !opts.fit.local_refinement
        && input.face_count() <= LOCAL_REFINEMENT_MAX_TRIANGLES;
    let first = encode_fitted_once(input, hints, opts)?;
    // Closed-patch refinements of the fits without local refinement: [as given, plain planes].
    let mut refined = [first.1.closed_refinements, 0];
    let mut best = first;
    for (p, l) in [(true, false), (false, true), (true, true)] {
        if (p && !plain) || (l && !local) || (l && refined[usize::from(p)] == 0) {
            continue;
        }
        let mut o = opts.clone();
        let mut what = Vec::new();
        if p {
            o.fit.keep_planes_on_faces = false;
            what.push(
                "with plane patches decimated freely and all chains of a failing group refined",
            );
        }
        if l {
            o.fit.local_refinement = true;
            what.push("with closed patches refined only where they failed");
        }
        let what = what.join(", ");
        match encode_fitted_once(input, hints, &o) {
            Ok((bytes, mut report)) => {
                if !l {
                    refined[usize::from(p)] = report.closed_refinements;
                }
                if bytes.len() < best.0.len()
                    && (report.within_tolerance || !best.1.within_tolerance)
                {
                    report.notes.push(format!(
                        "kept the fit {what}: {} bytes instead of {}",
                        bytes.len(),
                        best.0.len()
                    ));
                    best = (bytes, report);
                }
            }
            Err(e) => {
                // The fit so far stands; say why this one was not considered.
                best.1
                    .notes
                    .push(format!("the fit {what} did not finish: {e}"));
            }
        }
    }
    Ok(best)
}

/// One fit and encode of [`encode_fitted`].
fn encode_fitted_once(
    input: &ControlMesh,
    hints: &[SurfaceHint],
    opts: &ModelEncodeOptions,
) -> Result<(Vec<u8>, FitReport)> {
    let extent = input
        .bounding_box()
        .map(|(lo, hi)| (hi - lo).max_element())
        .unwrap_or(1.0);
    let tol = opts.fit.tolerance.unwrap_or(1e-3 * input.diagonal());
    let bits = opts
        .quantization_bits
        .unwrap_or_else(|| bits_for_tolerance(extent, tol, 0.25));
    let mut fit_opts = opts.fit.clone();
    if opts.quantization_bits.is_some() {
        // The caller chose the precision: keep it.
        fit_opts.max_coarser_bits = 0;
    }
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
    };
    // The codec numbers groups in its own traversal order; the fit attributes errors to
    // groups by the input's numbering, so give the decoded mesh the input's group order.
    let mut reconstruct =
        |control: &ControlMesh, level: u8, coarser: u8| -> Result<(ControlMesh, usize)> {
            let (bytes, map) = codec::encode_with_map(control, &encode_opts(level, coarser))?;
            let mut mesh = codec::decode(&bytes, &Limits::default())?.mesh;
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
    let mut bytes = codec::encode(&outcome.control, &final_opts)
        .map_err(|e| crate::fit::encoder::with_faces_involved(e, &outcome.control))?;
    let mut report = outcome.report;
    let n = outcome.control.face_count();
    let starts = opts.try_start_faces.min(n);
    if starts > 1 {
        let first_len = bytes.len();
        let mut best_start = 0;
        for k in 1..starts {
            let start = k * n / starts;
            let rotated = rotate_faces(&outcome.control, start);
            // A start the codec refuses is just not a candidate (the first one stands).
            if let Ok(b) = codec::encode(&rotated, &final_opts) {
                if b.len() < bytes.len() {
                    bytes = b;
                    best_start = start;
                }
            }
        }
        if best_start > 0 {
            report.notes.push(format!(
                "traversal started at control face {best_start} of {n}: {} bytes instead of \
                 {first_len}",
                bytes.len()
            ));
        }
    }
    Ok((bytes, report))
}

/// The same control mesh with its face list rotated to begin at face `start` (positions,
/// groups, sharp edges and corners unchanged): the codec's traversal then starts there.
fn rotate_faces(mesh: &ControlMesh, start: usize) -> ControlMesh {
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

/// A `.scode` file decoded to the surface a viewer shows by default.
#[derive(Clone, Debug)]
pub struct DecodedSurface {
    /// Raw-mode files: the stored mesh; control-mesh files: the subdivided surface.
    pub mesh: ControlMesh,
    /// Limit normals, when the surface was projected to the limit.
    pub normals: Option<Vec<glam::DVec3>>,
    /// Subdivision level applied (0 for raw-mode files unless asked otherwise).
    pub level: u32,
    /// Whether positions are limit positions.
    pub limit: bool,
    pub content: Content,
}

/// How to turn a decoded `.scode` file into a surface; `None` fields take the file's
/// defaults: a raw mesh stays as stored (level 0, no limit), a control mesh is subdivided to
/// its default level and projected to the limit surface.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfaceOptions {
    pub level: Option<u32>,
    pub limit: Option<bool>,
    /// How boundary patches are triangulated (sparse, as S-CODE, by default).
    pub boundary_patches: crate::subdiv::BoundaryPatchOutput,
}

/// Decodes `bytes` and builds the surface the decoder shows (see [`SurfaceOptions`]). One
/// implementation for `scode decode`, `scode info --against` and `scode report`, so they all
/// measure the same surface.
pub fn decode_surface(
    bytes: &[u8],
    limits: &Limits,
    opts: &SurfaceOptions,
) -> Result<DecodedSurface> {
    let decoded = codec::decode(bytes, limits)?;
    let content = decoded.header.content;
    let (default_level, default_limit) = match content {
        Content::RawMesh => (0, false),
        Content::ControlMesh { default_level } => (u32::from(default_level), true),
    };
    let level = opts.level.unwrap_or(default_level);
    let limit = opts.limit.unwrap_or(default_limit);
    let (mesh, normals) = if level == 0 && !limit {
        (decoded.mesh, None)
    } else {
        let sopts = crate::subdiv::SubdivOptions {
            limit,
            boundary_patches: opts.boundary_patches,
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
    })
}
