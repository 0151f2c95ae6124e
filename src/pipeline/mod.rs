//! The whole encoder: fitting (`fit`) plus the bitstream (`codec`). It lives above both so
//! that neither depends on the other; the fit measures its error on the control mesh exactly
//! as this module's codec round trip reconstructs it.

use std::path::Path;

use crate::codec::{self, Content, EncodeOptions};
use crate::error::Result;
use crate::fit::encoder::{fit_model, FitOptions, FitReport, SurfaceHint};
use crate::io::faces_json::{self, SurfaceType};
use crate::mesh::ControlMesh;
use glam::DVec3;

mod check;
mod search;
#[cfg(feature = "internals")]
pub use crate::surface::{
    decode_surface, file_tolerance, AccuracyReport, DecodedSurface, Detail, SurfaceOptions,
    DEFAULT_RELATIVE_TOLERANCE, TOLERANCE_STEPS,
};
#[cfg(feature = "internals")]
pub use check::measure_file_against_input;
use check::trusted_limits;
#[cfg(feature = "step")]
pub use search::encode_step_bytes;
pub use search::{encode_fitted, Effort};
#[cfg(all(feature = "step", feature = "internals"))]
pub use search::{encode_step, StepTessellation, STEP_TESSELLATIONS};
#[cfg(feature = "internals")]
pub use search::{LOCAL_REFINEMENT_MAX_TRIANGLES, PLAIN_PLANES_MAX_TRIANGLES, TRAVERSAL_STARTS};

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
        SurfaceType::Sphere => SurfaceHint::Sphere,
        SurfaceType::Torus => SurfaceHint::Torus,
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
pub fn step_exact_surfaces(
    model: &crate::io::step::StepModel,
) -> Vec<Option<crate::fit::encoder::ExactSurface>> {
    model
        .faces
        .iter()
        .map(|f| f.exact.and_then(crate::fit::encoder::ExactSurface::new))
        .collect()
}

/// Per group of a STEP model tessellated with `analytic_factor`
/// ([`crate::io::step::StepOptions::analytic_chordal_factor`]), for
/// [`FitOptions::facet_chord`]: the chordal tolerance its facets were made with (faces with an
/// exact analytic surface at the analytic factor times the model's).
#[cfg(feature = "step")]
pub fn step_facet_chords(model: &crate::io::step::StepModel, analytic_factor: f64) -> Vec<f64> {
    model
        .faces
        .iter()
        .map(|f| {
            if f.exact.is_some() {
                model.chordal_tolerance * analytic_factor.max(1.0)
            } else {
                model.chordal_tolerance
            }
        })
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
pub fn step_options_for(tolerance: crate::mesh::Tolerance) -> crate::io::step::StepOptions {
    crate::io::step::StepOptions {
        chordal_tolerance: tolerance.scaled(STEP_CHORD_FRACTION),
        ..Default::default()
    }
}

/// Per-group surface hints from the `<name>.faces.json` sidecar next to `input`, matched by
/// group name; `None` when there is no sidecar.
#[cfg(feature = "internals")]
pub fn sidecar_hints(
    input: &Path,
    mesh: &ControlMesh,
) -> Result<Option<(std::path::PathBuf, Vec<SurfaceHint>)>> {
    let Some(side) = faces_json::sidecar_path_for(input) else {
        return Ok(None);
    };
    let faces = faces_json::read_faces_json(&side)?;
    Ok(Some((side, hints_for_faces(mesh, &faces))))
}

/// Per-group surface hints from the bytes of a `faces.json` sidecar (named `name` in
/// errors), matched by group name: groups without a face of their name get none.
pub fn sidecar_hints_from_bytes(
    bytes: &[u8],
    name: &Path,
    mesh: &ControlMesh,
) -> Result<Vec<SurfaceHint>> {
    let faces = faces_json::parse_faces_json(bytes, name)?;
    Ok(hints_for_faces(mesh, &faces))
}

/// The surface hint of each group of `mesh` from the sidecar face of its name.
fn hints_for_faces(mesh: &ControlMesh, faces: &[faces_json::FaceInfo]) -> Vec<SurfaceHint> {
    faces_json::face_info_for_groups(mesh, faces)
        .iter()
        .map(|fi| fi.map_or(SurfaceHint::Unknown, |f| hint_for(&f.surface)))
        .collect()
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
    // The fit's last measurement is of this file's control mesh at its default level,
    // sampled as `scode info --against` samples it (see `ErrorMeter::new`): its figures
    // are the file's.
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
