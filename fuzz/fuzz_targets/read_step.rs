//! Arbitrary bytes into the STEP reader through the entry point and options `scode encode`
//! uses ([`scode::io::step::read_step_bytes`] with the options for the default tolerance):
//! never a panic in scode's own code, a typed error or a model whose mesh is valid and
//! whose tables agree with it (see `common`).
//!
//! truck and ruststep panic on some files; the reader runs them in watched threads that
//! turn a panic into a skipped face or an input error, which is what the command-line tool
//! reports. libFuzzer's panic hook would abort on those, so this target's hook lets panics
//! located in dependencies' sources pass on to that handling and aborts on every other one.
#![no_main]

mod common;

use std::path::Path;
use std::sync::Once;

use libfuzzer_sys::fuzz_target;
use scode::io::step::read_step_bytes;
use scode::pipeline::step_options_for;
use scode::{Error, Tolerance};

/// True for a panic raised in a dependency's source (a registry or git checkout of cargo).
fn in_dependency(info: &std::panic::PanicHookInfo<'_>) -> bool {
    info.location().is_some_and(|l| {
        let f = l.file();
        f.contains("/.cargo/registry/") || f.contains("/.cargo/git/")
    })
}

fn install_panic_hook() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let abort = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !in_dependency(info) {
                abort(info);
            }
        }));
    });
}

fuzz_target!(|data: &[u8]| {
    install_panic_hook();
    let name = Path::new("fuzz-input.step");
    let opts = step_options_for(Tolerance::DEFAULT);
    let model = match read_step_bytes(name, data, &opts) {
        Ok(model) => model,
        Err(Error::LimitsExceeded { .. }) if !common::seeds_must_read() => return,
        Err(e) => return common::check_error(&e, name),
    };
    let mesh = &model.mesh;
    if mesh.face_count() > 0 {
        common::check_mesh(mesh);
    }
    assert_eq!(model.faces.len(), mesh.groups.len());
    for body in &model.bodies {
        assert!(body.first_group as usize + body.group_count as usize <= mesh.groups.len());
    }
    for edge in &model.edges {
        assert!(edge
            .vertices
            .iter()
            .all(|&v| (v as usize) < mesh.vertex_count()));
        assert!(edge
            .groups
            .iter()
            .all(|&g| (g as usize) < mesh.groups.len()));
    }
    for &c in &mesh.corners {
        assert!((c as usize) < mesh.vertex_count());
    }
    assert!(model.chordal_tolerance.is_finite() && model.chordal_tolerance > 0.0);
});
