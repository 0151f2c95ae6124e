//! Arbitrary bytes into the glTF reader through the entry point `scode encode` uses, as a
//! `.glb` when they start with the GLB magic and as a `.gltf` otherwise (so one corpus holds
//! both and mutations cross between them): never a panic, a typed input error or a valid
//! mesh (see `common`). External files are refused (the bytes have no folder): the `data:`
//! URIs and the GLB chunk are what is read.
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use scode::io::MeshFormat;

fuzz_target!(|data: &[u8]| {
    let format = if data.starts_with(b"glTF") {
        MeshFormat::Glb
    } else {
        MeshFormat::Gltf
    };
    common::read_mesh_target(data, format)
});
