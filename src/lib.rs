//! scode: a subdivision-surface codec for CAD models.
//!
//! The pipeline reads top to bottom in the module list: a [`mesh::ControlMesh`] is read by
//! [`io`], refined by [`subdiv`], produced from CAD faces by [`fit`], stored by [`codec`],
//! and measured by [`metrics`]. Each layer uses only the ones above it in this list
//! (`codec` and `metrics` never depend on `fit`).
//!
//! Features: `encoder` (default) enables `io`, `fit`, `metrics` and `pipeline` and their
//! dependencies; without it the crate is the decoder alone (`codec`, `mesh`, `subdiv`).
#![forbid(unsafe_code)]

pub mod error;
pub mod mesh;

#[cfg(feature = "encoder")]
pub mod io;
pub mod subdiv;

#[cfg(feature = "encoder")]
pub mod fit;

pub mod codec;
#[cfg(feature = "encoder")]
pub mod metrics;

#[cfg(feature = "encoder")]
pub mod pipeline;
#[cfg(feature = "report")]
pub mod report;

pub use error::{Error, Result};
pub use mesh::{ControlMesh, Tolerance};
