//! The fitting encoder: from a face-grouped triangle mesh (a tessellated B-rep) to a coarse
//! control mesh whose subdivision surface stays within a tolerance of the input.
//!
//! [`fit_model`] drives the steps, each in its own module and each deterministic:
//! 1. **Faces** ([`super::classify`]). The input's groups (one per CAD face) with their
//!    surface types where the caller knows them, the rest classified by least-squares
//!    primitive fits; an ungrouped mesh is segmented first ([`super::segment`]).
//! 2. **Chains** ([`super::chains`]). Corners and the boundary chains between them
//!    ([`super::curves`]), and the few vertices of each chain that become control points,
//!    shared by both adjacent faces.
//! 3. **Build** ([`super::build`]). A constrained decimation ([`super::decimate`]) to the
//!    control mesh, face by face (a round redoes only the faces whose problem changed):
//!    sharp edges on the group boundaries, corners at the B-rep vertices, watertight by
//!    construction.
//! 4. **Solve** ([`super::solve`]). Control points placed so the limit surface under the
//!    decoder's own rules matches the input, by linearised least squares.
//! 5. **Measure** ([`super::measure`], against [`super::reference`]). The caller's
//!    `reconstruct` callback quantises the control mesh the way the bitstream will; the
//!    decoded surface at the default level is measured against the input both ways.
//! 6. **Refine** ([`super::refine`], driven by [`super::rounds`]). Faces and chains that
//!    exceed the tolerance get more control points (the plan of [`super::plan`]) and the
//!    model is rebuilt, until the tolerance holds; then closed patches that ended far within
//!    it are coarsened again once, and ([`super::quantise`]) the smaller file of the two
//!    models, each at the coarsest quantisation that still holds the tolerance, is kept.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::DVec3;

use super::chains::Chains;
use super::classify::classify_faces;
use super::decimate::SurfaceRef;
use super::domain::PlaneDomain;
pub use super::exact::ExactSurface;
use super::plan::{kind_name, Plan};
use super::quantise::{smallest_file, Quantised};
use super::reference::{reference_facets, triangulated, Allowances, FacetAllowance, Facets};
use super::rounds::Rounds;
use crate::error::{Error, Result};
use crate::mesh::{ControlMesh, PatchKind, Tolerance};
use crate::metrics::{DistanceOptions, SampleCount};

/// What the input says a group's surface is (a STEP face type or a sidecar entry).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SurfaceHint {
    Plane,
    Cylinder,
    Cone,
    /// A sphere or torus: a boundary patch when the face is narrow enough for one (see
    /// `fit::classify`), else a closed patch.
    Sphere,
    Torus,
    /// B-spline, revolution, ...: a closed patch.
    Freeform,
    /// Unknown: classify from the geometry.
    Unknown,
}

/// Options of [`fit_model`].
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    /// Largest allowed distance between input and decoded surface; default
    /// [`Tolerance::DEFAULT`] (relative bounds are taken against the input's diagonal).
    pub tolerance: Tolerance,
    /// Largest allowed mean distance (the larger of the two directions' means); `None`:
    /// unbounded. The fit's rounds are driven by `tolerance`; this bound keeps the
    /// quantisation search from trading mean error for bytes (at a loose `tolerance` a
    /// coarser grid step can keep the max within it while the mean grows). A fit whose mean
    /// is over it even at the default step is reported out of tolerance.
    pub mean_tolerance: Option<Tolerance>,
    /// Decode level the tolerance is checked at (the level stored as the file's default);
    /// default: the coarsest of 3, 4 and 5 the fit finds it takes (a finer level where the
    /// chord error between a face's decoded triangles' corners is what it misses by).
    pub default_level: Option<u8>,
    /// Segmentation of ungrouped meshes: dihedral angle of sharp edges.
    pub sharp_angle_deg: f64,
    /// Rebuild rounds with more control points before the groups still out of tolerance
    /// are stored as their input facets; a few more rounds may follow to measure those
    /// (each facets the groups still failing) before the fit gives up on the tolerance.
    pub max_rounds: usize,
    /// Random area-weighted samples of the input for the error measurement, and of the
    /// decoded surface as many per unit of the input's area (besides the vertices and the
    /// points along thin triangles' edges). The default is `scode info --against`'s, so the
    /// fit measures a file as it does.
    pub samples: SampleCount,
    /// After the fit, try up to this many bits coarser quantisation than the default, and keep
    /// the coarsest that still meets the tolerance (0: keep the default); then (with
    /// `quarter_bit_steps`) up to 3/4 bit more in quarter bits, each kept only if it also
    /// makes the file smaller and keeps the RMS error within a quarter of the tolerance (a
    /// fractional step trades RMS error for bytes, and the RMS bound keeps the surface as
    /// close to the reference on average as the whole-bit steps do).
    pub max_coarser_bits: u8,
    /// Whether the quantisation search goes on in quarter bits after whole bits (see
    /// `max_coarser_bits`): two more measurements for a few percent on most models.
    pub quarter_bit_steps: bool,
    /// Refine a failing closed patch only near where it fails (its decimation threshold
    /// lowered within two control edges of the samples out of tolerance) instead of
    /// everywhere. That is all it changes: a fit without failing closed patches is the same
    /// either way. Off by default: it makes smaller files on some models and larger ones on
    /// others; `Effort::Max` tries both.
    pub local_refinement: bool,
    /// Plane patches keep the control points their faces need: the decimation refuses a
    /// collapse that would make an interior edge leave the face (across a hole or a concave
    /// notch; a plane's interior edges decode straight), and a failing group refines only the
    /// boundary chains near where it fails, not all of them: fewer control points on plates
    /// with many holes. On by default, for face groups from the input; a segmented mesh's
    /// planes are decimated freely (its regions' outlines are the segmenter's guesses, and
    /// keeping them costs control points for no gain in accuracy). `Effort::Max` tries both.
    pub keep_planes_on_faces: bool,
    /// Once the model is within tolerance, coarsen the refined closed patches that ended far
    /// within it by half a refinement step, restore those that then fail, and keep whichever
    /// model (converged or relaxed, each at its coarsest quantisation) makes the smaller file
    /// (see `Relaxation`). Costs one or two more rounds.
    pub relax: bool,
    /// By input group: the face's exact surface where the input knows it (a STEP face's
    /// plane, cylinder, cone, sphere or torus), else `None`; empty for none at all. The input
    /// is then a B-rep's tessellation ([`Reference::Brep`]): the decoded surface of a group
    /// with an exact surface is held within the tolerance of that surface where it lies over
    /// the face (see `facet_chord` for the rest), and a closed patch is fitted onto it (as
    /// are creases whose faces all have one).
    pub exact_surfaces: Vec<Option<ExactSurface>>,
    /// By input group, with `exact_surfaces`: how far the measured facets (the input's, or
    /// `reference`'s) may lie from the B-rep face they tessellate, their chordal tolerance
    /// in model units. A face without an exact surface is held to the tolerance less this
    /// (its facets plus their chord bound its distance to the B-rep); a face with one is
    /// held to the tolerance of its exact surface where it lies over the face, and where it
    /// strays beyond the face's outline, of its facets plus their chord. Empty: 0.
    pub facet_chord: Vec<f64>,
    /// Measure beyond the input's own chord error: each input facet's estimated distance
    /// from the CAD surface it tessellates (from its vertex normals, and from the analytic
    /// surface of cylinder and cone faces) is allowed on top of the tolerance. Off by default,
    /// so that the tolerance bounds the plain distance to the input, as any mesh tool
    /// measures it; on for a coarse tessellation of a smooth part, whose facets no smooth
    /// surface comes nearer to than their sagitta (without it, the fit stores such faces as
    /// their facets: [`FitReport::faceted_groups`]). With `exact_surfaces` (STEP input) the
    /// B-rep is measured instead (`facet_chord`), and this is not read.
    pub chord_allowance: bool,
    /// A finer tessellation of the same faces (the same groups, by name, in the same order)
    /// to measure the decoded surface against instead of the input; the fit still starts
    /// from and fits to the input's triangles. `None`: measured against the input.
    pub reference: Option<ControlMesh>,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            tolerance: Tolerance::DEFAULT,
            mean_tolerance: None,
            default_level: None,
            sharp_angle_deg: 30.0,
            max_rounds: 8,
            samples: DistanceOptions::default().samples,
            max_coarser_bits: 3,
            quarter_bit_steps: true,
            local_refinement: false,
            keep_planes_on_faces: true,
            relax: true,
            exact_surfaces: Vec::new(),
            facet_chord: Vec::new(),
            chord_allowance: false,
            reference: None,
        }
    }
}

/// Measured distances between the input and the decoded surface (model units).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FitError {
    pub max: f64,
    pub rms: f64,
    pub mean: f64,
    /// The quantity the tolerance bounds: the largest distance to the reference as
    /// [`FitReport::reference`] says (the plain distance to the input, the distance beyond
    /// its facets' own chord error, or the distance to the B-rep). Against a B-rep, `max`,
    /// `rms` and `mean` are of distances to the B-rep too.
    pub max_excess: f64,
}

/// What a fit's error is measured against: the reference the tolerance is a promise about.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Reference {
    /// The input mesh as given: the plain distance, what `scode info --against` and any
    /// mesh tool measure.
    #[default]
    InputMesh,
    /// The input mesh, less each facet's chord error (its estimated distance from the CAD
    /// surface it tessellates): for coarse tessellations, whose facets a smooth surface
    /// cannot come nearer to than their sagitta ([`crate::EncodeOptions::chord_allowance`]).
    InputBeyondChord,
    /// A B-rep (STEP input): faces on analytic surfaces against those surfaces where the
    /// decoded surface lies over the face, the others (and points beyond a face's outline)
    /// against a tessellation of the B-rep plus its chordal tolerance, an upper bound of the
    /// distance to the B-rep (`FitOptions::facet_chord`).
    Brep,
}

impl Reference {
    /// What the error was measured against, for messages ("vs ...").
    pub fn describe(self) -> &'static str {
        match self {
            Reference::InputMesh => "the input mesh",
            Reference::InputBeyondChord => "the input mesh beyond its facets' chord error",
            Reference::Brep => {
                "the B-rep (exact surfaces; other faces as their facets plus their chord)"
            }
        }
    }
}

/// What the encoder did, for `--verbose` and the report.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FitReport {
    pub tolerance: f64,
    /// What the error was measured against.
    pub reference: Reference,
    /// [`FitOptions::mean_tolerance`], model units.
    pub mean_tolerance: Option<f64>,
    pub diagonal: f64,
    /// The input had no groups and was segmented.
    pub segmented: bool,
    /// Patch kinds of the output groups ("closed", "plane", "cylinder", "cone").
    pub patch_kinds: BTreeMap<&'static str, usize>,
    pub control_vertices: usize,
    pub control_faces: usize,
    pub rounds: usize,
    pub default_level: u8,
    /// Error of the decoded surface (quantised, default level, limit positions).
    pub error: FitError,
    pub within_tolerance: bool,
    /// How many times a failing closed patch was refined (over all rounds and groups). When
    /// it is 0, [`FitOptions::local_refinement`] would not have changed the fit.
    pub closed_refinements: usize,
    /// Groups stored as their input facets: no smooth patch came within the tolerance of
    /// them (see [`FitOptions::chord_allowance`] for coarse tessellations of smooth parts).
    pub faceted_groups: usize,
    /// Stage name and seconds.
    pub timings: Vec<(&'static str, f64)>,
    pub notes: Vec<String>,
}

/// The result of [`fit_model`].
pub struct FitOutcome {
    /// The control mesh to store (before quantisation).
    pub control: ControlMesh,
    /// How many quarter bits coarser than the caller's default quantisation still meets
    /// the tolerance (the `reconstruct` argument that was measured last within it): the grid
    /// step is the default's times `2^(coarser_quarter_bits / 4)`.
    pub coarser_quarter_bits: u8,
    pub default_level: u8,
    pub report: FitReport,
}

/// Fits a control mesh to `input` (a triangle or polygon mesh; polygons are fan-split).
/// `hints[g]` is what the input says group g's surface is (or `Unknown`). `reconstruct`
/// must return the control mesh exactly as the decoder will see it (quantised with a grid
/// step `2^(coarser / 4)` times the caller's default, stored for decode level `level`), with the
/// input's group numbering, and the size of the file it was decoded from:
/// `reconstruct(control, level, coarser) -> (decoded, bytes)`. The sizes decide between
/// candidate control meshes that all meet the tolerance.
pub fn fit_model(
    input: &ControlMesh,
    hints: &[SurfaceHint],
    opts: &FitOptions,
    reconstruct: &mut Reconstruct<'_>,
) -> Result<FitOutcome> {
    let t_start = Instant::now();
    let mut report = FitReport::default();
    input.validate()?;
    if input.face_count() == 0 {
        return Err(Error::Mesh("the input has no faces".into()));
    }
    // The fit works on the input's triangles.
    let mesh = triangulated(input);
    let diag = mesh.diagonal();
    let (tol, mean_tol) = checked_tolerances(opts, diag)?;
    report.tolerance = tol;
    report.reference = match (opts.chord_allowance, opts.exact_surfaces.is_empty()) {
        (_, false) => Reference::Brep,
        (true, true) => Reference::InputBeyondChord,
        (false, true) => Reference::InputMesh,
    };
    report.mean_tolerance = mean_tol;
    report.diagonal = diag;
    let mut t = Instant::now();
    let faces = classify_faces(mesh, hints, opts, tol, &mut report)?;
    let keep_planes_on_faces = opts.keep_planes_on_faces && !faces.segmented;
    report.timings.push(("faces", t.elapsed().as_secs_f64()));
    t = Instant::now();
    let chains = Chains::new(&faces.mesh, tol)?;
    let input = Facets::new(faces.mesh.clone(), faces.tris.clone());
    let plane_domains = if keep_planes_on_faces {
        plane_domains(&input, &faces.surfaces, tol)
    } else {
        Vec::new()
    };
    // What the decoded surface is measured against: the input, or the finer tessellation of
    // the same faces the caller gave (`FitOptions::reference`).
    let kinds: Vec<PatchKind> = faces.plans.iter().map(|p| p.kind).collect();
    let reference = reference_facets(
        opts.reference.as_ref(),
        &faces.mesh,
        faces.segmented,
        &mut report,
    );
    let (measured, net) = match &reference {
        Some(r) => (r, None),
        None => (&input, Some(&chains.net)),
    };
    // A segmented input's groups are not the input's: no exact surfaces then.
    let exact: &[Option<ExactSurface>] = if faces.segmented {
        &[]
    } else {
        &opts.exact_surfaces
    };
    let rule = match report.reference {
        Reference::InputMesh => FacetAllowance::Plain,
        Reference::InputBeyondChord => FacetAllowance::Estimated,
        Reference::Brep => FacetAllowance::Brep {
            exact,
            facet_chord: if faces.segmented {
                &[]
            } else {
                &opts.facet_chord
            },
        },
    };
    let allowances = Allowances::new(measured, net, &kinds, rule)?;
    report.timings.push(("curves", t.elapsed().as_secs_f64()));
    let exact_faces = exact.iter().flatten().count();
    if exact_faces > 0 {
        report.notes.push(format!(
            "{exact_faces} of {} faces measured against their exact surfaces too",
            faces.mesh.groups.len()
        ));
    }
    let sampling = DistanceOptions {
        samples: opts.samples,
        ..Default::default()
    };
    let meter = allowances.meter(measured, exact, &sampling, tol);
    let mut plan = Plan::new(
        faces.plans.clone(),
        faces.mesh.vertex_count(),
        chains.net.chains.len(),
        tol,
    );
    // Faceting meets a tolerance held to the input mesh itself, which the facets are, and
    // one held to a B-rep whose facets are within their chordal tolerance of it (which the
    // STEP tessellation keeps well below the tolerance): the last resort of a face no smooth
    // patch gets within the tolerance of. Beyond estimated chord errors smooth patches get
    // there.
    for group in &mut plan.groups {
        group.facetable = report.reference != Reference::InputBeyondChord;
    }
    let rounds = Rounds {
        faces: &faces,
        chains: &chains,
        input: &input,
        exact,
        plane_domains: &plane_domains,
        meter: &meter,
        opts,
        tol,
        keep_planes_on_faces,
    };
    let candidates = rounds.run(&mut plan, reconstruct, &mut report)?;
    t = Instant::now();
    let chosen = smallest_file(
        candidates,
        faces.segmented,
        &meter,
        opts,
        (tol, mean_tol),
        reconstruct,
        &mut report,
    )?;
    report
        .timings
        .push(("quantisation", t.elapsed().as_secs_f64()));
    finish_report(&mut report, &chosen, tol, mean_tol);
    report
        .timings
        .push(("total", t_start.elapsed().as_secs_f64()));
    Ok(FitOutcome {
        control: chosen.control,
        coarser_quarter_bits: chosen.coarser_quarter_bits,
        default_level: chosen.level,
        report,
    })
}

/// The tolerance and the mean tolerance the fit holds, in model units for a model of
/// diagonal `diag`, checked to be positive and finite.
fn checked_tolerances(opts: &FitOptions, diag: f64) -> Result<(f64, Option<f64>)> {
    let tol = opts.tolerance.checked(diag, "tolerance")?;
    let mean = opts
        .mean_tolerance
        .map(|m| m.checked(diag, "mean tolerance"))
        .transpose()?;
    Ok((tol, mean))
}

/// Where each plane face lies in its plane, for the decimation's domain test (`None` for
/// the other faces).
fn plane_domains(input: &Facets, surfaces: &[SurfaceRef], tol: f64) -> Vec<Option<PlaneDomain>> {
    input
        .group_tris
        .iter()
        .zip(surfaces)
        .map(|(ids, surface)| match *surface {
            SurfaceRef::Plane { normal } => {
                let t: Vec<[DVec3; 3]> = ids
                    .iter()
                    .map(|&t| input.tris[t as usize].map(|v| input.mesh.positions[v as usize]))
                    .collect();
                PlaneDomain::new(&t, normal, tol)
            }
            _ => None,
        })
        .collect()
}

/// The report's summary of the chosen model.
fn finish_report(report: &mut FitReport, chosen: &Quantised, tol: f64, mean_tol: Option<f64>) {
    let err = chosen.err;
    if chosen.coarser_quarter_bits > 0 {
        report.notes.push(format!(
            "quantisation: {} bits coarser than the default still meets the tolerance \
             (max error {:.3e}, {:.2} tol vs {})",
            f64::from(chosen.coarser_quarter_bits) / 4.0,
            err.max,
            err.max_excess / tol,
            report.reference.describe()
        ));
    }
    let mean_ok = mean_tol.is_none_or(|mt| err.mean <= mt);
    report.error = err;
    report.within_tolerance = err.max_excess <= tol && mean_ok;
    if !mean_ok {
        report.notes.push(format!(
            "mean error {:.3e} is over the mean tolerance {:.3e}: lower the tolerance",
            err.mean,
            mean_tol.unwrap_or(f64::INFINITY)
        ));
    }
    report.default_level = chosen.level;
    report.faceted_groups = chosen.faceted;
    report.control_vertices = chosen.control.vertex_count();
    report.control_faces = chosen.control.face_count();
    for g in &chosen.control.groups {
        *report.patch_kinds.entry(kind_name(&g.patch)).or_insert(0) += 1;
    }
}

/// The quantise-encode-decode callback of [`fit_model`]: `(control, level, coarser)` to the
/// decoded control mesh and the size of its file in bytes; `coarser` counts quarter bits.
pub type Reconstruct<'a> = dyn FnMut(&ControlMesh, u8, u8) -> Result<(ControlMesh, usize)> + 'a;

/// Adds to a mesh error the CAD faces (groups) whose control faces break the control mesh's
/// topology (a side used twice in one direction, or by more than two faces; else the faces
/// around a vertex with more than two open sides, where holes touch), so a failing
/// fit names the B-rep faces to look at instead of only vertex numbers.
pub(crate) fn with_faces_involved(e: Error, control: &ControlMesh) -> Error {
    let Error::Mesh(msg) = e else { return e };
    let mut uses: std::collections::BTreeMap<(u32, u32), Vec<(usize, bool)>> = Default::default();
    for f in 0..control.face_count() {
        let face = control.face(f);
        for k in 0..face.len() {
            let (a, b) = (face[k], face[(k + 1) % face.len()]);
            uses.entry(crate::mesh::edge_key(a, b))
                .or_default()
                .push((f, a < b));
        }
    }
    let mut groups = std::collections::BTreeSet::new();
    for faces in uses.values() {
        let forward = faces.iter().filter(|u| u.1).count();
        if faces.len() > 2 || forward > 1 || faces.len() - forward > 1 {
            for &(f, _) in faces {
                if let Some(&g) = control.face_groups.get(f) {
                    groups.insert(g);
                }
            }
        }
    }
    if groups.is_empty() {
        // A vertex where two holes touch (more than two open sides): the faces around it.
        let mut open_sides: BTreeMap<u32, usize> = BTreeMap::new();
        for (&(a, b), faces) in &uses {
            if faces.len() == 1 {
                *open_sides.entry(a).or_default() += 1;
                *open_sides.entry(b).or_default() += 1;
            }
        }
        for f in 0..control.face_count() {
            if control
                .face(f)
                .iter()
                .any(|v| open_sides.get(v).is_some_and(|&n| n > 2))
            {
                if let Some(&g) = control.face_groups.get(f) {
                    groups.insert(g);
                }
            }
        }
    }
    if groups.is_empty() {
        return Error::Mesh(msg);
    }
    let names: Vec<String> = groups
        .iter()
        .take(8)
        .map(|&g| {
            control
                .groups
                .get(g as usize)
                .map_or_else(|| format!("group {g}"), |gr| format!("'{}'", gr.name))
        })
        .collect();
    Error::Mesh(format!(
        "{msg} (CAD faces involved: {}{})",
        names.join(", "),
        if groups.len() > 8 { ", ..." } else { "" }
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles of groups `a` and `b` touching at vertex 0 only, and a third group
    /// elsewhere: the error names the two faces around the pinch, not the third.
    #[test]
    fn faces_around_a_pinched_vertex_are_named() {
        let mut m = ControlMesh::new();
        for p in [
            DVec3::ZERO,
            DVec3::X,
            DVec3::Y,
            -DVec3::X,
            -DVec3::Y,
            DVec3::new(5.0, 0.0, 0.0),
            DVec3::new(6.0, 0.0, 0.0),
            DVec3::new(5.0, 1.0, 0.0),
        ] {
            m.push_vertex(p);
        }
        for name in ["a", "b", "c"] {
            m.push_group(name, PatchKind::Closed);
        }
        m.push_face(&[0, 1, 2], 0);
        m.push_face(&[0, 3, 4], 1);
        m.push_face(&[5, 6, 7], 2);
        let e = with_faces_involved(Error::Mesh("vertex 0 is pinched".into()), &m).to_string();
        assert!(e.contains("'a'") && e.contains("'b'"), "{e}");
        assert!(!e.contains("'c'"), "{e}");
        // Other errors pass through as they are.
        let e = with_faces_involved(Error::Parameter("p".into()), &m);
        assert!(matches!(e, Error::Parameter(_)));
    }

    /// A side used twice in one direction names the faces using it.
    #[test]
    fn faces_sharing_a_side_in_one_direction_are_named() {
        let mut m = ControlMesh::new();
        for p in [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::NEG_Y] {
            m.push_vertex(p);
        }
        m.push_group("a", PatchKind::Closed);
        m.push_group("b", PatchKind::Closed);
        m.push_face(&[0, 1, 2], 0);
        m.push_face(&[0, 1, 3], 1);
        let e = with_faces_involved(Error::Mesh("edge".into()), &m).to_string();
        assert!(e.contains("CAD faces involved: 'a', 'b'"), "{e}");
    }
}
