//! From STEP text to truck B-rep faces, keeping STEP ids and naming what truck cannot use.
//!
//! This mirrors `truck_stepio::r#in::Table::to_compressed_shell` (0.3.0), but walks the
//! shell itself so that each face keeps its id, a face that fails to convert is reported
//! instead of dropped, and nothing goes through truck's `eprintln!` paths for faces.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use glam::{DMat4, DVec3};
use truck_stepio::r#in::alias::{Curve3D, ElementarySurface, Surface, SweptCurve};
use truck_stepio::r#in::alias::{Invertible, Matrix4, Point3, Transform, Vector3};
use truck_stepio::r#in::ruststep::ast::Name;
use truck_stepio::r#in::ruststep::tables::{EntityTable, IntoOwned, PlaceHolder};
use truck_stepio::r#in::{
    FaceAnyHolder, FaceBoundHolder, FaceSurfaceHolder, Table, VertexPointHolder,
};
use truck_topology::compress::{CompressedEdge, CompressedEdgeIndex, CompressedFace};

use super::analytic::Analytic;
use super::check;
use super::text::{self, Records};
use super::watch::{Cancel, Workers};
use super::{FaceSurface, SkippedFace};
use crate::error::{Error, Result};
use crate::io::faces_json::SurfaceType;
use crate::mesh::{AnalyticSurface, Axis};

/// One face truck could convert, with its id and exact surface description.
#[derive(Clone)]
pub(super) struct ParsedFace {
    pub face_id: u64,
    /// Boundaries index into [`ParsedBody::edges`].
    pub face: CompressedFace<Surface>,
    /// In file units.
    pub info: FaceSurface,
    /// The exact surface from the STEP record (plane, cylinder, cone, sphere, torus), in
    /// its own parametrisation and orientation (`same_sense` not applied); `None` for
    /// other surfaces, which only truck's `face.surface` describes.
    pub exact: Option<Analytic>,
    /// The face's `same_sense`: whether its normal is the surface's.
    pub same_sense: bool,
}

/// One body's converted faces, with the edges and vertices they use (indices local to the
/// body, like truck's `CompressedShell`) and their STEP ids.
#[derive(Clone)]
pub(super) struct ParsedBody {
    pub name: String,
    /// From the body's coordinates to the model's (assembly placement; identity for parts).
    pub placement: DMat4,
    pub step_id: u64,
    pub entity: String,
    pub vertices: Vec<Point3>,
    pub vertex_ids: Vec<u64>,
    pub edges: Vec<CompressedEdge<Curve3D>>,
    pub edge_ids: Vec<u64>,
    pub faces: Vec<ParsedFace>,
}

#[derive(Clone)]
pub(super) struct Parsed {
    pub bodies: Vec<ParsedBody>,
    pub skipped: Vec<SkippedFace>,
    pub notes: Vec<String>,
    pub millimetres_per_unit: Option<f64>,
    /// The read's watched jobs: every tessellation of the file counts its abandoned
    /// threads with the parse's and the conversion's.
    pub workers: Workers,
}

fn entity_ref<T>(p: &PlaceHolder<T>) -> Option<u64> {
    match p {
        PlaceHolder::Ref(Name::Entity(id)) => Some(*id),
        _ => None,
    }
}

/// Parses the text and converts every body's faces. Errors only when nothing can be read.
pub(super) fn parse(path: &Path, raw: &str, opts: &super::StepOptions) -> Result<Loaded> {
    check::check(raw).map_err(|p| Error::input(path, p.to_string()))?;
    let (text, pcurve, empty) = text::prepass(raw);
    // The pre-pass keeps every line where it was (the parabola rewrite below does not), so
    // a syntax error found in this text is on the line the user sees.
    let prepassed = text.clone();
    let mut records = text::scan(&text);
    let mut notes = Vec::new();
    let (text, parabolas) = text::parabolas_to_bsplines(&text, &records);
    if parabolas > 0 {
        records = text::scan(&text);
        notes.push(format!(
            "rewrote {parabolas} PARABOLA curves as the quadratic B-splines they are over \
             their edges (truck's conversion of faces bounded by a parabola does not finish)"
        ));
    }
    if pcurve > 0 {
        notes.push(format!(
            "rewrote {pcurve} SURFACE_CURVE master flags .PCURVE_S1./.PCURVE_S2. to .CURVE_3D. \
             (truck would drop the 3D curve)"
        ));
    }
    if empty > 0 {
        notes.push(format!(
            "rewrote {empty} empty list parameters `()` to `$` (ruststep rejects them)"
        ));
    }
    if records.by_id.is_empty() {
        return Err(Error::input(path, "no DATA section with instances"));
    }
    let face_count =
        records.ids_named("ADVANCED_FACE").count() + records.ids_named("FACE_SURFACE").count();
    if face_count == 0 {
        let tess = records
            .by_id
            .values()
            .find(|r| {
                r.names
                    .iter()
                    .any(|n| n.starts_with("TESSELLATED") || n.contains("TRIANGULATED"))
            })
            .map(|r| r.display_name());
        return Err(Error::input(
            path,
            match tess {
                Some(t) => format!(
                    "no B-rep faces (ADVANCED_FACE): the file holds tessellated geometry \
                     only ({t}), which the STEP reader does not support; encode the mesh \
                     instead"
                ),
                None => "no B-rep faces (ADVANCED_FACE) in the file".to_string(),
            },
        ));
    }
    let millimetres_per_unit = if opts.to_millimetres {
        records.millimetres_per_unit()
    } else {
        None
    };
    let exchange = truck_stepio::r#in::ruststep::parser::parse(&text).map_err(|e| {
        let detail = match check::locate_syntax_error(&prepassed) {
            Some(p) => format!("STEP syntax error at {p}"),
            // ruststep's own message, on one line.
            None => format!(
                "STEP syntax error: {}",
                e.to_string()
                    .split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" ")
            ),
        };
        Error::input(path, detail)
    })?;
    let Some(data) = exchange.data.first() else {
        return Err(Error::input(path, "no DATA section"));
    };
    let table = Table::from_data_section(data);

    // Bodies: solids, or every shell when there are none.
    let mut body_shells: Vec<BodyShells> = Vec::new();
    let mut in_solid = std::collections::BTreeSet::new();
    for (&id, r) in &records.by_id {
        if r.is("MANIFOLD_SOLID_BREP") || r.is("BREP_WITH_VOIDS") {
            let shells: Vec<(u64, bool)> = r
                .refs
                .iter()
                .filter_map(|&s| resolve_shell(&records, s))
                .collect();
            for s in &shells {
                in_solid.insert(s.0);
            }
            body_shells.push((id, r.display_name(), shells));
        }
    }
    let all_shells: Vec<u64> = records
        .by_id
        .iter()
        .filter(|(_, r)| r.is("CLOSED_SHELL") || r.is("OPEN_SHELL"))
        .map(|(&id, _)| id)
        .collect();
    let mut skipped = Vec::new();
    if body_shells.is_empty() {
        for &s in &all_shells {
            body_shells.push((s, records.name_of(s), vec![(s, false)]));
        }
    } else {
        let free: Vec<u64> = all_shells
            .iter()
            .copied()
            .filter(|s| !in_solid.contains(s))
            .collect();
        let mut free_faces = 0;
        for &s in &free {
            for &f in &records.by_id[&s].refs {
                free_faces += 1;
                skipped.push(SkippedFace {
                    face_id: f,
                    body: format!("#{s}"),
                    entity: format!("{} #{s}", records.name_of(s)),
                    reason: "face of a shell that bounds no solid; only solids are read when \
                             the file has solids"
                        .into(),
                });
            }
        }
        if !free.is_empty() {
            notes.push(format!(
                "{} shells ({free_faces} faces) bound no solid and were left out",
                free.len()
            ));
        }
    }

    // Assembly instances: each solid once per placement.
    let solid_ids: Vec<u64> = body_shells.iter().map(|b| b.0).collect();
    let instances = records
        .solid_instances(&solid_ids)
        .map_err(|e| Error::input(path, format!("assembly structure: {e}")))?;
    let total: usize = instances.values().map(Vec::len).sum();
    if total > solid_ids.len() || instances.values().flatten().any(|m| *m != DMat4::IDENTITY) {
        notes.push(format!(
            "assembly: {} solids placed as {total} instances",
            solid_ids.len()
        ));
    }
    let radians_per_angle_unit = records.radians_per_angle_unit();
    Ok(Loaded {
        radians_per_angle_unit,
        table: Arc::new(table),
        records: Arc::new(records),
        body_shells,
        instances,
        skipped,
        notes,
        millimetres_per_unit,
    })
}

/// `(solid or shell id, entity name, [(shell id, flip)])`: the shells of one body.
type BodyShells = (u64, String, Vec<(u64, bool)>);

/// The parsed file, before its faces are converted.
pub(super) struct Loaded {
    table: Arc<Table>,
    records: Arc<Records>,
    /// `(solid or shell id, entity name, [(shell id, flip)])` per body.
    body_shells: Vec<BodyShells>,
    instances: BTreeMap<u64, Vec<DMat4>>,
    skipped: Vec<SkippedFace>,
    notes: Vec<String>,
    millimetres_per_unit: Option<f64>,
    /// Plane-angle unit of the file (cone semi-angles), radians per unit.
    radians_per_angle_unit: f64,
}

/// Converts every face of every body, each in a watchdog thread (`face_timeout`): a face
/// whose conversion panics or hangs is skipped and named, the others are kept. An error
/// when more conversions than a read tolerates are still running after their timeout.
pub(super) fn convert(
    loaded: Loaded,
    opts: &super::StepOptions,
    workers: Workers,
) -> Result<Parsed> {
    let Loaded {
        table,
        records,
        body_shells,
        instances,
        mut skipped,
        mut notes,
        millimetres_per_unit,
        radians_per_angle_unit,
    } = loaded;
    let mut exact_faces = 0usize;
    let mut bodies: Vec<ParsedBody> = Vec::new();
    for (id, entity, shells) in body_shells {
        let name = format!("body{}", bodies.len() + 1);
        let mut body = ParsedBody {
            name: name.clone(),
            step_id: id,
            entity,
            placement: DMat4::IDENTITY,
            vertices: Vec::new(),
            vertex_ids: Vec::new(),
            edges: Vec::new(),
            edge_ids: Vec::new(),
            faces: Vec::new(),
        };
        let mut maps = IdMaps::default();
        for (shell_id, flip) in shells {
            let Some(shell) = table.shell.get(&shell_id) else {
                skipped.push(SkippedFace {
                    face_id: shell_id,
                    body: name.clone(),
                    entity: format!("{} #{shell_id}", records.name_of(shell_id)),
                    reason: "shell could not be read".into(),
                });
                continue;
            };
            for face in &shell.cfs_faces {
                let face_id = entity_ref(face).unwrap_or(0);
                let (t, r, f, m) = (table.clone(), records.clone(), face.clone(), maps.clone());
                let (nv, ne) = (body.vertices.len(), body.edges.len());
                workers.check()?;
                // truck_stepio's conversion cannot poll a token: a face that hangs in it is
                // abandoned at the timeout and counted.
                let watched = workers.run(
                    "scode-step-convert",
                    opts.face_timeout,
                    move |_: &Cancel| convert_face(&t, &r, &f, &m, nv, ne, radians_per_angle_unit),
                );
                let result = watched
                    .or_why("converting the face (truck)", opts.face_timeout)
                    .map_err(|why| (face_and_surface(&records, face_id), why))
                    .and_then(|r| r);
                match result {
                    Ok(out) => {
                        for (vid, p) in out.new_vertices {
                            maps.vertex.insert(vid, body.vertices.len());
                            body.vertices.push(p);
                            body.vertex_ids.push(vid);
                        }
                        for (eid, a, b, curve) in out.new_edges {
                            maps.edge.insert(eid, body.edges.len());
                            body.edges.push(CompressedEdge {
                                vertices: (a, b),
                                curve,
                            });
                            body.edge_ids.push(eid);
                        }
                        let mut cface = out.face;
                        if flip {
                            cface.orientation = !cface.orientation;
                        }
                        let mut info = out.info;
                        info.body = bodies.len() as u32;
                        exact_faces += usize::from(out.exact.is_some());
                        body.faces.push(ParsedFace {
                            face_id: out.real_id,
                            face: cface,
                            info,
                            exact: out.exact,
                            same_sense: out.same_sense,
                        });
                    }
                    Err((entity, reason)) => skipped.push(SkippedFace {
                        face_id,
                        body: name.clone(),
                        entity,
                        reason,
                    }),
                }
            }
        }
        let placements = instances.get(&id).cloned().unwrap_or_default();
        let n = placements.len();
        for (k, m) in placements.into_iter().enumerate() {
            let mut b = body.clone();
            b.name = format!("body{}", bodies.len() + 1);
            for f in &mut b.faces {
                f.info.body = bodies.len() as u32;
            }
            if n > 1 {
                b.entity = format!("{} (instance {} of {n})", b.entity, k + 1);
            }
            b.placement = m;
            bodies.push(b);
        }
    }
    if exact_faces > 0 {
        notes.push(format!(
            "{exact_faces} faces on planes, cylinders, cones, spheres or tori evaluated exactly \
             from their STEP records"
        ));
    }
    Ok(Parsed {
        bodies,
        skipped,
        notes,
        millimetres_per_unit,
        workers,
    })
}

/// `ADVANCED_FACE #12 on B_SPLINE_SURFACE_WITH_KNOTS #40`: a face and its surface (the
/// last reference of a face instance), for messages about faces that could not be read.
fn face_and_surface(records: &Records, face_id: u64) -> String {
    let face = format!("{} #{face_id}", records.name_of(face_id));
    match records.get(face_id).and_then(|r| r.refs.last()) {
        Some(&s) if records.get(s).is_some() => format!("{face} on {} #{s}", records.name_of(s)),
        _ => face,
    }
}

/// `(shell id, flip)` for a CLOSED_SHELL / OPEN_SHELL or an ORIENTED_*_SHELL around one.
fn resolve_shell(records: &Records, id: u64) -> Option<(u64, bool)> {
    let r = records.get(id)?;
    if r.is("CLOSED_SHELL") || r.is("OPEN_SHELL") {
        return Some((id, false));
    }
    if r.is("ORIENTED_CLOSED_SHELL") || r.is("ORIENTED_OPEN_SHELL") {
        let inner = *r.refs.last()?;
        let flip = r.params.replace(' ', "").ends_with(".F.)");
        return resolve_shell(records, inner).map(|(s, f)| (s, f ^ flip));
    }
    None
}

/// STEP id -> index in the body, for vertices and edges.
#[derive(Clone, Default)]
struct IdMaps {
    vertex: BTreeMap<u64, usize>,
    edge: BTreeMap<u64, usize>,
}

type FaceError = (String, String);

/// Converts one face; on failure returns `(entity, reason)`. Edges and vertices are added
/// to the body only when the whole face converts.
fn convert_face(
    table: &Table,
    records: &Records,
    face: &PlaceHolder<FaceAnyHolder>,
    maps: &IdMaps,
    n_vertices: usize,
    n_edges: usize,
    radians_per_angle_unit: f64,
) -> std::result::Result<FaceOut, FaceError> {
    let face_id = entity_ref(face).unwrap_or(0);
    let (orientation, real_id, holder) = face_surface_of(table, records, face_id)?;
    let (surface, info, exact) =
        convert_surface(table, records, &holder, real_id, radians_per_angle_unit)?;
    let mut bounds = BoundReader {
        table,
        records,
        maps,
        n_vertices,
        n_edges,
        new_vertices: Vec::new(),
        new_edges: Vec::new(),
    };
    let mut boundaries = Vec::new();
    for bound in &holder.bounds {
        if let Some(wire) = bounds.wire(bound, real_id)? {
            boundaries.push(wire);
        }
    }
    Ok(FaceOut {
        real_id,
        face: CompressedFace {
            surface,
            boundaries,
            orientation,
        },
        info,
        exact,
        same_sense: holder.same_sense,
        new_vertices: bounds.new_vertices,
        new_edges: bounds.new_edges,
    })
}

/// `ENTITY #id`, naming an entity in an error.
fn entity_name(records: &Records, id: u64) -> String {
    format!("{} #{id}", records.name_of(id))
}

/// The FACE_SURFACE under face `face_id` (itself, or the face of an ORIENTED_FACE), with
/// the face's orientation and the FACE_SURFACE's id.
fn face_surface_of(
    table: &Table,
    records: &Records,
    face_id: u64,
) -> std::result::Result<(bool, u64, FaceSurfaceHolder), FaceError> {
    let unsupported = |id: u64| {
        (
            entity_name(records, id),
            "face entity is not supported by the STEP reader".to_string(),
        )
    };
    if let Some(of) = table.oriented_face.get(&face_id) {
        let inner = entity_ref(&of.face_element).unwrap_or(face_id);
        let h = match &of.face_element {
            PlaceHolder::Owned(h) => Some(h.clone()),
            PlaceHolder::Ref(_) => table.face_surface.get(&inner).cloned(),
        };
        match h {
            Some(h) => Ok((of.orientation, inner, h)),
            None => Err(unsupported(inner)),
        }
    } else if let Some(h) = table.face_surface.get(&face_id) {
        Ok((true, face_id, h.clone()))
    } else {
        Err(unsupported(face_id))
    }
}

/// truck's surface of a face (turned round when the face's `same_sense` is false), its
/// description (from the exact surface where the record gives one) and the exact surface.
fn convert_surface(
    table: &Table,
    records: &Records,
    holder: &FaceSurfaceHolder,
    real_id: u64,
    radians_per_angle_unit: f64,
) -> std::result::Result<(Surface, FaceSurface, Option<Analytic>), FaceError> {
    let surface_id = entity_ref(&holder.face_geometry).unwrap_or(real_id);
    let here = || entity_name(records, surface_id);
    let owned = holder
        .face_geometry
        .clone()
        .into_owned(table)
        .map_err(|e| {
            (
                here(),
                format!("surface entity is not supported by the STEP reader ({e})"),
            )
        })?;
    let mut surface = Surface::try_from(&owned)
        .map_err(|e| (here(), format!("surface cannot be converted: {e}")))?;
    let mut info = surface_info(&surface, records.name_of(surface_id), real_id);
    info.surface_id = surface_id;
    // The exact surface from the record; an unreadable record leaves truck's surface.
    let exact = Analytic::from_record(records, surface_id, radians_per_angle_unit)
        .ok()
        .flatten();
    if let Some(a) = &exact {
        let (surface, exact) = a.describe();
        info.surface = surface;
        info.exact = Some(exact);
    }
    if !holder.same_sense {
        surface.invert();
    }
    Ok((surface, info, exact))
}

/// Reads a face's bounds as wires of body edge indices. Edges and vertices the body does
/// not have yet are collected here, numbered after the body's `n_edges` and `n_vertices`.
struct BoundReader<'t> {
    table: &'t Table,
    records: &'t Records,
    maps: &'t IdMaps,
    n_vertices: usize,
    n_edges: usize,
    new_vertices: Vec<(u64, Point3)>,
    /// (EDGE_CURVE id, start vertex, end vertex, curve).
    new_edges: Vec<(u64, usize, usize, Curve3D)>,
}

impl BoundReader<'_> {
    fn here(&self, id: u64) -> String {
        entity_name(self.records, id)
    }

    /// The wire of one face bound (of face `real_id`), in the face's direction; `None`
    /// for a VERTEX_LOOP (a cone apex or sphere pole carries no curve: truck ignores it
    /// too).
    fn wire(
        &mut self,
        bound: &PlaceHolder<FaceBoundHolder>,
        real_id: u64,
    ) -> std::result::Result<Option<Vec<CompressedEdgeIndex>>, FaceError> {
        let table = self.table;
        let fb: Option<FaceBoundHolder> = match bound {
            PlaceHolder::Owned(h) => Some(h.clone()),
            PlaceHolder::Ref(Name::Entity(id)) => table.face_bound.get(id).cloned(),
            _ => None,
        };
        let Some(fb) = fb else {
            let id = entity_ref(bound).unwrap_or(0);
            return Err((self.here(id), "face bound is not supported".into()));
        };
        let ori = fb.orientation;
        let loop_holder = match &fb.bound {
            PlaceHolder::Owned(h) => Some(h.clone()),
            PlaceHolder::Ref(Name::Entity(id)) => table.edge_loop.get(id).cloned(),
            _ => None,
        };
        let Some(edge_loop) = loop_holder else {
            let id = entity_ref(&fb.bound).unwrap_or(0);
            if self.records.get(id).is_some_and(|r| r.is("VERTEX_LOOP")) {
                return Ok(None);
            }
            return Err((self.here(id), "loop entity is not supported".into()));
        };
        let mut wire = Vec::new();
        for e in &edge_loop.edge_list {
            let Some(eid) = entity_ref(e) else {
                return Err((self.here(real_id), "inline edge is not supported".into()));
            };
            let (curve_id, orientation) = if let Some(oe) = table.oriented_edge.get(&eid) {
                let Some(inner) = entity_ref(&oe.edge_element) else {
                    return Err((self.here(eid), "inline edge is not supported".into()));
                };
                (inner, oe.orientation == ori)
            } else if table.edge_curve.contains_key(&eid) {
                (eid, ori)
            } else {
                return Err((self.here(eid), "edge entity is not supported".into()));
            };
            let index = self.edge_index(curve_id)?;
            wire.push(CompressedEdgeIndex { index, orientation });
        }
        if !ori {
            wire.reverse();
        }
        Ok(Some(wire))
    }

    /// Body index of EDGE_CURVE `curve_id`, converting it (and its vertices) when the body
    /// does not have it yet.
    fn edge_index(&mut self, curve_id: u64) -> std::result::Result<usize, FaceError> {
        if let Some(&i) = self.maps.edge.get(&curve_id) {
            return Ok(i);
        }
        if let Some(k) = self.new_edges.iter().position(|x| x.0 == curve_id) {
            return Ok(self.n_edges + k);
        }
        let table = self.table;
        let Some(ec) = table.edge_curve.get(&curve_id) else {
            return Err((self.here(curve_id), "edge entity is not supported".into()));
        };
        let geom_id = entity_ref(&ec.edge_geometry).unwrap_or(curve_id);
        let owned = ec.clone().into_owned(table).map_err(|e| {
            (
                self.here(geom_id),
                format!("curve of edge #{curve_id} is not supported by the STEP reader ({e})"),
            )
        })?;
        let curve = owned.parse_curve3d().map_err(|e| {
            (
                self.here(geom_id),
                format!("curve of edge #{curve_id} cannot be converted: {e}"),
            )
        })?;
        let a = self.vertex_index(&ec.edge_start, curve_id)?;
        let b = self.vertex_index(&ec.edge_end, curve_id)?;
        self.new_edges.push((curve_id, a, b, curve));
        Ok(self.n_edges + self.new_edges.len() - 1)
    }

    /// Body index of a vertex of EDGE_CURVE `curve_id`, reading it when the body does not
    /// have it yet.
    fn vertex_index(
        &mut self,
        p: &PlaceHolder<VertexPointHolder>,
        curve_id: u64,
    ) -> std::result::Result<usize, FaceError> {
        let vid = entity_ref(p).ok_or_else(|| {
            (
                self.here(curve_id),
                "inline vertex is not supported".to_string(),
            )
        })?;
        if let Some(&i) = self.maps.vertex.get(&vid) {
            return Ok(i);
        }
        if let Some(k) = self.new_vertices.iter().position(|x| x.0 == vid) {
            return Ok(self.n_vertices + k);
        }
        let vp = EntityTable::<VertexPointHolder>::get_owned(self.table, vid)
            .map_err(|e| (self.here(vid), format!("vertex cannot be read ({e})")))?;
        self.new_vertices
            .push((vid, Point3::from(&vp.vertex_geometry)));
        Ok(self.n_vertices + self.new_vertices.len() - 1)
    }
}

/// A converted face with the vertices and edges it adds to its body.
struct FaceOut {
    real_id: u64,
    face: CompressedFace<Surface>,
    info: FaceSurface,
    exact: Option<Analytic>,
    same_sense: bool,
    new_vertices: Vec<(u64, Point3)>,
    new_edges: Vec<(u64, usize, usize, Curve3D)>,
}

fn dv(p: Point3) -> DVec3 {
    DVec3::new(p.x, p.y, p.z)
}

fn dvv(v: Vector3) -> DVec3 {
    DVec3::new(v.x, v.y, v.z)
}

/// Origin and unit direction of a revolution axis, through a placement matrix.
fn placed_axis(m: &Matrix4, origin: Point3, axis: Vector3) -> Axis {
    Axis {
        origin: dv(m.transform_point(origin)),
        direction: dvv(m.transform_vector(axis)).normalize_or_zero(),
    }
}

/// Type and exact parameters of a truck surface (before `same_sense` is applied).
fn surface_info(surface: &Surface, entity: String, face_id: u64) -> FaceSurface {
    let mut info = FaceSurface {
        face_id,
        surface_id: 0,
        body: 0,
        surface: SurfaceType::Other(entity.clone()),
        entity,
        exact: None,
        revolution_axis: None,
    };
    match surface {
        Surface::ElementarySurface(es) => match es.as_ref() {
            ElementarySurface::Plane(p) => {
                info.surface = SurfaceType::Plane;
                info.exact = Some(AnalyticSurface::Plane {
                    point: dv(p.origin()),
                    normal: dvv(p.normal()),
                });
            }
            ElementarySurface::Sphere(s) => {
                info.surface = SurfaceType::Sphere;
                let m = s.transform();
                info.exact = Some(AnalyticSurface::Sphere {
                    center: placed_axis(m, s.entity().0.center(), Vector3::unit_z()).origin,
                    radius: s.entity().0.radius(),
                });
            }
            ElementarySurface::ToroidalSurface(t) => {
                info.surface = SurfaceType::Torus;
                let m = t.transform();
                info.exact = Some(AnalyticSurface::Torus {
                    axis: placed_axis(m, t.entity().center(), Vector3::unit_z()),
                    major_radius: t.entity().large_radius(),
                    minor_radius: t.entity().small_radius(),
                });
            }
            ElementarySurface::CylindricalSurface(c) => {
                info.surface = SurfaceType::Cylinder;
                let m = c.transform();
                let rc = c.entity();
                let axis = placed_axis(m, rc.origin(), rc.axis());
                let a = dv(m.transform_point(rc.entity_curve().0));
                info.exact = Some(AnalyticSurface::Cylinder {
                    axis,
                    radius: radial(a, &axis).length(),
                });
            }
            ElementarySurface::ConicalSurface(c) => {
                info.surface = SurfaceType::Cone;
                let m = c.transform();
                let rc = c.entity();
                let axis = placed_axis(m, rc.origin(), rc.axis());
                let a = dv(m.transform_point(rc.entity_curve().0));
                let b = dv(m.transform_point(rc.entity_curve().1));
                let ra = radial(a, &axis);
                let rb = radial(b, &axis);
                let sa = ra.length();
                let sb = if sa > 0.0 {
                    rb.dot(ra) / sa
                } else {
                    rb.length()
                };
                if (sa - sb).abs() > 1e-300 {
                    let t = sa / (sa - sb);
                    let apex = a + t * (b - a);
                    let far = if sa >= sb.abs() { a } else { b };
                    let mut d = axis.direction;
                    if (far - apex).dot(d) < 0.0 {
                        d = -d;
                    }
                    let h = (far - apex).dot(d);
                    info.exact = Some(AnalyticSurface::Cone {
                        axis: Axis {
                            origin: apex,
                            direction: d,
                        },
                        half_angle: radial(far, &axis).length().atan2(h),
                    });
                }
            }
        },
        Surface::SweptCurve(sc) => match sc.as_ref() {
            SweptCurve::ExtrudedCurve(_) => info.surface = SurfaceType::SurfaceOfExtrusion,
            SweptCurve::RevolutedCurve(r) => {
                info.surface = SurfaceType::SurfaceOfRevolution;
                info.revolution_axis = Some(placed_axis(
                    r.transform(),
                    r.entity().origin(),
                    r.entity().axis(),
                ));
            }
        },
        Surface::BSplineSurface(_) | Surface::NurbsSurface(_) => {
            info.surface = SurfaceType::BSplineSurface;
        }
    }
    info
}

/// Component of `p - axis.origin` perpendicular to the axis.
fn radial(p: DVec3, axis: &Axis) -> DVec3 {
    let v = p - axis.origin;
    v - v.dot(axis.direction) * axis.direction
}
