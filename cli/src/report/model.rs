//! One model of the report: what its decoded surfaces are measured against, which mesh each
//! baseline is given, and the loop over its settings.
//!
//! A mesh file is its own reference and every codec encodes it. A STEP part is measured
//! against its B-rep ([`BrepReference`]) by default: scode encodes the STEP file itself,
//! and each baseline gets the part tessellated by scode's STEP reader at a series of
//! chordal tolerances, each quantised at the bits that suit that tolerance, so the
//! equal-error pairing finds the smallest file of each baseline at each accuracy whatever
//! tessellation it came from.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::brep::{BrepReference, FaceRuler};
use super::discover::{ModelInput, ModelSource};
use super::run::{
    empty_model, equal_error, run_draco, run_gltfpack, run_scode_point, write_draco_input,
    write_gltfpack_input, Baselines, ModelReport, PointResult, Progress, Reference, ReportOptions,
    Ruler,
};
use super::steps::Setting;
use scode::io;
use scode::io::step::{read_step_tessellations, surface_name, StepModel, StepOptions};
use scode::mesh::{edge_key, ControlMesh, Tolerance};
use scode::metrics::raw_binary_bytes;
use scode::pipeline::{bits_for_tolerance, step_options_for};

/// How finely the B-rep reference tessellates the faces it measures through facets: its
/// chordal tolerance is the tightest accuracy of the report divided by this.
pub const REFERENCE_CHORD_DIVISOR: f64 = 20.0;

/// The reference tessellates faces it measures exactly this much coarser: their facets
/// only say which face a point is nearest to (a point charged to a neighbouring face is
/// measured to a point of that face, never closer than the part), so they need not be as
/// fine as the facets that are the ruler themselves, and tessellating every analytic face
/// 20x finer than the tightest accuracy takes longer than the STEP reader's time limits on
/// tori and cones.
const REFERENCE_ANALYTIC_FACTOR: f64 = 5.0;

/// The share of a model's time budget its reading may take (the nominal tessellation, the
/// reference and the baselines' tessellations); the rest is for the encodes and their
/// measurements. Without it the finest tessellations of a part with many B-spline faces
/// take the whole budget and no codec is measured at all.
const PREPARE_SHARE: f64 = 0.5;

/// A model read and ready to measure.
struct Prepared {
    /// The mesh rates are per (vertex count, raw size): the input, or a STEP part's
    /// tessellation at scode's default chordal tolerance.
    nominal: ControlMesh,
    brep: Option<BrepReference>,
    /// What the baselines encode: the input (no chordal tolerance), or a STEP part's
    /// tessellations with their chordal tolerance (fraction of the diagonal).
    inputs: Vec<(Option<f64>, ControlMesh)>,
    step: bool,
    reference: String,
    faces: Vec<String>,
}

impl Prepared {
    fn ruler(&self) -> Ruler<'_> {
        match &self.brep {
            Some(reference) => Ruler::Brep {
                reference,
                nominal: &self.nominal,
            },
            None => Ruler::Input(&self.nominal),
        }
    }

    /// The points to run: every setting on a mesh file; on a STEP part, the fitted
    /// settings on the file and, per tessellation, the baselines' settings at the three
    /// bit counts around the one whose quantisation error is the chordal tolerance.
    fn jobs(&self, settings: &[Setting], opts: &ReportOptions) -> Vec<(Setting, Option<usize>)> {
        if !self.step {
            return settings
                .iter()
                .map(|s| (*s, s.baseline().map(|_| 0)))
                .collect();
        }
        let draco = settings.iter().any(|s| matches!(s, Setting::Draco { .. }));
        let gltfpack = settings
            .iter()
            .any(|s| matches!(s, Setting::Gltfpack { .. }));
        let extent = self
            .nominal
            .bounding_box()
            .map_or(1.0, |(lo, hi)| (hi - lo).max_element());
        let diagonal = self.nominal.diagonal();
        let mut jobs = Vec::new();
        for (i, (chord, _)) in self.inputs.iter().enumerate() {
            let chord = chord.unwrap_or(1e-3);
            let b0 = bits_for_tolerance(extent, chord * diagonal, 1.0);
            let bits = [b0.saturating_sub(1), b0, b0 + 1];
            if draco {
                // The first -cl only: every point on a part is measured against its B-rep,
                // and the other levels give the same geometry in more bytes.
                for &cl in opts.draco_cl.iter().take(1) {
                    for qp in bits.iter().map(|&b| b.clamp(1, 30)) {
                        jobs.push((Setting::Draco { qp, cl }, Some(i)));
                    }
                }
            }
            if gltfpack {
                for &cc in &opts.gltfpack_cc {
                    let mut vps: Vec<u8> = bits.iter().map(|&b| b.clamp(1, 16)).collect();
                    vps.dedup();
                    for vp in vps {
                        jobs.push((Setting::Gltfpack { vp, cc }, Some(i)));
                    }
                }
            }
        }
        jobs.extend(
            settings
                .iter()
                .filter(|s| matches!(s, Setting::Fitted { .. }))
                .map(|s| (*s, None)),
        );
        // From the loosest accuracy to the tightest, each baseline tessellation (whose
        // files reach about twice its chordal tolerance) before the scode point it pairs
        // with, so the model's time budget cuts the tightest points of every codec alike.
        let accuracy = |(s, i): &(Setting, Option<usize>)| match (s, i) {
            (Setting::Fitted { tolerance }, _) => (*tolerance, 1),
            (_, Some(i)) => (2.0 * self.inputs[*i].0.unwrap_or(1e-3), 0),
            _ => (0.0, 1),
        };
        jobs.sort_by(|a, b| {
            let (ka, kb) = (accuracy(a), accuracy(b));
            kb.0.total_cmp(&ka.0).then(ka.1.cmp(&kb.1))
        });
        jobs
    }
}

/// Reads a model and builds its reference (see the module documentation).
fn prepare(model: &ModelInput, opts: &ReportOptions) -> Result<Prepared, String> {
    match &model.source {
        ModelSource::Unsupported(reason) => Err(reason.clone()),
        ModelSource::Mesh => {
            if opts.reference == Some(Reference::Brep) {
                return Err(
                    "--reference brep needs a STEP file: a mesh file has no B-rep".to_string(),
                );
            }
            let (mesh, _) = io::read_mesh(&model.path).map_err(|e| format!("cannot read: {e}"))?;
            Ok(Prepared {
                inputs: vec![(None, mesh.clone())],
                nominal: mesh,
                brep: None,
                step: false,
                reference: "the input mesh".into(),
                faces: Vec::new(),
            })
        }
        ModelSource::Step => prepare_step(&model.path, opts),
    }
}

/// A STEP part: its default tessellation, the baselines' tessellations and the B-rep
/// reference (unless the input is the reference), read in that order.
///
/// Each tessellation is read on its own with the time left of the model's share for reading
/// ([`PREPARE_SHARE`]), so one that is too fine for the time (B-spline faces at a tiny
/// chordal tolerance) costs only itself and the encodes keep their share: the baselines'
/// series stops at the finest tessellation that could be made, and the reference falls back
/// to the default tessellation and says so.
fn prepare_step(path: &Path, opts: &ReportOptions) -> Result<Prepared, String> {
    let t0 = Instant::now();
    let share = opts.model_timeout.mul_f64(PREPARE_SHARE);
    let read = |o: StepOptions| -> Result<StepModel, String> {
        let budget = share.saturating_sub(t0.elapsed());
        if budget.is_zero() {
            return Err(format!(
                "the share of the model's time budget for reading it ({:.0} s) is used up",
                share.as_secs_f64()
            ));
        }
        let o = StepOptions {
            total_timeout: o.total_timeout.min(budget),
            face_timeout: o.face_timeout.min(budget),
            ..o
        };
        let mut m =
            read_step_tessellations(path, std::slice::from_ref(&o)).map_err(|e| e.to_string())?;
        m.pop()
            .ok_or_else(|| "the STEP reader returned nothing".to_string())
    };
    let at = |chord: f64| StepOptions {
        chordal_tolerance: Tolerance::Relative(chord),
        ..StepOptions::default()
    };
    let nominal =
        read(step_options_for(Tolerance::DEFAULT)).map_err(|e| format!("cannot read: {e}"))?;
    let mut skipped: Vec<String> = nominal.skipped.iter().map(|f| f.to_string()).collect();
    // Faces any read skipped (a face's tessellation may fail at one chordal tolerance and
    // not at another): left out of the reference and of every baseline's mesh, so that
    // every codec and the ruler cover the same faces.
    let mut skipped_faces: BTreeSet<u64> = nominal.skipped.iter().map(|f| f.face_id).collect();
    let mut chords = opts.tessellation_chords.clone();
    chords.sort_by(|a, b| b.total_cmp(a));
    let mut tessellations: Vec<(f64, StepModel)> = Vec::new();
    let mut stopped = None;
    for c in chords {
        match read(at(c)) {
            Ok(m) => {
                skipped.extend(m.skipped.iter().map(|f| f.to_string()));
                skipped_faces.extend(m.skipped.iter().map(|f| f.face_id));
                tessellations.push((c, m));
            }
            Err(e) => {
                // A finer tessellation takes longer still: the series ends here.
                stopped = Some(format!(
                    "; the baselines' tessellations stop above chordal tolerance {c:.1e} ({e})"
                ));
                break;
            }
        }
    }
    // The reference is read last: the baselines need their tessellations to be measured at
    // all.
    let reference_read = if opts.reference.unwrap_or(Reference::Brep) == Reference::Brep {
        let (r, chord, failures) = match read_reference(opts, &read) {
            Ok(found) => found,
            // The default tessellation is the last resort: its chordal tolerance is in the
            // description, so accuracies near it are read for what they are. (Not the
            // finest baseline tessellation: a tessellator that fails a face at a fine chord
            // falls back to one that does not follow the face's edges, which would be
            // every codec's error.)
            Err(failures) => (
                nominal.clone(),
                scode::pipeline::DEFAULT_RELATIVE_TOLERANCE * scode::pipeline::STEP_CHORD_FRACTION,
                failures,
            ),
        };
        skipped.extend(r.skipped.iter().map(|f| f.to_string()));
        skipped_faces.extend(r.skipped.iter().map(|f| f.face_id));
        Some((r, chord, failures))
    } else {
        None
    };
    let (reference, faces, mut description) = match reference_read {
        Some((r, chord, failures)) => {
            let (mut reference, faces, mut description) =
                brep_reference(&without_faces(&r, &skipped_faces), chord)?;
            // scode encodes the nominal tessellation: the faces it has that another read
            // skipped are not measured.
            reference.leave_out(
                nominal
                    .faces
                    .iter()
                    .zip(&nominal.mesh.groups)
                    .filter(|(f, _)| skipped_faces.contains(&f.face_id))
                    .map(|(_, g)| g.name.clone()),
            );
            if !failures.is_empty() {
                description.push_str(&format!(
                    " (finer reference tessellations failed: {})",
                    failures.join("; ")
                ));
            }
            (Some(reference), faces, description)
        }
        None => {
            let d = format!(
                "the part tessellated by scode at chordal tolerance {:.1e} of the diagonal",
                scode::pipeline::DEFAULT_RELATIVE_TOLERANCE * scode::pipeline::STEP_CHORD_FRACTION
            );
            (None, Vec::new(), d)
        }
    };
    description.extend(stopped);
    let inputs: Vec<(Option<f64>, ControlMesh)> = tessellations
        .iter()
        .map(|(c, m)| (Some(*c), without_faces(m, &skipped_faces).mesh))
        .collect();
    skipped.sort();
    skipped.dedup();
    if !skipped.is_empty() {
        description.push_str(&format!(
            "; faces some tessellation of the part lacks (left out of the reference and of every codec's measurement): {}",
            skipped.join("; ")
        ));
    }
    Ok(Prepared {
        nominal: nominal.mesh,
        brep: reference,
        inputs,
        step: true,
        reference: description,
        faces,
    })
}

/// `model` without the faces whose ids are in `dropped` (their groups removed, the others
/// renumbered in order; vertices kept, so the part's diagonal stays).
fn without_faces(model: &StepModel, dropped: &BTreeSet<u64>) -> StepModel {
    let keep: Vec<bool> = model
        .faces
        .iter()
        .map(|f| !dropped.contains(&f.face_id))
        .collect();
    if keep.iter().all(|&k| k) || keep.len() != model.mesh.groups.len() {
        return model.clone();
    }
    let mut renumbered = vec![u32::MAX; keep.len()];
    let mut mesh = ControlMesh {
        positions: model.mesh.positions.clone(),
        corners: model.mesh.corners.clone(),
        ..ControlMesh::default()
    };
    for (g, group) in model.mesh.groups.iter().enumerate() {
        if keep[g] {
            renumbered[g] = mesh.groups.len() as u32;
            mesh.groups.push(group.clone());
        }
    }
    for f in 0..model.mesh.face_count() {
        let g = model.mesh.face_groups[f] as usize;
        if keep.get(g).copied().unwrap_or(false) {
            mesh.push_face(model.mesh.face(f), renumbered[g]);
        }
    }
    // A sharp edge stays where a kept face still has it.
    let kept_edges: BTreeSet<(u32, u32)> = (0..mesh.face_count())
        .flat_map(|f| {
            let face = mesh.face(f);
            (0..face.len()).map(move |i| edge_key(face[i], face[(i + 1) % face.len()]))
        })
        .collect();
    mesh.sharp_edges = model
        .mesh
        .sharp_edges
        .intersection(&kept_edges)
        .copied()
        .collect();
    StepModel {
        mesh,
        faces: model
            .faces
            .iter()
            .zip(&keep)
            .filter(|(_, &k)| k)
            .map(|(f, _)| f.clone())
            .collect(),
        ..model.clone()
    }
}

/// The reference tessellation: at the tightest accuracy / [`REFERENCE_CHORD_DIVISOR`],
/// else (out of time) at a fifth of it, each given a share of the budget (within what
/// `read` allows). Returns the model, its chordal tolerance (fraction of the diagonal) and
/// why the finer ones failed; or, when none could be made, why.
fn read_reference(
    opts: &ReportOptions,
    read: &dyn Fn(StepOptions) -> Result<StepModel, String>,
) -> Result<(StepModel, f64, Vec<String>), Vec<String>> {
    let tightest = opts
        .tolerances
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let tightest = if tightest.is_finite() { tightest } else { 1e-3 };
    let mut failures = Vec::new();
    // A fifth and a sixth of the budget: the rest is the baselines' tessellations and
    // every encode and measurement.
    for (divisor, share) in [(REFERENCE_CHORD_DIVISOR, 5.0), (5.0, 6.0)] {
        let chord = tightest / divisor;
        let share = opts.model_timeout.div_f64(share);
        let o = StepOptions {
            chordal_tolerance: Tolerance::Relative(chord),
            analytic_chordal_factor: REFERENCE_ANALYTIC_FACTOR,
            face_timeout: share.min(Duration::from_secs(60)),
            total_timeout: share,
            ..StepOptions::default()
        };
        match read(o) {
            Ok(m) => return Ok((m, chord, failures)),
            Err(e) => failures.push(format!("chordal tolerance {chord:.1e}: {e}")),
        }
    }
    Err(failures)
}

/// The B-rep reference of a STEP model tessellated at `chord` (fraction of the diagonal),
/// with one line per face saying how it is measured and a summary.
fn brep_reference(
    r: &StepModel,
    chord: f64,
) -> Result<(BrepReference, Vec<String>, String), String> {
    let exact: Vec<_> = r.faces.iter().map(|f| f.exact).collect();
    let analytic_chord = r.chordal_tolerance * REFERENCE_ANALYTIC_FACTOR;
    let reference = BrepReference::new(r.mesh.clone(), &exact, analytic_chord)
        .map_err(|e| format!("cannot build the B-rep reference: {e}"))?;
    let rulers = reference.rulers();
    let faces: Vec<String> = r
        .faces
        .iter()
        .zip(&r.mesh.groups)
        .zip(&rulers)
        .map(|((f, g), ruler)| {
            format!(
                "{} ({}, #{}): {}",
                g.name,
                surface_name(&f.surface),
                f.face_id,
                match ruler {
                    FaceRuler::Exact => "exact surface".to_string(),
                    FaceRuler::Facets => format!("facets at chordal tolerance {chord:.1e}"),
                }
            )
        })
        .collect();
    let exact_count = rulers.iter().filter(|r| **r == FaceRuler::Exact).count();
    let description = format!(
        "the B-rep: {exact_count} of {} faces measured to their exact surface, the others to \
         a tessellation at chordal tolerance {chord:.1e} of the diagonal",
        rulers.len()
    );
    Ok((reference, faces, description))
}

/// Where one job writes its files: the model's folder, or a tessellation's subfolder.
fn job_dir(dir: &Path, chord: Option<f64>) -> PathBuf {
    match chord {
        Some(c) => dir.join(format!("chord_{c:.1e}")),
        None => dir.to_path_buf(),
    }
}

/// The baselines' input files of one input mesh, written when first needed.
struct BaselineInputs {
    draco: PathBuf,
    draco_ok: Result<(), String>,
    glb: PathBuf,
    glb_ok: Result<(), String>,
}

fn write_inputs(dir: &Path, mesh: &ControlMesh, baselines: &Baselines) -> BaselineInputs {
    let draco = dir.join("input_f32.ply");
    let glb = dir.join("input.glb");
    let made = std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()));
    let draco_ok = match (&made, baselines.draco) {
        (Err(e), _) => Err(e.clone()),
        (Ok(()), Some(_)) => write_draco_input(&draco, mesh).map_err(|e| e.to_string()),
        (Ok(()), None) => Ok(()),
    };
    let glb_ok = match (&made, baselines.gltfpack) {
        (Err(e), _) => Err(e.clone()),
        (Ok(()), Some(_)) => write_gltfpack_input(&glb, mesh).map_err(|e| e.to_string()),
        (Ok(()), None) => Ok(()),
    };
    BaselineInputs {
        draco,
        draco_ok,
        glb,
        glb_ok,
    }
}

/// Runs every setting on one model. Never panics out: a panic while reading or measuring
/// becomes the model's error.
pub(super) fn run_model(
    index: usize,
    model: &ModelInput,
    dir: &Path,
    settings: &[Setting],
    baselines: &Baselines,
    opts: &ReportOptions,
    progress: &(dyn Fn(Progress) + Sync),
) -> ModelReport {
    let t0 = Instant::now();
    let mut report = empty_model(model);
    let prepared = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| prepare(model, opts)));
    let prepared = match prepared {
        Ok(Ok(p)) => p,
        Ok(Err(e)) => {
            report.error = Some(e);
            return report;
        }
        Err(_) => {
            report.error = Some("reader panicked".into());
            return report;
        }
    };
    report.vertices = prepared.nominal.vertex_count();
    report.triangles = prepared
        .nominal
        .faces()
        .map(|f| f.len().saturating_sub(2))
        .sum::<usize>();
    report.raw_bytes = raw_binary_bytes(&prepared.nominal);
    report.reference = prepared.reference.clone();
    report.faces = prepared.faces.clone();
    if let Err(e) = std::fs::create_dir_all(dir) {
        report.error = Some(format!("cannot create {}: {e}", dir.display()));
        return report;
    }
    let ruler = prepared.ruler();
    let mut inputs: BTreeMap<usize, BaselineInputs> = BTreeMap::new();
    for (setting, input) in prepared.jobs(settings, opts) {
        let chord = input.and_then(|i| prepared.inputs.get(i)).and_then(|m| m.0);
        let elapsed = t0.elapsed();
        let outcome = if elapsed >= opts.model_timeout {
            Err(format!(
                "skipped: the model's time budget ({} s) is used up",
                opts.model_timeout.as_secs()
            ))
        } else {
            let timeout = opts.step_timeout.min(opts.model_timeout - elapsed);
            let out_dir = job_dir(dir, chord);
            let base = input.map(|i| {
                inputs
                    .entry(i)
                    .or_insert_with(|| write_inputs(&out_dir, &prepared.inputs[i].1, baselines))
                    as &BaselineInputs
            });
            let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                run_point(
                    model,
                    setting,
                    base,
                    &out_dir.join(setting.file_name()),
                    (baselines, &ruler, opts, timeout),
                )
            }));
            run.unwrap_or_else(|_| Err("measurement panicked".into()))
        };
        let point = PointResult {
            setting,
            tessellation: chord,
            outcome,
        };
        progress(Progress::StepFinished {
            model: index,
            name: model.name.clone(),
            step: point.label(),
            ok: point.outcome.is_ok(),
        });
        report.points.push(point);
    }
    report.equal_error = equal_error(&report.points);
    report.seconds = t0.elapsed().as_secs_f64();
    report
}

/// Runs one setting: a baseline on its input files, or scode on the model's file.
fn run_point(
    model: &ModelInput,
    setting: Setting,
    inputs: Option<&BaselineInputs>,
    output: &Path,
    (baselines, ruler, opts, timeout): (&Baselines, &Ruler, &ReportOptions, Duration),
) -> Result<super::run::Measured, String> {
    match (setting, inputs) {
        (Setting::Draco { qp, cl }, Some(files)) => match (&files.draco_ok, baselines.draco) {
            (Ok(()), Some(tools)) => run_draco(
                tools,
                &files.draco,
                output,
                qp,
                cl,
                ruler,
                opts.runs,
                timeout,
            ),
            (Err(e), _) => Err(format!("cannot write Draco input: {e}")),
            (_, None) => Err("Draco not found".into()),
        },
        (Setting::Gltfpack { vp, cc }, Some(files)) => match (&files.glb_ok, baselines.gltfpack) {
            (Ok(()), Some(tool)) => run_gltfpack(
                tool,
                &files.glb,
                output,
                (vp, cc),
                ruler,
                opts.runs,
                timeout,
            ),
            (Err(e), _) => Err(format!("cannot write gltfpack input: {e}")),
            (_, None) => Err("gltfpack not found".into()),
        },
        (s, None) if s.is_scode() => run_scode_point(model, output, s, ruler, opts, timeout),
        (s, _) => Err(format!(
            "{} {}: no input to run it on",
            s.codec(),
            s.label()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brep_reference_needs_a_step_file() {
        let dir = std::env::temp_dir().join(format!("scode-report-model-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.obj");
        std::fs::write(&path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let model = ModelInput {
            path: path.clone(),
            name: "t.obj".into(),
            source: ModelSource::Mesh,
        };
        let mut opts = ReportOptions::quick();
        opts.reference = Some(Reference::Brep);
        let e = prepare(&model, &opts).err().unwrap();
        assert!(e.contains("needs a STEP file"), "{e}");
        opts.reference = None;
        let p = prepare(&model, &opts).unwrap();
        assert!(!p.step && p.brep.is_none() && p.inputs.len() == 1);
        // A mesh runs every setting, baselines on its one input.
        let jobs = p.jobs(&opts.settings(true, true), &opts);
        assert_eq!(jobs.len(), opts.settings(true, true).len());
        assert!(jobs.iter().all(|(s, i)| s.is_scode() == i.is_none()));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_face_left_out_goes_with_its_triangles_and_edges() {
        // Three faces in a strip of triangles, with sharp edges between them.
        let mut mesh = ControlMesh::new();
        for i in 0..5 {
            mesh.push_vertex(glam::DVec3::new(f64::from(i), f64::from(i % 2), 0.0));
        }
        let mut faces = Vec::new();
        for (g, id) in [11u64, 22, 33].into_iter().enumerate() {
            mesh.push_group(format!("face_{}", g + 1), scode::mesh::PatchKind::Closed);
            let g = g as u32;
            mesh.push_face(&[g, g + 1, g + 2], g);
            faces.push(scode::io::step::FaceSurface {
                face_id: id,
                surface_id: 0,
                body: 0,
                surface: scode::io::SurfaceType::Plane,
                entity: "PLANE".into(),
                exact: None,
                revolution_axis: None,
            });
        }
        mesh.sharp_edges = [(1, 2), (1, 3), (2, 3)].into_iter().collect();
        let model = StepModel {
            mesh,
            faces,
            ..StepModel::default()
        };
        let kept = without_faces(&model, &[22].into_iter().collect());
        let names: Vec<&str> = kept.mesh.groups.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names, ["face_1", "face_3"]);
        assert_eq!(
            kept.faces.iter().map(|f| f.face_id).collect::<Vec<_>>(),
            [11, 33]
        );
        assert_eq!(kept.mesh.face_groups, [0, 1]);
        assert_eq!(kept.mesh.face(1), [2, 3, 4]);
        // Vertices stay (the part's size does not change); (1, 3) was only face 2's edge.
        assert_eq!(kept.mesh.positions.len(), 5);
        assert_eq!(
            kept.mesh.sharp_edges,
            [(1, 2), (2, 3)].into_iter().collect()
        );
        assert_eq!(without_faces(&model, &BTreeSet::new()).mesh.groups.len(), 3);
    }
}
