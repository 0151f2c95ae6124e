//! Wavefront OBJ reader and writer.
//!
//! # Conventions
//! * **Groups**: `g name...` starts (or re-enters) the group called `name` (several names on
//!   one line are joined with single spaces, as one group). `o name` names the object; faces
//!   after an `o` and before any `g` go to a group named after the object. Groups are matched
//!   by name, in order of first declaration. Faces before any `g`/`o` go to a group with an
//!   empty name. A `g` group that never receives a face is dropped (noted in the report);
//!   an `o` line alone declares nothing (the corpus files put `o` before their `g` lines).
//!   `usemtl` does not split groups (materials are ignored).
//! * **Sharp edges**: `l a b c ...` polyline elements; each consecutive pair of vertices is a
//!   sharp (crease) edge.
//! * **Corners**: `p a b c ...` point elements; every listed vertex is a corner (B-rep vertex).
//!   The writer emits the same, so sharp edges and corners round-trip through OBJ, and
//!   viewers that know OBJ draw them as lines and points.
//! * Polygons are kept as polygons. Indices may be negative (relative), and `v/vt/vn`,
//!   `v//vn`, `v/vt` forms are accepted (only the vertex index is used). CRLF line ends and
//!   `#` comments work; `vt`, `vn`, `s`, `usemtl`, `mtllib` are ignored silently, other
//!   unknown statements are ignored with a note.
//!
//! # Why a hand-written parser
//! `tobj` re-indexes vertices per model, splits models on `usemtl`, reads f32 unless
//! `use_f64`, and has no notion of `l`/`p` elements; the control mesh needs the file's own
//! f64 vertex numbering, polygons, lines and points. OBJ is a line format that takes
//! ~150 lines to parse exactly, so we parse it here.
//!
//! The writer prints coordinates with Rust's shortest round-trip formatting (`{:?}`), so a
//! written file reads back to bit-identical f64 positions.

use std::collections::HashMap;
#[cfg(feature = "internals")]
use std::io::{self, Write};
use std::path::Path;

use glam::DVec3;

use super::repair::RawMesh;
use crate::error::{Error, Result};
#[cfg(feature = "internals")]
use crate::mesh::ControlMesh;

/// Parses OBJ text into a [`RawMesh`] (file numbering, nothing welded yet).
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawMesh> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes); // UTF-8 BOM
    let mut raw = RawMesh::new();
    // Group name -> index, for re-entering a group by name. Lookup only; group order is the
    // order of first declaration.
    let mut group_index: HashMap<String, u32> = HashMap::new();
    let mut current_group: Option<u32> = None;
    let mut object_name: Option<String> = None;
    // `f`, `l` and `p` elements with 0-based indices, checked against the final vertex count
    // at the end because positive indices may refer forward.
    let mut faces: Vec<PendingElement> = Vec::new();
    let mut lines_and_points: Vec<PendingElement> = Vec::new();
    let mut element_indices: Vec<i64> = Vec::new();
    let mut polygon: Vec<i64> = Vec::new();
    // Unsupported statement -> count, in order of first appearance.
    let mut ignored: Vec<(String, usize)> = Vec::new();

    let err = |line: usize, detail: String| Error::input(path, format!("line {line}: {detail}"));

    for (line_no, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let line_no = line_no + 1;
        let line = match line.iter().position(|&b| b == b'#') {
            Some(hash) => &line[..hash],
            None => line,
        };
        let mut tokens = line
            .split(|b| b.is_ascii_whitespace())
            .filter(|t| !t.is_empty());
        let Some(keyword) = tokens.next() else {
            continue;
        };
        match keyword {
            b"v" => {
                let mut xyz = [0.0f64; 3];
                for (axis, c) in xyz.iter_mut().enumerate() {
                    let token = tokens
                        .next()
                        .ok_or_else(|| err(line_no, "vertex needs 3 coordinates".to_string()))?;
                    *c = parse_f64(token).ok_or_else(|| {
                        err(
                            line_no,
                            format!(
                                "invalid vertex coordinate `{}`",
                                String::from_utf8_lossy(token)
                            ),
                        )
                    })?;
                    if !c.is_finite() {
                        return Err(err(
                            line_no,
                            format!(
                                "vertex {} has a non-finite {} coordinate `{}`",
                                raw.positions.len() + 1,
                                ["x", "y", "z"][axis],
                                String::from_utf8_lossy(token)
                            ),
                        ));
                    }
                }
                raw.positions.push(DVec3::from(xyz));
                raw.vertex_lines.push(line_no as u32);
            }
            b"f" | b"fo" => {
                polygon.clear();
                for token in tokens {
                    polygon.push(parse_index(token).ok_or_else(|| {
                        err(
                            line_no,
                            format!("invalid face index `{}`", String::from_utf8_lossy(token)),
                        )
                    })?);
                }
                if polygon.len() < 3 {
                    raw.drop_short_face(format!("line {line_no}"));
                    continue;
                }
                raw.input_faces += 1;
                let group = match current_group {
                    Some(g) => g,
                    None => {
                        let name = object_name.clone().unwrap_or_default();
                        let g = intern_group(&mut raw, &mut group_index, name);
                        current_group = Some(g);
                        g
                    }
                };
                let n_so_far = raw.positions.len() as i64;
                let start = element_indices.len();
                for &i in &polygon {
                    element_indices.push(resolve(i, n_so_far, line_no, "face", path)?);
                }
                faces.push(PendingElement {
                    kind: ElementKind::Face(group),
                    line: line_no,
                    indices: start..element_indices.len(),
                });
            }
            b"g" => {
                let name = join_names(tokens);
                current_group = Some(intern_group(&mut raw, &mut group_index, name));
            }
            b"o" => {
                object_name = Some(join_names(tokens));
                current_group = None;
            }
            b"l" | b"p" => {
                let kind = if keyword == b"l" {
                    ElementKind::Line
                } else {
                    ElementKind::Point
                };
                let n_so_far = raw.positions.len() as i64;
                let start = element_indices.len();
                for token in tokens {
                    let i = parse_index(token).ok_or_else(|| {
                        err(
                            line_no,
                            format!("invalid vertex index `{}`", String::from_utf8_lossy(token)),
                        )
                    })?;
                    element_indices.push(resolve(i, n_so_far, line_no, kind.name(), path)?);
                }
                lines_and_points.push(PendingElement {
                    kind,
                    line: line_no,
                    indices: start..element_indices.len(),
                });
            }
            b"vt" | b"vn" | b"vp" | b"s" | b"usemtl" | b"mtllib" => {}
            other => {
                let name = String::from_utf8_lossy(other).into_owned();
                match ignored.iter_mut().find(|(n, _)| *n == name) {
                    Some((_, count)) => *count += 1,
                    None => ignored.push((name, 1)),
                }
            }
        }
    }

    // Resolve elements now that the vertex count is known.
    let nv = raw.positions.len() as i64;
    let mut short_lines = 0;
    let mut verts = Vec::new();
    for element in faces.iter().chain(&lines_and_points) {
        verts.clear();
        for &i in &element_indices[element.indices.clone()] {
            if i >= nv {
                return Err(err(
                    element.line,
                    format!(
                        "{} references vertex {} but the file has only {nv} vertices",
                        element.kind.name(),
                        i + 1
                    ),
                ));
            }
            verts.push(i as u32);
        }
        match element.kind {
            ElementKind::Face(group) => {
                raw.push_face(&verts, group);
                raw.face_lines.push(element.line as u32);
            }
            ElementKind::Line => {
                if verts.len() < 2 {
                    short_lines += 1;
                }
                raw.sharp_edges
                    .extend(verts.windows(2).map(|w| [w[0], w[1]]));
            }
            ElementKind::Point => raw.corners.extend_from_slice(&verts),
        }
    }
    if short_lines > 0 {
        raw.notes.push(format!(
            "{short_lines} `l` elements with fewer than 2 vertices ignored"
        ));
    }
    for (name, count) in ignored {
        raw.notes
            .push(format!("{count} unsupported `{name}` statements ignored"));
    }
    Ok(raw)
}

/// What an `f`, `l` or `p` statement becomes.
#[derive(Clone, Copy)]
enum ElementKind {
    /// A face in this group.
    Face(u32),
    /// A polyline of sharp edges.
    Line,
    /// Corner vertices.
    Point,
}

impl ElementKind {
    fn name(self) -> &'static str {
        match self {
            ElementKind::Face(_) => "face",
            ElementKind::Line => "line",
            ElementKind::Point => "point",
        }
    }
}

/// An element whose (0-based) indices sit in a shared array until the vertex count is known.
struct PendingElement {
    kind: ElementKind,
    line: usize,
    indices: std::ops::Range<usize>,
}

/// Returns the index of the group called `name`, creating it if new.
fn intern_group(raw: &mut RawMesh, index: &mut HashMap<String, u32>, name: String) -> u32 {
    if let Some(&g) = index.get(&name) {
        return g;
    }
    let g = raw.group_names.len() as u32;
    raw.group_names.push(name.clone());
    index.insert(name, g);
    g
}

fn join_names<'a>(tokens: impl Iterator<Item = &'a [u8]>) -> String {
    tokens
        .map(|t| String::from_utf8_lossy(t).into_owned())
        .collect::<Vec<_>>()
        .join(" ")
}

/// Parses one float token exactly (Rust's `f64::from_str` is correctly rounded).
fn parse_f64(token: &[u8]) -> Option<f64> {
    std::str::from_utf8(token).ok()?.parse::<f64>().ok()
}

/// Parses the vertex part of `v`, `v/vt`, `v//vn`, `v/vt/vn` (1-based, may be negative).
fn parse_index(token: &[u8]) -> Option<i64> {
    let v = token.split(|&b| b == b'/').next()?;
    let i = std::str::from_utf8(v).ok()?.parse::<i64>().ok()?;
    (i != 0).then_some(i)
}

/// Converts a 1-based or negative OBJ index to 0-based (negative indices count back from the
/// vertices read so far). Positive indices are checked later against the final count.
fn resolve(i: i64, n_so_far: i64, line: usize, what: &str, path: &Path) -> Result<i64> {
    if i > 0 {
        Ok(i - 1)
    } else if -i <= n_so_far {
        Ok(n_so_far + i)
    } else {
        Err(Error::input(
            path,
            format!(
                "line {line}: {what} has relative index {i} but only {n_so_far} vertices precede it"
            ),
        ))
    }
}

/// Writes `mesh` as OBJ: full-precision `v` lines, optional `vn` (then faces use `v//vn`),
/// faces under `g` lines, `l` lines for sharp edges and `p` lines for corners.
#[cfg(feature = "internals")]
pub fn write(out: &mut dyn Write, mesh: &ControlMesh, normals: Option<&[DVec3]>) -> io::Result<()> {
    let mut w = super::buffered(out);
    writeln!(w, "# written by scode {}", env!("CARGO_PKG_VERSION"))?;
    writeln!(
        w,
        "# {} vertices, {} faces, {} groups; `l` = sharp edges, `p` = corner vertices",
        mesh.vertex_count(),
        mesh.face_count(),
        mesh.groups.len()
    )?;
    // Numbers are formatted into one reusable line: the shortest text that reads back as
    // the same f64, as `{:?}` gives, without going through `fmt`.
    let mut floats = zmij::Buffer::new();
    let mut ints = itoa::Buffer::new();
    let mut line = Vec::with_capacity(128);
    for (tag, values) in [(&b"v"[..], Some(&mesh.positions[..])), (b"vn", normals)] {
        for p in values.into_iter().flatten() {
            line.clear();
            line.extend_from_slice(tag);
            for c in p.to_array() {
                line.push(b' ');
                line.extend_from_slice(floats.format(c).as_bytes());
            }
            line.push(b'\n');
            w.write_all(&line)?;
        }
    }
    let name = |g: u32| -> String {
        mesh.groups
            .get(g as usize)
            .map(|g| g.name.replace(['\n', '\r'], " "))
            .unwrap_or_default()
    };
    // Readers number groups in order of first declaration: if faces do not meet the groups
    // in index order, declare them all first so group indices round-trip.
    let mut first_seen = Vec::new();
    let mut seen = vec![false; mesh.groups.len()];
    for &g in &mesh.face_groups {
        if let Some(s) = seen.get_mut(g as usize) {
            if !*s {
                *s = true;
                first_seen.push(g);
            }
        }
    }
    if first_seen.iter().enumerate().any(|(i, &g)| g as usize != i) {
        for g in 0..mesh.groups.len() as u32 {
            writeln!(w, "g {}", name(g))?;
        }
    }
    let mut current = None;
    for f in 0..mesh.face_count() {
        let g = mesh.face_groups[f];
        if current != Some(g) {
            writeln!(w, "g {}", name(g))?;
            current = Some(g);
        }
        line.clear();
        line.push(b'f');
        for &v in mesh.face(f) {
            let index = ints.format(u64::from(v) + 1).as_bytes();
            line.push(b' ');
            line.extend_from_slice(index);
            if normals.is_some() {
                line.extend_from_slice(b"//");
                line.extend_from_slice(index);
            }
        }
        line.push(b'\n');
        w.write_all(&line)?;
    }
    for &(a, b) in &mesh.sharp_edges {
        writeln!(w, "l {} {}", a + 1, b + 1)?;
    }
    let corners: Vec<u32> = mesh.corners.iter().copied().collect();
    for chunk in corners.chunks(16) {
        w.write_all(b"p")?;
        for &c in chunk {
            write!(w, " {}", c + 1)?;
        }
        w.write_all(b"\n")?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::test_support::corpus_dir;
    use crate::io::{read_mesh, read_mesh_bytes, write_mesh_to, MeshFormat};

    fn read(text: &str) -> Result<(ControlMesh, crate::io::ReadReport)> {
        read_mesh_bytes(text.as_bytes(), MeshFormat::Obj, Path::new("test.obj"))
    }

    #[test]
    fn groups_sharp_edges_corners_and_index_forms() {
        let text = "# comment\r\n\
            o part\r\n\
            v 0 0 0\r\nv 1 0 0\r\nv 1 1 0\r\nv 0 1 0\r\nv 0.5 0.5 1\r\n\
            vt 0 0\nvn 0 0 1\n\
            g top\n\
            f 1/1/1 2/1/1 3/1/1 4/1/1\n\
            g side one\n\
            usemtl red\n\
            f -5//1 -4//1 -1//1\n\
            f 2/1 3/1 5/1\n\
            g top\n\
            f 3 4 5\n\
            g unused\n\
            l 1 2 3\n\
            p 1 5\n";
        let (mesh, report) = read(text).unwrap();
        assert_eq!(mesh.vertex_count(), 5);
        assert_eq!(mesh.face_count(), 4);
        assert_eq!(mesh.face(0), &[0, 1, 2, 3]);
        assert_eq!(mesh.face(1), &[0, 1, 4]);
        let names: Vec<_> = mesh.groups.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names, vec!["top", "side one"]);
        assert_eq!(mesh.face_groups, vec![0, 1, 1, 0]);
        assert!(mesh.is_sharp(0, 1) && mesh.is_sharp(1, 2));
        assert_eq!(mesh.sharp_edges.len(), 2);
        assert_eq!(mesh.corners.iter().copied().collect::<Vec<_>>(), vec![0, 4]);
        assert_eq!(report.dropped_empty_groups, 1);
        assert!(report.repairs.iter().any(|r| r.contains("`unused`")));
        assert_eq!(report.input_vertices, 5);
        assert_eq!(report.input_faces, 4);
    }

    #[test]
    fn object_name_is_the_group_when_there_is_no_g() {
        let (mesh, report) = read("o thing\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(mesh.groups[0].name, "thing");
        assert!(report.unchanged(), "{report}");
        let (mesh, _) = read("\u{feff}v 0 0 0\nv 1 0 0\nv 0 1 0\nf 3 2 1\n").unwrap();
        assert_eq!(mesh.groups[0].name, "");
    }

    #[test]
    fn duplicates_across_groups_are_welded() {
        let text = "g a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n\
                    g b\nv 1 0 0\nv -0 1 0\nv 1 1 0\nf 4 6 5\n";
        let (mesh, report) = read(text).unwrap();
        assert_eq!(mesh.vertex_count(), 4);
        assert_eq!(report.welded_vertices, 2);
        assert_eq!(mesh.face(1), &[1, 3, 2]);
    }

    /// A closed cube stored the way per-object exporters do it: each face group with its own
    /// copies of its 4 corners. Welding restores the 8 shared vertices and a closed surface.
    #[test]
    fn per_group_duplicated_cube_is_welded_closed() {
        let corner = |i: u32| [(i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2 & 1) as f64];
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let mut text = String::new();
        for (g, quad) in quads.iter().enumerate() {
            text += &format!("g side{g}\n");
            for &c in quad {
                let [x, y, z] = corner(c);
                text += &format!("v {x} {y} {z}\n");
            }
            text += "f -4 -3 -2 -1\nl -4 -3\n";
        }
        let (mesh, report) = read(&text).unwrap();
        assert_eq!(
            (mesh.vertex_count(), mesh.face_count(), mesh.groups.len()),
            (8, 6, 6)
        );
        assert_eq!(report.welded_vertices, 16);
        assert_eq!(report.boundary_edges, 0);
        assert_eq!(report.nonmanifold_edges, 0);
        assert_eq!(report.coincident_vertices_kept, 0);
        assert_eq!(mesh.sharp_edges.len(), 6);
        assert!(!report.unchanged());
    }

    /// Two closed tetrahedra touching at one point (separate solids of an assembly): the
    /// coincident vertices are not welded, so the solids stay separate.
    #[test]
    fn touching_closed_solids_are_not_welded() {
        let tet = |o: f64| {
            format!(
                "v {o} 0 0\nv {} 0 0\nv {o} 1 0\nv {o} 0 1\n\
                 f -4 -2 -3\nf -4 -3 -1\nf -4 -1 -2\nf -3 -2 -1\n",
                o + 1.0
            )
        };
        // The first tetrahedron's vertex (1,0,0) is the second's (1,0,0).
        let (mesh, report) = read(&(tet(0.0) + &tet(1.0))).unwrap();
        assert_eq!(mesh.vertex_count(), 8);
        assert_eq!(report.coincident_vertices_kept, 1);
        assert_eq!(report.welded_vertices, 0);
        assert_eq!((report.boundary_edges, report.nonmanifold_edges), (0, 0));
        assert!(report.unchanged());
    }

    #[test]
    fn malformed_inputs_give_errors_naming_the_line() {
        let cases = [
            ("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "line 1"),
            ("v 0 0 0\nv 1 inf 0\nv 0 1 0\nf 1 2 3\n", "line 2"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "line 4"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", "line 4"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "line 4"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 x\nf 1 2 3\n", "line 3"),
            ("v 0 0\n", "line 1"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nl 1 9\n", "line 5"),
            ("", "no vertices"),
            ("v 0 0 0\nv 1 0 0\n", "no faces"),
        ];
        for (text, needle) in cases {
            let err = read(text).unwrap_err();
            let msg = err.to_string();
            assert!(matches!(err, Error::Input { .. }), "{msg}");
            assert!(
                msg.contains("test.obj") && msg.contains(needle),
                "{text:?}: {msg}"
            );
        }
    }

    #[test]
    fn degenerate_faces_are_repaired_or_dropped() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 0 0 0\n\
                    f 1 2 3\nf 2 4 3 3\nf 1 2 5\nf 1 2\n";
        let (mesh, report) = read(text).unwrap();
        assert_eq!(mesh.face_count(), 2);
        assert_eq!(mesh.face(1), &[1, 3, 2]);
        assert_eq!(report.repaired_faces, 1);
        assert_eq!(report.dropped_degenerate_faces, 2); // `f 1 2 5` after welding, `f 1 2`
        assert_eq!(report.input_faces, 4);
    }

    fn sample_mesh() -> ControlMesh {
        use crate::mesh::PatchKind;
        let mut m = ControlMesh::new();
        let pts = [
            [0.1, -0.0, 1e-300],
            [1.0 / 3.0, 2.0f64.sqrt(), -7.25e12],
            [std::f64::consts::PI, 0.3, 0.7],
            [-1.5, 2.5, 1.0],
            [5.0, 5.0, 5.0],
        ];
        for p in pts {
            m.push_vertex(DVec3::from(p));
        }
        let b = m.push_group("second group", PatchKind::default());
        let a = m.push_group("face_7", PatchKind::default());
        m.push_face(&[0, 1, 2, 3], a);
        m.push_face(&[1, 4, 2], b);
        m.push_face(&[3, 2, 4], a);
        m.set_sharp(1, 2);
        m.set_sharp(4, 2);
        m.corners.insert(4);
        m.corners.insert(0);
        m
    }

    #[test]
    fn round_trip_is_exact() {
        let mesh = sample_mesh();
        let normals: Vec<DVec3> = (0..5).map(|i| DVec3::new(0.0, 0.0, i as f64)).collect();
        for n in [None, Some(normals.as_slice())] {
            let mut bytes = Vec::new();
            write_mesh_to(&mut bytes, MeshFormat::Obj, &mesh, n).unwrap();
            let (back, report) =
                read_mesh_bytes(&bytes, MeshFormat::Obj, Path::new("rt.obj")).unwrap();
            assert_eq!(back, mesh);
            for (a, b) in back.positions.iter().zip(&mesh.positions) {
                assert_eq!(
                    a.to_array().map(f64::to_bits),
                    b.to_array().map(f64::to_bits)
                );
            }
            assert!(report.unchanged(), "{report}");
        }
    }

    /// (file, vertices, triangles, groups) from MANIFEST.md.
    const CORPUS: &[(&str, usize, usize, usize)] = &[
        ("meshes/fandisk.obj", 6475, 12946, 1),
        ("meshes/rocker-arm.obj", 10044, 20088, 1),
        ("abc/abc_00000006.obj", 16332, 32664, 15),
        ("abc/abc_00007974_5.obj", 7845, 15702, 24),
        ("tess/screw_coarse.obj", 293, 582, 10),
        ("tess/screw_fine.obj", 2376, 4748, 10),
        ("tess/four_cone_coarse.obj", 627, 1250, 10),
        (
            "tess/nist_ftc_08_asme1_ap242-2_cadexport.obj",
            1636,
            3368,
            272,
        ),
        ("tess/trj6_b1-ec-214_coarse.obj", 15083, 30170, 292),
        ("tess/trj4_pm2-ec-214_fine.obj", 64671, 129310, 840),
        ("tess/Ventilator_coarse.obj", 15590, 31180, 305),
    ];

    #[test]
    fn corpus_counts_match_manifest() {
        let Some(dir) = corpus_dir() else { return };
        for &(file, nv, nf, ng) in CORPUS {
            let (mesh, report) = read_mesh(&dir.join(file)).unwrap();
            assert_eq!(
                (mesh.vertex_count(), mesh.face_count(), mesh.groups.len()),
                (nv, nf, ng),
                "{file}: {report}"
            );
            assert!(mesh.is_triangle_mesh());
            assert_eq!(report.nonmanifold_edges, 0, "{file}");
            assert_eq!(report.boundary_edges, 0, "{file}");
            assert_eq!(report.dropped_degenerate_faces, 0, "{file}");
        }
        // The assembly's touching solids: 22 coincident vertex pairs kept apart (welding them
        // would create 22 non-manifold edges).
        let (_, report) = read_mesh(&dir.join("tess/trj4_pm2-ec-214_fine.obj")).unwrap();
        assert_eq!(report.coincident_vertices_kept, 22);
        assert_eq!(report.welded_vertices, 0);
    }

    #[test]
    fn every_corpus_obj_reads() {
        let Some(dir) = corpus_dir() else { return };
        let manifest = std::fs::read_to_string(dir.join("MANIFEST.md")).unwrap();
        let mut checked = 0;
        for sub in ["meshes", "abc", "tess"] {
            let mut entries: Vec<_> = std::fs::read_dir(dir.join(sub))
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| p.extension().is_some_and(|e| e == "obj"))
                .collect();
            entries.sort();
            for path in entries {
                let (mesh, report) = read_mesh(&path).unwrap();
                let rel = format!("{sub}/{}", path.file_name().unwrap().to_string_lossy());
                // Manifest row: | file | kind | vertices | triangles | faces | ...
                let row = manifest
                    .lines()
                    .find(|l| l.starts_with(&format!("| {rel} |")))
                    .unwrap_or_else(|| panic!("{rel} not in manifest"));
                let cols: Vec<&str> = row.split('|').map(str::trim).collect();
                let nv: usize = cols[3].parse().unwrap();
                let nf: usize = cols[4].parse().unwrap();
                assert_eq!(
                    (mesh.vertex_count(), mesh.face_count()),
                    (nv, nf),
                    "{rel}: {report}"
                );
                if let Ok(ng) = cols[5].parse::<usize>() {
                    assert_eq!(mesh.groups.len(), ng, "{rel}");
                }
                assert_eq!(report.welded_vertices, 0, "{rel}: {report}");
                assert_eq!(report.nonmanifold_edges, 0, "{rel}: {report}");
                if row.contains("watertight;") {
                    assert_eq!(report.boundary_edges, 0, "{rel}: {report}");
                }
                checked += 1;
            }
        }
        assert!(checked >= 30, "only {checked} OBJ files found");
    }
}
