//! Running one encoder setting on one model: scode (in this process or in a child process
//! with a time limit) and Draco (its command-line tools, with a time limit).

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use scode::codec::{self, Content, EncodeOptions};
use scode::error::{Error, Result};
use scode::io;
use scode::mesh::Tolerance;
use scode::pipeline::{encode_fitted, sidecar_hints, ModelEncodeOptions};

/// One encoder setting: a point of a rate-distortion curve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Setting {
    /// scode's fitting encoder with this tolerance, as a fraction of the bbox diagonal.
    Fitted { tolerance: f64 },
    /// scode raw mode (the input mesh itself, quantised).
    Raw { bits: u8 },
    /// `draco_encoder -qp qp -cl cl`.
    Draco { qp: u8, cl: u8 },
    /// `gltfpack -vp vp` (with `-cc` when `cc`) on the input written as glb.
    Gltfpack { vp: u8, cc: bool },
}

impl Setting {
    pub fn codec(&self) -> &'static str {
        match self {
            Setting::Fitted { .. } => "scode",
            Setting::Raw { .. } => "scode raw",
            Setting::Draco { .. } => "draco",
            Setting::Gltfpack { .. } => "gltfpack",
        }
    }

    /// Short label used in tables, the CSV and progress messages.
    pub fn label(&self) -> String {
        match self {
            Setting::Fitted { tolerance } => format!("tol {tolerance:.0e}"),
            Setting::Raw { bits } => format!("{bits} bit"),
            Setting::Draco { qp, cl } => format!("qp {qp} cl {cl}"),
            Setting::Gltfpack { vp, cc: true } => format!("vp {vp} cc"),
            Setting::Gltfpack { vp, cc: false } => format!("vp {vp}"),
        }
    }

    pub fn is_scode(&self) -> bool {
        self.baseline().is_none()
    }

    /// The other codec this setting runs, `None` for scode's own settings.
    pub fn baseline(&self) -> Option<Baseline> {
        match self {
            Setting::Draco { .. } => Some(Baseline::Draco),
            Setting::Gltfpack { .. } => Some(Baseline::Gltfpack),
            Setting::Fitted { .. } | Setting::Raw { .. } => None,
        }
    }

    /// File name of this setting's output inside the model's work directory.
    pub fn file_name(&self) -> String {
        match self {
            Setting::Fitted { tolerance } => format!("fitted_{tolerance:.0e}.scode"),
            Setting::Raw { bits } => format!("raw_{bits}.scode"),
            Setting::Draco { qp, cl } => format!("draco_qp{qp}_cl{cl}.drc"),
            Setting::Gltfpack { vp, cc } => {
                format!("gltfpack_vp{vp}{}.glb", if *cc { "_cc" } else { "" })
            }
        }
    }
}

/// A codec the report compares scode with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Baseline {
    /// Google's Draco (`draco_encoder`/`draco_decoder`).
    Draco,
    /// meshoptimizer's `gltfpack`.
    Gltfpack,
}

impl Baseline {
    /// Every baseline, in the order tables list them.
    pub const ALL: [Baseline; 2] = [Baseline::Draco, Baseline::Gltfpack];

    pub fn name(self) -> &'static str {
        match self {
            Baseline::Draco => "Draco",
            Baseline::Gltfpack => "gltfpack",
        }
    }
}

/// An scode encode to run: read `input`, encode with `setting`, write `output`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScodeJob {
    pub input: PathBuf,
    pub output: PathBuf,
    pub setting: Setting,
    /// Timing repeats (the median is reported); encodes slower than
    /// [`SLOW_ENCODE_SECONDS`] are timed once.
    pub runs: usize,
}

/// What an scode encode produced.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ScodeJobResult {
    pub bytes: u64,
    /// Wall time of every timed run, seconds.
    pub encode_seconds: Vec<f64>,
    /// A remark for the table (e.g. the fitter did not meet its tolerance).
    pub note: Option<String>,
}

/// An encode that takes longer than this is not repeated for timing.
pub const SLOW_ENCODE_SECONDS: f64 = 2.0;

/// Runs `job` in this process: encodes `runs` times (fewer for slow encodes) and writes the
/// output file. This is what the child process of [`StepRunner::Subprocess`] executes.
pub fn run_scode_job(job: &ScodeJob) -> Result<ScodeJobResult> {
    if io::step::is_step_path(&job.input) {
        return run_step_job(job);
    }
    let (mesh, _) = io::read_mesh(&job.input)?;
    let mut result = ScodeJobResult::default();
    let mut bytes = Vec::new();
    for run in 0..job.runs.max(1) {
        let t0 = Instant::now();
        bytes = match job.setting {
            Setting::Raw { bits } => codec::encode(
                &mesh,
                &EncodeOptions {
                    quantization_bits: bits,
                    content: Content::RawMesh,
                    store_group_names: true,
                    ..Default::default()
                },
            )?,
            Setting::Fitted { tolerance } => {
                let hints = sidecar_hints(&job.input, &mesh)?
                    .map(|(_, h)| h)
                    .unwrap_or_default();
                let mut opts = ModelEncodeOptions::default();
                opts.fit.tolerance = Tolerance::Relative(tolerance);
                let (bytes, fit) = encode_fitted(&mesh, &hints, &opts)?;
                if run == 0 && !fit.within_tolerance {
                    result.note = Some(format!(
                        "fit missed its tolerance by {:.2}x after {} rounds",
                        fit.error.max_excess / fit.tolerance.max(f64::MIN_POSITIVE),
                        fit.rounds
                    ));
                }
                bytes
            }
            Setting::Draco { .. } | Setting::Gltfpack { .. } => {
                return Err(Error::Parameter(format!(
                    "a {} setting is not an scode job",
                    job.setting.codec()
                )))
            }
        };
        let secs = t0.elapsed().as_secs_f64();
        result.encode_seconds.push(secs);
        if secs > SLOW_ENCODE_SECONDS {
            break;
        }
    }
    std::fs::write(&job.output, &bytes).map_err(|e| Error::io(&job.output, e))?;
    result.bytes = bytes.len() as u64;
    Ok(result)
}

/// [`run_scode_job`] on a STEP file: the fitted encoder on the B-rep itself
/// (`pipeline::encode_step`, what `scode encode part.step` does).
fn run_step_job(job: &ScodeJob) -> Result<ScodeJobResult> {
    let Setting::Fitted { tolerance } = job.setting else {
        return Err(Error::Parameter(format!(
            "{} {} takes a mesh, not a STEP file",
            job.setting.codec(),
            job.setting.label()
        )));
    };
    let mut opts = ModelEncodeOptions::default();
    opts.fit.tolerance = Tolerance::Relative(tolerance);
    let mut result = ScodeJobResult::default();
    let mut bytes = Vec::new();
    for run in 0..job.runs.max(1) {
        let t0 = Instant::now();
        let (_, b, fit) = scode::pipeline::encode_step(&job.input, &opts)?;
        if run == 0 && !fit.within_tolerance {
            result.note = Some(format!(
                "fit missed its tolerance by {:.2}x after {} rounds",
                fit.error.max_excess / fit.tolerance.max(f64::MIN_POSITIVE),
                fit.rounds
            ));
        }
        bytes = b;
        let secs = t0.elapsed().as_secs_f64();
        result.encode_seconds.push(secs);
        if secs > SLOW_ENCODE_SECONDS {
            break;
        }
    }
    std::fs::write(&job.output, &bytes).map_err(|e| Error::io(&job.output, e))?;
    result.bytes = bytes.len() as u64;
    Ok(result)
}

/// The child-process side of [`StepRunner::Subprocess`]: `job_json` is a serialised
/// [`ScodeJob`]; returns the serialised [`ScodeJobResult`] to print on stdout.
pub fn run_scode_job_json(job_json: &str) -> Result<String> {
    let job: ScodeJob = serde_json::from_str(job_json)
        .map_err(|e| Error::Parameter(format!("bad report job: {e}")))?;
    let result = run_scode_job(&job)?;
    serde_json::to_string(&result).map_err(|e| Error::Parameter(format!("{e}")))
}

/// Marker before the result JSON on the child's stdout (the child may print other lines).
pub const RESULT_MARKER: &str = "SCODE-REPORT-RESULT ";

/// How scode encodes are run.
#[derive(Clone, Debug, PartialEq)]
pub enum StepRunner {
    /// In this process, panics caught (`catch_unwind`). The time limit cannot stop a running
    /// encode here; it is only checked between steps.
    InProcess,
    /// In a child process `program args.. <job json>` that calls [`run_scode_job_json`] and
    /// prints [`RESULT_MARKER`] + the result. A panic, crash or overrun (the child is killed
    /// at the time limit) becomes an error row. The `scode` binary does this with its hidden
    /// `report-step` subcommand.
    Subprocess { program: PathBuf, args: Vec<String> },
}

/// Runs one scode job with `runner` and a time limit.
pub fn run_scode(
    runner: &StepRunner,
    job: &ScodeJob,
    timeout: Duration,
) -> std::result::Result<ScodeJobResult, String> {
    match runner {
        StepRunner::InProcess => {
            let outcome =
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run_scode_job(job)));
            match outcome {
                Ok(Ok(r)) => Ok(r),
                Ok(Err(e)) => Err(e.to_string()),
                Err(panic) => Err(format!("encoder panicked: {}", panic_message(&*panic))),
            }
        }
        StepRunner::Subprocess { program, args } => {
            let json = serde_json::to_string(job).map_err(|e| e.to_string())?;
            let mut cmd = Command::new(program);
            cmd.args(args).arg(json);
            let out = run_with_timeout(cmd, timeout)?;
            if !out.success {
                return Err(format!(
                    "encoder failed ({}): {}",
                    out.status,
                    tail(&out.stderr, 3)
                ));
            }
            let line = out
                .stdout
                .lines()
                .rev()
                .find_map(|l| l.strip_prefix(RESULT_MARKER))
                .ok_or_else(|| format!("encoder printed no result: {}", tail(&out.stderr, 3)))?;
            serde_json::from_str(line).map_err(|e| format!("bad encoder result: {e}"))
        }
    }
}

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

/// The last `n` non-empty lines of `text`, joined with " | ".
pub(crate) fn tail(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(n)..].join(" | ")
}

/// What a finished child process said.
pub(crate) struct ProcessOutput {
    pub success: bool,
    pub status: String,
    pub stdout: String,
    pub stderr: String,
    pub wall_seconds: f64,
}

/// Runs `cmd`, killing it after `timeout`. Output pipes are drained by threads so a chatty
/// child cannot block. A timeout is an `Err` naming the limit.
pub(crate) fn run_with_timeout(
    mut cmd: Command,
    timeout: Duration,
) -> std::result::Result<ProcessOutput, String> {
    let program = cmd.get_program().to_string_lossy().into_owned();
    cmd.stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let t0 = Instant::now();
    let mut child = cmd
        .spawn()
        .map_err(|e| format!("cannot run {program}: {e}"))?;
    let drain = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut s = Vec::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_end(&mut s);
            }
            String::from_utf8_lossy(&s).into_owned()
        })
    };
    let out_thread = drain(
        child
            .stdout
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let err_thread = drain(
        child
            .stderr
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if t0.elapsed() >= timeout => {
                let _ = child.kill();
                let _ = child.wait();
                let _ = (out_thread.join(), err_thread.join());
                return Err(format!("timed out after {} s", timeout.as_secs()));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => return Err(format!("cannot wait for {program}: {e}")),
        }
    };
    let wall_seconds = t0.elapsed().as_secs_f64();
    Ok(ProcessOutput {
        success: status.success(),
        status: status.to_string(),
        stdout: out_thread.join().unwrap_or_default(),
        stderr: err_thread.join().unwrap_or_default(),
        wall_seconds,
    })
}

/// Where Draco's command-line tools are.
#[derive(Clone, Debug, PartialEq)]
pub struct DracoTools {
    pub encoder: PathBuf,
    pub decoder: PathBuf,
}

/// Finds `draco_encoder` and `draco_decoder` in `dir`, or else on `PATH` when `dir` is
/// `None`. The error says where it looked and how to install Draco.
pub fn find_draco(dir: Option<&Path>) -> std::result::Result<DracoTools, String> {
    let dirs: Vec<PathBuf> = match dir {
        Some(d) => vec![d.to_path_buf()],
        None => std::env::var_os("PATH")
            .map(|p| std::env::split_paths(&p).collect())
            .unwrap_or_default(),
    };
    let find = |name: &str| dirs.iter().map(|d| d.join(name)).find(|p| p.is_file());
    match (find("draco_encoder"), find("draco_decoder")) {
        (Some(encoder), Some(decoder)) => Ok(DracoTools { encoder, decoder }),
        _ => Err(format!(
            "Draco not found: no draco_encoder and draco_decoder in {} (install the Debian \
             package `draco` or pass --draco-dir); the report continues without Draco",
            match dir {
                Some(d) => d.display().to_string(),
                None => "PATH".into(),
            }
        )),
    }
}

/// Finds the `gltfpack` executable (meshoptimizer) in `dir`, or else on `PATH` when `dir`
/// is `None`. The error says where it looked and how to install it.
pub fn find_gltfpack(dir: Option<&Path>) -> std::result::Result<PathBuf, String> {
    let dirs: Vec<PathBuf> = match dir {
        Some(d) => vec![d.to_path_buf()],
        None => std::env::var_os("PATH")
            .map(|p| std::env::split_paths(&p).collect())
            .unwrap_or_default(),
    };
    dirs.iter()
        .map(|d| d.join("gltfpack"))
        .find(|p| p.is_file())
        .ok_or_else(|| {
            format!(
                "gltfpack not found: no gltfpack in {} (install the npm package `gltfpack`, \
                 e.g. `npm install -g gltfpack`, or pass --gltfpack-dir); the report continues \
                 without gltfpack",
                match dir {
                    Some(d) => d.display().to_string(),
                    None => "PATH".into(),
                }
            )
        })
}

/// Parses Draco's "(12 ms to encode)" / "(3 ms to decode)" timing.
pub(crate) fn draco_ms(stdout: &str, verb: &str) -> Option<f64> {
    let key = format!(" ms to {verb})");
    let end = stdout.find(&key)?;
    let start = stdout[..end].rfind('(')? + 1;
    stdout[start..end].trim().parse().ok()
}

/// Median of `values` (0 for none).
pub fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_and_parsing() {
        assert_eq!(Setting::Fitted { tolerance: 1e-3 }.label(), "tol 1e-3");
        assert_eq!(
            Setting::Fitted { tolerance: 5e-4 }.file_name(),
            "fitted_5e-4.scode"
        );
        assert_eq!(Setting::Draco { qp: 11, cl: 7 }.label(), "qp 11 cl 7");
        let out = "Encoder options:\n\nEncoded mesh saved to f.drc (35 ms to encode).\n";
        assert_eq!(draco_ms(out, "encode"), Some(35.0));
        assert_eq!(
            draco_ms(
                "Decoded geometry saved to f.ply (19 ms to decode)",
                "decode"
            ),
            Some(19.0)
        );
        assert_eq!(draco_ms("nothing", "decode"), None);
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0]), 2.5);
        assert_eq!(median(&[]), 0.0);
        assert_eq!(tail("a\n\nb\nc\n", 2), "b | c");
    }

    #[test]
    fn missing_draco_is_a_message() {
        let e = find_draco(Some(Path::new("/nonexistent-draco-dir"))).unwrap_err();
        assert!(
            e.contains("Draco not found") && e.contains("/nonexistent-draco-dir"),
            "{e}"
        );
    }

    #[test]
    fn missing_gltfpack_is_a_message() {
        let e = find_gltfpack(Some(Path::new("/nonexistent-gltfpack-dir"))).unwrap_err();
        assert!(
            e.contains("gltfpack not found") && e.contains("/nonexistent-gltfpack-dir"),
            "{e}"
        );
        assert_eq!(Setting::Gltfpack { vp: 12, cc: true }.label(), "vp 12 cc");
        assert_eq!(
            Setting::Gltfpack { vp: 9, cc: false }.file_name(),
            "gltfpack_vp9.glb"
        );
        assert_eq!(
            Setting::Gltfpack { vp: 9, cc: true }.baseline(),
            Some(Baseline::Gltfpack)
        );
        assert!(Setting::Raw { bits: 10 }.baseline().is_none());
    }

    #[test]
    fn timeouts_and_failures_are_errors() {
        let mut sleep = Command::new("sleep");
        sleep.arg("5");
        let e = run_with_timeout(sleep, Duration::from_millis(200))
            .err()
            .unwrap();
        assert!(e.contains("timed out"), "{e}");
        let e = run_with_timeout(Command::new("/nonexistent/program"), Duration::from_secs(1))
            .err()
            .unwrap();
        assert!(e.contains("cannot run"), "{e}");
        let mut sh = Command::new("sh");
        sh.args(["-c", "echo out; echo err >&2; exit 3"]);
        let out = run_with_timeout(sh, Duration::from_secs(10)).unwrap();
        assert!(!out.success);
        assert_eq!(out.stdout.trim(), "out");
        assert_eq!(out.stderr.trim(), "err");
    }
}
