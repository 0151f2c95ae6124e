//! The `scode` command-line tool. Thin on purpose: it parses arguments, calls the libraries
//! and prints; every codec algorithm lives in the `scode` library crate, `scode report` in
//! this package's library (`scode_cli::report`).
#![forbid(unsafe_code)]

mod cli;

/// Large per-call arrays (subdivision levels, distance queries) are reused by mimalloc
/// instead of being unmapped and faulted in again on the next call (Cargo feature `mimalloc`).
#[cfg(feature = "mimalloc")]
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use std::process::ExitCode;

use clap::Parser;

use cli::exit;

fn main() -> ExitCode {
    let args = match cli::Cli::try_parse() {
        Ok(args) => args,
        Err(e) => {
            // `--help` and `--version` print to stdout and succeed; every other parse
            // failure is a usage error with the status of all usage errors (clap's own
            // would be 2, the input-error status here).
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() {
                exit::USAGE
            } else {
                exit::OK
            });
        }
    };
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("scode: error: {}", exit::message(&err));
            ExitCode::from(exit::status(&err))
        }
    }
}
