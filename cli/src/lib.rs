//! The library part of the `scode` command-line tool: `scode report`, the rate-distortion
//! comparison with Draco and gltfpack, its tables and plots. The commands themselves are the
//! binary (`src/main.rs`, `src/cli/`); every codec algorithm is the `scode` library's.
#![forbid(unsafe_code)]

pub mod report;
