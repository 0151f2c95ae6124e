//! Face-by-face tessellation with truck and welding into one vertex pool.
//!
//! Each face is tessellated alone (a one-face shell with only its own edges), so a face
//! that panics or hangs costs only itself. truck polylines an edge the same way whichever
//! face it is tessellated with (same curve, same range, same tolerance), so the first face
//! that uses an edge fixes its polyline in the pool and every later face snaps its boundary
//! vertices to those pool points: shared boundaries are shared vertices.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::time::Instant;

use glam::DVec3;
use truck_meshalgo::prelude::{PolygonMesh, RobustMeshableShape};
use truck_stepio::r#in::alias::{
    BoundedCurve, Curve3D, ParametricCurve, Point3, PolylineCurve, Surface,
};
use truck_topology::compress::{
    CompressedEdge, CompressedEdgeIndex, CompressedFace, CompressedShell,
};

use super::brep::{Parsed, ParsedBody, ParsedFace};
use super::conform;
use super::watch::{Cancel, Guarded, Watched, Workers};
#[cfg(feature = "internals")]
use super::BrepEdge;
use super::{Body, FaceSurface, SkippedFace, StepModel, StepOptions};
use crate::error::{Error, Result};
use crate::io::faces_json::SurfaceType;
use crate::mesh::{AnalyticSurface, Axis, BoundarySurface, ControlMesh, PatchKind, Tolerance};

type MeshedShell = CompressedShell<Point3, PolylineCurve<Point3>, Option<PolygonMesh>>;
/// One face as a shell of its own, for truck's tessellator.
type FaceShell = CompressedShell<Point3, Curve3D, Surface>;
/// A face shell whose curves and surface stop truck's tessellator at the job's timeout.
type GuardedShell = CompressedShell<Point3, Guarded<Curve3D>, Guarded<Surface>>;

fn dv(p: &Point3) -> DVec3 {
    DVec3::new(p.x, p.y, p.z)
}

/// Bounding-box diagonal of the B-rep vertices and sampled edge curves, each body where its
/// placement puts it as the tessellation does (file units): a relative chordal tolerance is
/// a fraction of the diagonal of the model the encoder measures. An edge curve is sampled
/// only when its parameter range runs from one of its vertices to the other: a reader may
/// give an edge its whole underlying curve (a full circle under an arc, a long line), which
/// the tessellation trims to the vertices, and whose other points would make the diagonal,
/// and so the chord, larger than the tessellated model's.
fn brep_diagonal(parsed: &Parsed) -> f64 {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for b in &parsed.bodies {
        let place = |p: &Point3| b.placement.transform_point3(dv(p));
        for p in &b.vertices {
            let p = place(p);
            lo = lo.min(p);
            hi = hi.max(p);
        }
        for e in &b.edges {
            let (t0, t1) = e.curve.range_tuple();
            if !(t0.is_finite() && t1.is_finite()) {
                continue;
            }
            let samples: Vec<DVec3> = (0..=16)
                .map(|k| place(&e.curve.subs(t0 + (t1 - t0) * k as f64 / 16.0)))
                .collect();
            let (Some(&first), Some(&last)) = (samples.first(), samples.last()) else {
                continue;
            };
            let (Some(a), Some(c)) = (b.vertices.get(e.vertices.0), b.vertices.get(e.vertices.1))
            else {
                continue;
            };
            let (a, c) = (place(a), place(c));
            let span = samples.iter().fold(0.0f64, |m, p| m.max(p.distance(first)));
            let near = |p: DVec3, q: DVec3| p.distance(q) <= 1e-3 * span + 1e-12;
            let from_vertex_to_vertex =
                (near(first, a) && near(last, c)) || (near(first, c) && near(last, a));
            if !from_vertex_to_vertex {
                continue;
            }
            for p in samples.into_iter().filter(|p| p.is_finite()) {
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
    }
    let d = (hi - lo).length();
    if d.is_finite() {
        d
    } else {
        0.0
    }
}

/// One face as a shell of its own (local edge and vertex indices), plus the body-level
/// index of each local edge.
fn single_face_shell(
    body: &ParsedBody,
    face: &CompressedFace<Surface>,
) -> (FaceShell, Vec<usize>, Vec<usize>) {
    let mut edge_local: BTreeMap<usize, usize> = BTreeMap::new();
    let mut vertex_local: BTreeMap<usize, usize> = BTreeMap::new();
    let mut edges_global = Vec::new();
    let mut vertices_global = Vec::new();
    let mut boundaries = Vec::new();
    for wire in &face.boundaries {
        let mut w = Vec::new();
        for ei in wire {
            let local = *edge_local.entry(ei.index).or_insert_with(|| {
                edges_global.push(ei.index);
                edges_global.len() - 1
            });
            w.push(CompressedEdgeIndex {
                index: local,
                orientation: ei.orientation,
            });
        }
        boundaries.push(w);
    }
    let mut edges = Vec::new();
    for &g in &edges_global {
        let e = &body.edges[g];
        let mut vl = |v: usize| {
            *vertex_local.entry(v).or_insert_with(|| {
                vertices_global.push(v);
                vertices_global.len() - 1
            })
        };
        let a = vl(e.vertices.0);
        let b = vl(e.vertices.1);
        edges.push(CompressedEdge {
            vertices: (a, b),
            curve: e.curve.clone(),
        });
    }
    let vertices = vertices_global.iter().map(|&v| body.vertices[v]).collect();
    (
        CompressedShell {
            vertices,
            edges,
            faces: vec![CompressedFace {
                surface: face.surface.clone(),
                boundaries,
                orientation: face.orientation,
            }],
        },
        edges_global,
        vertices_global,
    )
}

/// `shell` with its curves and surfaces evaluated through the job's token.
fn guard_shell(shell: FaceShell, cancel: &Cancel) -> GuardedShell {
    CompressedShell {
        vertices: shell.vertices,
        edges: shell
            .edges
            .into_iter()
            .map(|e| CompressedEdge {
                vertices: e.vertices,
                curve: Guarded::new(e.curve, cancel),
            })
            .collect(),
        faces: shell
            .faces
            .into_iter()
            .map(|f| CompressedFace {
                surface: Guarded::new(f.surface, cancel),
                boundaries: f.boundaries,
                orientation: f.orientation,
            })
            .collect(),
    }
}

/// Pool of welded vertices. Boundary points (B-rep vertices and edge polyline points) are
/// added with [`Pool::push_welded`], which returns an existing point of the same body within
/// the weld distance: files that repeat a VERTEX_POINT at one position, or edges whose
/// polylines touch, then share one vertex instead of two at the same place (which a face's
/// triangulation could not tell apart).
#[derive(Default)]
struct Pool {
    positions: Vec<DVec3>,
    /// (body, grid cell) -> boundary points in it; cell size = weld distance.
    cells: BTreeMap<(usize, [i64; 3]), Vec<u32>>,
}

impl Pool {
    fn push(&mut self, p: DVec3) -> u32 {
        self.positions.push(p);
        (self.positions.len() - 1) as u32
    }

    fn cell(p: DVec3, size: f64) -> [i64; 3] {
        let c = (p / size).floor();
        [c.x as i64, c.y as i64, c.z as i64]
    }

    fn push_welded(&mut self, body: usize, p: DVec3, weld: f64) -> u32 {
        let c = Self::cell(p, weld);
        let mut best: Option<(u32, f64)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let key = (body, [c[0] + dx, c[1] + dy, c[2] + dz]);
                    for &id in self.cells.get(&key).into_iter().flatten() {
                        let d = self.positions[id as usize].distance(p);
                        if d <= weld && best.is_none_or(|b| d < b.1) {
                            best = Some((id, d));
                        }
                    }
                }
            }
        }
        if let Some((id, _)) = best {
            return id;
        }
        let id = self.push(p);
        self.cells.entry((body, c)).or_default().push(id);
        id
    }
}

/// Tessellates every face of `parsed` and welds the faces into one mesh, a group per face,
/// in millimetres when the file gives its unit.
pub(super) fn tessellate(path: &Path, parsed: Parsed, opts: &StepOptions) -> Result<StepModel> {
    if parsed.bodies.iter().all(|b| b.faces.is_empty()) {
        return Err(no_face_error(path, &parsed.skipped));
    }
    let scale = parsed.millimetres_per_unit.unwrap_or(1.0);
    let tol = Tolerances::choose(path, brep_diagonal(&parsed), scale, opts)?;
    let Parsed {
        bodies,
        skipped,
        notes,
        millimetres_per_unit,
        workers,
    } = parsed;
    let mut model = WeldedModel::new(path, opts, tol, &bodies, skipped, workers);
    for (body_index, body) in bodies.iter().enumerate() {
        model.add_body(body_index, body)?;
    }
    model.finish(&bodies, notes, millimetres_per_unit)
}

/// The tolerances of one tessellation, in file units.
struct Tolerances {
    /// Bounding-box diagonal of the B-rep.
    diag: f64,
    /// Chordal tolerance of truck's tessellation and of edges that a face without an exact
    /// analytic surface uses.
    chord: f64,
    /// Faces with an exact analytic surface, and edges only they use, get `chord` times this.
    analytic_factor: f64,
    /// How far a vertex of truck's face tessellation may move to snap to an edge point.
    snap: f64,
    /// Polyline points closer than this to the previous one are the same point.
    merge: f64,
    /// Boundary points closer than this are one vertex (model coordinates).
    weld: f64,
}

impl Tolerances {
    /// The tolerances `opts` ask for on a model whose diagonal is `diag` file units of
    /// `scale` millimetres; an error when they are not positive numbers.
    fn choose(path: &Path, diag: f64, scale: f64, opts: &StepOptions) -> Result<Self> {
        let chord_mm = match opts.chordal_tolerance {
            Tolerance::Absolute(t) => t,
            Tolerance::Relative(f) => f * diag * scale,
        };
        if !(chord_mm > 0.0 && chord_mm.is_finite()) {
            return Err(Error::input(
                path,
                format!(
                    "cannot choose a chordal tolerance (model size {diag}, tolerance {chord_mm})"
                ),
            ));
        }
        // truck panics below its TOLERANCE (1e-6) in file units.
        let chord = (chord_mm / scale).max(2e-6);
        let analytic_factor = opts.analytic_chordal_factor;
        if !(analytic_factor > 0.0 && analytic_factor.is_finite()) {
            return Err(Error::Parameter(format!(
                "the chordal factor of analytic faces must be positive, got {analytic_factor}"
            )));
        }
        Ok(Self {
            diag,
            chord,
            analytic_factor,
            snap: 0.05 * chord,
            merge: 1e-9 * diag.max(chord),
            weld: 1e-3 * chord,
        })
    }
}

/// What the tessellation did that the notes report.
#[derive(Default)]
struct Tally {
    /// Faces tessellated by `conform` (boundary = edge polylines by construction).
    conforming: usize,
    /// The faces that fell back to truck's tessellation, with the reason.
    fallback: Vec<String>,
    /// Edge polylines trimmed to their vertices.
    trimmed_edges: usize,
    /// Edge uses turned round to chain their loop.
    reversed_in_loop: usize,
    /// Triangles dropped because they overlapped others of their face.
    overlapping: usize,
    /// Boundary vertices of truck's face meshes that matched no edge point.
    unsnapped: usize,
    /// Largest move of a vertex of truck's face meshes onto an edge point (file units).
    snap_max: f64,
}

impl Tally {
    /// Appends the notes on these counts; `scale` turns file units into the model's.
    fn push_notes(&self, notes: &mut Vec<String>, scale: f64) {
        notes.push(format!(
            "{} faces tessellated on their edge polylines; {} by truck's tessellator",
            self.conforming,
            self.fallback.len()
        ));
        if self.trimmed_edges > 0 {
            notes.push(format!(
                "{} edge polylines trimmed to their vertices (truck's curve ran past them)",
                self.trimmed_edges
            ));
        }
        if self.reversed_in_loop > 0 {
            notes.push(format!(
                "{} edge uses turned round to chain their loops",
                self.reversed_in_loop
            ));
        }
        for f in self.fallback.iter().take(20) {
            notes.push(format!("truck tessellated {f}"));
        }
        if self.overlapping > 0 {
            notes.push(format!(
                "dropped {} triangles that overlapped others of their face (folded or doubled \
                 tessellation)",
                self.overlapping
            ));
        }
        if self.unsnapped > 0 {
            notes.push(format!(
                "{} face-boundary vertices matched no edge point (possible cracks)",
                self.unsnapped
            ));
        }
        notes.push(format!(
            "boundary vertices snapped to edge polylines (largest move {:.3e})",
            self.snap_max * scale
        ));
    }
}

/// One face of a body on its way into the model, with what its steps share.
struct FaceInBody<'b> {
    body_index: usize,
    body: &'b ParsedBody,
    /// The face's position in its body (file order, skipped faces counted).
    index: usize,
    parsed: &'b ParsedFace,
    /// `ENTITY #surface_id`, for messages.
    name: String,
    /// Body-level index of each edge the face uses.
    edges: Vec<usize>,
}

impl FaceInBody<'_> {
    /// This face, left out for `reason`.
    fn skip(&self, reason: String) -> SkippedFace {
        SkippedFace {
            face_id: self.parsed.face_id,
            body: self.body.name.clone(),
            entity: self.name.clone(),
            reason,
        }
    }
}

/// How an edge's polyline meets the edge's vertices.
enum VertexFit {
    /// It runs from one vertex to the other.
    Whole,
    /// It ran past a vertex or stopped short of it and was trimmed to the vertices.
    Trimmed,
    /// It misses a vertex: the edge's curve does not pass through it.
    Missed,
}

/// The model under construction: the welded vertex pool, the mesh with a group per face,
/// what each face and body became, and the faces left out.
struct WeldedModel<'a> {
    path: &'a Path,
    opts: &'a StepOptions,
    tol: Tolerances,
    pool: Pool,
    /// (body, vertex) -> pool id.
    vertex_pool: BTreeMap<(usize, usize), u32>,
    /// (body, edge) -> pool ids of its polyline.
    edge_pool: BTreeMap<(usize, usize), Vec<u32>>,
    /// (body, edge) -> groups of the faces using it.
    edge_groups: BTreeMap<(usize, usize), Vec<u32>>,
    /// Edges whose curve does not pass through their vertices; faces using them are skipped.
    bad_edges: BTreeSet<(usize, usize)>,
    mesh: ControlMesh,
    /// The surface of each group's face.
    faces: Vec<FaceSurface>,
    bodies: Vec<Body>,
    skipped: Vec<SkippedFace>,
    tally: Tally,
    /// Group names are stored in the file: the body prefix only when there are several.
    single_body: bool,
    started: Instant,
    total_faces: usize,
    faces_done: usize,
    /// Runs each face's jobs and counts those that could not be stopped.
    workers: Workers,
}

impl<'a> WeldedModel<'a> {
    fn new(
        path: &'a Path,
        opts: &'a StepOptions,
        tol: Tolerances,
        bodies: &[ParsedBody],
        skipped: Vec<SkippedFace>,
        workers: Workers,
    ) -> Self {
        WeldedModel {
            path,
            opts,
            tol,
            pool: Pool::default(),
            vertex_pool: BTreeMap::new(),
            edge_pool: BTreeMap::new(),
            edge_groups: BTreeMap::new(),
            bad_edges: BTreeSet::new(),
            mesh: ControlMesh::new(),
            faces: Vec::new(),
            bodies: Vec::new(),
            skipped,
            tally: Tally::default(),
            single_body: bodies.len() == 1,
            started: Instant::now(),
            total_faces: bodies.iter().map(|b| b.faces.len()).sum(),
            faces_done: 0,
            workers,
        }
    }

    /// Adds the body's faces, each as a group or as a skipped face, then the body. An
    /// error only when the total timeout runs out or more jobs than a read tolerates could
    /// not be stopped.
    fn add_body(&mut self, body_index: usize, body: &ParsedBody) -> Result<()> {
        let first_group = self.mesh.groups.len() as u32;
        let analytic_only = analytic_only_edges(body);
        for (index, parsed) in body.faces.iter().enumerate() {
            self.check_total_time(body, parsed)?;
            self.workers.check()?;
            self.faces_done += 1;
            let (shell, edges, _) = single_face_shell(body, &parsed.face);
            let face = FaceInBody {
                body_index,
                body,
                index,
                parsed,
                name: format!("{} #{}", parsed.info.entity, parsed.info.surface_id),
                edges,
            };
            if let Err(skipped) = self.add_face(&face, shell, &analytic_only) {
                self.skipped.push(skipped);
            }
        }
        let group_count = self.mesh.groups.len() as u32 - first_group;
        self.bodies.push(Body {
            name: body.name.clone(),
            step_id: body.step_id,
            entity: body.entity.clone(),
            first_group,
            group_count,
        });
        Ok(())
    }

    /// The error that ends the tessellation when it has run past the total timeout before
    /// the next face.
    fn check_total_time(&self, body: &ParsedBody, next: &ParsedFace) -> Result<()> {
        if self.started.elapsed() <= self.opts.total_timeout {
            return Ok(());
        }
        Err(Error::input(
            self.path,
            format!(
                "tessellating the faces did not finish within {:.0} s ({} of {} faces done; \
                 next: face #{} of {}); giving up",
                self.opts.total_timeout.as_secs_f64(),
                self.faces_done,
                self.total_faces,
                next.face_id,
                body.name
            ),
        ))
    }

    /// The chord for polylining edge `ge`: the analytic faces' (coarser) one when only
    /// faces with an exact analytic surface use the edge, else the finer one.
    fn edge_chord(&self, analytic_only: &BTreeMap<usize, bool>, ge: usize) -> f64 {
        if analytic_only.get(&ge).copied().unwrap_or(false) {
            self.tol.chord * self.tol.analytic_factor
        } else {
            self.tol.chord
        }
    }

    /// Adds one face as a group: pools its edge polylines, tessellates it on them (ours,
    /// or truck's where ours cannot be done) and keeps its triangles. The error is the
    /// face left out, with why.
    fn add_face(
        &mut self,
        face: &FaceInBody,
        shell: FaceShell,
        analytic_only: &BTreeMap<usize, bool>,
    ) -> Result<(), SkippedFace> {
        self.polyline_new_edges(face, analytic_only)
            .map_err(|why| face.skip(why))?;
        self.refuse_bad_edges(face)?;
        let loops = self.face_loops(face);
        let segments = self.edge_segments(face);
        let triangles = match self.conforming_triangles(face, loops, &segments) {
            Ok(triangles) => triangles,
            Err(why) => self
                .truck_triangles(face, shell, &segments, why)
                .map_err(|why| face.skip(why))?,
        };
        self.push_face(face, &triangles)
            .map_err(|why| face.skip(why))
    }

    /// Polylines the face's edges that no earlier face used (truck's polylining of the edge
    /// curve) and pools them: the first face that uses an edge fixes its polyline, later
    /// faces reuse those points. The error says why truck could not polyline them.
    fn polyline_new_edges(
        &mut self,
        face: &FaceInBody,
        analytic_only: &BTreeMap<usize, bool>,
    ) -> Result<(), String> {
        let need: Vec<(usize, Curve3D, f64)> = face
            .edges
            .iter()
            .filter(|&&ge| !self.edge_pool.contains_key(&(face.body_index, ge)))
            .map(|&ge| {
                let curve = face.body.edges[ge].curve.clone();
                (ge, curve, self.edge_chord(analytic_only, ge))
            })
            .collect();
        if need.is_empty() {
            return Ok(());
        }
        let watched = self.workers.run(
            "scode-step-edges",
            self.opts.face_timeout,
            move |cancel: &Cancel| {
                need.into_iter()
                    .map(|(ge, c, chord)| {
                        let range = c.range_tuple();
                        let c = Guarded::new(c, cancel);
                        (ge, PolylineCurve::from_curve(&c, range, chord).0)
                    })
                    .collect::<Vec<(usize, Vec<Point3>)>>()
            },
        );
        let polylines = watched.or_why("polylining its edges (truck)", self.opts.face_timeout)?;
        for (ge, pts) in polylines {
            self.add_edge_polyline(face.body_index, face.body, ge, pts);
        }
        Ok(())
    }

    /// Pools the polyline of edge `ge` of body `bi`, turned to run from the edge's start
    /// vertex to its end and trimmed to the vertices. An edge whose curve misses a vertex
    /// is pooled too, and marked bad.
    fn add_edge_polyline(&mut self, bi: usize, body: &ParsedBody, ge: usize, mut pts: Vec<Point3>) {
        let (va, vb) = body.edges[ge].vertices;
        let (a, b) = (dv(&body.vertices[va]), dv(&body.vertices[vb]));
        // A curve parametrised the other way is turned round.
        if let (Some(f), Some(l)) = (pts.first(), pts.last()) {
            let (f, l) = (dv(f), dv(l));
            if f.distance(b) + l.distance(a) < f.distance(a) + l.distance(b) {
                pts.reverse();
            }
        }
        if va != vb && pts.len() > 2 {
            match trim_to_vertices(&mut pts, a, b, &self.tol) {
                VertexFit::Whole => {}
                VertexFit::Trimmed => self.tally.trimmed_edges += 1,
                VertexFit::Missed => {
                    self.bad_edges.insert((bi, ge));
                }
            }
        }
        let ids = self.pool_polyline(bi, body, (va, vb), &pts);
        self.edge_pool.insert((bi, ge), ids);
    }

    /// Pool ids of an edge polyline that runs from vertex `va` to `vb` of body `bi`: the
    /// vertices' ids at its ends, welded points between them.
    fn pool_polyline(
        &mut self,
        bi: usize,
        body: &ParsedBody,
        (va, vb): (usize, usize),
        pts: &[Point3],
    ) -> Vec<u32> {
        let ends = [va, vb].map(|v| self.pool_vertex(bi, body, v));
        let mut ids = vec![ends[0]];
        let mut last = dv(&body.vertices[va]);
        let end = dv(&body.vertices[vb]);
        let n = pts.len();
        for p in pts.iter().take(n.saturating_sub(1)).skip(1) {
            let p = dv(p);
            // Degenerate edges (a pole) and doubled points add no vertex.
            if p.distance(last) <= self.tol.merge || p.distance(end) <= self.tol.merge {
                continue;
            }
            let at = body.placement.transform_point3(p);
            ids.push(self.pool.push_welded(bi, at, self.tol.weld));
            last = p;
        }
        ids.push(ends[1]);
        ids.dedup();
        ids
    }

    /// Pool id of vertex `v` of body `bi`, pooled (welded) on first use.
    fn pool_vertex(&mut self, bi: usize, body: &ParsedBody, v: usize) -> u32 {
        let pool = &mut self.pool;
        let weld = self.tol.weld;
        *self.vertex_pool.entry((bi, v)).or_insert_with(|| {
            pool.push_welded(
                bi,
                body.placement.transform_point3(dv(&body.vertices[v])),
                weld,
            )
        })
    }

    /// Leaves the face out when the curve of one of its edges misses the edge's vertices.
    fn refuse_bad_edges(&self, face: &FaceInBody) -> Result<(), SkippedFace> {
        let bi = face.body_index;
        let Some(&ge) = face
            .edges
            .iter()
            .find(|&&ge| self.bad_edges.contains(&(bi, ge)))
        else {
            return Ok(());
        };
        Err(SkippedFace {
            face_id: face.parsed.face_id,
            body: face.body.name.clone(),
            entity: format!("EDGE_CURVE #{}", face.body.edge_ids[ge]),
            reason: "the edge's curve (as truck converts it) does not pass through its vertices"
                .into(),
        })
    }

    /// The face's loops over pool vertices, with their positions in body coordinates.
    fn face_loops(&mut self, face: &FaceInBody) -> Vec<Vec<(u32, DVec3)>> {
        let unplace = face.body.placement.inverse();
        let mut loops = Vec::new();
        for wire in &face.parsed.face.boundaries {
            let ids = self.chain_wire(face.body_index, wire);
            let positions = &self.pool.positions;
            loops.push(
                ids.iter()
                    .map(|&id| (id, unplace.transform_point3(positions[id as usize])))
                    .collect(),
            );
        }
        loops
    }

    /// One loop of a face of body `bi` as a cycle of pool ids: its edges' polylines joined
    /// end to start, each joint once.
    fn chain_wire(&mut self, bi: usize, wire: &[CompressedEdgeIndex]) -> Vec<u32> {
        let mut ids: Vec<u32> = Vec::new();
        let n = wire.len();
        for (k, ei) in wire.iter().enumerate() {
            let mut chain = self.edge_pool[&(bi, ei.index)].clone();
            if !ei.orientation {
                chain.reverse();
            }
            // An edge whose orientation in the loop is wrong (it does not start where the
            // previous one ended, but ends there) is turned round.
            let joins = |c: &[u32], prev: Option<u32>| prev.is_none_or(|p| c[0] == p);
            let prev = ids.last().copied().or_else(|| {
                // The first edge: check it against the next one.
                let next = &self.edge_pool[&(bi, wire[(k + 1) % n].index)];
                let c = &chain;
                let last = *c.last().unwrap_or(&u32::MAX);
                let (n0, n1) = (next[0], *next.last().unwrap_or(&u32::MAX));
                if n > 1 && last != n0 && last != n1 && (c[0] == n0 || c[0] == n1) {
                    Some(u32::MAX)
                } else {
                    None
                }
            });
            let turned_first = prev == Some(u32::MAX);
            let turned_later =
                !turned_first && !joins(&chain, prev) && chain.last() == prev.as_ref();
            if turned_first || turned_later {
                chain.reverse();
                self.tally.reversed_in_loop += 1;
            }
            // The joint point is the previous edge's end.
            if !ids.is_empty() {
                ids.pop();
            }
            ids.extend(chain);
        }
        if ids.len() > 1 && ids.first() == ids.last() {
            ids.pop();
        }
        ids.dedup();
        while ids.len() > 1 && ids.first() == ids.last() {
            ids.pop();
        }
        ids
    }

    /// The segments of the face's edge polylines, as undirected pairs of pool ids.
    fn edge_segments(&self, face: &FaceInBody) -> BTreeSet<(u32, u32)> {
        let mut segments = BTreeSet::new();
        for &ge in &face.edges {
            let polyline = &self.edge_pool[&(face.body_index, ge)];
            for w in polyline.windows(2).filter(|w| w[0] != w[1]) {
                segments.insert(crate::mesh::edge_key(w[0], w[1]));
            }
        }
        segments
    }

    /// Our conforming tessellation of the face on its `loops`, over pool ids (its new
    /// points join the pool). The error says why it cannot be used.
    fn conforming_triangles(
        &mut self,
        face: &FaceInBody,
        loops: Vec<Vec<(u32, DVec3)>>,
        segments: &BTreeSet<(u32, u32)>,
    ) -> Result<Vec<[u32; 3]>, String> {
        match self.run_conforming(face.parsed, loops) {
            Watched::Done(Ok(cm)) => {
                if !follows_edges(&cm.triangles, segments) {
                    return Err("its triangles do not follow its edge polylines".to_string());
                }
                let place = face.body.placement;
                let ids: Vec<u32> = cm
                    .new_points
                    .iter()
                    .map(|&p| self.pool.push(place.transform_point3(p)))
                    .collect();
                let id = |v: conform::FaceVertex| match v {
                    conform::FaceVertex::Pool(i) => i,
                    conform::FaceVertex::New(k) => ids[k as usize],
                };
                self.tally.conforming += 1;
                Ok(cm.triangles.iter().map(|t| t.map(id)).collect())
            }
            Watched::Done(Err(msg)) => Err(msg),
            Watched::Panicked(msg) => Err(format!("panicked: {msg}")),
            Watched::TimedOut { stopped } => Err(format!(
                "did not finish within {:.0} s{}",
                self.opts.face_timeout.as_secs_f64(),
                if stopped {
                    " (stopped)"
                } else {
                    " (abandoned, still running)"
                }
            )),
        }
    }

    /// Runs the conforming tessellation of a face in a thread under the face timeout. It
    /// uses the exact surface where the STEP record gives one (its normal is the record's:
    /// triangles are turned round when the face's `same_sense` is false, as truck's surface
    /// was), else truck's.
    fn run_conforming(
        &self,
        parsed: &ParsedFace,
        loops: Vec<Vec<(u32, DVec3)>>,
    ) -> Watched<Result<conform::ConformingMesh, String>> {
        let surface = parsed.face.surface.clone();
        let (exact, same_sense) = (parsed.exact, parsed.same_sense);
        let chord = self.tol.chord;
        let face_chord = chord * self.tol.analytic_factor;
        let stretch = self.opts.stretch_parameter_plane;
        self.workers.run(
            "scode-step-face",
            self.opts.face_timeout,
            move |cancel: &Cancel| match exact {
                Some(a) => {
                    let a = Guarded::new(a, cancel);
                    conform::conforming_tessellation(&a, &loops, face_chord, stretch).map(
                        |mut cm| {
                            if !same_sense {
                                for t in &mut cm.triangles {
                                    t.swap(1, 2);
                                }
                            }
                            cm
                        },
                    )
                }
                None => {
                    let surface = Guarded::new(surface, cancel);
                    conform::conforming_tessellation(&surface, &loops, chord, stretch)
                }
            },
        )
    }

    /// truck's tessellation of the face's one-face `shell`, its vertices snapped to the
    /// face's edge points, for a face ours could not do (`why`). The error says why truck's
    /// cannot be used either.
    fn truck_triangles(
        &mut self,
        face: &FaceInBody,
        shell: FaceShell,
        segments: &BTreeSet<(u32, u32)>,
        why: String,
    ) -> Result<Vec<[u32; 3]>, String> {
        let fell_back = format!("face #{} ({}): {why}", face.parsed.face_id, face.name);
        self.tally.fallback.push(fell_back);
        let chord = self.tol.chord;
        let watched = self.workers.run(
            "scode-step-face",
            self.opts.face_timeout,
            move |cancel: &Cancel| guard_shell(shell, cancel).robust_triangulation(chord),
        );
        let meshed: MeshedShell =
            watched.or_why("the tessellator (truck)", self.opts.face_timeout)?;
        let Some(poly) = meshed.faces.first().and_then(|f| f.surface.as_ref()) else {
            return Err("the tessellator (truck) could not triangulate the face".into());
        };
        let map = self.snap_to_edge_points(face, poly);
        let triangles: Vec<[u32; 3]> = poly
            .faces()
            .triangle_iter()
            .map(|tri| [map[tri[0].pos], map[tri[1].pos], map[tri[2].pos]])
            .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
            .collect();
        // A face whose triangles leave its edges would crack or fold the welded model:
        // leave it out (named) so the rest is a clean surface.
        let as_pool: Vec<[conform::FaceVertex; 3]> = triangles
            .iter()
            .map(|t| t.map(conform::FaceVertex::Pool))
            .collect();
        if !follows_edges(&as_pool, segments) {
            return Err(format!(
                "neither our tessellation ({why}) nor truck's follows the face's edges"
            ));
        }
        Ok(triangles)
    }

    /// Pool ids for the vertices of truck's mesh of the face: the nearest of the face's
    /// edge points within the snap tolerance, else a new pool vertex.
    fn snap_to_edge_points(&mut self, face: &FaceInBody, poly: &PolygonMesh) -> Vec<u32> {
        let mut candidates: Vec<(DVec3, u32)> = Vec::new();
        for &ge in &face.edges {
            for &id in &self.edge_pool[&(face.body_index, ge)] {
                candidates.push((self.pool.positions[id as usize], id));
            }
        }
        candidates.sort_by(|a, b| a.0.x.total_cmp(&b.0.x).then(a.1.cmp(&b.1)));
        candidates.dedup_by_key(|c| c.1);
        let positions = poly.positions();
        let boundary = mesh_boundary_vertices(poly);
        let mut map = Vec::with_capacity(positions.len());
        for (i, p) in positions.iter().enumerate() {
            let p = face.body.placement.transform_point3(dv(p));
            match nearest(&candidates, p, self.tol.snap) {
                Some((id, d)) => {
                    self.tally.snap_max = self.tally.snap_max.max(d);
                    map.push(id);
                }
                None => {
                    if boundary[i] {
                        self.tally.unsnapped += 1;
                    }
                    map.push(self.pool.push(p));
                }
            }
        }
        map
    }

    /// Adds the face's triangles to the mesh as a group of its own and records the face's
    /// surface (axis in model coordinates) and the group of each of its edges. The error
    /// when no triangle is left.
    fn push_face(&mut self, face: &FaceInBody, triangles: &[[u32; 3]]) -> Result<(), String> {
        let name = self.group_name(face);
        let group = self.mesh.push_group(name, patch_kind(&face.parsed.info));
        let orientation = face.parsed.face.orientation;
        if self.push_manifold_triangles(triangles, orientation, group) == 0 {
            self.mesh.groups.pop();
            return Err("the tessellation has no triangles".into());
        }
        for &ge in &face.edges {
            let groups = self.edge_groups.entry((face.body_index, ge)).or_default();
            groups.push(group);
        }
        let place = face.body.placement;
        let mut info = face.parsed.info.clone();
        info.body = self.bodies.len() as u32;
        info.exact = info.exact.map(|s| {
            s.placed(
                |p| place.transform_point3(p),
                |v| place.transform_vector3(v),
            )
        });
        if let Some(a) = &mut info.revolution_axis {
            a.origin = place.transform_point3(a.origin);
            a.direction = place.transform_vector3(a.direction).normalize_or_zero();
        }
        self.faces.push(info);
        Ok(())
    }

    /// `face_<k>` for the body's k-th face (1-based, in file order, skipped faces counted),
    /// as the corpus tessellations number CAD faces: the bitstream stores every name, and a
    /// run of numbers costs about a byte a face where STEP instance ids (`#157`, irregular
    /// gaps) cost two or three. `scode info part.step` lists each group with its
    /// ADVANCED_FACE id.
    fn group_name(&self, face: &FaceInBody) -> String {
        if self.single_body {
            format!("face_{}", face.index + 1)
        } else {
            format!("{}/face_{}", face.body.name, face.index + 1)
        }
    }

    /// Adds the triangles to `group` (turned round when the face's `orientation` is
    /// false) and returns how many were added. Each face must be an oriented 2-manifold
    /// for the fit: a triangle that would use a directed edge twice, or an edge a third
    /// time (truck overlaps on some periodic and trimmed faces, or welding folded a
    /// sliver), is dropped and counted.
    fn push_manifold_triangles(
        &mut self,
        triangles: &[[u32; 3]],
        orientation: bool,
        group: u32,
    ) -> usize {
        let mut added = 0;
        let mut directed: BTreeSet<(u32, u32)> = BTreeSet::new();
        let mut uses: BTreeMap<(u32, u32), u8> = BTreeMap::new();
        for &tri in triangles {
            let mut t = tri;
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                continue;
            }
            if !orientation {
                t.swap(1, 2);
            }
            let es = [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])];
            let clash = es.iter().any(|&(a, b)| {
                directed.contains(&(a, b))
                    || uses
                        .get(&crate::mesh::edge_key(a, b))
                        .is_some_and(|&n| n >= 2)
            });
            if clash {
                self.tally.overlapping += 1;
                continue;
            }
            for &(a, b) in &es {
                directed.insert((a, b));
                *uses.entry(crate::mesh::edge_key(a, b)).or_insert(0) += 1;
            }
            self.mesh.push_face(&t, group);
            added += 1;
        }
        added
    }

    /// The finished model: knife-edge ears split, the pool compacted to the vertices the
    /// faces use (in millimetres when the file gives its unit), faces oriented, corners and
    /// sharp group boundaries marked, the B-rep edges over the mesh's vertices, and the
    /// notes. An error when no face made it.
    fn finish(
        mut self,
        #[cfg_attr(
            not(feature = "internals"),
            expect(
                unused_variables,
                reason = "only the B-rep edges read the parsed bodies"
            )
        )]
        bodies: &[ParsedBody],
        mut notes: Vec<String>,
        millimetres_per_unit: Option<f64>,
    ) -> Result<StepModel> {
        if self.mesh.face_count() == 0 {
            return Err(no_face_error(self.path, &self.skipped));
        }
        let scale = millimetres_per_unit.unwrap_or(1.0);
        let closed: Vec<bool> = self.faces.iter().map(keeps_interior_vertices).collect();
        let split = split_doubled_ears(&mut self.mesh, &mut self.pool.positions, &closed);
        if split > 0 {
            notes.push(format!(
                "{split} triangles that two faces both closed on their shared edge (a knife \
                 edge) split in one of them"
            ));
        }
        let new_id = self.compact_pool(scale);
        let flipped = orient_faces(&mut self.mesh, &self.bodies);
        if flipped > 0 {
            notes.push(format!(
                "{flipped} faces flipped to agree with their neighbours' orientation"
            ));
        }
        self.mark_vertex_corners(&new_id);
        self.mesh.sharpen_group_boundaries();
        #[cfg(feature = "internals")]
        let edges = self.brep_edges(bodies, &new_id);
        for f in &mut self.faces {
            scale_surface(f, scale);
        }
        for (group, face) in self.mesh.groups.iter_mut().zip(&self.faces) {
            group.patch = patch_kind(face);
        }
        self.tally.push_notes(&mut notes, scale);
        let open = open_edge_count(&self.mesh);
        if open > 0 {
            notes.push(format!(
                "{open} mesh edges are open (bounded by one triangle): open shells or skipped \
                 faces"
            ));
        }
        self.mesh.validate()?;
        Ok(StepModel {
            mesh: self.mesh,
            faces: self.faces,
            #[cfg(feature = "internals")]
            bodies: self.bodies,
            #[cfg(feature = "internals")]
            edges,
            skipped: self.skipped,
            chordal_tolerance: self.tol.chord * scale,
            #[cfg(feature = "internals")]
            millimetres_per_unit,
            notes,
        })
    }

    /// Keeps the pool vertices the faces use, numbered in order of first use, as the mesh's
    /// positions times `scale`. Returns each pool vertex's new id (`u32::MAX` if unused).
    fn compact_pool(&mut self, scale: f64) -> Vec<u32> {
        let mut new_id = vec![u32::MAX; self.pool.positions.len()];
        let mut positions = Vec::new();
        for v in self.mesh.face_vertices.iter_mut() {
            let old = *v as usize;
            if new_id[old] == u32::MAX {
                new_id[old] = positions.len() as u32;
                positions.push(self.pool.positions[old] * scale);
            }
            *v = new_id[old];
        }
        self.mesh.positions = positions;
        new_id
    }

    /// Marks the mesh vertices that are B-rep vertices as corners.
    fn mark_vertex_corners(&mut self, new_id: &[u32]) {
        for &id in self.vertex_pool.values() {
            let n = new_id[id as usize];
            if n != u32::MAX {
                self.mesh.corners.insert(n);
            }
        }
    }

    /// The B-rep edges that faces in the mesh use, as polylines over the mesh's vertices
    /// with the groups on either side.
    #[cfg(feature = "internals")]
    fn brep_edges(&self, bodies: &[ParsedBody], new_id: &[u32]) -> Vec<BrepEdge> {
        let mut edges = Vec::new();
        for (key, ids) in &self.edge_pool {
            let Some(groups) = self.edge_groups.get(key) else {
                continue;
            };
            let mut groups = groups.clone();
            groups.sort_unstable();
            groups.dedup();
            let vertices: Vec<u32> = ids.iter().map(|&i| new_id[i as usize]).collect();
            if vertices.contains(&u32::MAX) {
                continue;
            }
            edges.push(BrepEdge {
                step_id: bodies[key.0].edge_ids[key.1],
                vertices,
                groups,
            });
        }
        edges
    }
}

/// For each edge of the body: whether only faces with an exact analytic surface use it
/// (those edges get the analytic faces' coarser chord).
fn analytic_only_edges(body: &ParsedBody) -> BTreeMap<usize, bool> {
    let mut analytic_only: BTreeMap<usize, bool> = BTreeMap::new();
    for f in &body.faces {
        for ei in f.face.boundaries.iter().flatten() {
            let e = analytic_only.entry(ei.index).or_insert(true);
            *e &= f.exact.is_some();
        }
    }
    analytic_only
}

/// Trims an edge polyline to its vertices `a` (start) and `b` (end). truck sometimes trims
/// an edge's curve to the wrong range (the curve runs past a vertex or stops short of it,
/// or is the whole B-spline of which the edge uses a part): keep the stretch between the
/// vertices' nearest points on the polyline, and refuse an edge whose curve misses a
/// vertex. Nearest points on its segments, not its points: a nearly straight curve has few
/// points, and a vertex in the middle of a long segment is on the curve (corpus trj6 has
/// 48 faces with such edges).
fn trim_to_vertices(pts: &mut Vec<Point3>, a: DVec3, b: DVec3, tol: &Tolerances) -> VertexFit {
    let diag = tol.diag;
    let (mut sa, da) = nearest_on_polyline(pts, a);
    let (mut sb, db) = nearest_on_polyline(pts, b);
    let last = (pts.len() - 1) as f64;
    // A closed curve (a whole B-spline circle of which the edge is a part) runs the edge's
    // way (truck turns it round for `same_sense` false), and its closing point is both
    // ends: there the edge starts at the first point and ends at the last, and an edge
    // whose end comes before its start runs through the closing point (corpus trj3: taken
    // as the start, the edge ending at the closing point would be the complementary arc,
    // and two faces would fail).
    let closing = dv(&pts[0]);
    let closed = closing.distance(dv(&pts[pts.len() - 1])) <= 1e-6 * diag;
    if closed {
        if closing.distance(a) <= da + 1e-6 * diag {
            sa = 0.0;
        }
        if closing.distance(b) <= db + 1e-6 * diag {
            sb = last;
        }
    }
    if da.max(db) > 10.0 * tol.chord + 1e-6 * diag {
        return VertexFit::Missed;
    }
    if sa > 0.0 || sb < last {
        // The vertices stand for the ends (only the points between them are used below).
        let inner = polyline_between(pts, sa, sb, closed);
        let point = |p: DVec3| Point3::new(p.x, p.y, p.z);
        *pts = std::iter::once(point(a))
            .chain(inner)
            .chain(std::iter::once(point(b)))
            .collect();
        return VertexFit::Trimmed;
    }
    VertexFit::Whole
}

/// The points of a polyline strictly between positions `sa` and `sb` along it (as from
/// [`nearest_on_polyline`]), in the order from `sa` to `sb`. On a `closed` polyline with
/// `sa` after `sb` the stretch runs through the closing point.
fn polyline_between(pts: &[Point3], sa: f64, sb: f64, closed: bool) -> Vec<Point3> {
    if closed && sa > sb {
        // Through the closing point (the last point is the first).
        return (0..pts.len())
            .filter(|&k| k as f64 > sa)
            .chain((1..pts.len()).filter(|&k| (k as f64) < sb))
            .map(|k| pts[k])
            .collect();
    }
    let between = |k: usize| {
        let k = k as f64;
        k > sa.min(sb) && k < sa.max(sb)
    };
    let mut inner: Vec<Point3> = (0..pts.len())
        .filter(|&k| between(k))
        .map(|k| pts[k])
        .collect();
    if sa > sb {
        inner.reverse();
    }
    inner
}

/// Two faces meeting at a knife edge (the solid's angle along their B-rep edge near zero)
/// can each close an ear on the same two edge segments: one triangle in both faces, so the
/// edge joining the ear's other two corners is an interior edge of both (four triangles on
/// one edge, which no control mesh can hold). In one of the two faces (a closed patch's if
/// there is one: a boundary patch should keep no interior vertex), the ear and its
/// neighbour across that edge are split at the edge's midpoint: the triangles cover what
/// they covered, and each edge has two faces again. `closed` is indexed by group. Returns
/// how many ears were split.
fn split_doubled_ears(
    mesh: &mut ControlMesh,
    positions: &mut Vec<DVec3>,
    closed: &[bool],
) -> usize {
    let tris: Vec<[u32; 3]> = (0..mesh.face_count())
        .map(|f| {
            let v = mesh.face(f);
            [v[0], v[1], v[2]]
        })
        .collect();
    let groups = mesh.face_groups.clone();
    let sorted = |t: [u32; 3]| {
        let mut s = t;
        s.sort_unstable();
        s
    };
    let mut by_set: BTreeMap<[u32; 3], Vec<usize>> = BTreeMap::new();
    for (f, &t) in tris.iter().enumerate() {
        by_set.entry(sorted(t)).or_default().push(f);
    }
    let mut by_edge: BTreeMap<(u32, u32), Vec<usize>> = BTreeMap::new();
    for (f, t) in tris.iter().enumerate() {
        for k in 0..3 {
            by_edge
                .entry(crate::mesh::edge_key(t[k], t[(k + 1) % 3]))
                .or_default()
                .push(f);
        }
    }
    // Face -> the triangles replacing it.
    let mut replaced: BTreeMap<usize, Vec<[u32; 3]>> = BTreeMap::new();
    for faces in by_set.values() {
        let &[f1, f2] = faces.as_slice() else {
            continue;
        };
        if groups[f1] == groups[f2] || replaced.contains_key(&f1) || replaced.contains_key(&f2) {
            continue;
        }
        let s = if closed.get(groups[f1] as usize) == Some(&true) {
            f1
        } else {
            f2
        };
        let t = tris[s];
        // The ear's edge inside its face: the one edge with another triangle of that face.
        let inner: Vec<(usize, usize)> = (0..3)
            .filter_map(|k| {
                let e = crate::mesh::edge_key(t[k], t[(k + 1) % 3]);
                let others: Vec<usize> = by_edge[&e]
                    .iter()
                    .copied()
                    .filter(|&h| h != s && groups[h] == groups[s])
                    .collect();
                (others.len() == 1).then(|| (k, others[0]))
            })
            .collect();
        let &[(k, n)] = inner.as_slice() else {
            continue;
        };
        if replaced.contains_key(&n) {
            continue;
        }
        let (a, b, tip) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
        let tn = tris[n];
        let Some(j) = (0..3).find(|&j| tn[j] == b && tn[(j + 1) % 3] == a) else {
            continue; // the neighbour is not oriented like the ear
        };
        let c = tn[(j + 2) % 3];
        let m = positions.len() as u32;
        positions.push(0.5 * (positions[a as usize] + positions[b as usize]));
        replaced.insert(s, vec![[a, m, tip], [m, b, tip]]);
        replaced.insert(n, vec![[b, m, c], [m, a, c]]);
    }
    if replaced.is_empty() {
        return 0;
    }
    mesh.face_offsets.clear();
    mesh.face_vertices.clear();
    mesh.face_groups.clear();
    for (f, t) in tris.iter().enumerate() {
        match replaced.get(&f) {
            Some(new) => {
                for t in new {
                    mesh.push_face(t, groups[f]);
                }
            }
            None => {
                mesh.push_face(t, groups[f]);
            }
        }
    }
    replaced.len() / 2
}

fn scale_surface(f: &mut FaceSurface, s: f64) {
    f.exact = f.exact.map(|e| e.scaled(s));
    if let Some(a) = &mut f.revolution_axis {
        a.origin *= s;
    }
}

/// The patch kind a face's exact surface asks for: boundary patches with the exact axis for
/// planes, cylinders, cones, spheres and tori (a sphere's axis is the fit's choice, see
/// `fit::classify`); closed patches for everything else.
pub(super) fn patch_kind(f: &FaceSurface) -> PatchKind {
    match (&f.surface, f.exact) {
        (SurfaceType::Plane, _) => PatchKind::Boundary(BoundarySurface::Plane),
        (SurfaceType::Cylinder, Some(AnalyticSurface::Cylinder { axis, .. })) => {
            PatchKind::Boundary(BoundarySurface::Cylinder { axis })
        }
        (SurfaceType::Cone, Some(AnalyticSurface::Cone { axis, .. })) => {
            PatchKind::Boundary(BoundarySurface::Cone { axis })
        }
        (SurfaceType::Sphere, Some(AnalyticSurface::Sphere { center, .. })) => {
            PatchKind::Boundary(BoundarySurface::Sphere {
                axis: Axis {
                    origin: center,
                    direction: DVec3::Z,
                },
            })
        }
        (
            SurfaceType::Torus,
            Some(AnalyticSurface::Torus {
                axis, major_radius, ..
            }),
        ) => PatchKind::Boundary(BoundarySurface::Torus { axis, major_radius }),
        _ => PatchKind::Closed,
    }
}

/// Whether the fit may refine a face as a closed patch (a closed patch, or a sphere or torus
/// that the fit finds too wide for a boundary patch): [`split_doubled_ears`] prepares those.
fn keeps_interior_vertices(f: &FaceSurface) -> bool {
    matches!(
        patch_kind(f),
        PatchKind::Closed
            | PatchKind::Boundary(BoundarySurface::Sphere { .. } | BoundarySurface::Torus { .. })
    )
}

/// Whether a face's triangles form an oriented surface whose boundary is exactly its edge
/// polylines (`segments`, undirected): each boundary side is a polyline segment, every
/// segment is used (twice for a seam), no side is used more than twice or twice in one
/// direction.
pub(super) fn follows_edges(
    triangles: &[[conform::FaceVertex; 3]],
    segments: &BTreeSet<(u32, u32)>,
) -> bool {
    use conform::FaceVertex;
    let key = |a: FaceVertex, b: FaceVertex| if a <= b { (a, b) } else { (b, a) };
    let mut uses: BTreeMap<(FaceVertex, FaceVertex), u32> = BTreeMap::new();
    let mut directed: BTreeSet<(FaceVertex, FaceVertex)> = BTreeSet::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if !directed.insert((a, b)) {
                return false;
            }
            *uses.entry(key(a, b)).or_insert(0) += 1;
        }
    }
    for (&(a, b), &n) in &uses {
        if n > 2 {
            return false;
        }
        if n == 1 {
            let (FaceVertex::Pool(a), FaceVertex::Pool(b)) = (a, b) else {
                return false;
            };
            if !segments.contains(&crate::mesh::edge_key(a, b)) {
                return false;
            }
        }
    }
    segments
        .iter()
        .all(|&(a, b)| uses.contains_key(&key(FaceVertex::Pool(a), FaceVertex::Pool(b))))
}

/// Nearest point to `q` on the polyline `pts`, as a position along it (segment index plus
/// the parameter on that segment, so `0` is the first point and `len - 1` the last), and its
/// distance. The first of equally near points.
fn nearest_on_polyline(pts: &[Point3], q: DVec3) -> (f64, f64) {
    let mut best = (0.0, f64::INFINITY);
    for (i, w) in pts.windows(2).enumerate() {
        let (a, b) = (dv(&w[0]), dv(&w[1]));
        let ab = b - a;
        let l2 = ab.length_squared();
        let t = if l2 > 0.0 {
            ((q - a).dot(ab) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = (a + t * ab).distance(q);
        if d < best.1 {
            best = (i as f64 + t, d);
        }
    }
    best
}

/// Index of the candidate nearest to `p` within `tol`, with its distance. `candidates` is
/// sorted by x.
fn nearest(candidates: &[(DVec3, u32)], p: DVec3, tol: f64) -> Option<(u32, f64)> {
    let start = candidates.partition_point(|c| c.0.x < p.x - tol);
    let mut best: Option<(u32, f64)> = None;
    for c in &candidates[start..] {
        if c.0.x > p.x + tol {
            break;
        }
        let d = c.0.distance(p);
        if d <= tol && best.is_none_or(|b| d < b.1) {
            best = Some((c.1, d));
        }
    }
    best
}

/// Which vertices of a face mesh lie on its boundary (an edge used by one triangle).
fn mesh_boundary_vertices(poly: &PolygonMesh) -> Vec<bool> {
    let mut count: BTreeMap<(usize, usize), u32> = BTreeMap::new();
    for t in poly.faces().triangle_iter() {
        for k in 0..3 {
            let (a, b) = (t[k].pos, t[(k + 1) % 3].pos);
            *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    let mut on = vec![false; poly.positions().len()];
    for ((a, b), n) in count {
        if n == 1 {
            on[a] = true;
            on[b] = true;
        }
    }
    on
}

fn open_edge_count(mesh: &ControlMesh) -> usize {
    let mut count: BTreeMap<(u32, u32), u32> = BTreeMap::new();
    for f in mesh.faces() {
        for k in 0..f.len() {
            *count
                .entry(crate::mesh::edge_key(f[k], f[(k + 1) % f.len()]))
                .or_insert(0) += 1;
        }
    }
    count.values().filter(|&&n| n == 1).count()
}

/// Makes neighbouring faces agree in orientation (truck's per-face orientation is not
/// reliable on every file), then turns each closed body outward (positive volume). Visits
/// faces breadth-first over shared edges, in group order, so the result is deterministic.
/// Returns how many faces were flipped.
fn orient_faces(mesh: &mut ControlMesh, bodies: &[Body]) -> usize {
    let ng = mesh.groups.len();
    let mut tris_of: Vec<Vec<usize>> = vec![Vec::new(); ng];
    // undirected edge -> (group, directed edge) of every triangle side on it
    type EdgeUses = Vec<(u32, (u32, u32))>;
    let mut by_edge: BTreeMap<(u32, u32), EdgeUses> = BTreeMap::new();
    for f in 0..mesh.face_count() {
        let g = mesh.face_groups[f];
        tris_of[g as usize].push(f);
        let t = mesh.face(f);
        for k in 0..t.len() {
            let (a, b) = (t[k], t[(k + 1) % t.len()]);
            by_edge
                .entry(crate::mesh::edge_key(a, b))
                .or_default()
                .push((g, (a, b)));
        }
    }
    // Directed boundary edges of each group shared with other groups.
    let mut shared: Vec<Vec<((u32, u32), u32)>> = vec![Vec::new(); ng];
    for uses in by_edge.values() {
        for &(g, d) in uses {
            for &(h, _) in uses {
                if h != g {
                    shared[g as usize].push((d, h));
                }
            }
        }
    }
    let mut flip = vec![false; ng];
    let mut visited = vec![false; ng];
    for start in 0..ng {
        if visited[start] {
            continue;
        }
        visited[start] = true;
        let mut queue = std::collections::VecDeque::from([start]);
        while let Some(g) = queue.pop_front() {
            for &(_, h) in &shared[g] {
                let h = h as usize;
                if visited[h] {
                    continue;
                }
                // Orient h against every visited neighbour.
                let (mut same, mut opp) = (0, 0);
                for &((a, b), k) in &shared[h] {
                    let k = k as usize;
                    if !visited[k] {
                        continue;
                    }
                    for &(kg, (c, d)) in &by_edge[&crate::mesh::edge_key(a, b)] {
                        if kg as usize != k {
                            continue;
                        }
                        let (c, d) = if flip[k] { (d, c) } else { (c, d) };
                        if (c, d) == (a, b) {
                            same += 1;
                        } else {
                            opp += 1;
                        }
                    }
                }
                flip[h] = same > opp;
                visited[h] = true;
                queue.push_back(h);
            }
        }
    }
    // Outward: positive signed volume per body (meaningful for closed bodies only).
    for b in bodies {
        let groups = b.first_group as usize..(b.first_group + b.group_count) as usize;
        let mut volume = 0.0;
        for g in groups.clone() {
            for &f in &tris_of[g] {
                let t = mesh.face(f);
                let (p, q, r) = (
                    mesh.positions[t[0] as usize],
                    mesh.positions[t[1] as usize],
                    mesh.positions[t[2] as usize],
                );
                let v = p.dot(q.cross(r)) / 6.0;
                volume += if flip[g] { -v } else { v };
            }
        }
        if volume < 0.0 {
            for g in groups {
                flip[g] = !flip[g];
            }
        }
    }
    let mut count = 0;
    for (g, tris) in tris_of.iter().enumerate() {
        if !flip[g] {
            continue;
        }
        count += 1;
        for &f in tris {
            let s = mesh.face_offsets[f] as usize;
            mesh.face_vertices.swap(s + 1, s + 2);
        }
    }
    count
}

/// The error when no face at all could be read: names the distinct causes.
fn no_face_error(path: &Path, skipped: &[SkippedFace]) -> Error {
    let mut reasons: Vec<String> = skipped
        .iter()
        .map(|s| format!("{}: {}", s.entity.split(' ').next().unwrap_or(""), s.reason))
        .collect();
    reasons.sort();
    reasons.dedup();
    reasons.truncate(4);
    Error::input(
        path,
        format!(
            "no face could be read ({} skipped: {})",
            skipped.len(),
            reasons.join("; ")
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square face on a plane whose origin is infinite (what `1.0E400` in a placement
    /// would become without the text checks): truck's tessellator divides its boundary for
    /// ever (the NaN distances never meet the tolerance) and allocates without end. Given
    /// through `guard_shell`, it stops at the face timeout and leaves no thread.
    #[test]
    fn a_runaway_truck_tessellation_stops_at_the_face_timeout() {
        use std::time::Duration;
        use truck_stepio::r#in::alias::{ElementarySurface, Line, Plane};
        let corners = [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)]
            .map(|(x, y)| Point3::new(x, y, 0.0));
        let o = Point3::new(f64::INFINITY, 0.0, 0.0);
        let plane = Plane::new(o, o + truck_stepio::r#in::alias::Vector3::unit_x(), o);
        let shell: FaceShell = CompressedShell {
            vertices: corners.to_vec(),
            edges: (0..4)
                .map(|i| CompressedEdge {
                    vertices: (i, (i + 1) % 4),
                    curve: Curve3D::Line(Line(corners[i], corners[(i + 1) % 4])),
                })
                .collect(),
            faces: vec![CompressedFace {
                surface: Surface::ElementarySurface(Box::new(ElementarySurface::Plane(plane))),
                boundaries: vec![(0..4)
                    .map(|index| CompressedEdgeIndex {
                        index,
                        orientation: true,
                    })
                    .collect()],
                orientation: true,
            }],
        };
        let workers = Workers::default();
        let timeout = Duration::from_millis(300);
        let t0 = Instant::now();
        let w = workers.run("test-runaway", timeout, move |cancel: &Cancel| {
            guard_shell(shell, cancel).robust_triangulation(0.01)
        });
        assert!(matches!(w, Watched::TimedOut { stopped: true }));
        assert!(t0.elapsed() < timeout + super::super::watch::GRACE);
        assert_eq!(workers.still_running(), 0);
    }

    /// Two faces closing the same ear on their shared edge `a - tip - b`: face 0's
    /// triangles are split at the midpoint of `a - b`, face 1's are left alone, and every
    /// edge ends with at most two faces, one in each direction.
    #[test]
    fn doubled_ear_is_split_in_the_closed_face() {
        let mut positions = vec![
            DVec3::new(0.0, 0.0, 0.0),  // a
            DVec3::new(1.0, 0.1, 0.0),  // tip
            DVec3::new(2.0, 0.0, 0.0),  // b
            DVec3::new(1.0, -1.0, 0.0), // c, face 0
            DVec3::new(1.0, -1.0, 0.5), // c', face 1
        ];
        let mut mesh = ControlMesh::new();
        let closed = mesh.push_group("closed", PatchKind::Closed);
        let plane = mesh.push_group("plane", PatchKind::Boundary(BoundarySurface::Plane));
        mesh.push_face(&[0, 2, 1], closed);
        mesh.push_face(&[2, 0, 3], closed);
        mesh.push_face(&[0, 1, 2], plane);
        mesh.push_face(&[0, 2, 4], plane);
        let area = |m: &ControlMesh, p: &[DVec3], g: u32| -> f64 {
            (0..m.face_count())
                .filter(|&f| m.face_groups[f] == g)
                .map(|f| {
                    let v = m.face(f);
                    let q = [0, 1, 2].map(|k| p[v[k] as usize]);
                    0.5 * (q[1] - q[0]).cross(q[2] - q[0]).length()
                })
                .sum()
        };
        let before = [area(&mesh, &positions, 0), area(&mesh, &positions, 1)];
        assert_eq!(
            split_doubled_ears(&mut mesh, &mut positions, &[true, false]),
            1
        );
        assert_eq!(positions.len(), 6);
        assert_eq!(positions[5], DVec3::new(1.0, 0.0, 0.0));
        assert_eq!(mesh.face_count(), 6);
        assert_eq!(mesh.face_groups, vec![0, 0, 0, 0, 1, 1]);
        for g in 0..2 {
            assert!((area(&mesh, &positions, g) - before[g as usize]).abs() < 1e-12);
        }
        let mut directed = BTreeSet::new();
        let mut uses: BTreeMap<(u32, u32), usize> = BTreeMap::new();
        for f in 0..mesh.face_count() {
            let v = mesh.face(f);
            for k in 0..3 {
                assert!(directed.insert((v[k], v[(k + 1) % 3])), "face {f}");
                *uses
                    .entry(crate::mesh::edge_key(v[k], v[(k + 1) % 3]))
                    .or_default() += 1;
            }
        }
        assert!(uses.values().all(|&n| n <= 2));
        // The plane face still holds a - b; the closed face no longer does.
        assert_eq!(uses[&(0, 2)], 2);
        // Nothing doubled: a second pass changes nothing.
        assert_eq!(
            split_doubled_ears(&mut mesh, &mut positions, &[true, false]),
            0
        );
    }
}
