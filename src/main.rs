//! The `scode` command-line tool; all logic lives in the library (`src/cli`).
fn main() {
    std::process::exit(scode_cli_main());
}

fn scode_cli_main() -> i32 {
    eprintln!("scode: CLI not built yet");
    1
}
