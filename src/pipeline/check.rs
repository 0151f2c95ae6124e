//! Measuring a written file against the input it encodes, the one way the project reports
//! it: `scode info --against`, `scode report` and the encoder's check of its own output
//! ([`check_as_info_does`]) all measure through [`measure_file_against_input`].

use glam::DVec3;

use crate::codec::Limits;
use crate::error::Result;
use crate::fit::encoder::FitReport;
use crate::mesh::{ControlMesh, Tolerance};
use crate::metrics::DistanceOptions;
use crate::metrics::{edge_spacing_for_tolerance, hausdorff_by_group, hausdorff_with_misses};
use crate::metrics::{DistanceReport, Misses};
use crate::surface::{decode_default_surface, DefaultSurface};

/// How many more fits a model gets when the file of one fails the check of
/// [`check_as_info_does`] that the fit's own measurement passed.
pub(super) const MISS_REFITS: usize = 2;

/// The most points of each side a refit takes from the check's misses.
pub(super) const MAX_MISSES: usize = 2000;

/// The file `bytes` against `input`: the surface of its default level (a raw-mode file: its
/// stored mesh) as A, the input as B, sampled as `opts` says (`scode info --against` and
/// `scode report`: [`DistanceOptions::default`]); the level measured (0 for raw mode) and
/// the samples farther than `beyond` from the other side. `near` is a distance most samples
/// are expected within (the tolerance, when there is one): it only splits the work. A
/// control mesh is measured group by group ([`hausdorff_by_group`]), so memory holds the
/// level's positions, not its triangles.
pub fn measure_file_against_input(
    bytes: &[u8],
    input: &ControlMesh,
    limits: &Limits,
    opts: &DistanceOptions,
    near: f64,
    beyond: f64,
) -> Result<(DistanceReport, Misses, u32)> {
    match decode_default_surface(bytes, limits)? {
        DefaultSurface::Stored(mesh) => {
            let (r, m) = hausdorff_with_misses(&mesh, input, opts, beyond)?;
            Ok((r, m, 0))
        }
        DefaultSurface::ByGroup { surface, level } => {
            let (r, m) = hausdorff_by_group(&surface, input, opts, near, beyond)?;
            Ok((r, m, level))
        }
    }
}

/// `points` thinned to one per cube of side `cell` (the first in order), and at most `max`
/// of those, evenly spaced in order.
pub(super) fn thinned(points: &[DVec3], cell: f64, max: usize) -> Vec<DVec3> {
    let mut seen = std::collections::HashSet::new();
    let kept: Vec<DVec3> = points
        .iter()
        .copied()
        .filter(|p| seen.insert((*p / cell).floor().as_i64vec3().to_array()))
        .collect();
    if kept.len() <= max {
        return kept;
    }
    (0..max).map(|i| kept[i * kept.len() / max]).collect()
}

/// Measures the written file as `scode info --against` does ([`measure_file_against_input`])
/// and keeps the larger figures. The fit's own measurement samples the decoded surface per
/// face and more sparsely, so a file it finds within the tolerance can come out a little
/// farther by the user's check; "within tolerance" is then said only when both agree.
pub(super) fn check_as_info_does(
    bytes: &[u8],
    input: &ControlMesh,
    report: &mut FitReport,
) -> Result<Misses> {
    let tol = report.tolerance;
    // The edge points the fit measured too, and at least those `scode info --against` takes.
    let opts = DistanceOptions {
        edge_spacing: Some(Tolerance::Absolute(edge_spacing_for_tolerance(
            tol,
            input.diagonal(),
        ))),
        ..Default::default()
    };
    let (r, misses, _) =
        measure_file_against_input(bytes, input, &trusted_limits(), &opts, tol, tol)?;
    let e = &mut report.error;
    e.max = e.max.max(r.max);
    e.max_excess = e.max_excess.max(r.max);
    e.rms = e.rms.max(r.rms);
    e.mean = e.mean.max(r.mean);
    let mean_ok = report.mean_tolerance.is_none_or(|mt| e.mean <= mt);
    if report.within_tolerance && !(e.max_excess <= report.tolerance && mean_ok) {
        report.within_tolerance = false;
        report.notes.push(format!(
            "measured as `scode info --against` does, the file is {:.3e} from the input \
             (the fit's own samples found it within the tolerance)",
            r.max
        ));
    }
    Ok(misses)
}

/// Limits for decoding the encoder's own output while fitting: only the format's count
/// limits apply, not the budgets that guard a decode of untrusted files.
pub(super) fn trusted_limits() -> Limits {
    Limits {
        max_subdivided_faces: u64::MAX,
        max_memory: u64::MAX,
        max_work_per_element: u64::MAX,
        ..Limits::default()
    }
}
