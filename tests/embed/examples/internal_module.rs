//! Must not compile: without the library's feature `internals`, its internal modules are
//! private to it and the control mesh type is not exported. `scripts/test.sh` checks that
//! each `use` below fails (E0603 "module is private", E0432 "unresolved import"); the example
//! is built only with this package's feature `compile-fail`.
#![allow(unused_imports)]

use scode::codec;
use scode::error;
use scode::fit;
use scode::io;
use scode::mesh;
use scode::metrics;
use scode::pipeline;
use scode::subdiv;
use scode::surface;
use scode::ControlMesh;

fn main() {}
