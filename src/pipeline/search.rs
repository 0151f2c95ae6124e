//! Every encoder search that fits or encodes a model more than once and keeps the smallest
//! file lives here, behind one knob, [`Effort`]: the fitting variants of small meshes, the STEP
//! tessellations, the codec's traversal start and the quantisation steps (the last is run
//! inside the fit, which owns the error measurement; this module sets how far it goes).
//!
//! The fitted bytes depend on the input triangles and on discrete choices (where the
//! traversal starts, whether a plane patch keeps its face's outline) in ways no rule predicts
//! well, so [`Effort::Max`] tries them. [`Effort::Default`] decides them from the model and
//! fits once: the choices it makes are the ones that win on most models.

use std::fmt;
use std::str::FromStr;

use crate::codec::{self, EncodeOptions};
use crate::error::{Error, Result};
use crate::fit::encoder::{FitOptions, FitReport, SurfaceHint};
use crate::mesh::{ControlMesh, PatchKind};

use super::{encode_fitted_once, rotate_faces, ModelEncodeOptions};

/// How hard the encoder searches for a smaller file. Every effort meets the same tolerance
/// and measures it the same way; they differ in how many alternatives are fitted or encoded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Effort {
    /// For batch conversion: one fit without the relaxation round (which coarsens refined
    /// closed patches again and costs one or two more rounds), quantisation steps in whole
    /// bits only, and the control mesh encoded in the fit's own face order.
    Fast,
    /// One fit whose choices are decided from the model: plane patches keep their faces'
    /// outlines when the input has face groups, closed patches are refined everywhere when
    /// they fail, and a STEP file is tessellated once (analytic faces at the coarser chord,
    /// since they are measured against their exact surfaces). The searches that cost a small
    /// fraction of the fit still run: the quantisation step (whole and quarter bits) and
    /// 16 traversal starts.
    #[default]
    Default,
    /// Every alternative, the smallest file kept: on meshes of at most 20 000 / 25 000
    /// triangles the fits with closed patches refined only where they fail and with plane
    /// patches decimated freely, and five tessellations of a STEP file. Several
    /// times the time of [`Effort::Default`] for a few percent fewer bytes on some models.
    Max,
}

impl Effort {
    pub const ALL: [Effort; 3] = [Effort::Fast, Effort::Default, Effort::Max];

    pub fn name(self) -> &'static str {
        match self {
            Effort::Fast => "fast",
            Effort::Default => "default",
            Effort::Max => "max",
        }
    }

    /// The fit options this effort runs with, from the caller's.
    pub(crate) fn fit_options(self, fit: &FitOptions) -> FitOptions {
        let mut fit = fit.clone();
        if self == Effort::Fast {
            fit.relax = false;
            fit.quarter_bit_steps = false;
        }
        fit
    }

    /// Traversal starts [`smallest_traversal_start`] tries.
    pub(crate) fn traversal_starts(self) -> usize {
        match self {
            Effort::Fast => 1,
            Effort::Default | Effort::Max => TRAVERSAL_STARTS,
        }
    }
}

impl fmt::Display for Effort {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Effort {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Effort::ALL
            .into_iter()
            .find(|e| e.name() == s)
            .ok_or_else(|| Error::Parameter(format!("unknown effort '{s}' (fast, default or max)")))
    }
}

/// Traversal starts tried at [`Effort::Default`] and [`Effort::Max`]: the codec's traversal
/// begins at the first control face, and where it begins moves the file by a few percent
/// either way while the control mesh, and so the decoded surface, stays the same. One
/// encode per start, about a millisecond per thousand control faces.
pub const TRAVERSAL_STARTS: usize = 16;

/// Largest input (triangles) [`Effort::Max`] also fits with local refinement of closed
/// patches ([`FitOptions::local_refinement`]). [`Effort`]'s documentation (public, where this
/// constant is not) states this number, [`PLAIN_PLANES_MAX_TRIANGLES`] and
/// [`TRAVERSAL_STARTS`].
pub const LOCAL_REFINEMENT_MAX_TRIANGLES: usize = 20_000;

/// Largest input (triangles) [`Effort::Max`] also fits with plane patches decimated freely
/// (without [`FitOptions::keep_planes_on_faces`]).
pub const PLAIN_PLANES_MAX_TRIANGLES: usize = 25_000;

/// Fits `input` and encodes the control mesh. Returns the `.scode` bytes and what the fit did.
///
/// At [`Effort::Max`], small inputs are also fitted the other ways the fit options allow
/// (plane patches decimated freely, closed patches refined only where they fail) and the
/// smallest file is kept (the first on a tie; a fit within tolerance beats one that is not).
pub fn encode_fitted(
    input: &ControlMesh,
    hints: &[SurfaceHint],
    opts: &ModelEncodeOptions,
) -> Result<(Vec<u8>, FitReport)> {
    let first = encode_fitted_once(input, hints, opts)?;
    if opts.effort != Effort::Max {
        return Ok(first);
    }
    // The other fits: every combination of the two alternatives that apply. A fit with
    // local refinement is the same as the one without it when no closed patch failed there
    // (`FitReport::closed_refinements`), so it is skipped then: most small models have no
    // failing closed patch, and each skipped fit saves a whole fit's time.
    let plain = opts.fit.keep_planes_on_faces && input.face_count() <= PLAIN_PLANES_MAX_TRIANGLES;
    let local = !opts.fit.local_refinement && input.face_count() <= LOCAL_REFINEMENT_MAX_TRIANGLES;
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

/// Encodes `control` with its face list rotated to start at `starts` evenly spaced faces and
/// returns the smallest file (the fit's own order on a tie), noting a start other than the
/// first in `report`. `bytes` is the encoding of the fit's own order, the one the fit
/// measured: a start is a candidate only when it decodes to the same surface
/// ([`decoded_surface_key`]; the codec numbers groups without names in traversal order,
/// and where two analytic patches meet the group order picks the frame of their edge).
pub(crate) fn smallest_traversal_start(
    control: &ControlMesh,
    encode_opts: &EncodeOptions,
    starts: usize,
    mut bytes: Vec<u8>,
    report: &mut FitReport,
) -> Vec<u8> {
    let n = control.face_count();
    let starts = starts.min(n);
    let first_len = bytes.len();
    let mut best_start = 0;
    let limits = codec::Limits::default();
    let Some(measured) = decoded_surface_key(&bytes, &limits) else {
        return bytes;
    };
    for k in 1..starts {
        let start = k * n / starts;
        let rotated = rotate_faces(control, start);
        // A start the codec refuses is just not a candidate (the first one stands).
        if let Ok(b) = codec::encode(&rotated, encode_opts) {
            if b.len() < bytes.len() && decoded_surface_key(&b, &limits).as_ref() == Some(&measured)
            {
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
    bytes
}

/// What fixes the surface a file decodes to, whatever the numbering of its vertices and
/// faces: per group, in order, its patch kind and its faces (each by its corners' positions,
/// rotated to the smallest, sorted), with the sharp edges and corners by position. `None`
/// when the file does not decode.
fn decoded_surface_key(bytes: &[u8], limits: &codec::Limits) -> Option<SurfaceKey> {
    let mesh = codec::decode(bytes, limits).ok()?.mesh;
    let at = |v: u32| mesh.positions[v as usize].to_array().map(f64::to_bits);
    let mut groups: Vec<(PatchKind, Vec<Vec<[u64; 3]>>)> =
        mesh.groups.iter().map(|g| (g.patch, Vec::new())).collect();
    for (f, &g) in mesh.face_groups.iter().enumerate() {
        let mut corners: Vec<[u64; 3]> = mesh.face(f).iter().map(|&v| at(v)).collect();
        let first = (0..corners.len()).min_by_key(|&k| corners[k]).unwrap_or(0);
        corners.rotate_left(first);
        groups.get_mut(g as usize)?.1.push(corners);
    }
    for (_, faces) in &mut groups {
        faces.sort_unstable();
    }
    let mut sharp: Vec<[[u64; 3]; 2]> = mesh
        .sharp_edges
        .iter()
        .map(|&(a, b)| {
            let mut e = [at(a), at(b)];
            e.sort_unstable();
            e
        })
        .collect();
    sharp.sort_unstable();
    let mut corners: Vec<[u64; 3]> = mesh.corners.iter().map(|&v| at(v)).collect();
    corners.sort_unstable();
    Some(SurfaceKey {
        groups,
        sharp,
        corners,
    })
}

/// See [`decoded_surface_key`].
#[derive(PartialEq)]
struct SurfaceKey {
    groups: Vec<(PatchKind, Vec<Vec<[u64; 3]>>)>,
    sharp: Vec<[[u64; 3]; 2]>,
    corners: Vec<[u64; 3]>,
}

#[cfg(feature = "step")]
pub use step::encode_step_bytes;
#[cfg(all(feature = "step", feature = "internals"))]
pub use step::{encode_step, StepTessellation, STEP_TESSELLATIONS};

#[cfg(feature = "step")]
mod step {
    use std::path::Path;

    use super::{encode_fitted, Effort};
    use crate::error::Result;
    use crate::fit::encoder::FitReport;
    use crate::io::step::{read_step_tessellations_bytes, StepModel};
    use crate::mesh::ControlMesh;
    use crate::pipeline::{
        same_faces, step_exact_surfaces, step_facet_chords, step_hints, step_options_for,
        ModelEncodeOptions, STEP_CHORD_FRACTION, STEP_COARSE_CHORD_FRACTION,
    };

    /// One way [`encode_step`] tessellates a STEP file.
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub struct StepTessellation {
        /// What it is, for the chosen model's notes.
        pub what: &'static str,
        /// Every face's chordal tolerance, as a factor on [`STEP_CHORD_FRACTION`] of the
        /// encode tolerance.
        pub chord_factor: f64,
        /// Faces on planes, cylinders, cones, spheres and tori: a further factor on theirs
        /// (they are measured against their exact surfaces, so their facets' chord error is
        /// no allowance the fit may spend).
        pub analytic_factor: f64,
        /// Measured against the first tessellation of [`STEP_TESSELLATIONS`] (the same faces
        /// at the finer chord) instead of itself, so B-spline faces too are held to the fine
        /// facets ([`crate::fit::encoder::FitOptions::reference`]).
        pub against_fine: bool,
        /// Each face triangulated in its parameter plane stretched to the surface's lengths
        /// ([`crate::io::step::StepOptions::stretch_parameter_plane`]).
        pub stretch: bool,
    }

    const COARSE: f64 = STEP_COARSE_CHORD_FRACTION / STEP_CHORD_FRACTION;

    /// The tessellations [`Effort::Max`] fits; [`Effort::Default`] and [`Effort::Fast`] fit
    /// the second alone: one tessellation, every face measured against what it fits (its
    /// facets, and the exact surface of an analytic face), and analytic faces, which are held
    /// to their exact surfaces whatever their facets, given fewer facets to follow.
    pub const STEP_TESSELLATIONS: [StepTessellation; 5] = [
        StepTessellation {
            what: "every face at the chordal tolerance",
            chord_factor: 1.0,
            analytic_factor: 1.0,
            against_fine: false,
            stretch: true,
        },
        StepTessellation {
            what: "analytic faces at a coarser chord, measured against their exact surfaces",
            chord_factor: 1.0,
            analytic_factor: COARSE,
            against_fine: false,
            stretch: true,
        },
        StepTessellation {
            what: "every face at a coarser chord, measured against the finer tessellation",
            chord_factor: COARSE,
            analytic_factor: 1.0,
            against_fine: true,
            stretch: true,
        },
        StepTessellation {
            what: "every face at the chordal tolerance, triangulated in its raw parameter plane",
            chord_factor: 1.0,
            analytic_factor: 1.0,
            against_fine: false,
            stretch: false,
        },
        StepTessellation {
            what: "analytic faces at a coarser chord, triangulated in their raw parameter planes",
            chord_factor: 1.0,
            analytic_factor: COARSE,
            against_fine: false,
            stretch: false,
        },
    ];

    impl Effort {
        /// The tessellations fitted, in order.
        fn step_tessellations(self) -> &'static [StepTessellation] {
            match self {
                Effort::Max => &STEP_TESSELLATIONS,
                Effort::Default | Effort::Fast => &STEP_TESSELLATIONS[1..2],
            }
        }
    }

    /// Reads a STEP file with its tessellation tied to the encode tolerance
    /// (`opts.fit.tolerance`; a relative one is a fraction of the tessellation's diagonal),
    /// fits it with the B-rep's surface types and its faces' exact surfaces, and encodes it.
    /// Lengths are in millimetres, the model's output unit.
    ///
    /// The file is parsed and its faces converted once, and tessellated once per
    /// [`StepTessellation`] of the effort ([`read_step_tessellations`]); at [`Effort::Max`]
    /// every tessellation is fitted and the best file is kept. Best is: fewer skipped faces,
    /// then the tolerance met, then fewer bytes. A tessellation equal to an earlier one is
    /// not fitted again (a model of planes only), nor is one measured against the first
    /// tessellation when its faces differ from it (a face skipped in one of them). When a fit
    /// fails the others' files are kept; when all fail, the first error is returned. The
    /// chosen model's notes say which tessellation it was.
    #[cfg(feature = "internals")]
    pub fn encode_step(
        path: &Path,
        opts: &ModelEncodeOptions,
    ) -> Result<(StepModel, Vec<u8>, FitReport)> {
        let bytes = std::fs::read(path).map_err(|e| crate::error::Error::io(path, e))?;
        encode_step_bytes(path, &bytes, opts)
    }

    /// [`encode_step`] on the file's bytes; `path` only names the file in messages.
    pub fn encode_step_bytes(
        path: &Path,
        bytes: &[u8],
        opts: &ModelEncodeOptions,
    ) -> Result<(StepModel, Vec<u8>, FitReport)> {
        let variants = opts.effort.step_tessellations();
        let step_opts: Vec<_> = variants
            .iter()
            .map(|v| {
                let mut o = step_options_for(opts.fit.tolerance);
                o.chordal_tolerance = o.chordal_tolerance.scaled(v.chord_factor);
                o.analytic_chordal_factor = v.analytic_factor;
                o.stretch_parameter_plane = v.stretch;
                o
            })
            .collect();
        let models = read_step_tessellations_bytes(path, bytes, &step_opts)?;
        let mut best: Option<(StepModel, Vec<u8>, FitReport)> = None;
        let mut first_error = None;
        let mut fitted_meshes: Vec<ControlMesh> = Vec::new();
        // The first tessellation's mesh and its faces' chordal tolerances, the reference of
        // those measured against it.
        let mut fine: Option<(ControlMesh, Vec<f64>)> = None;
        for (v, mut model) in variants.iter().zip(models) {
            if fitted_meshes.contains(&model.mesh) {
                continue;
            }
            let own_chord = step_facet_chords(&model, v.analytic_factor);
            let (reference, facet_chord) = match (v.against_fine, &fine) {
                (false, _) => (None, own_chord.clone()),
                (true, Some((f, c))) if same_faces(f, &model.mesh) => (Some(f.clone()), c.clone()),
                (true, _) => continue,
            };
            let mut opts = opts.clone();
            opts.fit.exact_surfaces = step_exact_surfaces(&model);
            opts.fit.facet_chord = facet_chord;
            opts.fit.reference = reference;
            let fitted = encode_fitted(&model.mesh, &step_hints(&model), &opts);
            if fine.is_none() {
                fine = Some((model.mesh.clone(), own_chord));
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
                            "encoded from the tessellation with {} ({} bytes)",
                            v.what,
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
}
