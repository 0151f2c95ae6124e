//! The `scode` command-line tool. Thin on purpose: it parses arguments, calls the library and
//! prints; every algorithm lives in the `scode` library crate.

mod cli;

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
