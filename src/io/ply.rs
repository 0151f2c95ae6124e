//! PLY reader (ascii, binary little- and big-endian, via `ply-rs-bw`) and binary
//! little-endian writer.
//!
//! # Conventions
//! * `vertex` element: `x`, `y`, `z` (any numeric type); an optional integer `corner`
//!   property marks corner vertices (non-zero = corner).
//! * `face` element: `vertex_indices` (or `vertex_index`) list; a scalar face property named
//!   `group`, `face_id`, `patch`, `patch_id`, `segment`, `segment_id` or `label` (first one
//!   found, in this order) gives the group. Groups are ordered by value; a group is named by a
//!   `comment scode group <value> <name>` header line when present, else `face_<value>`
//!   (the corpus' CAD-face naming). Without such a property, all faces form one group.
//! * `sharp_edge` element with `vertex1`, `vertex2`: sharp edges. (Not the generic PLY `edge`
//!   element, which many tools use for wireframes rather than creases.)
//! * Other elements are read and ignored (noted in the report).
//!
//! The writer emits exactly this: positions as `double` (so they round-trip exactly),
//! optional `float` normals `nx ny nz`, `uchar corner`, faces with a `uint group`, the group
//! names as comments, and a `sharp_edge` element.

use std::collections::{BTreeMap, BTreeSet};
use std::io::BufReader;
#[cfg(feature = "internals")]
use std::io::{self, Write};
use std::path::Path;

use glam::DVec3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    BeginList, DefaultElement, ElementDef, Header, Property, PropertyAccess, PropertyAccessResult,
    PropertyType,
};

use super::repair::RawMesh;
use crate::error::{Error, Result};
#[cfg(feature = "internals")]
use crate::mesh::ControlMesh;

/// Face properties that carry the group, in order of preference.
const GROUP_PROPERTIES: &[&str] = &[
    "group",
    "face_id",
    "patch",
    "patch_id",
    "segment",
    "segment_id",
    "label",
];

/// Header comment prefix that names a group: `comment scode group <value> <name>`.
const GROUP_COMMENT: &str = "scode group ";

/// Integer or float scalar as f64 (`None` for lists).
fn scalar_f64(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v.into(),
        Property::UChar(v) => v.into(),
        Property::Short(v) => v.into(),
        Property::UShort(v) => v.into(),
        Property::Int(v) => v.into(),
        Property::UInt(v) => v.into(),
        Property::Float(v) => v.into(),
        Property::Double(v) => v,
        _ => return None,
    })
}

/// Integer scalar as i64 (`None` for floats and lists).
fn scalar_i64(p: &Property) -> Option<i64> {
    Some(match *p {
        Property::Char(v) => v.into(),
        Property::UChar(v) => v.into(),
        Property::Short(v) => v.into(),
        Property::UShort(v) => v.into(),
        Property::Int(v) => v.into(),
        Property::UInt(v) => v.into(),
        _ => return None,
    })
}

/// One vertex as the parser fills it. A dedicated struct instead of `DefaultElement` (an
/// `IndexMap` per vertex) keeps 100k-vertex files fast. NaN marks a missing coordinate.
struct PlyVertex {
    xyz: [f64; 3],
    corner: bool,
    bad_type: bool,
}

impl PropertyAccess for PlyVertex {
    fn new() -> Self {
        PlyVertex {
            xyz: [f64::NAN; 3],
            corner: false,
            bad_type: false,
        }
    }
    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let axis = match name {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            "corner" => {
                match scalar_i64(&property) {
                    Some(v) => self.corner = v != 0,
                    None => self.bad_type = true,
                }
                return PropertyAccessResult::Set;
            }
            _ => return PropertyAccessResult::Ignored,
        };
        match scalar_f64(&property) {
            Some(v) => self.xyz[axis] = v,
            None => self.bad_type = true,
        }
        PropertyAccessResult::Set
    }
}

/// One face: its index list (filled in place for `int`/`uint` lists, the common case) and
/// its group value with the rank of the property it came from in [`GROUP_PROPERTIES`].
struct PlyFace {
    indices: Vec<i64>,
    ints: Vec<i32>,
    uints: Vec<u32>,
    group: Option<(usize, i64)>,
}

impl PropertyAccess for PlyFace {
    fn new() -> Self {
        PlyFace {
            indices: Vec::new(),
            ints: Vec::new(),
            uints: Vec::new(),
            group: None,
        }
    }
    fn begin_list_int(&mut self, name: &str, _len: usize) -> BeginList<'_, i32> {
        if is_index_list(name) {
            BeginList::Fill(&mut self.ints)
        } else {
            BeginList::UseSetter
        }
    }
    fn begin_list_uint(&mut self, name: &str, _len: usize) -> BeginList<'_, u32> {
        if is_index_list(name) {
            BeginList::Fill(&mut self.uints)
        } else {
            BeginList::UseSetter
        }
    }
    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        if is_index_list(name) {
            self.indices = match property {
                Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
                Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
                Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
                Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
                Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
                Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
                _ => return PropertyAccessResult::UnsupportedType,
            };
            return PropertyAccessResult::Set;
        }
        if let Some(rank) = GROUP_PROPERTIES.iter().position(|&g| g == name) {
            // A non-integer candidate is left unset; `parse` reports it if it is the one used.
            if let Some(v) = scalar_i64(&property) {
                if self.group.is_none_or(|(r, _)| rank < r) {
                    self.group = Some((rank, v));
                }
            }
            return PropertyAccessResult::Set;
        }
        PropertyAccessResult::Ignored
    }
}

fn is_index_list(name: &str) -> bool {
    name == "vertex_indices" || name == "vertex_index"
}

/// One `sharp_edge` element.
struct PlyEdge {
    v: [i64; 2],
}

impl PropertyAccess for PlyEdge {
    fn new() -> Self {
        PlyEdge { v: [-1, -1] }
    }
    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let slot = match name {
            "vertex1" => 0,
            "vertex2" => 1,
            _ => return PropertyAccessResult::Ignored,
        };
        match scalar_i64(&property) {
            Some(v) => {
                self.v[slot] = v;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::UnsupportedType,
        }
    }
}

/// Parses a PLY file into a [`RawMesh`].
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawMesh> {
    let ply_err = |e: &dyn std::fmt::Display| Error::input(path, format!("invalid PLY: {e}"));
    if !bytes.starts_with(b"ply") {
        return Err(Error::input(
            path,
            "not a PLY file (missing `ply` magic line)",
        ));
    }
    let mut reader = Reader::new(BufReader::new(bytes));
    let header: Header = Parser::<DefaultElement>::new()
        .read_header(&mut reader)
        .map_err(|e| ply_err(&e))?;

    let mut raw = RawMesh::new();
    let mut vertices: Vec<PlyVertex> = Vec::new();
    let mut faces: Vec<PlyFace> = Vec::new();
    let mut edges: Vec<PlyEdge> = Vec::new();
    let mut face_def: Option<&ElementDef> = None;
    for (name, def) in &header.elements {
        match name.as_str() {
            "vertex" => {
                for axis in ["x", "y", "z"] {
                    match def.properties.get(axis).map(|p| &p.data_type) {
                        Some(PropertyType::Scalar(_)) => {}
                        _ => {
                            return Err(Error::input(
                                path,
                                format!("PLY vertex element has no scalar `{axis}` property"),
                            ))
                        }
                    }
                }
                vertices = Parser::<PlyVertex>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| ply_err(&e))?;
            }
            "face" => {
                if !def.properties.keys().any(|k| is_index_list(k)) {
                    return Err(Error::input(
                        path,
                        "PLY face element has no `vertex_indices` list",
                    ));
                }
                face_def = Some(def);
                faces = Parser::<PlyFace>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| ply_err(&e))?;
            }
            "sharp_edge" => {
                edges = Parser::<PlyEdge>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| ply_err(&e))?;
            }
            other => {
                Parser::<DefaultElement>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| ply_err(&e))?;
                raw.notes.push(format!(
                    "PLY element `{other}` ({} items) ignored",
                    def.count
                ));
            }
        }
    }

    for (i, v) in vertices.iter().enumerate() {
        if v.bad_type {
            return Err(Error::input(
                path,
                format!("PLY vertex {i}: a coordinate or `corner` has a list type"),
            ));
        }
        if !v.xyz.iter().all(|c| c.is_finite()) {
            return Err(Error::input(
                path,
                format!("PLY vertex {i} has a non-finite coordinate {:?}", v.xyz),
            ));
        }
        raw.positions.push(DVec3::from(v.xyz));
        if v.corner {
            raw.corners.push(i as u32);
        }
    }

    // Groups: by value, ascending; names from `comment scode group <value> <name>`.
    let group_property = face_def.and_then(|def| {
        GROUP_PROPERTIES
            .iter()
            .position(|g| def.properties.contains_key(*g))
    });
    let mut names: BTreeMap<i64, String> = BTreeMap::new();
    for c in &header.comments {
        if let Some(rest) = c.trim_start().strip_prefix(GROUP_COMMENT) {
            let (value, name) = rest.split_once(' ').unwrap_or((rest, ""));
            if let Ok(v) = value.parse::<i64>() {
                names.insert(v, name.to_string());
            }
        }
    }
    let mut values: BTreeSet<i64> = names.keys().copied().collect();
    if let Some(rank) = group_property {
        for (f, face) in faces.iter().enumerate() {
            match face.group {
                Some((r, v)) if r == rank => {
                    values.insert(v);
                }
                _ => {
                    return Err(Error::input(
                        path,
                        format!(
                            "PLY face {f}: group property `{}` is not an integer scalar",
                            GROUP_PROPERTIES[rank]
                        ),
                    ))
                }
            }
        }
    } else {
        values.clear();
        values.insert(0);
    }
    let value_to_group: BTreeMap<i64, u32> = values
        .iter()
        .enumerate()
        .map(|(i, &v)| (v, i as u32))
        .collect();
    for v in &values {
        raw.group_names.push(match (group_property, names.get(v)) {
            (None, _) => String::new(),
            (Some(_), Some(name)) => name.clone(),
            (Some(_), None) => format!("face_{v}"),
        });
    }

    let nv = raw.positions.len() as i64;
    let mut polygon = Vec::new();
    for (f, face) in faces.iter_mut().enumerate() {
        let indices: Vec<i64> = if !face.ints.is_empty() {
            face.ints.iter().map(|&i| i64::from(i)).collect()
        } else if !face.uints.is_empty() {
            face.uints.iter().map(|&i| i64::from(i)).collect()
        } else {
            std::mem::take(&mut face.indices)
        };
        polygon.clear();
        for &i in &indices {
            if i < 0 || i >= nv {
                return Err(Error::input(
                    path,
                    format!("PLY face {f} references vertex {i}, but there are {nv} vertices"),
                ));
            }
            polygon.push(i as u32);
        }
        if polygon.len() < 3 {
            raw.drop_short_face(format!("face {f}"));
            continue;
        }
        raw.input_faces += 1;
        let group = match group_property {
            Some(_) => face
                .group
                .and_then(|(_, v)| value_to_group.get(&v).copied())
                .unwrap_or(0),
            None => 0,
        };
        raw.push_face(&polygon, group);
    }
    for (e, edge) in edges.iter().enumerate() {
        let [a, b] = edge.v;
        if a < 0 || b < 0 || a >= nv || b >= nv {
            return Err(Error::input(
                path,
                format!(
                    "PLY sharp_edge {e} ({a}, {b}) references a missing vertex ({nv} vertices)"
                ),
            ));
        }
        raw.sharp_edges.push([a as u32, b as u32]);
    }
    Ok(raw)
}

/// Writes `mesh` as binary little-endian PLY (see the module docs for the layout).
#[cfg(feature = "internals")]
pub fn write(out: &mut dyn Write, mesh: &ControlMesh, normals: Option<&[DVec3]>) -> io::Result<()> {
    let mut w = super::buffered(out);
    let max_degree = mesh.faces().map(<[u32]>::len).max().unwrap_or(0);
    let count_type = if max_degree <= u8::MAX as usize {
        "uchar"
    } else {
        "uint"
    };
    writeln!(w, "ply")?;
    writeln!(w, "format binary_little_endian 1.0")?;
    writeln!(w, "comment written by scode {}", env!("CARGO_PKG_VERSION"))?;
    for (g, group) in mesh.groups.iter().enumerate() {
        writeln!(
            w,
            "comment {GROUP_COMMENT}{g} {}",
            group.name.replace(['\n', '\r'], " ")
        )?;
    }
    writeln!(w, "element vertex {}", mesh.vertex_count())?;
    for axis in ["x", "y", "z"] {
        writeln!(w, "property double {axis}")?;
    }
    if normals.is_some() {
        for axis in ["nx", "ny", "nz"] {
            writeln!(w, "property float {axis}")?;
        }
    }
    writeln!(w, "property uchar corner")?;
    writeln!(w, "element face {}", mesh.face_count())?;
    writeln!(w, "property list {count_type} uint vertex_indices")?;
    writeln!(w, "property uint group")?;
    writeln!(w, "element sharp_edge {}", mesh.sharp_edges.len())?;
    writeln!(w, "property uint vertex1")?;
    writeln!(w, "property uint vertex2")?;
    writeln!(w, "end_header")?;
    // One record per vertex and face, assembled on the stack and written in one call: the
    // output is the mesh's arrays in file order, with no copy of the whole file.
    let corners = super::corner_mask(mesh);
    let mut record = [0u8; 3 * 8 + 3 * 4 + 1];
    let len = if normals.is_some() { 37 } else { 25 };
    for (v, p) in mesh.positions.iter().enumerate() {
        for (k, c) in p.to_array().into_iter().enumerate() {
            record[8 * k..8 * k + 8].copy_from_slice(&c.to_le_bytes());
        }
        if let Some(normals) = normals {
            for (k, c) in normals[v].to_array().into_iter().enumerate() {
                record[24 + 4 * k..28 + 4 * k].copy_from_slice(&(c as f32).to_le_bytes());
            }
        }
        record[len - 1] = corners[v] as u8;
        w.write_all(&record[..len])?;
    }
    let mut record = Vec::with_capacity(4 + 4 * max_degree + 4);
    for (f, face) in mesh.faces().enumerate() {
        record.clear();
        if count_type == "uchar" {
            record.push(face.len() as u8);
        } else {
            record.extend_from_slice(&(face.len() as u32).to_le_bytes());
        }
        for &v in face {
            record.extend_from_slice(&v.to_le_bytes());
        }
        record.extend_from_slice(&mesh.face_groups[f].to_le_bytes());
        w.write_all(&record)?;
    }
    for &(a, b) in &mesh.sharp_edges {
        let mut pair = [0u8; 8];
        pair[..4].copy_from_slice(&a.to_le_bytes());
        pair[4..].copy_from_slice(&b.to_le_bytes());
        w.write_all(&pair)?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{read_mesh_bytes, write_mesh_to, MeshFormat, ReadReport};
    use crate::mesh::PatchKind;

    fn read(bytes: &[u8]) -> Result<(ControlMesh, ReadReport)> {
        read_mesh_bytes(bytes, MeshFormat::Ply, Path::new("t.ply"))
    }

    fn sample_mesh() -> ControlMesh {
        let mut m = ControlMesh::new();
        for p in [
            [0.1, 0.0, -0.0],
            [1.0 / 3.0, 0.0, 1e-300],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 2.0f64.sqrt()],
            [0.5, 2.0, 0.25],
        ] {
            m.push_vertex(DVec3::from(p));
        }
        let a = m.push_group("face_3", PatchKind::default());
        let b = m.push_group("second one", PatchKind::default());
        m.push_face(&[0, 1, 2, 3], b);
        m.push_face(&[3, 2, 4], a);
        m.set_sharp(2, 3);
        m.corners.insert(4);
        m.corners.insert(1);
        m
    }

    #[test]
    fn round_trip_binary_little_endian() {
        let mesh = sample_mesh();
        let normals: Vec<DVec3> = (0..5).map(|i| DVec3::new(i as f64, 0.0, 1.0)).collect();
        for n in [None, Some(normals.as_slice())] {
            let mut bytes = Vec::new();
            write_mesh_to(&mut bytes, MeshFormat::Ply, &mesh, n).unwrap();
            assert!(bytes.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
            let (back, report) = read(&bytes).unwrap();
            assert_eq!(back, mesh);
            assert!(report.unchanged(), "{report}");
        }
    }

    #[test]
    fn ascii_with_face_id_and_extra_elements() {
        let text = "ply\nformat ascii 1.0\ncomment hello\n\
            element vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
            property uchar red\n\
            element face 3\nproperty list uchar int vertex_indices\nproperty int face_id\n\
            element material 1\nproperty float shininess\n\
            end_header\n\
            0 0 0 255\n1 0 0 0\n1 1 0 0\n0 1 0.5 0\n\
            3 0 1 2 7\n3 0 2 3 -2\n3 0 2 3 7\n\
            0.5\n";
        let (mesh, report) = read(text.as_bytes()).unwrap();
        assert_eq!(mesh.face_count(), 3);
        let names: Vec<_> = mesh.groups.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names, vec!["face_-2", "face_7"]);
        assert_eq!(mesh.face_groups, vec![1, 0, 1]);
        assert_eq!(mesh.positions[3], DVec3::new(0.0, 1.0, 0.5));
        assert!(report.repairs.iter().any(|r| r.contains("material")));
        assert_eq!(report.nonmanifold_edges, 1);
    }

    /// A binary big-endian file with float positions, `uchar`/`int` lists and a `patch`.
    #[test]
    fn binary_big_endian() {
        let mut bytes = b"ply\nformat binary_big_endian 1.0\n\
            element vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
            element face 2\nproperty uchar patch\nproperty list uchar uint vertex_indices\n\
            end_header\n"
            .to_vec();
        for p in [
            [0.0f32, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.25],
        ] {
            for c in p {
                bytes.extend_from_slice(&c.to_be_bytes());
            }
        }
        for (patch, face) in [(4u8, [0u32, 1, 2]), (9, [0, 2, 3])] {
            bytes.push(patch);
            bytes.push(3);
            for v in face {
                bytes.extend_from_slice(&v.to_be_bytes());
            }
        }
        let (mesh, _) = read(&bytes).unwrap();
        assert_eq!(mesh.face(1), &[0, 2, 3]);
        assert_eq!(mesh.positions[3], DVec3::new(0.0, 1.0, 0.25));
        assert_eq!(mesh.groups[1].name, "face_9");
        assert_eq!(mesh.face_groups, vec![0, 1]);

        // Truncated payload: an error, not a panic.
        let err = read(&bytes[..bytes.len() - 3]).unwrap_err();
        assert!(err.to_string().contains("t.ply"), "{err}");
    }

    #[test]
    fn malformed_inputs_are_errors() {
        let header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\n\
                      property double y\nproperty double z\n\
                      element face 1\nproperty list uchar int vertex_indices\nend_header\n";
        for (body, needle) in [
            ("0 0 0\n1 0 0\n0 1 nan\n3 0 1 2\n", "Line 12"),
            ("0 0 0\n1 0 0\n0 1 1e999\n3 0 1 2\n", "vertex 2"),
            ("0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "face 0"),
            ("0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", "face 0"),
            ("0 0 0\n1 0 0\n", "invalid PLY"),
            ("0 0 0\n1 0 0\n0 1 0\n3 0 1\n", "invalid PLY"),
        ] {
            let err = read(format!("{header}{body}").as_bytes()).unwrap_err();
            assert!(matches!(err, Error::Input { .. }));
            let msg = err.to_string();
            assert!(
                msg.contains("t.ply") && msg.contains(needle),
                "{body:?}: {msg}"
            );
        }
        // Binary NaN: reaches our own check, which names the vertex.
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n\
            property float x\nproperty float y\nproperty float z\nelement face 1\n\
            property list uchar int vertex_indices\nend_header\n"
            .to_vec();
        for c in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, f32::NAN, 0.0] {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
        bytes.push(3);
        for v in [0i32, 1, 2] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let msg = read(&bytes).unwrap_err().to_string();
        assert!(
            msg.contains("vertex 2") && msg.contains("non-finite"),
            "{msg}"
        );

        for bad in [
            &b"solid x"[..],
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n",
            b"ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\n\
              property float y\nproperty float z\nend_header\n0 0 0\n",
        ] {
            assert!(read(bad).is_err());
        }
    }
}
