//! The fit's last step: the coarsest quantisation that still holds the tolerance, for each
//! candidate model, and the candidate whose file is then smallest.
//!
//! The quantisation step was chosen for a quarter of the tolerance; the limit surface
//! averages control points, so coarser steps often still fit.

use super::encoder::{with_faces_involved, FitError, FitOptions, FitReport, Reconstruct};
use super::measure::ErrorMeter;
use super::rounds::Candidate;
use crate::error::{Error, Result};
use crate::mesh::ControlMesh;

/// The model to store, at its quantisation.
pub(super) struct Quantised {
    pub err: FitError,
    pub control: ControlMesh,
    pub level: u8,
    /// Quarter bits coarser than the caller's default step.
    pub coarser_quarter_bits: u8,
    /// How many groups are their input facets.
    pub faceted: usize,
}

/// Quantises each candidate as coarsely as the tolerances (max, and mean if bounded; model
/// units) allow and returns the one whose
/// file is smallest (the first on a tie). A segmented model's made-up group names are
/// dropped first.
pub(super) fn smallest_file(
    candidates: Vec<Candidate>,
    segmented: bool,
    meter: &ErrorMeter<'_>,
    opts: &FitOptions,
    tolerances: (f64, Option<f64>),
    reconstruct: &mut Reconstruct<'_>,
    report: &mut FitReport,
) -> Result<Quantised> {
    let compared = candidates.len() > 1;
    let mut chosen: Option<(Quantised, usize)> = None;
    let mut sizes = Vec::new();
    for mut candidate in candidates {
        if segmented {
            // The segmenter's region names ("face_i") are made up here, not the input's: do
            // not spend bytes on them (they can be a sixth of a small file). Groups and patch
            // kinds stay.
            for g in &mut candidate.control.groups {
                g.name.clear();
            }
            if compared {
                // The sizes decide between the candidates: measure them without the names.
                candidate.bytes = reconstruct(&candidate.control, candidate.level, 0)
                    .map_err(|e| with_faces_involved(e, &candidate.control))?
                    .1;
            }
        }
        let (err, coarser, bytes) =
            coarsest_step(&candidate, meter, opts, tolerances, reconstruct)?;
        sizes.push((candidate.control.vertex_count(), coarser, bytes));
        if chosen.as_ref().is_none_or(|c| bytes < c.1) {
            let quantised = Quantised {
                err,
                control: candidate.control,
                level: candidate.level,
                coarser_quarter_bits: coarser,
                faceted: candidate.faceted,
            };
            chosen = Some((quantised, bytes));
        }
    }
    if let [(cv, cb, cbytes), (rv, rb, rbytes)] = sizes[..] {
        report.notes.push(format!(
            "relaxed: {rv} control vertices, {} bits coarser, {rbytes} bytes; converged: \
             {cv}, {} bits coarser, {cbytes} bytes; kept the {}",
            f64::from(rb) / 4.0,
            f64::from(cb) / 4.0,
            if rbytes < cbytes {
                "relaxed"
            } else {
                "converged"
            }
        ));
    }
    chosen
        .map(|c| c.0)
        .ok_or_else(|| Error::Mesh("fitting produced no control mesh".into()))
}

/// The coarsest step at which `candidate` still meets the tolerance: its error there, how
/// many quarter bits coarser than the default it is, and the file's size.
///
/// Binary search over whole bits 0..=max (the error grows with the step, though not
/// strictly: it also depends on how the grid falls on the control points), at most two or
/// three measurements; then quarter bits beyond the whole count found, halving (+1/2, then
/// +1/4 or +3/4): a whole bit doubles the step, and the tolerance often still holds at 1.2
/// to 1.7 times the step where it fails at 2. A fraction must also shrink the file and keep
/// the RMS error within a quarter of the tolerance (see `FitOptions::max_coarser_bits`).
fn coarsest_step(
    candidate: &Candidate,
    meter: &ErrorMeter<'_>,
    opts: &FitOptions,
    (tol, mean_tol): (f64, Option<f64>),
    reconstruct: &mut Reconstruct<'_>,
) -> Result<(FitError, u8, usize)> {
    let Candidate {
        mut err,
        ref control,
        level,
        mut bytes,
        ..
    } = *candidate;
    let mut coarser_bits = 0;
    if err.max_excess > tol {
        return Ok((err, coarser_bits, bytes));
    }
    let mean_ok = |e: &FitError| mean_tol.is_none_or(|mt| e.mean <= mt);
    // The chord allowance is for the input's facets, not for quantisation noise: the plain
    // max error may not grow beyond max(tolerance, the unquantised fit's).
    let max_cap = tol.max(err.max);
    let (mut lo, mut hi) = (0u8, opts.max_coarser_bits);
    // The quarter bit to try beyond `lo` whole bits once the search has settled (2, then 1
    // or 3; 0 when done, or when the caller fixed the precision (`max_coarser_bits` 0) or
    // asked for whole bits only). `coarser` counts quarter bits.
    let mut quarter = if opts.max_coarser_bits > 0 && opts.quarter_bit_steps {
        2u8
    } else {
        0
    };
    loop {
        let coarser = if lo < hi {
            4 * (lo + hi).div_ceil(2)
        } else if quarter > 0 {
            4 * lo + quarter
        } else {
            break;
        };
        let (decoded, coarser_bytes) =
            reconstruct(control, level, coarser).map_err(|e| with_faces_involved(e, control))?;
        // A failing step usually fails where the finer one was worst: probing those samples
        // first decides it without a full measurement (same decision).
        let m = meter
            .measure_unless_over(&decoded, level, Some(max_cap))
            .map_err(|e| with_faces_involved(e, &decoded))?;
        let whole = coarser % 4 == 0;
        let within = m.filter(|m| {
            m.error.max_excess <= tol
                && m.error.max <= max_cap
                && mean_ok(&m.error)
                && (whole || (coarser_bytes < bytes && m.error.rms <= 0.25 * tol))
        });
        let held = within.is_some();
        if let Some(m) = within {
            coarser_bits = coarser;
            err = m.error;
            bytes = coarser_bytes;
        }
        if whole {
            if held {
                lo = coarser / 4;
            } else {
                hi = coarser / 4 - 1;
            }
        } else if quarter == 2 {
            quarter = if held { 3 } else { 1 };
        } else {
            quarter = 0;
        }
    }
    Ok((err, coarser_bits, bytes))
}
