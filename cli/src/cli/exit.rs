//! Exit statuses of `scode` and the one-line error message printed before exiting.
//!
//! Scripts that convert uploads need to tell a bad request from a bad file and from a
//! result that misses what was asked, without parsing messages: each kind of failure has
//! its own status, listed in `scode --help` ([`HELP`]) and the README.

use scode::Error;

/// Success.
pub const OK: u8 = 0;
/// Usage or parameter error: unknown option, missing output, a value out of range, an
/// output that would overwrite the input or does not fit what the command writes.
pub const USAGE: u8 = 1;
/// Input or I/O error: a file cannot be read or written, or an input model is malformed
/// or unsupported.
pub const INPUT: u8 = 2;
/// A `.scode` file is malformed (names the section and field).
pub const FORMAT: u8 = 3;
/// A resource limit was exceeded (decoder limits, `encode --max-seconds` or
/// `--max-memory`, STEP worker threads that cannot be stopped).
pub const LIMITS: u8 = 4;
/// `encode`: the decoded surface misses `--tolerance` or `--mean-tolerance`; the file is
/// written (the closest the encoder came).
pub const TOLERANCE: u8 = 5;
/// `encode`: faces of a STEP file could not be read and `--allow-skipped` was not given;
/// nothing is written.
pub const SKIPPED: u8 = 6;

/// The exit-status table of `scode --help` (keep in step with the README).
pub const HELP: &str = "\
Exit status:
  0  success
  1  usage or parameter error (unknown option, value out of range, output that is the
     input or whose extension does not fit what is written)
  2  input or I/O error (file not readable or writable, malformed or unsupported model)
  3  malformed .scode file
  4  resource limit exceeded (decode limits, encode --max-seconds or --max-memory:
     nothing is written)
  5  encode: tolerance not met (the file is written)
  6  encode: STEP faces skipped without --allow-skipped (nothing is written)";

/// A failure of the command-line front end itself, with the status it exits with.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// The command line asks for something that cannot be done as asked.
    #[error("{0}")]
    Usage(String),
    /// The encoded file misses the requested tolerance.
    #[error("{0}")]
    ToleranceNotMet(String),
    /// Faces of the input were left out and the user did not allow it.
    #[error("{0}")]
    FacesSkipped(String),
    /// The encode went over its time or memory budget (`--max-seconds`, `--max-memory`).
    #[error("{0}")]
    BudgetExceeded(String),
}

/// The exit status for `err`: the first cause in its chain that says what kind of failure
/// it is decides; anything else (a socket or a terminal that fails) is an I/O error.
pub fn status(err: &anyhow::Error) -> u8 {
    for cause in err.chain() {
        if let Some(e) = cause.downcast_ref::<CliError>() {
            return match e {
                CliError::Usage(_) => USAGE,
                CliError::ToleranceNotMet(_) => TOLERANCE,
                CliError::FacesSkipped(_) => SKIPPED,
                CliError::BudgetExceeded(_) => LIMITS,
            };
        }
        if let Some(e) = cause.downcast_ref::<Error>() {
            return match e {
                Error::Parameter(_) => USAGE,
                Error::Io { .. } | Error::Input { .. } | Error::Mesh(_) => INPUT,
                Error::Format { .. } => FORMAT,
                Error::LimitsExceeded { .. } => LIMITS,
            };
        }
    }
    INPUT
}

/// `err` and its causes on one line, separated by `: `. A cause whose text the message
/// already ends with is left out: the library's I/O errors print their OS error in their
/// own message and also return it as their source.
pub fn message(err: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in err.chain() {
        let mut text = cause.to_string();
        if let Some(option) = cause.downcast_ref::<Error>().and_then(raising_option) {
            text.push_str(&format!("; {option} raises it"));
        }
        if text.is_empty() || msg.ends_with(&text) {
            continue;
        }
        if !msg.is_empty() {
            msg.push_str(": ");
        }
        msg.push_str(&text);
    }
    msg
}

/// The option of `scode decode` and `scode info` that raises the limit `err` exceeds, if one
/// does: the user can decide to spend more than the defaults allow.
fn raising_option(err: &Error) -> Option<&'static str> {
    let Error::LimitsExceeded { what, .. } = err else {
        return None;
    };
    if what.starts_with("decode memory") {
        Some("--max-memory")
    } else if what.starts_with("decode work") {
        Some("--max-work-per-element")
    } else if *what == "input bytes" || *what == "inflated section bytes" {
        Some("--max-bytes")
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anyhow::Context;

    #[test]
    fn os_errors_are_printed_once() {
        let io = std::io::Error::from(std::io::ErrorKind::NotFound);
        let os = io.to_string();
        let err = anyhow::Error::from(Error::io("/no/such.obj", io)).context("cannot read");
        let msg = message(&err);
        assert_eq!(msg, format!("cannot read: /no/such.obj: {os}"));
        assert_eq!(status(&err), INPUT);
    }

    #[test]
    fn statuses_follow_the_error_kind() {
        let s = |e: Error| status(&anyhow::Error::from(e).context("while doing it"));
        assert_eq!(s(Error::Parameter("x".into())), USAGE);
        assert_eq!(s(Error::input("a.obj", "bad")), INPUT);
        assert_eq!(s(Error::format("header", "magic", "bad")), FORMAT);
        assert_eq!(
            s(Error::LimitsExceeded {
                what: "bytes",
                value: 2,
                limit: 1
            }),
            LIMITS
        );
        let err = anyhow::Error::from(Error::LimitsExceeded {
            what: "decode memory with subdivision (bytes)",
            value: 2,
            limit: 1,
        });
        assert_eq!(
            message(&err),
            "limit exceeded: decode memory with subdivision (bytes) = 2 exceeds the limit 1; \
             --max-memory raises it"
        );
        let c = |e: CliError| status(&anyhow::Error::from(e));
        assert_eq!(c(CliError::Usage("u".into())), USAGE);
        assert_eq!(c(CliError::ToleranceNotMet("t".into())), TOLERANCE);
        assert_eq!(c(CliError::FacesSkipped("f".into())), SKIPPED);
        assert_eq!(status(&anyhow::anyhow!("socket closed")), INPUT);
        assert_eq!(
            status(
                &Err::<(), _>(CliError::Usage("u".into()))
                    .context("ctx")
                    .unwrap_err()
            ),
            USAGE
        );
    }
}
