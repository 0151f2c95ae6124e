//! Measuring a written file against the input it encodes, as `scode info --against` and
//! `scode report` do ([`measure_file_against_input`]).

use crate::codec::Limits;
#[cfg(feature = "internals")]
use crate::{
    error::Result,
    mesh::ControlMesh,
    metrics::{hausdorff, hausdorff_by_group, DistanceOptions, DistanceReport},
    surface::{decode_default_surface, DefaultSurface},
};

/// The file `bytes` against `input`: the surface of its default level (a raw-mode file: its
/// stored mesh) as A, the input as B, sampled as `opts` says (`scode info --against` and
/// `scode report`: [`DistanceOptions::default`]) and the level measured (0 for raw mode).
/// `near` is a distance most samples
/// are expected within (the tolerance, when there is one): it only splits the work. A
/// control mesh is measured group by group ([`hausdorff_by_group`]), so memory holds the
/// level's positions, not its triangles.
#[cfg(feature = "internals")]
pub fn measure_file_against_input(
    bytes: &[u8],
    input: &ControlMesh,
    limits: &Limits,
    opts: &DistanceOptions,
    near: f64,
) -> Result<(DistanceReport, u32)> {
    match decode_default_surface(bytes, limits)? {
        DefaultSurface::Stored(mesh) => Ok((hausdorff(&mesh, input, opts)?, 0)),
        DefaultSurface::ByGroup { surface, level } => {
            Ok((hausdorff_by_group(&surface, input, opts, near)?, level))
        }
    }
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
