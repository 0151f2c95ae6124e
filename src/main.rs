//! The `scode` command-line tool. Thin on purpose: it parses arguments, calls the library and
//! prints; every algorithm lives in the `scode` library crate.

mod cli;

/// Large per-call arrays (subdivision levels, distance queries) are reused by mimalloc
/// instead of being unmapped and faulted in again on the next call (Cargo feature `mimalloc`).
#[cfg(feature = "mimalloc")]
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("scode: error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
