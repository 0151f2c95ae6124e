//! scode: a subdivision-surface codec and file format (`.scode`) for CAD models.
//!
//! The encoder fits each CAD face of a model with a subdivision patch on one watertight
//! control mesh and stores that mesh; the decoder subdivides it back to a triangle surface
//! whose triangles keep their CAD face.
//!
//! # API
//!
//! - [`encode`] compresses an [`Input`] (a [`Mesh`] with face groups, a mesh file, or a STEP
//!   file) to `.scode` bytes with [`EncodeOptions`], returning [`Encoded`].
//! - [`decode`] turns `.scode` bytes into a [`Surface`] with [`DecodeOptions`]: to the
//!   tolerance the file was encoded for (default), to a tolerance, or to a uniform level,
//!   with limit positions and normals, within [`Limits`].
//! - [`inspect`] reads a file's header and sections ([`Info`]).
//! - Every fallible call returns [`Error`], which says what kind of problem it was
//!   (`Format`, `LimitsExceeded`, `Input`, `Parameter`, `Mesh`, `Io`).
//!
//! ```
//! # fn main() -> scode::Result<()> {
//! // Four triangles, one CAD face each.
//! let mesh = scode::Mesh {
//!     positions: vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
//!     triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
//!     groups: vec![0, 1, 2, 3],
//!     ..Default::default()
//! };
//! let encoded = scode::encode(scode::Input::Mesh(&mesh), &scode::EncodeOptions::default())?;
//! let surface = scode::decode(&encoded.bytes, &scode::DecodeOptions::level(2))?;
//! assert_eq!(surface.mesh.triangles.len(), surface.mesh.groups.len());
//! assert_eq!(scode::inspect(&encoded.bytes)?.groups, 4);
//! # Ok(())
//! # }
//! ```
//!
//! # Features
//!
//! - `encoder` (default): [`encode`] of meshes and mesh files (fitting, mesh readers,
//!   distance metrics). Without it the crate is the decoder alone ([`decode`], [`inspect`]).
//! - `step` (default): STEP input ([`Input::Step`]).
//! - `parallel` (default): multi-threaded refinement and fitting (rayon); same results.
//! - `legacy-formats` (default): decoding of format versions 1 and 2.
//! - `remesh` (default): decoding to a smallest angle ([`DecodeOptions::min_angle`]:
//!   constrained Delaunay refinement of plane patches).
//! - `internals` (off): makes the internal modules public. Not a stable interface: for the
//!   scode command-line tool, viewer, tests and fuzz targets of this repository.
//!
//! A decoder alone turns default features off; an embedder that encodes meshes but never
//! reads STEP adds `encoder`:
//! `scode = { version = "0.1", default-features = false, features = ["encoder"] }`. The
//! command-line tool, its reports, plots and allocator are the `scode-cli` package (`cli/`).
//!
//! # Internal modules
//!
//! Below the API the crate is layered in modules: mesh, io, subdiv, fit, codec, metrics,
//! surface, pipeline. They are private to the crate; the feature `internals` makes them
//! public (hidden from this documentation) for the repository's own users of them: the
//! `scode` command-line tool (package `scode-cli`), the WebAssembly viewer, the integration
//! tests, benches, examples and fuzz targets. Items that only those users need are built
//! with the feature alone. An embedder depends on the API above and leaves the feature off.
#![forbid(unsafe_code)]

// The internal modules: public (hidden from the documentation) with the feature `internals`,
// private to the crate without it. Each is declared twice, once per visibility, so that
// tools that follow `mod` items (rustfmt) see every module.
#[cfg(feature = "internals")]
#[doc(hidden)]
pub mod codec;
#[cfg(not(feature = "internals"))]
pub(crate) mod codec;
#[cfg(feature = "internals")]
#[doc(hidden)]
pub mod error;
#[cfg(not(feature = "internals"))]
pub(crate) mod error;
#[cfg(all(feature = "encoder", feature = "internals"))]
#[doc(hidden)]
pub mod fit;
#[cfg(all(feature = "encoder", not(feature = "internals")))]
pub(crate) mod fit;
#[cfg(all(feature = "encoder", feature = "internals"))]
#[doc(hidden)]
pub mod io;
#[cfg(all(feature = "encoder", not(feature = "internals")))]
pub(crate) mod io;
#[cfg(feature = "internals")]
#[doc(hidden)]
pub mod mesh;
#[cfg(not(feature = "internals"))]
pub(crate) mod mesh;
#[cfg(all(feature = "encoder", feature = "internals"))]
#[doc(hidden)]
pub mod metrics;
#[cfg(all(feature = "encoder", not(feature = "internals")))]
pub(crate) mod metrics;
#[cfg(all(feature = "encoder", feature = "internals"))]
#[doc(hidden)]
pub mod pipeline;
#[cfg(all(feature = "encoder", not(feature = "internals")))]
pub(crate) mod pipeline;
#[cfg(feature = "internals")]
#[doc(hidden)]
pub mod subdiv;
#[cfg(not(feature = "internals"))]
pub(crate) mod subdiv;
#[cfg(feature = "internals")]
#[doc(hidden)]
pub mod surface;
#[cfg(not(feature = "internals"))]
pub(crate) mod surface;

mod api;

pub use api::*;
pub use error::{Error, Result};
#[cfg(feature = "internals")]
#[doc(hidden)]
pub use mesh::ControlMesh;
pub use mesh::Tolerance;
