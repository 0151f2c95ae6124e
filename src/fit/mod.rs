//! Fitting encoder: turns a tessellated CAD model into subdivision patches.
//!
//! This first half does not need subdivision: [`segment`] splits an ungrouped mesh into
//! CAD-face-like regions, [`primitives`] fits analytic surfaces, and [`curves`] extracts
//! the boundary curve network (corners + chains) shared by adjacent patches.

mod adjacency;
pub mod curves;
pub mod decimate;
pub mod encoder;
mod linalg;
pub mod primitives;
pub mod segment;

#[cfg(test)]
pub(crate) mod test_support;
