//! Arbitrary bytes into the OBJ reader through the entry point `scode encode` uses: never a
//! panic, a typed input error or a valid mesh (see `common`).
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use scode::io::MeshFormat;

fuzz_target!(|data: &[u8]| common::read_mesh_target(data, MeshFormat::Obj));
