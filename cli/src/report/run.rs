//! The report's main loop: for every model, every setting is encoded, decoded and measured
//! against the input by `metrics`, then scode points are paired with Draco points of no
//! larger error.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use super::brep::BrepReference;
use super::discover::{discover_models, slug, ModelInput};
use super::model::run_model;
use super::steps::{
    draco_ms, find_draco, find_gltfpack, median, run_scode, run_with_timeout, Baseline, DracoTools,
    ScodeJob, Setting, StepRunner,
};
use scode::codec::Limits;
use scode::error::{Error, Result};
use scode::io;
use scode::mesh::ControlMesh;
use scode::metrics::{measure_against_input, RateDistortion};
use scode::pipeline::{decode_surface, Detail, SurfaceOptions};
use serde::{Deserialize, Serialize};

/// The default time budget of one model: the full corpus (37 models) at two models in
/// parallel then fits in about an hour at worst; the tightest tolerances of the largest
/// models are the steps it cuts.
pub const DEFAULT_MODEL_TIMEOUT_SECS: u64 = 180;

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
    /// gltfpack position quantisation bits (`-vp`).
    pub gltfpack_vp: Vec<u8>,
    /// gltfpack runs with (`true`) and/or without `-cc` (meshopt compression).
    pub gltfpack_cc: Vec<bool>,
    /// Where `gltfpack` is; `None`: search `PATH`.
    pub gltfpack_dir: Option<PathBuf>,
    /// Timing repeats per step (median reported).
    pub runs: usize,
    /// Models measured in parallel.
    pub jobs: usize,
    /// Longest one encode may take.
    pub step_timeout: Duration,
    /// Longest all steps of one model may take; later steps are skipped with an error row.
    pub model_timeout: Duration,
    pub runner: StepRunner,
    /// Where each model is written as soon as it is finished: `models/<name>.json` (what
    /// `resume` reads) and its rows appended to `results.csv`, so a run that is stopped
    /// keeps what it measured. `None`: nothing is written during the run.
    pub checkpoint: Option<PathBuf>,
    /// Reuse the models a previous run with the same options wrote to `checkpoint`
    /// instead of measuring them again.
    pub resume: bool,
    /// What errors are measured against; `None`: the B-rep for STEP files, the input for
    /// mesh files.
    pub reference: Option<Reference>,
    /// Chordal tolerances (fractions of the diagonal) of the tessellations of a STEP part
    /// the baselines are given, each quantised at the bits that suit it.
    pub tessellation_chords: Vec<f64>,
}

/// What a report measures decoded surfaces against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reference {
    /// The input mesh (for a STEP file: its tessellation at scode's default chordal
    /// tolerance).
    Input,
    /// The exact B-rep surfaces of a STEP file ([`BrepReference`]).
    Brep,
}

impl ReportOptions {
    /// The full comparison (what `scode report` runs without `--quick`): tolerances 4e-3
    /// down to 5e-5 of the diagonal, raw 10 bit, Draco -qp 6..16 at -cl 10 and 7, gltfpack
    /// -vp 8..16 with -cc, three timing runs.
    pub fn full() -> ReportOptions {
        ReportOptions {
            tolerances: vec![4e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4, 5e-5],
            raw_bits: vec![10],
            draco_qp: (6..=16).collect(),
            draco_cl: vec![10, 7],
            draco_dir: None,
            gltfpack_vp: (8..=16).collect(),
            gltfpack_cc: vec![true],
            gltfpack_dir: None,
            runs: 3,
            jobs: 1,
            step_timeout: Duration::from_secs(600),
            model_timeout: Duration::from_secs(DEFAULT_MODEL_TIMEOUT_SECS),
            runner: StepRunner::InProcess,
            checkpoint: None,
            resume: false,
            reference: None,
            tessellation_chords: vec![2e-3, 1e-3, 5e-4, 2.5e-4, 1e-4, 5e-5, 2.5e-5],
        }
    }

    /// A quick pass (CI, smoke tests): one tolerance, raw 10 bit, Draco -qp 8..14 every
    /// other bit at -cl 10, gltfpack -vp 8..14 every other bit with -cc, one timing run.
    pub fn quick() -> ReportOptions {
        ReportOptions {
            tolerances: vec![2e-3],
            draco_qp: vec![8, 10, 12, 14],
            draco_cl: vec![10],
            gltfpack_vp: vec![8, 10, 12, 14],
            tessellation_chords: vec![1e-3, 2.5e-4],
            runs: 1,
            ..ReportOptions::full()
        }
    }

    /// Every setting in the order they run: raw and the baselines that are installed first
    /// (fast), then fitting from the loosest tolerance (fastest) to the tightest, so a
    /// model's time budget cuts the slowest points.
    pub fn settings(&self, with_draco: bool, with_gltfpack: bool) -> Vec<Setting> {
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
        if with_gltfpack {
            for &cc in &self.gltfpack_cc {
                for &vp in &self.gltfpack_vp {
                    s.push(Setting::Gltfpack { vp, cc });
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
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
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
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointResult {
    pub setting: Setting,
    /// For a baseline on a STEP part: the chordal tolerance (fraction of the diagonal) of
    /// the tessellation it was given.
    #[serde(default)]
    pub tessellation: Option<f64>,
    pub outcome: std::result::Result<Measured, String>,
}

impl PointResult {
    /// The setting's label, with the tessellation's chordal tolerance when there is one.
    pub fn label(&self) -> String {
        match self.tessellation {
            Some(c) => format!("chord {c:.1e} {}", self.setting.label()),
            None => self.setting.label(),
        }
    }

    pub fn measured(&self) -> Option<&Measured> {
        self.outcome.as_ref().ok()
    }
}

/// The smallest point of one baseline at least as accurate as an scode point.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaselineMatch {
    pub baseline: Baseline,
    /// Index into [`ModelReport::points`] of the smallest point of this baseline whose max
    /// and RMS errors are both no larger; `None` when no point of it is that accurate.
    pub point: Option<usize>,
    /// Baseline bytes / scode bytes.
    pub ratio: Option<f64>,
}

/// An scode point and, per baseline, the smallest point that is at least as accurate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EqualError {
    /// Index into [`ModelReport::points`] of the scode point.
    pub scode: usize,
    /// One entry per baseline that has measured points on this model, in
    /// [`Baseline::ALL`] order.
    pub baselines: Vec<BaselineMatch>,
    /// The smallest of the baselines' matches (the best baseline at this error).
    pub best: Option<usize>,
    /// Best baseline bytes / scode bytes (the headline number).
    pub ratio: Option<f64>,
}

impl EqualError {
    /// The match of `baseline`, if it ran on this model.
    pub fn for_baseline(&self, baseline: Baseline) -> Option<&BaselineMatch> {
        self.baselines.iter().find(|b| b.baseline == baseline)
    }
}

/// Everything measured on one model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelReport {
    pub name: String,
    pub path: PathBuf,
    /// Input vertices, triangles (fan-triangulated) and raw binary size; 0 if unreadable.
    pub vertices: usize,
    pub triangles: usize,
    pub raw_bytes: u64,
    /// Why the model was not measured at all (unreadable, unsupported format).
    pub error: Option<String>,
    /// What the errors are measured against (the input mesh, or the B-rep and how).
    #[serde(default)]
    pub reference: String,
    /// With the B-rep as reference: each face and how it is measured (`face_3 (cylinder):
    /// exact surface`).
    #[serde(default)]
    pub faces: Vec<String>,
    pub points: Vec<PointResult>,
    pub equal_error: Vec<EqualError>,
    pub seconds: f64,
}

impl ModelReport {
    /// File-name-safe name for plots.
    pub fn slug(&self) -> String {
        slug(&self.name)
    }

    /// The equal-error ratio (best baseline / scode) of the scode point with this setting,
    /// if measured and matched.
    pub fn ratio_for(&self, setting: &Setting) -> Option<f64> {
        self.equal_error_for(setting).and_then(|e| e.ratio)
    }

    /// The equal-error pairing of the scode point with this setting.
    pub fn equal_error_for(&self, setting: &Setting) -> Option<&EqualError> {
        self.equal_error
            .iter()
            .find(|e| self.points.get(e.scode).map(|p| &p.setting) == Some(setting))
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
    /// The `gltfpack` executable, or why it is missing.
    pub gltfpack: std::result::Result<PathBuf, String>,
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
    /// A finished model could not be written to the checkpoint (the final report still
    /// has it).
    CheckpointFailed {
        message: String,
    },
    /// A model finished; `skipped_steps` steps it will never run (unreadable model, or
    /// one resumed from the checkpoint).
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
    let gltfpack = find_gltfpack(opts.gltfpack_dir.as_deref());
    let settings = opts.settings(tools.is_some(), gltfpack.is_ok());
    let baselines = Baselines {
        draco: tools,
        gltfpack: gltfpack.as_ref().ok().map(PathBuf::as_path),
    };
    progress(Progress::Planned {
        models: models.len(),
        steps_per_model: settings.len(),
    });
    let checkpoint = Checkpoint::open(opts)?;
    let resumed: Vec<Option<ModelReport>> = models
        .iter()
        .map(|m| checkpoint.as_ref().and_then(|c| c.resumed(m)))
        .collect();
    if let Some(c) = &checkpoint {
        c.start(resumed.iter().flatten())?;
    }
    let results: Mutex<Vec<Option<ModelReport>>> = Mutex::new(resumed);
    let next = AtomicUsize::new(0);
    let worker = || loop {
        let i = next.fetch_add(1, Ordering::SeqCst);
        let Some(model) = models.get(i) else { break };
        if results.lock().map(|r| r[i].is_some()).unwrap_or(false) {
            progress(Progress::ModelFinished {
                model: i,
                name: model.name.clone(),
                skipped_steps: settings.len(),
            });
            continue;
        }
        progress(Progress::ModelStarted {
            model: i,
            name: model.name.clone(),
        });
        let dir = work_dir.join(slug(&model.name));
        let report = run_model(i, model, &dir, &settings, &baselines, opts, progress);
        let skipped = settings.len().saturating_sub(report.points.len());
        progress(Progress::ModelFinished {
            model: i,
            name: model.name.clone(),
            skipped_steps: skipped,
        });
        if let Ok(mut r) = results.lock() {
            // Under the lock, so two workers never append to results.csv at once.
            if let Some(c) = &checkpoint {
                if let Err(message) = c.finished(&report) {
                    progress(Progress::CheckpointFailed { message });
                }
            }
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
        gltfpack,
        options: opts.clone(),
        scode_settings,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// The files a run writes as it goes (see [`ReportOptions::checkpoint`]).
struct Checkpoint {
    models_dir: PathBuf,
    csv: PathBuf,
    resume: bool,
}

impl Checkpoint {
    fn open(opts: &ReportOptions) -> Result<Option<Checkpoint>> {
        let Some(dir) = &opts.checkpoint else {
            return Ok(None);
        };
        let models_dir = dir.join("models");
        std::fs::create_dir_all(&models_dir).map_err(|e| Error::io(&models_dir, e))?;
        Ok(Some(Checkpoint {
            models_dir,
            csv: dir.join("results.csv"),
            resume: opts.resume,
        }))
    }

    fn path(&self, name: &str) -> PathBuf {
        self.models_dir.join(format!("{}.json", slug(name)))
    }

    /// The model a previous run finished, when resuming and its file is readable and names
    /// the same input; else `None` (the model is measured again).
    fn resumed(&self, m: &ModelInput) -> Option<ModelReport> {
        if !self.resume {
            return None;
        }
        let text = std::fs::read_to_string(self.path(&m.name)).ok()?;
        let report: ModelReport = serde_json::from_str(&text).ok()?;
        (report.name == m.name && report.path == m.path).then_some(report)
    }

    /// Starts `results.csv` with the header and the rows of the resumed models.
    fn start<'a>(&self, resumed: impl Iterator<Item = &'a ModelReport>) -> Result<()> {
        let mut text = format!("{}\n", super::table::CSV_HEADER);
        for m in resumed {
            text.push_str(&super::table::csv_rows(m));
        }
        std::fs::write(&self.csv, text).map_err(|e| Error::io(&self.csv, e))
    }

    /// Writes a finished model: its JSON (through a temporary file, so a killed run never
    /// leaves half a file for `resume`) and its rows appended to `results.csv`. A failure
    /// here costs the checkpoint, not the run: the final report is still written.
    fn finished(&self, m: &ModelReport) -> std::result::Result<(), String> {
        use std::io::Write;
        let path = self.path(&m.name);
        let tmp = path.with_extension("json.tmp");
        serde_json::to_vec(m)
            .map_err(std::io::Error::other)
            .and_then(|json| std::fs::write(&tmp, json))
            .and_then(|()| std::fs::rename(&tmp, &path))
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        std::fs::OpenOptions::new()
            .append(true)
            .open(&self.csv)
            .and_then(|mut f| f.write_all(super::table::csv_rows(m).as_bytes()))
            .map_err(|e| format!("cannot append to {}: {e}", self.csv.display()))
    }
}

pub(super) fn empty_model(m: &ModelInput) -> ModelReport {
    ModelReport {
        name: m.name.clone(),
        path: m.path.clone(),
        vertices: 0,
        triangles: 0,
        raw_bytes: 0,
        error: None,
        reference: String::new(),
        faces: Vec::new(),
        points: Vec::new(),
        equal_error: Vec::new(),
        seconds: 0.0,
    }
}

/// The baselines' tools that were found.
#[derive(Clone, Copy)]
pub(super) struct Baselines<'a> {
    pub draco: Option<&'a DracoTools>,
    pub gltfpack: Option<&'a Path>,
}

/// What decoded surfaces are measured against.
pub(super) enum Ruler<'a> {
    /// The input mesh itself.
    Input(&'a ControlMesh),
    /// The exact B-rep; `nominal` is the mesh whose vertex count and raw size the rates
    /// are per (the part's default tessellation).
    Brep {
        reference: &'a BrepReference,
        nominal: &'a ControlMesh,
    },
}

impl Ruler<'_> {
    /// Size and distance of a decoded surface of `bytes` bytes.
    pub fn rate(
        &self,
        bytes: u64,
        decoded: &ControlMesh,
    ) -> std::result::Result<RateDistortion, String> {
        let (distance, nominal) = match self {
            Ruler::Input(input) => (measure_against_input(decoded, input), *input),
            Ruler::Brep { reference, nominal } => (reference.measure(decoded), *nominal),
        };
        let distance = distance.map_err(|e| format!("cannot measure: {e}"))?;
        Ok(RateDistortion::new(bytes, nominal, &distance))
    }
}

pub(super) fn run_scode_point(
    model: &ModelInput,
    output: &Path,
    setting: Setting,
    ruler: &Ruler,
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
    let rd = match ruler {
        // As `scode info --against` measures it (group by group, the same figures).
        Ruler::Input(input) => {
            drop(surface);
            let near = scode::pipeline::DEFAULT_RELATIVE_TOLERANCE * input.diagonal();
            let (distance, _) = scode::pipeline::measure_file_against_input(
                &bytes,
                input,
                &Limits::default(),
                &Default::default(),
                near,
            )
            .map_err(|e| format!("cannot measure: {e}"))?;
            RateDistortion::new(bytes.len() as u64, input, &distance)
        }
        Ruler::Brep { .. } => ruler.rate(bytes.len() as u64, &surface.mesh)?,
    };
    Ok(Measured {
        rd,
        encode_ms: median(&encoded.encode_seconds) * 1e3,
        decode_ms: median(&decode_seconds) * 1e3,
        note: encoded.note,
    })
}

#[allow(clippy::too_many_arguments)]
pub(super) fn run_draco(
    tools: &DracoTools,
    draco_input: &Path,
    output: &Path,
    qp: u8,
    cl: u8,
    ruler: &Ruler,
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
    Ok(Measured {
        rd: ruler.rate(bytes, &decoded)?,
        encode_ms: median(&encode_ms),
        decode_ms: median(&decode_ms),
        note: None,
    })
}

/// Runs `gltfpack -vp vp [-cc]` on the input glb and measures its output. The output is
/// decoded by gltfpack itself (`-noq` on the output: meshopt decompression and
/// dequantisation into float positions, no simplification) and read back by scode's glTF
/// reader, so the geometry measured is what a viewer of the file shows; the decode time is
/// that repack's wall time, an upper bound of a viewer's decode.
pub(super) fn run_gltfpack(
    tool: &Path,
    glb_input: &Path,
    output: &Path,
    (vp, cc): (u8, bool),
    ruler: &Ruler,
    runs: usize,
    timeout: Duration,
) -> std::result::Result<Measured, String> {
    let run = |args: &[&std::ffi::OsStr]| -> std::result::Result<f64, String> {
        let mut cmd = std::process::Command::new(tool);
        cmd.args(args);
        let out = run_with_timeout(cmd, timeout)?;
        if !out.success {
            return Err(format!(
                "gltfpack failed ({}): {}",
                out.status,
                super::steps::tail(&(out.stdout + &out.stderr), 3)
            ));
        }
        Ok(out.wall_seconds * 1e3)
    };
    let vp_arg = vp.to_string();
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "-i".as_ref(),
        glb_input.as_os_str(),
        "-o".as_ref(),
        output.as_os_str(),
        "-vp".as_ref(),
        vp_arg.as_ref(),
    ];
    if cc {
        args.push("-cc".as_ref());
    }
    let encode_ms = (0..runs.max(1))
        .map(|_| run(&args))
        .collect::<std::result::Result<Vec<f64>, String>>()?;
    let bytes = std::fs::metadata(output)
        .map_err(|e| format!("cannot read {}: {e}", output.display()))?
        .len();
    let decoded_path = output.with_extension("decoded.glb");
    let decode_args: Vec<&std::ffi::OsStr> = vec![
        "-i".as_ref(),
        output.as_os_str(),
        "-o".as_ref(),
        decoded_path.as_os_str(),
        "-noq".as_ref(),
    ];
    let decode_ms = (0..runs.max(1))
        .map(|_| run(&decode_args))
        .collect::<std::result::Result<Vec<f64>, String>>()?;
    let (decoded, _) =
        io::read_mesh(&decoded_path).map_err(|e| format!("cannot read gltfpack output: {e}"))?;
    Ok(Measured {
        rd: ruler.rate(bytes, &decoded)?,
        encode_ms: median(&encode_ms),
        decode_ms: median(&decode_ms),
        note: None,
    })
}

/// The input as gltfpack reads it: a glb of one triangle primitive, float32 positions and
/// u32 indices, nothing else (scode's own glb writer adds a feature-id attribute, face
/// metadata and a LINES primitive of the sharp edges, which gltfpack would keep and pay for;
/// a mesh delivered through gltfpack has none of them).
pub(super) fn write_gltfpack_input(path: &Path, mesh: &ControlMesh) -> Result<()> {
    let tris = triangles(mesh);
    let (lo, hi) = mesh.bounding_box().unwrap_or_default();
    let mut bin = Vec::with_capacity(12 * mesh.vertex_count() + 12 * tris.len());
    for p in &mesh.positions {
        for c in p.to_array() {
            bin.extend_from_slice(&(c as f32).to_le_bytes());
        }
    }
    let positions_len = bin.len();
    for t in &tris {
        for &v in t {
            bin.extend_from_slice(&v.to_le_bytes());
        }
    }
    let as_f32 = |v: glam::DVec3| v.to_array().map(|c| c as f32);
    let doc = serde_json::json!({
        "asset": { "version": "2.0", "generator": "scode report" },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": 0 }, "indices": 1, "mode": 4 }] }],
        "buffers": [{ "byteLength": bin.len() }],
        "bufferViews": [
            { "buffer": 0, "byteOffset": 0, "byteLength": positions_len, "target": 34962 },
            { "buffer": 0, "byteOffset": positions_len, "byteLength": bin.len() - positions_len, "target": 34963 }
        ],
        "accessors": [
            { "bufferView": 0, "componentType": 5126, "count": mesh.vertex_count(), "type": "VEC3",
              "min": as_f32(lo), "max": as_f32(hi) },
            { "bufferView": 1, "componentType": 5125, "count": 3 * tris.len(), "type": "SCALAR" }
        ]
    });
    let mut json =
        serde_json::to_vec(&doc).map_err(|e| Error::io(path, std::io::Error::other(e)))?;
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let mut out = Vec::with_capacity(28 + json.len() + bin.len());
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let total = u32::try_from(total).map_err(|_| {
        Error::io(
            path,
            std::io::Error::other("mesh too large for a .glb file"),
        )
    })?;
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total.to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    std::fs::write(path, out).map_err(|e| Error::io(path, e))
}

/// The mesh's faces as triangles (polygons fan triangulated).
fn triangles(mesh: &ControlMesh) -> Vec<[u32; 3]> {
    mesh.faces()
        .flat_map(|f| (1..f.len().saturating_sub(1)).map(move |i| [f[0], f[i], f[i + 1]]))
        .collect()
}

/// The input as Draco reads it: binary PLY, float32 positions, triangles only (polygons fan
/// triangulated), no groups (Draco has none).
pub(super) fn write_draco_input(path: &Path, mesh: &ControlMesh) -> Result<()> {
    use std::io::Write;
    let tris = triangles(mesh);
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

/// For every measured scode point and every baseline, the smallest measured point of that
/// baseline whose max and RMS errors are both no larger (up to [`EQUAL_ERROR_SLACK`]; ties
/// on size: the more accurate one), the size ratio, and the best of the baselines.
pub fn equal_error(points: &[PointResult]) -> Vec<EqualError> {
    let measured = |keep: &dyn Fn(&Setting) -> bool| -> Vec<(usize, &Measured)> {
        points
            .iter()
            .enumerate()
            .filter(|(_, p)| keep(&p.setting))
            .filter_map(|(i, p)| p.measured().map(|m| (i, m)))
            .collect()
    };
    let baselines: Vec<(Baseline, Vec<(usize, &Measured)>)> = Baseline::ALL
        .iter()
        .map(|&b| (b, measured(&|s: &Setting| s.baseline() == Some(b))))
        .filter(|(_, pts)| !pts.is_empty())
        .collect();
    measured(&Setting::is_scode)
        .into_iter()
        .map(|(i, s)| {
            let as_accurate = |(_, d): &&(usize, &Measured)| {
                d.rd.max_error <= s.rd.max_error * (1.0 + EQUAL_ERROR_SLACK)
                    && d.rd.rms_error <= s.rd.rms_error * (1.0 + EQUAL_ERROR_SLACK)
            };
            let smallest = |a: &&(usize, &Measured), b: &&(usize, &Measured)| {
                a.1.rd
                    .bytes
                    .cmp(&b.1.rd.bytes)
                    .then(a.1.rd.max_error.total_cmp(&b.1.rd.max_error))
            };
            let ratio = |d: &Measured| d.rd.bytes as f64 / s.rd.bytes.max(1) as f64;
            let matches: Vec<(BaselineMatch, Option<(usize, &Measured)>)> = baselines
                .iter()
                .map(|(b, pts)| {
                    let best = pts.iter().filter(as_accurate).min_by(smallest).copied();
                    (
                        BaselineMatch {
                            baseline: *b,
                            point: best.map(|(j, _)| j),
                            ratio: best.map(|(_, d)| ratio(d)),
                        },
                        best,
                    )
                })
                .collect();
            let best = matches
                .iter()
                .filter_map(|(_, b)| b.as_ref())
                .min_by(smallest)
                .copied();
            EqualError {
                scode: i,
                baselines: matches.into_iter().map(|(m, _)| m).collect(),
                best: best.map(|(j, _)| j),
                ratio: best.map(|(_, d)| ratio(d)),
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
            tessellation: None,
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
                tessellation: None,
                outcome: Err("failed".into()),
            },
            point(Setting::Fitted { tolerance: 1e-5 }, 900, 1e-6, 1e-7), // nothing that good
        ];
        let eq = equal_error(&points);
        assert_eq!(eq.len(), 3);
        assert_eq!((eq[0].scode, eq[0].best), (0, Some(3)));
        assert!((eq[0].ratio.unwrap() - 6.0).abs() < 1e-12);
        assert_eq!((eq[1].scode, eq[1].best), (1, Some(5)));
        assert!((eq[1].ratio.unwrap() - 1.75).abs() < 1e-12);
        assert_eq!((eq[2].scode, eq[2].best, eq[2].ratio), (9, None, None));
        // Only Draco ran: one baseline entry, the same as the best.
        assert_eq!(eq[0].baselines.len(), 1);
        assert_eq!(eq[0].for_baseline(Baseline::Draco).unwrap().point, Some(3));
        assert!(eq[0].for_baseline(Baseline::Gltfpack).is_none());
    }

    #[test]
    fn equal_error_per_baseline_and_best_of_them() {
        let d = |qp| Setting::Draco { qp, cl: 10 };
        let g = |vp| Setting::Gltfpack { vp, cc: true };
        let points = vec![
            point(Setting::Fitted { tolerance: 1e-3 }, 500, 1e-3, 2e-4),
            point(d(10), 3000, 9e-4, 1e-4),
            point(d(12), 8000, 2e-4, 5e-5),
            point(g(12), 2000, 8e-4, 1e-4), // smaller than Draco's match: the best
            point(g(10), 1000, 3e-3, 1e-3), // too coarse
            point(Setting::Fitted { tolerance: 1e-4 }, 900, 1.5e-4, 4e-5),
        ];
        let eq = equal_error(&points);
        assert_eq!(eq.len(), 2);
        let draco = eq[0].for_baseline(Baseline::Draco).unwrap();
        let gltf = eq[0].for_baseline(Baseline::Gltfpack).unwrap();
        assert_eq!((draco.point, gltf.point), (Some(1), Some(3)));
        assert!((draco.ratio.unwrap() - 6.0).abs() < 1e-12);
        assert!((gltf.ratio.unwrap() - 4.0).abs() < 1e-12);
        assert_eq!(eq[0].best, Some(3));
        assert!((eq[0].ratio.unwrap() - 4.0).abs() < 1e-12);
        // Nothing of either baseline is as accurate as the second scode point.
        assert_eq!(eq[1].baselines.len(), 2);
        assert!(eq[1].baselines.iter().all(|b| b.point.is_none()));
        assert_eq!((eq[1].best, eq[1].ratio), (None, None));
    }

    #[test]
    fn gltfpack_input_reads_back_as_the_mesh() {
        let mut mesh = ControlMesh::new();
        mesh.positions = vec![
            glam::DVec3::new(0.0, 0.0, 0.0),
            glam::DVec3::new(1.5, 0.0, 0.0),
            glam::DVec3::new(1.5, 2.0, 0.0),
            glam::DVec3::new(0.0, 2.0, 0.25),
        ];
        mesh.face_vertices = vec![0, 1, 2, 3];
        mesh.face_offsets = vec![0, 4];
        mesh.face_groups = vec![0];
        mesh.groups = vec![scode::mesh::Group::default()];
        let dir = std::env::temp_dir().join(format!("scode-gltfpack-in-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("input.glb");
        write_gltfpack_input(&path, &mesh).unwrap();
        let (back, _) = io::read_mesh(&path).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(back.positions, mesh.positions);
        let tris: Vec<&[u32]> = back.faces().collect();
        assert_eq!(tris, [&[0, 1, 2][..], &[0, 2, 3][..]]);
    }

    #[test]
    fn settings_order_and_baseline_toggles() {
        let o = ReportOptions::full();
        let with = o.settings(true, true);
        assert_eq!(with.len(), 1 + 22 + 9 + 7);
        assert_eq!(with[0], Setting::Raw { bits: 10 });
        assert_eq!(with[1], Setting::Draco { qp: 6, cl: 10 });
        assert_eq!(with[23], Setting::Gltfpack { vp: 8, cc: true });
        assert_eq!(with.last(), Some(&Setting::Fitted { tolerance: 5e-5 }));
        assert_eq!(with[32], Setting::Fitted { tolerance: 4e-3 });
        let no_draco = o.settings(false, true);
        assert_eq!(no_draco.len(), 1 + 9 + 7);
        assert!(no_draco
            .iter()
            .all(|s| s.baseline() != Some(Baseline::Draco)));
        let without = o.settings(false, false);
        assert_eq!(without.len(), 8);
        assert!(without.iter().all(Setting::is_scode));
    }
}
