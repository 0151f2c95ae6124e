//! The report's main loop: for every model, every setting is encoded, decoded and measured
//! against the input by `metrics`, then scode points are paired with Draco points of no
//! larger error.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use super::discover::{discover_models, slug, ModelInput, ModelSource};
use super::steps::{
    draco_ms, find_draco, median, run_scode, run_with_timeout, DracoTools, ScodeJob, Setting,
    StepRunner,
};
use crate::codec::Limits;
use crate::error::{Error, Result};
use crate::io;
use crate::mesh::ControlMesh;
use crate::metrics::{measure_against_input, raw_binary_bytes, RateDistortion};
use crate::pipeline::{decode_surface, Detail, SurfaceOptions};

/// What to run.
#[derive(Clone, Debug, PartialEq)]
pub struct ReportOptions {
    /// Fitting tolerances, fractions of the bounding-box diagonal.
    pub tolerances: Vec<f64>,
    /// Quantisation bits of the raw-mode point(s).
    pub raw_bits: Vec<u8>,
    /// Draco position quantisation bits (`-qp`).
    pub draco_qp: Vec<u8>,
    /// Draco compression levels (`-cl`).
    pub draco_cl: Vec<u8>,
    /// Where `draco_encoder`/`draco_decoder` are; `None`: search `PATH`.
    pub draco_dir: Option<PathBuf>,
    /// Timing repeats per step (median reported).
    pub runs: usize,
    /// Models measured in parallel.
    pub jobs: usize,
    /// Longest one encode may take.
    pub step_timeout: Duration,
    /// Longest all steps of one model may take; later steps are skipped with an error row.
    pub model_timeout: Duration,
    pub runner: StepRunner,
}

impl ReportOptions {
    /// The full comparison (what `scode report` runs without `--quick`): four tolerances,
    /// raw 10 bit, Draco -qp 6..14 at -cl 10 and 7, three timing runs.
    pub fn full() -> ReportOptions {
        ReportOptions {
            tolerances: vec![4e-3, 2e-3, 1e-3, 5e-4],
            raw_bits: vec![10],
            draco_qp: (6..=14).collect(),
            draco_cl: vec![10, 7],
            draco_dir: None,
            runs: 3,
            jobs: 1,
            step_timeout: Duration::from_secs(600),
            model_timeout: Duration::from_secs(1800),
            runner: StepRunner::InProcess,
        }
    }

    /// A quick pass (CI, smoke tests): one tolerance, raw 10 bit, Draco -qp 7..14 every
    /// other bit at -cl 10, one timing run.
    pub fn quick() -> ReportOptions {
        ReportOptions {
            tolerances: vec![2e-3],
            draco_qp: vec![8, 10, 12, 14],
            draco_cl: vec![10],
            runs: 1,
            ..ReportOptions::full()
        }
    }

    /// Every setting in the order they run: raw and Draco first (fast), then fitting from
    /// the loosest tolerance (fastest) to the tightest, so a model's time budget cuts the
    /// slowest points.
    pub fn settings(&self, with_draco: bool) -> Vec<Setting> {
        let mut s: Vec<Setting> = self
            .raw_bits
            .iter()
            .map(|&bits| Setting::Raw { bits })
            .collect();
        if with_draco {
            for &cl in &self.draco_cl {
                for &qp in &self.draco_qp {
                    s.push(Setting::Draco { qp, cl });
                }
            }
        }
        let mut tol = self.tolerances.clone();
        tol.sort_by(|a, b| b.total_cmp(a));
        tol.dedup();
        s.extend(
            tol.into_iter()
                .map(|tolerance| Setting::Fitted { tolerance }),
        );
        s
    }
}

/// A measured point.
#[derive(Clone, Debug, PartialEq)]
pub struct Measured {
    pub rd: RateDistortion,
    /// Median encode wall time, milliseconds (Draco: the tool's own timing).
    pub encode_ms: f64,
    /// Median decode wall time, milliseconds (scode: decode + subdivision to the default
    /// level + limit projection; Draco: the tool's own timing).
    pub decode_ms: f64,
    pub note: Option<String>,
}

/// One setting run on one model: measured, or why not.
#[derive(Clone, Debug, PartialEq)]
pub struct PointResult {
    pub setting: Setting,
    pub outcome: std::result::Result<Measured, String>,
}

impl PointResult {
    pub fn measured(&self) -> Option<&Measured> {
        self.outcome.as_ref().ok()
    }
}

/// An scode point and the smallest Draco point that is at least as accurate.
#[derive(Clone, Debug, PartialEq)]
pub struct EqualError {
    /// Index into [`ModelReport::points`] of the scode point.
    pub scode: usize,
    /// Index of the smallest Draco point whose max and RMS errors are both no larger.
    pub draco: Option<usize>,
    /// Draco bytes / scode bytes (the headline number).
    pub ratio: Option<f64>,
}

/// Everything measured on one model.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelReport {
    pub name: String,
    pub path: PathBuf,
    /// Input vertices, triangles (fan-triangulated) and raw binary size; 0 if unreadable.
    pub vertices: usize,
    pub triangles: usize,
    pub raw_bytes: u64,
    /// Why the model was not measured at all (unreadable, unsupported format).
    pub error: Option<String>,
    pub points: Vec<PointResult>,
    pub equal_error: Vec<EqualError>,
    pub seconds: f64,
}

impl ModelReport {
    /// File-name-safe name for plots.
    pub fn slug(&self) -> String {
        slug(&self.name)
    }

    /// The equal-error ratio of the scode point with this setting, if measured and matched.
    pub fn ratio_for(&self, setting: &Setting) -> Option<f64> {
        self.equal_error
            .iter()
            .find(|e| &self.points[e.scode].setting == setting)
            .and_then(|e| e.ratio)
    }
}

/// Whether Draco took part.
#[derive(Clone, Debug, PartialEq)]
pub enum DracoStatus {
    Found(DracoTools),
    Missing(String),
}

/// The whole report.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    pub models: Vec<ModelReport>,
    pub draco: DracoStatus,
    pub options: ReportOptions,
    /// The scode settings compared (the columns of the summary).
    pub scode_settings: Vec<Setting>,
    pub seconds: f64,
}

/// Progress notifications (the CLI turns them into progress bars).
#[derive(Clone, Debug, PartialEq)]
pub enum Progress {
    /// Discovery done: this many models with this many steps each (at most).
    Planned {
        models: usize,
        steps_per_model: usize,
    },
    ModelStarted {
        model: usize,
        name: String,
    },
    StepFinished {
        model: usize,
        name: String,
        step: String,
        ok: bool,
    },
    /// A model finished; `skipped_steps` steps it will never run (unreadable model).
    ModelFinished {
        model: usize,
        name: String,
        skipped_steps: usize,
    },
}

/// Runs the report on `inputs` (files and directories), writing encoded files under
/// `work_dir/<model>/`. Fails only when the inputs cannot be listed; every per-model
/// failure becomes an error row.
pub fn run_report(
    inputs: &[PathBuf],
    work_dir: &Path,
    opts: &ReportOptions,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Report> {
    let t0 = Instant::now();
    let models = discover_models(inputs)?;
    if models.is_empty() {
        let first = inputs.first().cloned().unwrap_or_default();
        return Err(Error::input(first, "no model files found"));
    }
    let draco = match find_draco(opts.draco_dir.as_deref()) {
        Ok(t) => DracoStatus::Found(t),
        Err(msg) => DracoStatus::Missing(msg),
    };
    let tools = match &draco {
        DracoStatus::Found(t) => Some(t),
        DracoStatus::Missing(_) => None,
    };
    let settings = opts.settings(tools.is_some());
    progress(Progress::Planned {
        models: models.len(),
        steps_per_model: settings.len(),
    });
    let results: Mutex<Vec<Option<ModelReport>>> = Mutex::new(vec![None; models.len()]);
    let next = AtomicUsize::new(0);
    let worker = || loop {
        let i = next.fetch_add(1, Ordering::SeqCst);
        let Some(model) = models.get(i) else { break };
        progress(Progress::ModelStarted {
            model: i,
            name: model.name.clone(),
        });
        let dir = work_dir.join(slug(&model.name));
        let report = run_model(i, model, &dir, &settings, tools, opts, progress);
        let skipped = settings.len().saturating_sub(report.points.len());
        progress(Progress::ModelFinished {
            model: i,
            name: model.name.clone(),
            skipped_steps: skipped,
        });
        if let Ok(mut r) = results.lock() {
            r[i] = Some(report);
        }
    };
    std::thread::scope(|s| {
        for _ in 0..opts.jobs.clamp(1, models.len()) {
            s.spawn(worker);
        }
    });
    let models: Vec<ModelReport> = results
        .into_inner()
        .map_err(|_| Error::Parameter("a report worker panicked".into()))?
        .into_iter()
        .zip(&models)
        .map(|(r, m)| {
            r.unwrap_or_else(|| ModelReport {
                name: m.name.clone(),
                path: m.path.clone(),
                error: Some("not run (worker stopped)".into()),
                ..empty_model(m)
            })
        })
        .collect();
    let scode_settings = settings.iter().filter(|s| s.is_scode()).copied().collect();
    Ok(Report {
        models,
        draco,
        options: opts.clone(),
        scode_settings,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

fn empty_model(m: &ModelInput) -> ModelReport {
    ModelReport {
        name: m.name.clone(),
        path: m.path.clone(),
        vertices: 0,
        triangles: 0,
        raw_bytes: 0,
        error: None,
        points: Vec::new(),
        equal_error: Vec::new(),
        seconds: 0.0,
    }
}

/// Runs every setting on one model. Never panics out: a panic while reading or measuring
/// becomes the model's error.
fn run_model(
    index: usize,
    model: &ModelInput,
    dir: &Path,
    settings: &[Setting],
    draco: Option<&DracoTools>,
    opts: &ReportOptions,
    progress: &(dyn Fn(Progress) + Sync),
) -> ModelReport {
    let t0 = Instant::now();
    let mut report = empty_model(model);
    if let ModelSource::Unsupported(reason) = &model.source {
        report.error = Some(reason.clone());
        return report;
    }
    let read = std::panic::catch_unwind(|| io::read_mesh(&model.path));
    let input = match read {
        Ok(Ok((mesh, _))) => mesh,
        Ok(Err(e)) => {
            report.error = Some(format!("cannot read: {e}"));
            return report;
        }
        Err(_) => {
            report.error = Some("reader panicked".into());
            return report;
        }
    };
    report.vertices = input.vertex_count();
    report.triangles = input
        .faces()
        .map(|f| f.len().saturating_sub(2))
        .sum::<usize>();
    report.raw_bytes = raw_binary_bytes(&input);
    if let Err(e) = std::fs::create_dir_all(dir) {
        report.error = Some(format!("cannot create {}: {e}", dir.display()));
        return report;
    }
    let draco_input = dir.join("input_f32.ply");
    let draco_input_ok = match draco {
        Some(_) => write_draco_input(&draco_input, &input).map_err(|e| e.to_string()),
        None => Ok(()),
    };
    for setting in settings {
        let elapsed = t0.elapsed();
        let outcome = if elapsed >= opts.model_timeout {
            Err(format!(
                "skipped: the model's time budget ({} s) is used up",
                opts.model_timeout.as_secs()
            ))
        } else {
            let timeout = opts.step_timeout.min(opts.model_timeout - elapsed);
            let output = dir.join(setting.file_name());
            let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match setting {
                Setting::Draco { qp, cl } => match (&draco_input_ok, draco) {
                    (Ok(()), Some(tools)) => run_draco(
                        tools,
                        &draco_input,
                        &output,
                        *qp,
                        *cl,
                        &input,
                        opts.runs,
                        timeout,
                    ),
                    (Err(e), _) => Err(format!("cannot write Draco input: {e}")),
                    (_, None) => Err("Draco not found".into()),
                },
                _ => run_scode_point(model, &output, *setting, &input, opts, timeout),
            }));
            run.unwrap_or_else(|_| Err("measurement panicked".into()))
        };
        progress(Progress::StepFinished {
            model: index,
            name: model.name.clone(),
            step: setting.label(),
            ok: outcome.is_ok(),
        });
        report.points.push(PointResult {
            setting: *setting,
            outcome,
        });
    }
    report.equal_error = equal_error(&report.points);
    report.seconds = t0.elapsed().as_secs_f64();
    report
}

fn run_scode_point(
    model: &ModelInput,
    output: &Path,
    setting: Setting,
    input: &ControlMesh,
    opts: &ReportOptions,
    timeout: Duration,
) -> std::result::Result<Measured, String> {
    let job = ScodeJob {
        input: model.path.clone(),
        output: output.to_path_buf(),
        setting,
        runs: opts.runs,
    };
    let encoded = run_scode(&opts.runner, &job, timeout)?;
    let bytes =
        std::fs::read(output).map_err(|e| format!("cannot read {}: {e}", output.display()))?;
    if bytes.len() as u64 != encoded.bytes {
        return Err(format!(
            "{} holds {} bytes, the encoder reported {}",
            output.display(),
            bytes.len(),
            encoded.bytes
        ));
    }
    let mut decode_seconds = Vec::new();
    let mut surface = None;
    for _ in 0..opts.runs.max(1) {
        let t = Instant::now();
        let s = decode_surface(
            &bytes,
            &Limits::default(),
            &SurfaceOptions {
                detail: Detail::DefaultLevel,
                ..Default::default()
            },
        )
        .map_err(|e| format!("cannot decode: {e}"))?;
        decode_seconds.push(t.elapsed().as_secs_f64());
        surface = Some(s);
    }
    let surface = surface.ok_or("no decode run")?;
    let distance =
        measure_against_input(&surface.mesh, input).map_err(|e| format!("cannot measure: {e}"))?;
    Ok(Measured {
        rd: RateDistortion::new(bytes.len() as u64, input, &distance),
        encode_ms: median(&encoded.encode_seconds) * 1e3,
        decode_ms: median(&decode_seconds) * 1e3,
        note: encoded.note,
    })
}

#[allow(clippy::too_many_arguments)]
fn run_draco(
    tools: &DracoTools,
    draco_input: &Path,
    output: &Path,
    qp: u8,
    cl: u8,
    input: &ControlMesh,
    runs: usize,
    timeout: Duration,
) -> std::result::Result<Measured, String> {
    let mut encode_ms = Vec::new();
    for _ in 0..runs.max(1) {
        let mut cmd = std::process::Command::new(&tools.encoder);
        cmd.arg("-i").arg(draco_input).arg("-o").arg(output).args([
            "-qp",
            &qp.to_string(),
            "-cl",
            &cl.to_string(),
        ]);
        let out = run_with_timeout(cmd, timeout)?;
        if !out.success {
            return Err(format!(
                "draco_encoder failed ({}): {}",
                out.status,
                super::steps::tail(&(out.stdout + &out.stderr), 3)
            ));
        }
        encode_ms.push(draco_ms(&out.stdout, "encode").unwrap_or(out.wall_seconds * 1e3));
    }
    let bytes = std::fs::metadata(output)
        .map_err(|e| format!("cannot read {}: {e}", output.display()))?
        .len();
    let decoded_path = output.with_extension("decoded.ply");
    let mut decode_ms = Vec::new();
    for _ in 0..runs.max(1) {
        let mut cmd = std::process::Command::new(&tools.decoder);
        cmd.arg("-i").arg(output).arg("-o").arg(&decoded_path);
        let out = run_with_timeout(cmd, timeout)?;
        if !out.success {
            return Err(format!(
                "draco_decoder failed ({}): {}",
                out.status,
                super::steps::tail(&(out.stdout + &out.stderr), 3)
            ));
        }
        decode_ms.push(draco_ms(&out.stdout, "decode").unwrap_or(out.wall_seconds * 1e3));
    }
    let (decoded, _) =
        io::read_mesh(&decoded_path).map_err(|e| format!("cannot read Draco output: {e}"))?;
    let distance =
        measure_against_input(&decoded, input).map_err(|e| format!("cannot measure: {e}"))?;
    Ok(Measured {
        rd: RateDistortion::new(bytes, input, &distance),
        encode_ms: median(&encode_ms),
        decode_ms: median(&decode_ms),
        note: None,
    })
}

/// The input as Draco reads it: binary PLY, float32 positions, triangles only (polygons fan
/// triangulated), no groups (Draco has none).
fn write_draco_input(path: &Path, mesh: &ControlMesh) -> Result<()> {
    use std::io::Write;
    let tris: Vec<[u32; 3]> = mesh
        .faces()
        .flat_map(|f| (1..f.len().saturating_sub(1)).map(move |i| [f[0], f[i], f[i + 1]]))
        .collect();
    let mut buf = Vec::new();
    let header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\n\
         property float y\nproperty float z\nelement face {}\n\
         property list uchar int vertex_indices\nend_header\n",
        mesh.vertex_count(),
        tris.len()
    );
    buf.extend_from_slice(header.as_bytes());
    for p in &mesh.positions {
        for c in p.to_array() {
            buf.extend_from_slice(&(c as f32).to_le_bytes());
        }
    }
    for t in &tris {
        buf.push(3);
        for &v in t {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }
    let mut f = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    f.write_all(&buf).map_err(|e| Error::io(path, e))
}

/// Relative slack of "no larger" in the equal-error pairing: two files on the same
/// quantisation grid measure equal up to ~1e-5 relative (float32 vs f64 input, sampling), and
/// such a tie must count as equal error. Far below any real difference between settings.
pub const EQUAL_ERROR_SLACK: f64 = 1e-3;

/// For every measured scode point, the smallest measured Draco point whose max and RMS
/// errors are both no larger (up to [`EQUAL_ERROR_SLACK`]; ties on size: the more accurate
/// one), and the size ratio.
pub fn equal_error(points: &[PointResult]) -> Vec<EqualError> {
    let draco: Vec<(usize, &Measured)> = points
        .iter()
        .enumerate()
        .filter(|(_, p)| !p.setting.is_scode())
        .filter_map(|(i, p)| p.measured().map(|m| (i, m)))
        .collect();
    points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.setting.is_scode())
        .filter_map(|(i, p)| p.measured().map(|m| (i, m)))
        .map(|(i, s)| {
            let best = draco
                .iter()
                .filter(|(_, d)| {
                    d.rd.max_error <= s.rd.max_error * (1.0 + EQUAL_ERROR_SLACK)
                        && d.rd.rms_error <= s.rd.rms_error * (1.0 + EQUAL_ERROR_SLACK)
                })
                .min_by(|(_, a), (_, b)| {
                    a.rd.bytes
                        .cmp(&b.rd.bytes)
                        .then(a.rd.max_error.total_cmp(&b.rd.max_error))
                });
            EqualError {
                scode: i,
                draco: best.map(|(j, _)| *j),
                ratio: best.map(|(_, d)| d.rd.bytes as f64 / s.rd.bytes.max(1) as f64),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(setting: Setting, bytes: u64, max: f64, rms: f64) -> PointResult {
        PointResult {
            setting,
            outcome: Ok(Measured {
                rd: RateDistortion {
                    bytes,
                    max_error: max,
                    rms_error: rms,
                    ..Default::default()
                },
                encode_ms: 1.0,
                decode_ms: 1.0,
                note: None,
            }),
        }
    }

    #[test]
    fn equal_error_picks_smallest_draco_at_least_as_accurate() {
        let d = |qp| Setting::Draco { qp, cl: 10 };
        let points = vec![
            point(Setting::Fitted { tolerance: 1e-3 }, 500, 1e-3, 2e-4),
            point(Setting::Raw { bits: 10 }, 4000, 5e-4, 1e-4),
            point(d(8), 1000, 2e-3, 5e-4),  // too coarse for both
            point(d(10), 3000, 9e-4, 1e-4), // fits the fitted point
            point(d(11), 5000, 4e-4, 3e-4), // max ok for raw, rms too large
            point(d(13), 7000, 5.0001e-4, 1.00001e-4), // raw's error within the slack: a tie
            point(d(9), 6000, 5.01e-4, 1e-4), // 0.2 % above raw's max: not a tie
            point(d(12), 8000, 2e-4, 5e-5), // fits both
            PointResult {
                setting: d(14),
                outcome: Err("failed".into()),
            },
            point(Setting::Fitted { tolerance: 1e-5 }, 900, 1e-6, 1e-7), // nothing that good
        ];
        let eq = equal_error(&points);
        assert_eq!(eq.len(), 3);
        assert_eq!((eq[0].scode, eq[0].draco), (0, Some(3)));
        assert!((eq[0].ratio.unwrap() - 6.0).abs() < 1e-12);
        assert_eq!((eq[1].scode, eq[1].draco), (1, Some(5)));
        assert!((eq[1].ratio.unwrap() - 1.75).abs() < 1e-12);
        assert_eq!((eq[2].scode, eq[2].draco, eq[2].ratio), (9, None, None));
    }

    #[test]
    fn settings_order_and_draco_toggle() {
        let o = ReportOptions::full();
        let with = o.settings(true);
        assert_eq!(with.len(), 1 + 18 + 4);
        assert_eq!(with[0], Setting::Raw { bits: 10 });
        assert_eq!(with[1], Setting::Draco { qp: 6, cl: 10 });
        assert_eq!(with.last(), Some(&Setting::Fitted { tolerance: 5e-4 }));
        assert_eq!(with[19], Setting::Fitted { tolerance: 4e-3 });
        let without = o.settings(false);
        assert_eq!(without.len(), 5);
        assert!(without.iter().all(Setting::is_scode));
    }
}
