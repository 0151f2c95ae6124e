//! Rate-distortion figures of one compressed file: its size against the input's raw binary
//! size and its distance to the input. A decoded mesh is measured by
//! [`measure_against_input`]; a `.scode` file by `pipeline::measure_file_against_input`, with
//! the same samples on the input's side and the file's drawn group by group, so `scode info
//! --against` and `scode report` give the same figures.

use super::distance::{hausdorff, DistanceOptions, DistanceReport};
use crate::error::Result;
use crate::mesh::ControlMesh;

/// Size in bytes of the input as a plain binary triangle mesh: float32 x, y, z per vertex
/// plus three u32 indices per triangle (polygons count as fan triangles). The "1x" of a
/// compression ratio.
pub fn raw_binary_bytes(mesh: &ControlMesh) -> u64 {
    let triangles: u64 = mesh.faces().map(|f| f.len().saturating_sub(2) as u64).sum();
    12 * mesh.vertex_count() as u64 + 12 * triangles
}

/// The distance between a decoded surface and the input it encodes, measured the one way the
/// project reports errors: [`hausdorff`] with the default [`DistanceOptions`] (100k
/// area-weighted samples on each side plus every vertex, fixed seed), decoded surface as A.
pub fn measure_against_input(decoded: &ControlMesh, input: &ControlMesh) -> Result<DistanceReport> {
    hausdorff(decoded, input, &DistanceOptions::default())
}

/// One point of a rate-distortion curve.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RateDistortion {
    /// Compressed size.
    pub bytes: u64,
    /// `8 * bytes / input vertices`.
    pub bits_per_vertex: f64,
    /// `raw_binary_bytes(input) / bytes` (how many times smaller than the raw binary mesh).
    pub ratio_to_raw: f64,
    /// Symmetric sampled Hausdorff distance as a fraction of the bounding-box diagonal.
    pub max_error: f64,
    /// Symmetric RMS distance (the larger direction) as a fraction of the diagonal.
    pub rms_error: f64,
    /// Symmetric mean distance as a fraction of the diagonal.
    pub mean_error: f64,
}

impl RateDistortion {
    /// Combines a file size with a distance report of its decoded surface against `input`.
    pub fn new(bytes: u64, input: &ControlMesh, distance: &DistanceReport) -> RateDistortion {
        let rel = distance.relative();
        let nv = input.vertex_count().max(1) as f64;
        RateDistortion {
            bytes,
            bits_per_vertex: bytes as f64 * 8.0 / nv,
            ratio_to_raw: raw_binary_bytes(input) as f64 / (bytes.max(1) as f64),
            max_error: rel.max,
            rms_error: rel.rms,
            mean_error: rel.mean,
        }
    }
}
