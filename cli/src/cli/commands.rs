//! One function per subcommand: read inputs, call the library, print what happened.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use scode::codec::{self, Content, EncodeOptions, Limits};
use scode::io::{self, ReadReport};
use scode::mesh::{BoundarySurface, PatchKind};
use scode::subdiv::{self, SubdivOptions};
use scode::{ControlMesh, Tolerance};

use super::exit::CliError;
use super::{DecodeArgs, EncodeArgs, InfoArgs, ReportArgs, SegmentArgs, SubdivideArgs, Writes};
use scode::fit::encoder::{FitReport, Reference, SurfaceHint};
use scode::io::step;
use scode::pipeline::{
    decode_surface, encode_fitted, encode_step, sidecar_hints, Detail, ModelEncodeOptions,
    SurfaceOptions,
};

/// Reads a `.scode` file for decoding with `limits`: its size (from the file's metadata) is
/// checked against `max_input_bytes` before anything is read, and at most one byte more is
/// read, so a file that grows meanwhile is refused too.
fn read_scode(path: &Path, limits: &Limits) -> Result<Vec<u8>> {
    use std::io::Read;
    let max = limits.max_input_bytes;
    let too_big = |value| scode::Error::LimitsExceeded {
        what: "input bytes",
        value,
        limit: max,
    };
    let file = std::fs::File::open(path).map_err(|e| scode::Error::io(path, e))?;
    let size = file
        .metadata()
        .map_err(|e| scode::Error::io(path, e))?
        .len();
    if size > max {
        return Err(too_big(size)).with_context(|| format!("cannot read {}", path.display()));
    }
    let mut bytes = Vec::with_capacity(size as usize);
    file.take(max.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| scode::Error::io(path, e))?;
    if bytes.len() as u64 > max {
        return Err(too_big(bytes.len() as u64))
            .with_context(|| format!("cannot read {}", path.display()));
    }
    Ok(bytes)
}

/// Set when `encode --max-seconds` or `--max-memory` gives up on the encode; its output is then never written.
/// [`write_file`] holds the lock while it writes, so a file is written whole or not at all
/// and the one that gives up knows which.
static GAVE_UP: std::sync::Mutex<bool> = std::sync::Mutex::new(false);

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    let gave_up = GAVE_UP.lock().unwrap_or_else(|e| e.into_inner());
    if *gave_up {
        return Err(
            CliError::BudgetExceeded("over the encode's budget: nothing written".into()).into(),
        );
    }
    std::fs::write(path, bytes).map_err(|e| scode::Error::io(path, e).into())
}

/// `encode` with a whole-encode budget of time (`--max-seconds`) and resident memory
/// (`--max-memory`): the encode runs in its own thread while this one watches the clock and
/// the process's resident set; past either budget the output is barred (see [`GAVE_UP`])
/// and the error returned, and `main` returning ends the process, which stops every thread
/// of the encode (the fitting's and the STEP reader's alike) wherever it is, with no
/// cooperation needed.
pub fn encode_within(args: EncodeArgs, seconds: Option<f64>, memory: Option<u64>) -> Result<()> {
    use std::sync::mpsc::RecvTimeoutError;
    use std::time::{Duration, Instant};
    if memory.is_some() && resident_bytes().is_none() {
        return Err(CliError::Usage(
            "--max-memory needs the process's resident memory, which this system does not \
             report (/proc/self/status)"
                .into(),
        )
        .into());
    }
    let input = args.input.clone();
    let output = args
        .output
        .path()
        .map_or_else(|_| "the output".to_string(), |p| p.display().to_string());
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name("scode-encode".into())
        .spawn(move || {
            let _ = tx.send(encode(&args));
        })
        .context("cannot start the encode thread")?;
    let start = Instant::now();
    let deadline = seconds.map(|s| start + Duration::from_secs_f64(s));
    // Often enough that a budget is passed by what a few milliseconds allocate, rarely
    // enough that the readings cost nothing next to the encode.
    let poll = Duration::from_millis(5);
    let over = loop {
        let wait = match deadline {
            Some(d) => d.saturating_duration_since(Instant::now()).min(poll),
            None => poll,
        };
        match rx.recv_timeout(wait) {
            Ok(result) => return result,
            Err(RecvTimeoutError::Disconnected) => {
                return Err(anyhow::anyhow!(
                    "the encode of {} panicked (a bug; please report it)",
                    input.display()
                ))
            }
            Err(RecvTimeoutError::Timeout) => {}
        }
        if let (Some(max), Some(held)) = (memory, memory.and_then(|_| resident_bytes())) {
            if held > max {
                break format!(
                    "the encode needed more than {} of memory (--max-memory {max}; {} resident \
                     after {:.1} s)",
                    mib(max),
                    mib(held),
                    start.elapsed().as_secs_f64()
                );
            }
        }
        if let (Some(d), Some(s)) = (deadline, seconds) {
            if Instant::now() >= d {
                break format!("the encode did not finish within {s} s (--max-seconds)");
            }
        }
    };
    let mut gave_up = GAVE_UP.lock().unwrap_or_else(|e| e.into_inner());
    // An encode that wrote its file while the lock was being taken is done: report it.
    if let Ok(result) = rx.try_recv() {
        return result;
    }
    *gave_up = true;
    Err(CliError::BudgetExceeded(format!(
        "{}: {over}; stopped, {output} not written",
        input.display()
    ))
    .into())
}

fn mib(bytes: u64) -> String {
    format!("{:.0} MiB", bytes as f64 / f64::from(1u32 << 20))
}

/// The process's resident memory in bytes (`VmRSS` of /proc/self/status), where the system
/// reports it.
fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line
        .trim_start_matches("VmRSS:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    kib.checked_mul(1024)
}

fn is_scode(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("scode"))
}

fn print_read_report(path: &Path, report: &ReadReport) {
    println!(
        "read {}: {} vertices, {} faces ({:?})",
        path.display(),
        report.input_vertices,
        report.input_faces,
        report.format
    );
    if report.welded_vertices > 0 {
        println!(
            "  welded {} exact duplicate vertices (shared between groups)",
            report.welded_vertices
        );
    }
    for note in &report.repairs {
        println!("  repair: {note}");
    }
}

/// Reads a mesh file or decodes a .scode file into a control mesh.
fn load_control_mesh(path: &Path) -> Result<(ControlMesh, Option<Content>)> {
    if is_scode(path) {
        let limits = Limits::default();
        let bytes = read_scode(path, &limits)?;
        let decoded = codec::decode(&bytes, &limits)
            .with_context(|| format!("cannot decode {}", path.display()))?;
        Ok((decoded.mesh, Some(decoded.header.content)))
    } else {
        let (mesh, report) = io::read_mesh(path)?;
        print_read_report(path, &report);
        Ok((mesh, None))
    }
}

/// A spinner on stderr while a long step runs (hidden when stderr is not a terminal).
fn spinner(message: &str) -> indicatif::ProgressBar {
    let bar = if std::io::IsTerminal::is_terminal(&std::io::stderr())
        && std::env::var_os("CI").is_none()
    {
        indicatif::ProgressBar::new_spinner()
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_message(message.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    bar
}

/// Reads a STEP file for `encode --raw` (its tessellation, with the chordal tolerance tied
/// to the encode tolerance), prints what was read and warns about every skipped face.
fn read_step_input(args: &EncodeArgs) -> Result<ControlMesh> {
    let opts = scode::pipeline::step_options_for(args.tolerance());
    let bar = spinner(&format!("reading {}", args.input.display()));
    let result = step::read_step(&args.input, &opts);
    bar.finish_and_clear();
    let model = result?;
    print_step_summary(&args.input, &model, args.verbose);
    check_skipped(args, &model)?;
    Ok(model.mesh)
}

fn print_step_summary(path: &Path, model: &step::StepModel, verbose: bool) {
    let hist: Vec<String> = model
        .surface_histogram()
        .iter()
        .map(|(k, n)| format!("{n} {k}"))
        .collect();
    println!(
        "read {}: {} bodies, {} faces ({}), {} B-rep edges, {} corners; tessellated at {:.3e} mm \
         chordal tolerance: {} vertices, {} triangles{}",
        path.display(),
        model.bodies.len(),
        model.faces.len(),
        hist.join(", "),
        model.edges.len(),
        model.mesh.corners.len(),
        model.chordal_tolerance,
        model.mesh.vertex_count(),
        model.mesh.face_count(),
        match model.millimetres_per_unit {
            Some(f) if f != 1.0 => format!(" (converted to mm: x{f})"),
            Some(_) => String::new(),
            None => " (no length unit in the file: file units kept)".to_string(),
        }
    );
    for s in &model.skipped {
        eprintln!("warning: skipped {s}");
    }
    if verbose {
        for n in &model.notes {
            println!("  {n}");
        }
    }
}

/// The error that ends an encode whose STEP input lost faces, unless `--allow-skipped`
/// lets the rest be encoded (then a warning says how many are missing).
fn check_skipped(args: &EncodeArgs, model: &step::StepModel) -> Result<()> {
    let n = model.skipped.len();
    if n == 0 {
        return Ok(());
    }
    if args.allow_skipped {
        eprintln!("warning: {n} faces skipped; the rest of the model is encoded (--allow-skipped)");
        return Ok(());
    }
    Err(CliError::FacesSkipped(format!(
        "{}: {n} faces could not be read (listed above); nothing written (--allow-skipped \
         encodes the rest)",
        args.input.display()
    ))
    .into())
}

pub fn encode(args: &EncodeArgs) -> Result<()> {
    let output = args.output.checked(&args.input, Writes::Scode)?;
    check_raw_flags(args)?;
    let t0 = Instant::now();
    let model_opts = model_encode_options(args);
    let (mesh, step_fit) = read_encode_input(args, &model_opts)?;
    let t_read = t0.elapsed();
    let t1 = Instant::now();
    // What the fit missed, reported once the file is written.
    let mut missed: Vec<String> = Vec::new();
    let bytes = if args.raw {
        let opts = EncodeOptions {
            quantization_bits: args.bits.unwrap_or(10),
            content: Content::RawMesh,
            store_group_names: !args.no_names,
            ..Default::default()
        };
        codec::encode(&mesh, &opts)
            .with_context(|| format!("cannot encode {}", args.input.display()))?
    } else {
        let (bytes, fit) = match step_fit {
            Some(done) => done,
            None => fit_mesh(args, &mesh, &model_opts)?,
        };
        print_fit_summary(&fit);
        print_fit_error(&fit, &mut missed);
        if args.verbose {
            print_fit_details(&fit);
        }
        bytes
    };
    let t_encode = t1.elapsed();
    write_file(output, &bytes)?;
    let nv = mesh.vertex_count().max(1);
    println!(
        "wrote {}: {} bytes ({:.3} bits per input vertex; input {} vertices, {} faces, {} groups)",
        output.display(),
        bytes.len(),
        bytes.len() as f64 * 8.0 / nv as f64,
        mesh.vertex_count(),
        mesh.face_count(),
        mesh.groups.len()
    );
    if args.verbose {
        println!(
            "timings: read {:.1} ms, encode {:.1} ms",
            t_read.as_secs_f64() * 1e3,
            t_encode.as_secs_f64() * 1e3
        );
    }
    if !missed.is_empty() {
        return Err(CliError::ToleranceNotMet(format!(
            "tolerance NOT met for {} ({}); {} is written",
            args.input.display(),
            missed.join(", "),
            output.display()
        ))
        .into());
    }
    Ok(())
}

/// The usage errors of fitting options given with `--raw`.
fn check_raw_flags(args: &EncodeArgs) -> Result<()> {
    if args.raw && (args.tolerance.is_some() || args.mean_tolerance.is_some()) {
        return Err(CliError::Usage(
            "--tolerance and --mean-tolerance apply to fitting; with --raw use --bits to set \
             the precision"
                .into(),
        )
        .into());
    }
    if args.raw && args.chord_allowance {
        return Err(CliError::Usage(
            "--chord-allowance applies to fitting (it changes what the tolerance is measured \
             against); --raw stores the input as it is"
                .into(),
        )
        .into());
    }
    Ok(())
}

/// The fitting pipeline's options from the command line.
fn model_encode_options(args: &EncodeArgs) -> ModelEncodeOptions {
    let mut model_opts = ModelEncodeOptions {
        quantization_bits: args.bits,
        store_group_names: !args.no_names,
        effort: args.effort,
        ..Default::default()
    };
    model_opts.fit.tolerance = args.tolerance();
    model_opts.fit.mean_tolerance = args.mean_tolerance();
    model_opts.fit.chord_allowance = args.chord_allowance;
    model_opts
}

/// An encoded file and the fit's report on it.
type FittedFile = (Vec<u8>, FitReport);

/// Reads the input and prints what was read. A STEP file to fit is read and fitted in one
/// call (at `--effort max`, several tessellations): then the encoded bytes and the fit's
/// report come with the mesh.
fn read_encode_input(
    args: &EncodeArgs,
    model_opts: &ModelEncodeOptions,
) -> Result<(ControlMesh, Option<FittedFile>)> {
    let is_step = step::is_step_path(&args.input);
    Ok(if is_step && !args.raw {
        let bar = spinner(&format!("reading and fitting {}", args.input.display()));
        let result = encode_step(&args.input, model_opts);
        bar.finish_and_clear();
        let (model, bytes, fit) =
            result.with_context(|| format!("cannot encode {}", args.input.display()))?;
        print_step_summary(&args.input, &model, args.verbose);
        check_skipped(args, &model)?;
        (model.mesh, Some((bytes, fit)))
    } else if is_step {
        (read_step_input(args)?, None)
    } else {
        let (mesh, report) = io::read_mesh(&args.input)?;
        print_read_report(&args.input, &report);
        (mesh, None)
    })
}

/// Fits a mesh input, with the surface types of its `.faces.json` sidecar unless
/// `--no-sidecar`.
fn fit_mesh(
    args: &EncodeArgs,
    mesh: &ControlMesh,
    model_opts: &ModelEncodeOptions,
) -> Result<FittedFile> {
    let hints = match sidecar_hints(&args.input, mesh)? {
        Some((side, hints)) if !args.no_sidecar => {
            println!("using surface types from {}", side.display());
            hints
        }
        _ => Vec::new(),
    };
    let bar = spinner(&format!("fitting {}", args.input.display()));
    let result = encode_fitted(mesh, &hints, model_opts);
    bar.finish_and_clear();
    result.with_context(|| format!("cannot fit {}", args.input.display()))
}

/// Prints what the fit made: faces by patch kind, control mesh size, and the faces stored
/// as their input facets.
fn print_fit_summary(fit: &FitReport) {
    let kinds: Vec<String> = fit
        .patch_kinds
        .iter()
        .map(|(k, n)| format!("{n} {k}"))
        .collect();
    println!(
        "fitted {} faces ({}) with {} control vertices and {} control faces{}",
        fit.patch_kinds.values().sum::<usize>(),
        kinds.join(", "),
        fit.control_vertices,
        fit.control_faces,
        if fit.segmented {
            " (segmented: the input had no groups)"
        } else {
            ""
        }
    );
    if fit.faceted_groups > 0 {
        let (faces, their, them) = match fit.faceted_groups {
            1 => ("1 face is".to_string(), "its", "it"),
            n => (format!("{n} faces are"), "their", "them"),
        };
        println!(
            "{faces} stored as {their} input facets: no smooth patch came within the \
             tolerance of {them}{}",
            if fit.reference == Reference::InputMesh {
                " (on coarse facets, --chord-allowance holds the tolerance beyond their \
                 chord error and fits smooth patches, in fewer bytes)"
            } else {
                ""
            }
        );
    }
}

/// Prints the decoded surface's error against the tolerance (and the mean tolerance, when
/// given); each one missed is added to `missed`.
fn print_fit_error(fit: &FitReport, missed: &mut Vec<String>) {
    let d = fit.diagonal.max(f64::MIN_POSITIVE);
    println!(
        "decoded surface at level {} vs {}: max {:.4e} ({:.2e} of the diagonal), rms {:.4e}, mean {:.4e}; \
         tolerance {:.4e} {}",
        fit.default_level,
        fit.reference.describe(),
        fit.error.max,
        fit.error.max / d,
        fit.error.rms,
        fit.error.mean,
        fit.tolerance,
        if fit.error.max_excess <= fit.tolerance {
            "met".to_string()
        } else {
            missed.push(format!(
                "the max distance to {} is {:.2}x the tolerance{}",
                fit.reference.describe(),
                fit.error.max_excess / fit.tolerance,
                if fit.reference == Reference::InputMesh {
                    " (--chord-allowance holds the tolerance beyond the input's chord \
                     error)"
                } else {
                    ""
                }
            ));
            format!(
                "NOT met: {:.2}x the tolerance after {} rounds",
                fit.error.max_excess / fit.tolerance,
                fit.rounds
            )
        }
    );
    if let Some(mt) = fit.mean_tolerance {
        println!(
            "mean tolerance {mt:.4e} {}",
            if fit.error.mean <= mt {
                "met".to_string()
            } else {
                missed.push(format!(
                    "the mean distance is {:.2}x the mean tolerance",
                    fit.error.mean / mt
                ));
                format!(
                    "NOT met: the mean is {:.2}x it (lower --tolerance)",
                    fit.error.mean / mt
                )
            }
        );
    }
}

/// Prints the fit's notes and its time per stage (`--verbose`).
fn print_fit_details(fit: &FitReport) {
    for note in &fit.notes {
        println!("  {note}");
    }
    let mut totals: std::collections::BTreeMap<&str, f64> = Default::default();
    for (stage, secs) in &fit.timings {
        *totals.entry(stage).or_default() += secs;
    }
    let t: Vec<String> = totals
        .iter()
        .map(|(k, v)| format!("{k} {:.1} ms", v * 1e3))
        .collect();
    println!("  fit timings: {}", t.join(", "));
}

pub fn decode(args: &DecodeArgs) -> Result<()> {
    let output = args.output.checked(&args.input, Writes::Mesh)?;
    let format = io::MeshFormat::from_path(output)?;
    if args.quantize && !matches!(format, io::MeshFormat::Glb | io::MeshFormat::Gltf) {
        return Err(CliError::Usage(format!(
            "--quantize applies to glTF output (.glb, .gltf), not to .{format} ({})",
            output.display()
        ))
        .into());
    }
    let limits = args.limits.limits();
    if let Some(t) = args.tolerance {
        if !(t > 0.0 && t.is_finite()) {
            return Err(
                scode::Error::Parameter(format!("--tolerance must be positive, got {t}")).into(),
            );
        }
    }
    if let Some(h) = args.max_edge {
        if !(h > 0.0 && h.is_finite()) {
            return Err(
                scode::Error::Parameter(format!("--max-edge must be positive, got {h}")).into(),
            );
        }
    }
    if let Some(a) = args.min_angle {
        if !(a > 0.0 && a <= 30.0) {
            return Err(scode::Error::Parameter(format!(
                "--min-angle must be in (0, 30] degrees, got {a}"
            ))
            .into());
        }
    }
    let bytes = read_scode(&args.input, &limits)?;
    let detail = match (args.level, args.tolerance) {
        (Some(level), _) => Detail::Level(level),
        (None, Some(t)) => Detail::Tolerance(Tolerance::new(t, args.relative)),
        // Level positions are not the limit surface a tolerance is measured against.
        (None, None) if args.no_limit => Detail::DefaultLevel,
        (None, None) => Detail::FileTolerance,
    };
    let opts = SurfaceOptions {
        detail,
        limit: if args.limit {
            Some(true)
        } else if args.no_limit {
            Some(false)
        } else {
            None
        },
        boundary_patches: boundary_output(args.dense_boundary),
        max_edge: args.max_edge,
        min_angle: args.min_angle,
    };
    let t0 = Instant::now();
    let surface = decode_surface(&bytes, &limits, &opts)
        .with_context(|| format!("cannot decode {}", args.input.display()))?;
    let t_decode = t0.elapsed();
    let write = io::WriteOptions {
        quantize: args.quantize,
    };
    io::write_mesh_with(output, &surface.mesh, surface.normals.as_deref(), &write)?;
    let how = match &surface.accuracy {
        None => format!("level {}", surface.level),
        Some(a) => format!(
            "tolerance {:.4e}, levels {}, estimated distance to the limit surface at most {:.4e}, \
             {:.1} MB of memory charged",
            a.tolerance,
            level_histogram(&a.triangles_per_level),
            a.bound,
            a.memory as f64 / 1e6
        ),
    };
    println!(
        "wrote {}: {} vertices, {} faces ({how}; decode and subdivide {:.1} ms)",
        output.display(),
        surface.mesh.vertex_count(),
        surface.mesh.face_count(),
        t_decode.as_secs_f64() * 1e3,
    );
    if let Some(a) = surface.accuracy.as_ref().filter(|a| a.bound > a.tolerance) {
        println!(
            "note: some control triangles need a level beyond {} to meet the tolerance; \
             --tolerance with a smaller value allows finer levels",
            a.max_level
        );
    }
    if let Some(limit) = args.min_angle {
        let (longest, under) = edge_and_angle_summary(&surface.mesh, limit);
        println!(
            "longest edge {longest:.4e}; {under} of {} triangles have an angle under {limit} \
             degrees (--min-angle refines plane patches; curved patches keep the triangles \
             --max-edge gives)",
            surface.mesh.face_count()
        );
    }
    Ok(())
}

/// The longest edge of `mesh`'s triangles, and how many triangles have an angle under
/// `limit` degrees.
fn edge_and_angle_summary(mesh: &scode::ControlMesh, limit: f64) -> (f64, usize) {
    let (mut longest, mut under) = (0.0f64, 0);
    for face in mesh.faces() {
        let q: Vec<_> = face.iter().map(|&v| mesh.positions[v as usize]).collect();
        let mut smallest = 180.0f64;
        for k in 0..q.len() {
            let (a, b, c) = (q[k], q[(k + 1) % q.len()], q[(k + q.len() - 1) % q.len()]);
            longest = longest.max(a.distance(b));
            smallest = smallest.min((b - a).angle_between(c - a).to_degrees());
        }
        under += usize::from(smallest < limit);
    }
    (longest, under)
}

/// "0:12 1:40 3:2": control triangles per level shown, levels with none left out.
fn level_histogram(per_level: &[usize]) -> String {
    let parts: Vec<String> = per_level
        .iter()
        .enumerate()
        .filter(|&(_, &n)| n > 0)
        .map(|(m, n)| format!("{m}:{n}"))
        .collect();
    parts.join(" ")
}

fn boundary_output(dense: bool) -> subdiv::BoundaryPatchOutput {
    if dense {
        subdiv::BoundaryPatchOutput::Dense
    } else {
        subdiv::BoundaryPatchOutput::Sparse
    }
}

pub fn subdivide(args: &SubdivideArgs) -> Result<()> {
    let output = args.output.checked(&args.input, Writes::Mesh)?;
    let (control, _) = load_control_mesh(&args.input)?;
    let opts = SubdivOptions {
        limit: args.limit,
        boundary_patches: boundary_output(args.dense_boundary),
        ..Default::default()
    };
    let t0 = Instant::now();
    let (mesh, normals) = subdiv::subdivide(&control, args.level, &opts)
        .with_context(|| format!("cannot subdivide {}", args.input.display()))?;
    let elapsed = t0.elapsed();
    io::write_mesh(output, &mesh, normals.as_deref())?;
    println!(
        "wrote {}: {} vertices, {} triangles (level {}, {:.1} ms)",
        output.display(),
        mesh.vertex_count(),
        mesh.face_count(),
        args.level,
        elapsed.as_secs_f64() * 1e3
    );
    Ok(())
}

/// `info` on a STEP file: the plan (bodies, faces by surface type and the patch kind each
/// will become, skipped faces) before anything is fitted.
fn step_info(args: &InfoArgs) -> Result<()> {
    let model = step::read_step(&args.file, &step::StepOptions::default())?;
    print_step_summary(&args.file, &model, true);
    if !model.skipped.is_empty() {
        eprintln!(
            "warning: {} faces skipped; `scode encode` encodes the rest only with --allow-skipped",
            model.skipped.len()
        );
    }
    let kind = |f: &step::FaceSurface| match scode::pipeline::hint_for(&f.surface) {
        SurfaceHint::Plane => "boundary patch (plane)",
        SurfaceHint::Cylinder => "boundary patch (cylinder, exact axis)",
        SurfaceHint::Cone => "boundary patch (cone, exact apex and axis)",
        SurfaceHint::Sphere => "boundary patch (sphere, exact centre) unless a hemisphere or wider",
        SurfaceHint::Torus => {
            "boundary patch (torus, exact axis) unless a spindle torus or too wide"
        }
        SurfaceHint::Freeform => "closed patch",
        SurfaceHint::Unknown => "classified from the triangles",
    };
    for (b, body) in model.bodies.iter().enumerate() {
        let faces: Vec<&step::FaceSurface> = model
            .faces
            .iter()
            .filter(|f| f.body as usize == b)
            .collect();
        println!(
            "  {} ({} #{}): {} faces",
            body.name,
            body.entity,
            body.step_id,
            faces.len()
        );
        let mut by_type: std::collections::BTreeMap<String, (usize, &str)> = Default::default();
        for f in &faces {
            by_type
                .entry(step::surface_name(&f.surface))
                .or_insert((0, kind(f)))
                .0 += 1;
        }
        for (t, (n, k)) in by_type {
            println!("    {n:>5} {t:<12} -> {k}");
        }
    }
    if args.groups {
        let mut triangles = vec![0usize; model.faces.len()];
        for &g in &model.mesh.face_groups {
            triangles[g as usize] += 1;
        }
        for (g, f) in model.faces.iter().enumerate() {
            let exact = match (f.exact, f.revolution_axis) {
                (Some(e), _) => format!(" {e}"),
                (None, Some(a)) => format!(
                    " axis ({:.4}, {:.4}, {:.4}) dir ({:.4}, {:.4}, {:.4})",
                    a.origin.x, a.origin.y, a.origin.z, a.direction.x, a.direction.y, a.direction.z
                ),
                (None, None) => String::new(),
            };
            println!(
                "  group {g} {} (face #{}): {} triangles, {} ({}){exact} -> {}",
                model.mesh.groups[g].name,
                f.face_id,
                triangles[g],
                step::surface_name(&f.surface),
                f.entity,
                kind(f)
            );
        }
    }
    Ok(())
}

pub fn info(args: &InfoArgs) -> Result<()> {
    if step::is_step_path(&args.file) {
        return step_info(args);
    }
    if !is_scode(&args.file) {
        let (mesh, report) = io::read_mesh(&args.file)?;
        print_read_report(&args.file, &report);
        print_mesh_summary(&mesh, args.groups);
        return Ok(());
    }
    let limits = args.limits.limits();
    let bytes = read_scode(&args.file, &limits)?;
    let info = codec::inspect(&bytes, &limits)
        .with_context(|| format!("cannot read {}", args.file.display()))?;
    let h = &info.header;
    println!(
        "{}: .scode v{}.{}",
        args.file.display(),
        h.version_major,
        h.version_minor
    );
    match h.content {
        Content::RawMesh => println!("  content: raw mesh (decodes to the stored mesh)"),
        Content::ControlMesh { default_level } => {
            println!("  content: control mesh (default decode level {default_level})")
        }
    }
    println!(
        "  {} vertices, {} faces, {} groups, {} sharp edges, {} corners",
        h.vertex_count, h.face_count, h.group_count, info.sharp_edge_count, info.corner_count
    );
    println!(
        // The grid's box, not the model's: a fitted file may use a larger box for a step
        // between whole bit counts (spec §8.1).
        "  quantisation: {} bits, grid box min ({:.6}, {:.6}, {:.6}), extent {:.6}, step {:.6e}",
        h.quantization_bits,
        h.bbox_min[0],
        h.bbox_min[1],
        h.bbox_min[2],
        h.bbox_extent,
        h.quantization_step()
    );
    let nv = (h.vertex_count as f64).max(1.0);
    println!(
        "  {:<14} {:>10} {:>10} {:>12}",
        "section", "bytes", "raw bytes", "bits/vertex"
    );
    for s in &info.sections {
        println!(
            "  {:<14} {:>10} {:>10} {:>12.3}",
            s.name,
            s.stored_bytes,
            s.raw_bytes,
            s.stored_bytes as f64 * 8.0 / nv
        );
        if s.name == "connectivity" && info.group_bits > 0.0 {
            let group_bytes = info.group_bits / 8.0;
            println!(
                "    {:<12} {:>10.0} {:>10} {:>12.3}",
                "of it groups",
                group_bytes,
                "",
                info.group_bits / nv
            );
        }
    }
    println!(
        "  {:<14} {:>10} {:>10} {:>12.3}",
        "total",
        info.total_bytes,
        "",
        info.total_bytes as f64 * 8.0 / nv
    );
    if args.groups {
        let decoded = codec::decode(&bytes, &limits)?;
        let mesh = &decoded.mesh;
        let mut faces_of = vec![0usize; mesh.groups.len()];
        for &g in &mesh.face_groups {
            faces_of[g as usize] += 1;
        }
        for (i, group) in mesh.groups.iter().enumerate() {
            let patch = match group.patch {
                PatchKind::Closed => "closed patch".to_string(),
                PatchKind::Boundary(BoundarySurface::Plane) => "plane patch".to_string(),
                PatchKind::Boundary(BoundarySurface::Cylinder { axis }) => {
                    format!("cylinder patch, axis {}", fmt_axis(&axis))
                }
                PatchKind::Boundary(BoundarySurface::Cone { axis }) => {
                    format!("cone patch, apex/axis {}", fmt_axis(&axis))
                }
                PatchKind::Boundary(BoundarySurface::Sphere { axis }) => {
                    format!("sphere patch, centre/axis {}", fmt_axis(&axis))
                }
                PatchKind::Boundary(BoundarySurface::Torus { axis, major_radius }) => format!(
                    "torus patch, centre/axis {}, major radius {major_radius:.6}",
                    fmt_axis(&axis)
                ),
            };
            println!(
                "  group {i}: {:<24} {:>5} control faces, {patch}",
                if group.name.is_empty() {
                    "(unnamed)"
                } else {
                    &group.name
                },
                faces_of[i]
            );
        }
    }
    if let Some(reference) = &args.against {
        let (input, _) = io::read_mesh(reference)?;
        // Samples mostly lie within the default tolerance (it only splits the work).
        let near = scode::pipeline::DEFAULT_RELATIVE_TOLERANCE * input.diagonal();
        let (r, level) = scode::pipeline::measure_file_against_input(
            &bytes,
            &input,
            &limits,
            &Default::default(),
            near,
        )?;
        let d = r.diagonal.max(f64::MIN_POSITIVE);
        println!(
            "  against {} (decoded at level {level}):",
            reference.display()
        );
        println!(
            "    decoded -> input: max {:.4e}, rms {:.4e}; input -> decoded: max {:.4e}, rms {:.4e}",
            r.max_a_to_b, r.rms_a_to_b, r.max_b_to_a, r.rms_b_to_a
        );
        println!(
            "    symmetric: max {:.4e} ({:.3e} of the diagonal), rms {:.4e} ({:.3e}), mean {:.4e} ({:.3e})",
            r.max,
            r.max / d,
            r.rms,
            r.rms / d,
            r.mean,
            r.mean / d
        );
        let at = |p: glam::DVec3| format!("({:.4}, {:.4}, {:.4})", p.x, p.y, p.z);
        println!(
            "    farthest: decoded point {} from the input, input point {} from the decoded surface",
            at(r.worst_a_to_b),
            at(r.worst_b_to_a)
        );
    }
    Ok(())
}

pub fn segment(args: &SegmentArgs) -> Result<()> {
    let output = args.output.checked(&args.input, Writes::Mesh)?;
    let (mesh, report) = io::read_mesh(&args.input)?;
    print_read_report(&args.input, &report);
    let opts = scode::fit::segment::SegmentOptions {
        sharp_angle_deg: args.sharp_angle,
        ..Default::default()
    };
    let bar = spinner(&format!("segmenting {}", args.input.display()));
    let result = scode::fit::segment::segment(&mesh, &opts);
    bar.finish_and_clear();
    let (faces, seg) =
        result.with_context(|| format!("cannot segment {}", args.input.display()))?;
    io::write_mesh(output, &faces, None)?;
    println!("wrote {}: {}", output.display(), seg.summary());
    Ok(())
}

fn print_mesh_summary(mesh: &ControlMesh, list_groups: bool) {
    let mut degrees = std::collections::BTreeMap::new();
    for f in mesh.faces() {
        *degrees.entry(f.len()).or_insert(0usize) += 1;
    }
    let degrees: Vec<String> = degrees
        .iter()
        .map(|(d, n)| format!("{n} of degree {d}"))
        .collect();
    println!(
        "  {} vertices, {} faces ({}), {} groups, {} sharp edges, {} corners",
        mesh.vertex_count(),
        mesh.face_count(),
        degrees.join(", "),
        mesh.groups.len(),
        mesh.sharp_edges.len(),
        mesh.corners.len()
    );
    if let Some((lo, hi)) = mesh.bounding_box() {
        println!(
            "  bounding box ({:.6}, {:.6}, {:.6}) .. ({:.6}, {:.6}, {:.6}), diagonal {:.6}",
            lo.x,
            lo.y,
            lo.z,
            hi.x,
            hi.y,
            hi.z,
            (hi - lo).length()
        );
    }
    if list_groups {
        let mut counts = vec![0usize; mesh.groups.len()];
        for &g in &mesh.face_groups {
            counts[g as usize] += 1;
        }
        for (i, g) in mesh.groups.iter().enumerate() {
            println!(
                "  group {i} {:?}: {} faces, {:?}",
                g.name, counts[i], g.patch
            );
        }
    }
}

fn fmt_axis(axis: &scode::mesh::Axis) -> String {
    let (o, d) = (axis.origin, axis.direction);
    format!(
        "({:.4}, {:.4}, {:.4}) + t ({:.4}, {:.4}, {:.4})",
        o.x, o.y, o.z, d.x, d.y, d.z
    )
}

pub fn report(args: &ReportArgs) -> Result<()> {
    use scode_cli::report::{self, Progress, ReportOptions, StepRunner};
    let mut opts = if args.quick {
        ReportOptions::quick()
    } else {
        ReportOptions::full()
    };
    if let Some(t) = &args.tolerances {
        if t.is_empty() || t.iter().any(|&t| !(t > 0.0 && t < 1.0)) {
            return Err(CliError::Usage(
                "--tolerances must be fractions of the diagonal in (0, 1)".into(),
            )
            .into());
        }
        opts.tolerances = t.clone();
    }
    if let Some(r) = args.runs {
        opts.runs = r.max(1);
    }
    opts.jobs = args.jobs.max(1);
    opts.draco_dir = args.draco_dir.clone();
    opts.gltfpack_dir = args.gltfpack_dir.clone();
    opts.step_timeout = std::time::Duration::from_secs(args.timeout_secs);
    opts.model_timeout = std::time::Duration::from_secs(args.model_timeout_secs);
    opts.checkpoint = Some(args.output.clone());
    opts.resume = args.resume;
    opts.reference = args.reference.map(|r| match r {
        super::ReferenceArg::Brep => report::Reference::Brep,
        super::ReferenceArg::Input => report::Reference::Input,
    });
    opts.runner = StepRunner::Subprocess {
        program: std::env::current_exe().context("cannot find the scode executable")?,
        args: vec!["report-step".into()],
    };
    if let Err(msg) = report::find_draco(opts.draco_dir.as_deref()) {
        eprintln!("warning: {msg}");
    }
    if let Err(msg) = report::find_gltfpack(opts.gltfpack_dir.as_deref()) {
        eprintln!("warning: {msg}");
    }
    std::fs::create_dir_all(&args.output).map_err(|e| scode::Error::io(&args.output, e))?;
    let files_dir = args.output.join("files");
    let bars = ReportBars::new();
    let result = report::run_report(&args.inputs, &files_dir, &opts, &|p: Progress| {
        bars.update(&p)
    });
    bars.finish();
    let rep = result.context("report failed")?;
    let files = report::write_report(&rep, &args.output)?;
    for e in &files.plot_errors {
        eprintln!("warning: plot not drawn: {e}");
    }
    for s in report::summarise(&rep) {
        let median = (!s.ratios.is_empty()).then(|| report::median(&s.ratios));
        println!(
            "{:<10} {:<12} median best-baseline/scode bytes at equal error: {} ({} of {} models matched)",
            s.setting.codec(),
            s.setting.label(),
            median.map_or("-".into(), |m| format!("{m:.2}")),
            s.ratios.len(),
            s.measured
        );
    }
    let failed: usize = rep
        .models
        .iter()
        .map(|m| m.points.iter().filter(|p| p.outcome.is_err()).count())
        .sum();
    let unmeasured = rep.models.iter().filter(|m| m.error.is_some()).count();
    println!(
        "wrote {} and {} ({} plots; {} models, {} not measured, {} failed steps; {:.0} s)",
        files.markdown.display(),
        files.csv.display(),
        files.plots.len(),
        rep.models.len(),
        unmeasured,
        failed,
        rep.seconds
    );
    Ok(())
}

/// The child side of `scode report`: one encode, result on stdout after the marker.
pub fn report_step(job: &str) -> Result<()> {
    let out = scode_cli::report::run_scode_job_json(job)?;
    println!("{}{out}", scode_cli::report::RESULT_MARKER);
    Ok(())
}

/// Two progress bars on stderr (models and steps), hidden when stderr is not a terminal or
/// `CI` is set.
struct ReportBars {
    multi: indicatif::MultiProgress,
    models: indicatif::ProgressBar,
    steps: indicatif::ProgressBar,
}

impl ReportBars {
    fn new() -> Self {
        let visible = std::io::IsTerminal::is_terminal(&std::io::stderr())
            && std::env::var_os("CI").is_none();
        let multi = if visible {
            indicatif::MultiProgress::new()
        } else {
            indicatif::MultiProgress::with_draw_target(indicatif::ProgressDrawTarget::hidden())
        };
        let style = |t: &str| {
            indicatif::ProgressStyle::with_template(t)
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        };
        let models = multi.add(indicatif::ProgressBar::new(0));
        models.set_style(style(
            "models {pos}/{len} [{bar:30}] {elapsed_precise} {msg}",
        ));
        let steps = multi.add(indicatif::ProgressBar::new(0));
        steps.set_style(style("steps  {pos}/{len} [{bar:30}] {msg}"));
        steps.enable_steady_tick(std::time::Duration::from_millis(200));
        ReportBars {
            multi,
            models,
            steps,
        }
    }

    fn update(&self, p: &scode_cli::report::Progress) {
        use scode_cli::report::Progress;
        match p {
            Progress::Planned {
                models,
                steps_per_model,
            } => {
                self.models.set_length(*models as u64);
                self.steps.set_length((*models * *steps_per_model) as u64);
            }
            Progress::ModelStarted { name, .. } => self.models.set_message(name.clone()),
            Progress::CheckpointFailed { message } => {
                let _ = self.multi.println(format!("warning: {message}"));
                if self.multi.is_hidden() {
                    eprintln!("warning: {message}");
                }
            }
            Progress::StepFinished { name, step, ok, .. } => {
                self.steps.inc(1);
                self.steps.set_message(format!(
                    "{name}: {step}{}",
                    if *ok { "" } else { " (failed)" }
                ));
            }
            Progress::ModelFinished {
                name,
                skipped_steps,
                ..
            } => {
                self.models.inc(1);
                self.steps.inc(*skipped_steps as u64);
                if !self.multi.is_hidden() {
                    let _ = self.multi.println(format!("done: {name}"));
                }
            }
        }
    }

    fn finish(&self) {
        self.steps.finish_and_clear();
        self.models.finish_and_clear();
    }
}
