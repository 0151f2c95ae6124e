//! A light scanner over the text of a STEP file (ISO 10303-21), independent of truck.
//!
//! truck/ruststep turn entities into geometry but forget what they could not use, and they
//! know nothing of ids once a shell is converted. This scanner keeps, for every instance of
//! the DATA section, its id, entity name(s) and the ids it references: enough to name an
//! unsupported entity in a message, to find solids, shells and faces, and to read the length
//! unit. It also applies the text pre-passes truck needs (see crates.md, "STEP") and
//! rewrites parabolas, which truck's conversion hangs on, as B-splines.

use std::collections::BTreeMap;

use glam::{DMat4, DVec3};

/// One instance `#id = NAME(...)` or `#id = ( A(...) B(...) )` of the DATA section.
///
/// Only names and references are kept (not the parameters): every question this module
/// answers is "what is #id" or "what does #id point to", and keeping the parameter text of a
/// 3 MB file twice would be wasteful. `params` is kept for the few small records whose
/// values matter (units).
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// Entity names: one for a simple instance, several for a complex one.
    pub names: Vec<String>,
    /// Referenced instance ids in order of appearance (outside strings).
    pub refs: Vec<u64>,
    /// The parameter text, for records shorter than 200 bytes (else empty).
    pub params: String,
}

impl Record {
    /// The entity name for messages: `NAME` or `(A B C)` for complex instances.
    pub fn display_name(&self) -> String {
        if self.names.len() == 1 {
            return self.names[0].clone();
        }
        // Leave out the supertypes every geometric complex instance repeats.
        const GENERIC: [&str; 8] = [
            "REPRESENTATION_ITEM",
            "GEOMETRIC_REPRESENTATION_ITEM",
            "SURFACE",
            "CURVE",
            "BOUNDED_SURFACE",
            "BOUNDED_CURVE",
            "B_SPLINE_SURFACE",
            "B_SPLINE_CURVE",
        ];
        let specific: Vec<&str> = self
            .names
            .iter()
            .map(String::as_str)
            .filter(|n| !GENERIC.contains(n))
            .collect();
        let names = if specific.is_empty() {
            self.names.iter().map(String::as_str).collect()
        } else {
            specific
        };
        format!("({})", names.join(" "))
    }

    pub fn is(&self, name: &str) -> bool {
        self.names.iter().any(|n| n == name)
    }
}

/// All instances by id (ordered, so every walk over them is deterministic).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Records {
    pub by_id: BTreeMap<u64, Record>,
}

impl Records {
    pub fn get(&self, id: u64) -> Option<&Record> {
        self.by_id.get(&id)
    }

    /// Entity name of `#id` for messages (`#id (missing)` when absent).
    pub fn name_of(&self, id: u64) -> String {
        self.get(id)
            .map(Record::display_name)
            .unwrap_or_else(|| "missing instance".to_string())
    }

    /// Ids of instances with entity name `name`, ascending.
    pub fn ids_named<'a>(&'a self, name: &'a str) -> impl Iterator<Item = u64> + 'a {
        self.by_id
            .iter()
            .filter(move |(_, r)| r.is(name))
            .map(|(&id, _)| id)
    }

    /// Millimetres per model unit, from the LENGTH_UNIT referenced by a
    /// GLOBAL_UNIT_ASSIGNED_CONTEXT (first by id); `None` when the file does not say or uses
    /// a unit this scanner does not know.
    pub fn millimetres_per_unit(&self) -> Option<f64> {
        for id in self.ids_named("GLOBAL_UNIT_ASSIGNED_CONTEXT") {
            for &u in &self.by_id[&id].refs {
                let Some(unit) = self.get(u) else { continue };
                if !unit.is("LENGTH_UNIT") {
                    continue;
                }
                return self.unit_factor(unit, 0);
            }
        }
        None
    }

    /// Radians per plane-angle unit of the file (the PLANE_ANGLE_UNIT of the first
    /// GLOBAL_UNIT_ASSIGNED_CONTEXT): 1 for radians or when the file does not say, the
    /// conversion factor of a CONVERSION_BASED_UNIT (degrees: pi / 180).
    pub fn radians_per_angle_unit(&self) -> f64 {
        for id in self.ids_named("GLOBAL_UNIT_ASSIGNED_CONTEXT") {
            for &u in &self.by_id[&id].refs {
                let Some(unit) = self.get(u) else { continue };
                if !unit.is("PLANE_ANGLE_UNIT") || !unit.is("CONVERSION_BASED_UNIT") {
                    continue;
                }
                for &r in &unit.refs {
                    if let Some(m) = self.get(r) {
                        if m.is("PLANE_ANGLE_MEASURE_WITH_UNIT") {
                            if let Some(v) = parse_measure(&m.params).filter(|v| *v > 0.0) {
                                return v;
                            }
                        }
                    }
                }
                if unit.params.to_ascii_uppercase().contains("DEGREE") {
                    return std::f64::consts::PI / 180.0;
                }
            }
        }
        1.0
    }

    fn unit_factor(&self, unit: &Record, depth: u32) -> Option<f64> {
        if depth > 4 {
            return None;
        }
        let p = unit.params.to_ascii_uppercase();
        if unit.is("SI_UNIT") {
            if !p.contains(".METRE.") {
                return None;
            }
            let prefix = [
                (".KILO.", 1e6),
                (".CENTI.", 10.0),
                (".DECI.", 100.0),
                (".MILLI.", 1.0),
                (".MICRO.", 1e-3),
                (".NANO.", 1e-6),
            ];
            return Some(
                prefix
                    .iter()
                    .find(|(k, _)| p.contains(k))
                    .map_or(1000.0, |(_, f)| *f),
            );
        }
        if unit.is("CONVERSION_BASED_UNIT") {
            for (name, f) in [("'INCH'", 25.4), ("'FOOT'", 304.8), ("'MILLIMETRE'", 1.0)] {
                if p.contains(name) {
                    return Some(f);
                }
            }
            // LENGTH_MEASURE_WITH_UNIT(LENGTH_MEASURE(v), #base)
            for &r in &unit.refs {
                let m = self.get(r)?;
                if m.is("LENGTH_MEASURE_WITH_UNIT") {
                    let v = parse_measure(&m.params)?;
                    let base = self.get(*m.refs.first()?)?;
                    return Some(v * self.unit_factor(base, depth + 1)?);
                }
            }
        }
        None
    }
}

impl Records {
    /// Top-level arguments of a short simple record (`NAME(a,b,(c,d))` -> `a`, `b`, `(c,d)`).
    pub(super) fn args(&self, id: u64) -> Option<Vec<String>> {
        let p = &self.get(id)?.params;
        let open = p.find('(')?;
        let close = p.rfind(')')?;
        let inner = p.get(open + 1..close)?;
        let mut out = Vec::new();
        let mut depth = 0;
        let mut cur = String::new();
        let mut in_string = false;
        for c in inner.chars() {
            match c {
                '\'' => in_string = !in_string,
                '(' if !in_string => depth += 1,
                ')' if !in_string => depth -= 1,
                ',' if !in_string && depth == 0 => {
                    out.push(std::mem::take(&mut cur).trim().to_string());
                    continue;
                }
                _ => {}
            }
            cur.push(c);
        }
        out.push(cur.trim().to_string());
        Some(out)
    }

    /// The three numbers of a CARTESIAN_POINT or DIRECTION.
    fn triple(&self, id: u64) -> Option<DVec3> {
        let a = self.args(id)?;
        let list = a.get(1)?.trim().strip_prefix('(')?.strip_suffix(')')?;
        let v: Vec<f64> = list
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .ok()?;
        match v.as_slice() {
            [x, y, z] => Some(DVec3::new(*x, *y, *z)),
            [x, y] => Some(DVec3::new(*x, *y, 0.0)),
            _ => None,
        }
    }

    fn reference(&self, arg: &str) -> Option<u64> {
        arg.trim().strip_prefix('#')?.parse().ok()
    }

    /// AXIS2_PLACEMENT_3D as the matrix from its local frame to its representation's frame.
    pub fn placement(&self, id: u64) -> Option<DMat4> {
        let r = self.get(id)?;
        if !r.is("AXIS2_PLACEMENT_3D") {
            return None;
        }
        let a = self.args(id)?;
        let origin = self.triple(self.reference(a.get(1)?)?)?;
        let z = a
            .get(2)
            .and_then(|x| self.reference(x))
            .and_then(|d| self.triple(d))
            .unwrap_or(DVec3::Z)
            .normalize_or_zero();
        let x = a
            .get(3)
            .and_then(|x| self.reference(x))
            .and_then(|d| self.triple(d))
            .unwrap_or(DVec3::X);
        let mut x = (x - x.dot(z) * z).normalize_or_zero();
        if x == DVec3::ZERO {
            // No ref_direction, or one along the axis: ISO 10303-42 `first_proj_axis`
            // takes (1, 0, 0), or (0, 1, 0) when the axis is along x.
            x = (DVec3::Y - DVec3::Y.dot(z) * z).normalize_or_zero();
        }
        if z == DVec3::ZERO || x == DVec3::ZERO {
            return None;
        }
        let y = z.cross(x);
        Some(DMat4::from_cols(
            x.extend(0.0),
            y.extend(0.0),
            z.extend(0.0),
            origin.extend(1.0),
        ))
    }

    /// Where each solid appears in the assembly: for every solid id, one matrix (from the
    /// solid's coordinates to the root assembly's) per instance, ordered deterministically.
    /// Representations are linked by REPRESENTATION_RELATIONSHIP_WITH_TRANSFORMATION (child
    /// `rep_1` into parent `rep_2` through ITEM_DEFINED_TRANSFORMATION: `p_parent =
    /// M(item_2) * M(item_1)^-1 * p_child`, as Open CASCADE reads it) and by plain
    /// (SHAPE_)REPRESENTATION_RELATIONSHIPs, which alias two representations of one part.
    /// A file without transformations gives every solid one identity instance. Errors name
    /// the entity that cannot be used.
    pub fn solid_instances(
        &self,
        solids: &[u64],
    ) -> std::result::Result<BTreeMap<u64, Vec<DMat4>>, String> {
        // Union-find over representations linked without a transformation.
        let mut alias: BTreeMap<u64, u64> = BTreeMap::new();
        fn find(alias: &BTreeMap<u64, u64>, mut x: u64) -> u64 {
            while let Some(&p) = alias.get(&x) {
                if p == x {
                    break;
                }
                x = p;
            }
            x
        }
        // child group -> [(parent rep, matrix)]
        let mut links: Vec<(u64, u64, DMat4)> = Vec::new();
        for (&id, r) in &self.by_id {
            let is_rel = r
                .names
                .iter()
                .any(|n| n.ends_with("REPRESENTATION_RELATIONSHIP"));
            if !is_rel {
                continue;
            }
            let (Some(&a), Some(&b)) = (r.refs.first(), r.refs.get(1)) else {
                continue;
            };
            if r.is("REPRESENTATION_RELATIONSHIP_WITH_TRANSFORMATION") {
                let Some(&t) = r.refs.get(2) else {
                    return Err(format!("{} #{id} has no transformation", r.display_name()));
                };
                let tr = self.get(t);
                if !tr.is_some_and(|x| x.is("ITEM_DEFINED_TRANSFORMATION")) {
                    return Err(format!(
                        "unsupported entity {} #{t} (transformation of #{id})",
                        self.name_of(t)
                    ));
                }
                let refs = &self.by_id[&t].refs;
                let m = match (
                    refs.first().and_then(|&x| self.placement(x)),
                    refs.get(1).and_then(|&x| self.placement(x)),
                ) {
                    (Some(m1), Some(m2)) => m2 * m1.inverse(),
                    _ => {
                        return Err(format!(
                            "ITEM_DEFINED_TRANSFORMATION #{t}: its items are not \
                             AXIS2_PLACEMENT_3D placements"
                        ))
                    }
                };
                links.push((a, b, m));
            } else {
                let (ra, rb) = (find(&alias, a), find(&alias, b));
                if ra != rb {
                    alias.insert(ra.max(rb), ra.min(rb));
                }
            }
        }
        // Parents of each representation group.
        let mut parents: BTreeMap<u64, Vec<(u64, DMat4)>> = BTreeMap::new();
        for &(child, parent, m) in &links {
            parents
                .entry(find(&alias, child))
                .or_default()
                .push((find(&alias, parent), m));
        }
        // Representation containing each solid (the first one listing it as an item).
        let mut out = BTreeMap::new();
        for &solid in solids {
            let rep = self
                .by_id
                .iter()
                .find(|(_, r)| {
                    r.names.iter().any(|n| n.ends_with("REPRESENTATION")) && r.refs.contains(&solid)
                })
                .map(|(&id, _)| id);
            let mut instances = Vec::new();
            match rep {
                None => instances.push(DMat4::IDENTITY),
                Some(rep) => {
                    let mut stack = vec![(find(&alias, rep), DMat4::IDENTITY, 0u32)];
                    while let Some((g, m, depth)) = stack.pop() {
                        match parents.get(&g) {
                            Some(ps) if depth < 32 => {
                                for &(p, t) in ps.iter().rev() {
                                    stack.push((p, t * m, depth + 1));
                                }
                            }
                            _ => instances.push(m),
                        }
                        if instances.len() > 100_000 {
                            return Err("more than 100000 assembly instances".into());
                        }
                    }
                }
            }
            out.insert(solid, instances);
        }
        Ok(out)
    }
}

fn parse_measure(params: &str) -> Option<f64> {
    let s = params.split('(').nth(2)?;
    s.split(')').next()?.trim().parse().ok()
}

/// Text pre-passes that make truck/ruststep read files they would otherwise reject or hang
/// on (crates.md, "STEP"): `SURFACE_CURVE(..., .PCURVE_S1.)` makes truck drop the 3D curve
/// (rewrite the master flag to `.CURVE_3D.`), and ruststep rejects an empty list `()` used as
/// a parameter value (rewritten to `$`, "unset"). Strings and comments are left alone.
/// Returns the new text and how many rewrites of each kind were made.
pub fn prepass(text: &str) -> (String, usize, usize) {
    let bytes = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut pcurve = 0;
    let mut empty = 0;
    let mut i = 0;
    let mut last_sig: u8 = b' ';
    let mut start = 0;
    while i < bytes.len() {
        let c = bytes[i];
        match c {
            b'\'' => {
                // string: copy up to the closing quote ('' is an escaped quote)
                let mut j = i + 1;
                while j < bytes.len() {
                    if bytes[j] == b'\'' {
                        if j + 1 < bytes.len() && bytes[j + 1] == b'\'' {
                            j += 2;
                            continue;
                        }
                        break;
                    }
                    j += 1;
                }
                i = (j + 1).min(bytes.len());
                last_sig = b'\'';
            }
            b'/' if bytes.get(i + 1) == Some(&b'*') => {
                let end = text[i + 2..]
                    .find("*/")
                    .map_or(bytes.len(), |k| i + 2 + k + 2);
                i = end;
            }
            b'(' if last_sig == b',' || last_sig == b'(' => {
                let mut j = i + 1;
                while j < bytes.len() && bytes[j].is_ascii_whitespace() {
                    j += 1;
                }
                if bytes.get(j) == Some(&b')') {
                    out.push_str(&text[start..i]);
                    out.push('$');
                    empty += 1;
                    i = j + 1;
                    start = i;
                    last_sig = b'$';
                } else {
                    last_sig = b'(';
                    i += 1;
                }
            }
            b'.' if text[i..].starts_with(".PCURVE_S1.")
                || text[i..].starts_with(".PCURVE_S2.") =>
            {
                out.push_str(&text[start..i]);
                out.push_str(".CURVE_3D.");
                pcurve += 1;
                i += ".PCURVE_S1.".len();
                start = i;
                last_sig = b'.';
            }
            c if c.is_ascii_whitespace() => i += 1,
            c => {
                last_sig = c;
                i += 1;
            }
        }
    }
    out.push_str(&text[start..]);
    (out, pcurve, empty)
}

/// Rewrites every PARABOLA that bounds edges as the B_SPLINE_CURVE_WITH_KNOTS it is over
/// the edges' span: truck's conversion of a face with a parabola edge does not finish
/// (trj6: every face bounded by one of its four parabolas hangs, a thread spinning for the
/// rest of the process). ISO 10303-42 puts the parabola at `C + a (u^2 x + 2 u y)` (`C`,
/// `x`, `y` from its placement, `a` its focal distance); between `u0` and `u1` that is
/// exactly the quadratic Bezier curve with control points `P(u0)`, `P(u0) + (u1 - u0) / 2
/// P'(u0)`, `P(u1)`, written with knots `(u0, u1)` so the parametrisation (and the edges'
/// `same_sense`) is unchanged. `[u0, u1]` covers the vertices of every EDGE_CURVE on the
/// parabola (directly or through a SURFACE_CURVE / SEAM_CURVE). The new control points
/// take ids above the file's largest. A parabola whose edges or placement cannot be read
/// is left as it is. Returns the new text and the number of parabolas rewritten.
pub fn parabolas_to_bsplines(text: &str, records: &Records) -> (String, usize) {
    let parabolas: Vec<u64> = records.ids_named("PARABOLA").collect();
    if parabolas.is_empty() {
        return (text.to_string(), 0);
    }
    let vertices = edge_vertices_by_curve(records);
    let mut next_id = records.by_id.keys().next_back().copied().unwrap_or(0) + 1;
    // Statement id -> its replacement text.
    let mut replace: BTreeMap<u64, String> = BTreeMap::new();
    for id in parabolas {
        if let Some(t) = parabola_as_bspline(records, id, &vertices, &mut next_id) {
            replace.insert(id, t);
        }
    }
    if replace.is_empty() {
        return (text.to_string(), 0);
    }
    replace_statements(text, &replace)
}

/// Curve id -> vertex ids of the EDGE_CURVEs on it (directly or through a SURFACE_CURVE /
/// SEAM_CURVE).
fn edge_vertices_by_curve(records: &Records) -> BTreeMap<u64, Vec<u64>> {
    let mut vertices: BTreeMap<u64, Vec<u64>> = BTreeMap::new();
    for edge in records.ids_named("EDGE_CURVE") {
        let Some(r) = records.get(edge) else { continue };
        let [start, end, geometry] = [0, 1, 2].map(|k| r.refs.get(k).copied());
        let (Some(start), Some(end), Some(mut curve)) = (start, end, geometry) else {
            continue;
        };
        if let Some(c) = records.get(curve) {
            if c.is("SURFACE_CURVE") || c.is("SEAM_CURVE") {
                match c.refs.first() {
                    Some(&inner) => curve = inner,
                    None => continue,
                }
            }
        }
        vertices.entry(curve).or_default().extend([start, end]);
    }
    vertices
}

/// The position of a VERTEX_POINT.
fn vertex_point(records: &Records, v: u64) -> Option<DVec3> {
    let r = records.get(v)?;
    if !r.is("VERTEX_POINT") {
        return None;
    }
    records.triple(*r.refs.first()?)
}

/// The statements that replace PARABOLA `id`: the B-spline over the span of its edges'
/// vertices (`vertices`: curve id -> vertex ids) and its three control points, numbered
/// from `next_id` on (which moves past them). `None` when the parabola's placement, focal
/// distance or edges cannot be read.
fn parabola_as_bspline(
    records: &Records,
    id: u64,
    vertices: &BTreeMap<u64, Vec<u64>>,
    next_id: &mut u64,
) -> Option<String> {
    let a = records.args(id)?;
    let (Some(frame), Some(focal)) = (
        a.get(1)
            .and_then(|x| records.reference(x))
            .and_then(|p| records.placement(p)),
        a.get(2).and_then(|x| x.trim().parse::<f64>().ok()),
    ) else {
        return None;
    };
    let (x, y, c) = (
        frame.x_axis.truncate(),
        frame.y_axis.truncate(),
        frame.w_axis.truncate(),
    );
    if !(focal.is_finite() && focal.abs() > 0.0) {
        return None;
    }
    let us: Option<Vec<f64>> = vertices
        .get(&id)
        .map(|vs| {
            vs.iter()
                .map(|&v| vertex_point(records, v).map(|p| (p - c).dot(y) / (2.0 * focal)))
                .collect()
        })
        .unwrap_or(None);
    let us = us.filter(|u| !u.is_empty())?;
    let u0 = us.iter().copied().fold(f64::INFINITY, f64::min);
    let u1 = us.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(u1 > u0 && u0.is_finite() && u1.is_finite()) {
        return None;
    }
    let at = |u: f64| c + focal * (u * u * x + 2.0 * u * y);
    let tangent = |u: f64| 2.0 * focal * (u * x + y);
    let points = [at(u0), at(u0) + 0.5 * (u1 - u0) * tangent(u0), at(u1)];
    let real = |v: f64| format!("{v:.17E}");
    let ids = [*next_id, *next_id + 1, *next_id + 2];
    *next_id += 3;
    let mut t = format!(
        "#{id}=B_SPLINE_CURVE_WITH_KNOTS('',2,(#{},#{},#{}),.UNSPECIFIED.,.F.,.F.,(3,3),\
         ({},{}),.UNSPECIFIED.);",
        ids[0],
        ids[1],
        ids[2],
        real(u0),
        real(u1)
    );
    for (pid, p) in ids.iter().zip(points) {
        t.push_str(&format!(
            "\n#{pid}=CARTESIAN_POINT('',({},{},{}));",
            real(p.x),
            real(p.y),
            real(p.z)
        ));
    }
    Some(t)
}

/// Puts each replacement in `replace` (statement id -> text) where the statement `#id =
/// ...;` stands: a definition is `#id` at a statement start followed by `=`; strings and
/// comments are skipped. Returns the new text and how many statements were replaced.
fn replace_statements(text: &str, replace: &BTreeMap<u64, String>) -> (String, usize) {
    let bytes = text.as_bytes();
    let mut out = String::with_capacity(text.len() + 256 * replace.len());
    let mut copied = 0;
    let mut done = 0;
    let mut i = 0;
    let mut at_statement_start = false;
    while i < bytes.len() {
        match bytes[i] {
            b'\'' => {
                let mut j = i + 1;
                while j < bytes.len() {
                    if bytes[j] == b'\'' {
                        if bytes.get(j + 1) == Some(&b'\'') {
                            j += 2;
                            continue;
                        }
                        break;
                    }
                    j += 1;
                }
                i = j + 1;
                at_statement_start = false;
            }
            b'/' if bytes.get(i + 1) == Some(&b'*') => {
                i = text[i + 2..]
                    .find("*/")
                    .map_or(bytes.len(), |k| i + 2 + k + 2);
            }
            b';' => {
                i += 1;
                at_statement_start = true;
            }
            b'#' if at_statement_start => {
                let mut j = i + 1;
                while j < bytes.len() && bytes[j].is_ascii_digit() {
                    j += 1;
                }
                let id: Option<u64> = text[i + 1..j].parse().ok();
                at_statement_start = false;
                if let Some(new) = id.and_then(|id| replace.get(&id)) {
                    // The statement ends at the first `;` outside strings.
                    let mut k = j;
                    let mut in_string = false;
                    while k < bytes.len() && (in_string || bytes[k] != b';') {
                        if bytes[k] == b'\'' {
                            in_string = !in_string;
                        }
                        k += 1;
                    }
                    out.push_str(&text[copied..i]);
                    out.push_str(new);
                    copied = (k + 1).min(bytes.len());
                    done += 1;
                    i = copied;
                    at_statement_start = true;
                } else {
                    i = j;
                }
            }
            c if c.is_ascii_whitespace() => i += 1,
            _ => {
                at_statement_start = false;
                i += 1;
            }
        }
    }
    out.push_str(&text[copied..]);
    (out, done)
}

/// Scans the DATA section(s). Malformed statements are skipped (ruststep will report them
/// when it parses the same text); the scan itself never fails.
pub fn scan(text: &str) -> Records {
    let mut records = Records::default();
    let upper_data = find_data_start(text);
    let Some(mut pos) = upper_data else {
        return records;
    };
    let bytes = text.as_bytes();
    // Walk statements separated by ';' outside strings and comments.
    let mut stmt_start = pos;
    let mut in_string = false;
    while pos < bytes.len() {
        let c = bytes[pos];
        if in_string {
            if c == b'\'' {
                if bytes.get(pos + 1) == Some(&b'\'') {
                    pos += 2;
                    continue;
                }
                in_string = false;
            }
            pos += 1;
            continue;
        }
        match c {
            b'\'' => in_string = true,
            b'/' if bytes.get(pos + 1) == Some(&b'*') => {
                pos = text[pos + 2..]
                    .find("*/")
                    .map_or(bytes.len(), |k| pos + 2 + k + 2);
                continue;
            }
            b';' => {
                let stmt = &text[stmt_start..pos];
                if stmt.trim_start().starts_with("ENDSEC") {
                    // Another DATA section may follow.
                    match find_data_start(&text[pos..]) {
                        Some(k) => {
                            pos += k;
                            stmt_start = pos;
                            continue;
                        }
                        None => break,
                    }
                }
                if let Some((id, rec)) = parse_statement(stmt) {
                    records.by_id.insert(id, rec);
                }
                stmt_start = pos + 1;
            }
            _ => {}
        }
        pos += 1;
    }
    records
}

/// Byte offset just after the next `DATA;` (or `DATA(...);`) keyword.
fn find_data_start(text: &str) -> Option<usize> {
    let mut from = 0;
    while let Some(k) = text[from..].find("DATA") {
        let at = from + k;
        let before_ok = at == 0
            || !text.as_bytes()[at - 1].is_ascii_alphanumeric() && text.as_bytes()[at - 1] != b'_';
        let rest = text[at + 4..].trim_start();
        if before_ok && (rest.starts_with(';') || rest.starts_with('(')) {
            return text[at..].find(';').map(|e| at + e + 1);
        }
        from = at + 4;
    }
    None
}

fn parse_statement(stmt: &str) -> Option<(u64, Record)> {
    let mut s = stmt.trim();
    // Comments between statements end up at the start of the next one.
    while let Some(rest) = s.strip_prefix("/*") {
        s = rest
            .split_once("*/")
            .map_or("", |(_, after)| after)
            .trim_start();
    }
    let s = s.strip_prefix('#')?;
    let eq = s.find('=')?;
    let id: u64 = s[..eq].trim().parse().ok()?;
    let body = s[eq + 1..].trim();
    let mut names = Vec::new();
    let mut refs = Vec::new();
    let b = body.as_bytes();
    let complex = body.starts_with('(');
    let mut depth = 0i32;
    let mut i = 0;
    let mut in_string = false;
    while i < b.len() {
        let c = b[i];
        if in_string {
            if c == b'\'' {
                if b.get(i + 1) == Some(&b'\'') {
                    i += 2;
                    continue;
                }
                in_string = false;
            }
            i += 1;
            continue;
        }
        match c {
            b'\'' => in_string = true,
            b'(' => depth += 1,
            b')' => depth -= 1,
            b'#' => {
                let mut j = i + 1;
                while j < b.len() && b[j].is_ascii_digit() {
                    j += 1;
                }
                if let Ok(r) = body[i + 1..j].parse() {
                    refs.push(r);
                }
                i = j;
                continue;
            }
            c if (c.is_ascii_alphabetic() || c == b'_')
                && ((complex && depth == 1) || (!complex && depth == 0)) =>
            {
                let mut j = i;
                while j < b.len() && (b[j].is_ascii_alphanumeric() || b[j] == b'_') {
                    j += 1;
                }
                names.push(body[i..j].to_ascii_uppercase());
                i = j;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    if names.is_empty() {
        return None;
    }
    let params = if body.len() < 200 {
        body.to_string()
    } else {
        String::new()
    };
    Some((
        id,
        Record {
            names,
            refs,
            params,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "ISO-10303-21;\nHEADER;\nFILE_NAME('a;b','',(''),(''),'','','');\nENDSEC;\nDATA;\n\
#1 = CARTESIAN_POINT('it''s #9',(0.,0.,0.));\n\
#2 = ( LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.) );\n\
#3 = ( GEOMETRIC_REPRESENTATION_CONTEXT(3) GLOBAL_UNIT_ASSIGNED_CONTEXT((#2)) REPRESENTATION_CONTEXT('','') );\n\
/* comment #77; */\n\
#4 = SURFACE_CURVE('',#5,(#6,#7),\n  .PCURVE_S1.);\n\
#8 = ANNOTATION_PLANE('n',(#1),#2,());\n\
ENDSEC;\nEND-ISO-10303-21;\n";

    #[test]
    fn scans_names_and_references() {
        let r = scan(SAMPLE);
        assert_eq!(r.by_id.len(), 5);
        assert_eq!(r.get(1).unwrap().names, vec!["CARTESIAN_POINT"]);
        // '#9' inside the string is not a reference
        assert!(r.get(1).unwrap().refs.is_empty());
        assert_eq!(
            r.get(2).unwrap().display_name(),
            "(LENGTH_UNIT NAMED_UNIT SI_UNIT)"
        );
        assert_eq!(r.get(4).unwrap().refs, vec![5, 6, 7]);
        assert_eq!(r.ids_named("SURFACE_CURVE").collect::<Vec<_>>(), vec![4]);
        assert_eq!(r.millimetres_per_unit(), Some(1.0));
        assert_eq!(r.name_of(99), "missing instance");
    }

    #[test]
    fn units_metre_and_inch() {
        let m = SAMPLE.replace("SI_UNIT(.MILLI.,.METRE.)", "SI_UNIT($,.METRE.)");
        assert_eq!(scan(&m).millimetres_per_unit(), Some(1000.0));
        let inch = SAMPLE.replace(
            "( LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.) )",
            "( CONVERSION_BASED_UNIT('INCH',#9) LENGTH_UNIT() NAMED_UNIT(#10) )",
        );
        assert_eq!(scan(&inch).millimetres_per_unit(), Some(25.4));
    }

    #[test]
    fn prepass_rewrites_master_flag_and_empty_lists_only() {
        let (out, pcurve, empty) = prepass(SAMPLE);
        assert_eq!((pcurve, empty), (1, 1));
        assert!(out.contains(".CURVE_3D.);"));
        assert!(out.contains("#8 = ANNOTATION_PLANE('n',(#1),#2,$);"));
        // Record parameter lists like PLANE_ANGLE_UNIT() and strings stay as they are.
        let (same, _, e) =
            prepass("#1 = ( PLANE_ANGLE_UNIT() SI_UNIT($,.RADIAN.) ); #2 = A(',()');");
        assert_eq!(e, 0);
        assert!(same.contains("PLANE_ANGLE_UNIT()"));
        assert!(same.contains("',()'"));
    }

    /// A parabola bounding one edge becomes a quadratic B-spline with the same ends and the
    /// same midpoint (the parabola at the middle parameter), its new points numbered above
    /// the file's ids; the rest of the text is unchanged.
    #[test]
    fn parabola_becomes_its_quadratic_b_spline() {
        // C = (1, 2, 3), x = (0, 1, 0), y = (0, 0, 1) (axis (1, 0, 0)), focal distance 0.5:
        // P(u) = C + 0.5 (u^2 x + 2 u y); the edge runs from u = 1 to u = 3.
        let at = |u: f64| DVec3::new(1.0, 2.0, 3.0) + 0.5 * (u * u * DVec3::Y + 2.0 * u * DVec3::Z);
        let (p1, p3) = (at(1.0), at(3.0));
        let text = format!(
            "ISO-10303-21;\nHEADER;\nFILE_NAME('x;','',(''),(''),'','','');\nENDSEC;\nDATA;\n\
             #1=CARTESIAN_POINT('',(1.,2.,3.));\n#2=DIRECTION('',(1.,0.,0.));\n\
             #3=DIRECTION('',(0.,1.,0.));\n#4=AXIS2_PLACEMENT_3D('',#1,#2,#3);\n\
             #5 = PARABOLA('p;',#4,0.5);\n#6=CARTESIAN_POINT('',({},{},{}));\n\
             #7=CARTESIAN_POINT('',({},{},{}));\n#8=VERTEX_POINT('',#6);\n\
             #9=VERTEX_POINT('',#7);\n#10=EDGE_CURVE('',#9,#8,#5,.F.);\nENDSEC;\n\
             END-ISO-10303-21;\n",
            p1.x, p1.y, p1.z, p3.x, p3.y, p3.z
        );
        let records = scan(&text);
        let (out, n) = parabolas_to_bsplines(&text, &records);
        assert_eq!(n, 1);
        let after = scan(&out);
        assert_eq!(after.by_id.len(), records.by_id.len() + 3);
        let curve = after.get(5).unwrap();
        assert!(curve.is("B_SPLINE_CURVE_WITH_KNOTS"), "{out}");
        assert_eq!(curve.refs, vec![11, 12, 13]);
        for id in [1, 4, 10] {
            assert_eq!(after.get(id), records.get(id));
        }
        let b: Vec<DVec3> = [11, 12, 13].map(|i| after.triple(i).unwrap()).to_vec();
        let close = |a: DVec3, b: DVec3| a.distance(b) < 1e-12;
        assert!(close(b[0], p1) && close(b[2], p3), "{b:?}");
        // The quadratic Bezier at s = 1/2 is the parabola at u = 2.
        assert!(
            close(0.25 * b[0] + 0.5 * b[1] + 0.25 * b[2], at(2.0)),
            "{b:?}"
        );
        let args = after.args(5).unwrap();
        assert_eq!(args[1], "2");
        let knots: Vec<f64> = args[7]
            .trim_matches(|c| c == '(' || c == ')')
            .split(',')
            .map(|k| k.parse().unwrap())
            .collect();
        assert_eq!(knots, vec![1.0, 3.0]);
        // A file without parabolas is returned as it is.
        assert_eq!(parabolas_to_bsplines(&out, &after), (out.clone(), 0));
    }
}
