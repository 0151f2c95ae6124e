//! scode: a subdivision-surface codec for CAD models.
//!
//! The pipeline reads top to bottom in the module list: a [`mesh::ControlMesh`] is read by
//! [`io`], refined by [`subdiv`], produced from CAD faces by [`fit`], stored by [`codec`],
//! and measured by [`metrics`]. Each layer uses only the ones above it in this list
//! (`codec` and `metrics` never depend on `fit`).
#![forbid(unsafe_code)]

pub mod error;
pub mod mesh;

pub mod io;
pub mod subdiv;

pub mod fit;

pub mod codec;
pub mod metrics;

pub mod pipeline;
#[cfg(feature = "report")]
pub mod report;

pub use error::{Error, Result};
pub use mesh::ControlMesh;
