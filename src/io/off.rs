//! OFF (Object File Format) reader and writer.
//!
//! Accepted: an `OFF`/`COFF`/`NOFF`/`CNOFF` header (counts on the same line or the next),
//! then one vertex per line (first three numbers are the position; colours/normals after them
//! are ignored), then one face per line (`n i1 ... in`, optional colour ignored). `#` starts a
//! comment; blank lines are skipped. OFF has no groups, so everything is one unnamed group.

#[cfg(feature = "internals")]
use std::io::{self, Write};
use std::path::Path;

use glam::DVec3;

use super::repair::RawMesh;
use crate::error::{Error, Result};
#[cfg(feature = "internals")]
use crate::mesh::ControlMesh;

/// Parses OFF text into a [`RawMesh`].
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawMesh> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes); // UTF-8 BOM
    let err = |line: usize, detail: String| Error::input(path, format!("line {line}: {detail}"));
    // Non-empty lines with comments stripped, with their 1-based line numbers.
    let mut lines = bytes
        .split(|&b| b == b'\n')
        .enumerate()
        .filter_map(|(i, l)| {
            let l = match l.iter().position(|&b| b == b'#') {
                Some(h) => &l[..h],
                None => l,
            };
            let tokens: Vec<&[u8]> = l
                .split(|b| b.is_ascii_whitespace())
                .filter(|t| !t.is_empty())
                .collect();
            (!tokens.is_empty()).then_some((i + 1, tokens))
        });

    let Some((header_line, header)) = lines.next() else {
        return Err(Error::input(path, "empty OFF file"));
    };
    let keyword = header[0];
    if !matches!(keyword, b"OFF" | b"COFF" | b"NOFF" | b"CNOFF") {
        return Err(err(
            header_line,
            format!(
                "expected an `OFF` header, found `{}`",
                String::from_utf8_lossy(keyword)
            ),
        ));
    }
    let (count_line, counts) = if header.len() > 1 {
        (header_line, header[1..].to_vec())
    } else {
        lines
            .next()
            .ok_or_else(|| err(header_line, "missing vertex/face counts".into()))?
    };
    let count = |i: usize, what: &str| -> Result<usize> {
        let t = counts
            .get(i)
            .ok_or_else(|| err(count_line, format!("missing {what} count")))?;
        std::str::from_utf8(t)
            .ok()
            .and_then(|s| s.parse::<usize>().ok())
            .ok_or_else(|| {
                err(
                    count_line,
                    format!("invalid {what} count `{}`", String::from_utf8_lossy(t)),
                )
            })
    };
    let (nv, nf) = (count(0, "vertex")?, count(1, "face")?);

    let mut raw = RawMesh::new();
    raw.group_names.push(String::new());
    // Counts come from the file: never pre-allocate by them beyond what the bytes can hold.
    raw.positions.reserve(nv.min(bytes.len() / 6));
    for v in 0..nv {
        let (line, tokens) = lines
            .next()
            .ok_or_else(|| Error::input(path, format!("file ends after {v} of {nv} vertices")))?;
        if tokens.len() < 3 {
            return Err(err(line, "vertex needs 3 coordinates".into()));
        }
        let mut xyz = [0.0; 3];
        for (axis, c) in xyz.iter_mut().enumerate() {
            let t = tokens[axis];
            *c = std::str::from_utf8(t)
                .ok()
                .and_then(|s| s.parse::<f64>().ok())
                .ok_or_else(|| {
                    err(
                        line,
                        format!("invalid coordinate `{}`", String::from_utf8_lossy(t)),
                    )
                })?;
            if !c.is_finite() {
                return Err(err(
                    line,
                    format!(
                        "vertex {v} has a non-finite coordinate `{}`",
                        String::from_utf8_lossy(t)
                    ),
                ));
            }
        }
        raw.positions.push(DVec3::from(xyz));
        raw.vertex_lines.push(line as u32);
    }
    let mut face = Vec::new();
    for f in 0..nf {
        let (line, tokens) = lines
            .next()
            .ok_or_else(|| Error::input(path, format!("file ends after {f} of {nf} faces")))?;
        let parse_int = |t: &[u8]| {
            std::str::from_utf8(t)
                .ok()
                .and_then(|s| s.parse::<i64>().ok())
        };
        let n = parse_int(tokens[0])
            .filter(|&n| n >= 0)
            .ok_or_else(|| err(line, format!("face {f}: invalid vertex count")))?
            as usize;
        if tokens.len() < n + 1 {
            return Err(err(
                line,
                format!(
                    "face {f} announces {n} vertices but lists {}",
                    tokens.len() - 1
                ),
            ));
        }
        face.clear();
        for t in &tokens[1..=n] {
            let i = parse_int(t).ok_or_else(|| {
                err(
                    line,
                    format!("face {f}: invalid index `{}`", String::from_utf8_lossy(t)),
                )
            })?;
            if i < 0 || i as usize >= nv {
                return Err(err(
                    line,
                    format!(
                        "face {f} references vertex {i}, but there are {nv} vertices (0-based)"
                    ),
                ));
            }
            face.push(i as u32);
        }
        if n < 3 {
            raw.drop_short_face(format!("line {line}"));
            continue;
        }
        raw.input_faces += 1;
        raw.push_face(&face, 0);
        raw.face_lines.push(line as u32);
    }
    Ok(raw)
}

/// Writes `mesh` as OFF (positions at full precision; groups, sharp edges and corners are
/// not representable and are not written).
#[cfg(feature = "internals")]
pub fn write(out: &mut dyn Write, mesh: &ControlMesh) -> io::Result<()> {
    let mut w = io::BufWriter::new(out);
    writeln!(w, "OFF")?;
    writeln!(w, "{} {} 0", mesh.vertex_count(), mesh.face_count())?;
    for p in &mesh.positions {
        writeln!(w, "{:?} {:?} {:?}", p.x, p.y, p.z)?;
    }
    for face in mesh.faces() {
        write!(w, "{}", face.len())?;
        for v in face {
            write!(w, " {v}")?;
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
        read_mesh_bytes(text.as_bytes(), MeshFormat::Off, Path::new("t.off"))
    }

    #[test]
    fn reads_polygons_and_header_variants() {
        let text = "OFF # cube-ish\n5 2 0\n\n0 0 0\n1 0 0\n1 1 0 255 0 0\n0 1 0\n0.5 0.5 1\n\
                    4 0 1 2 3 0.1 0.2 0.3\n3 1 4 2\n";
        let (mesh, report) = read(text).unwrap();
        assert_eq!(mesh.face_count(), 2);
        assert_eq!(mesh.face(0), &[0, 1, 2, 3]);
        assert!(report.unchanged());
        let (mesh, _) = read("OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\r\n").unwrap();
        assert_eq!(mesh.face_count(), 1);
    }

    #[test]
    fn malformed_inputs_are_errors() {
        for (text, needle) in [
            ("PLY\n", "line 1"),
            ("OFF\n3 1\n0 0 0\n1 0 0\n", "ends after 2 of 3 vertices"),
            ("OFF\n3 1\n0 0 0\n1 0 0\n0 1 nan\n3 0 1 2\n", "line 5"),
            ("OFF\n3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "line 6"),
            ("OFF\n3 1\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n", "line 6"),
            ("OFF\n3 x\n", "line 2"),
            ("OFF\n3 0\n0 0 0\n1 0 0\n0 1 0\n", "no faces"),
        ] {
            let msg = read(text).unwrap_err().to_string();
            assert!(
                msg.contains("t.off") && msg.contains(needle),
                "{text:?}: {msg}"
            );
        }
    }

    #[test]
    fn round_trip() {
        let (mesh, _) =
            read("OFF\n4 2 0\n0 0 0\n0.1 0 0\n0.1 0.2 0\n0 0.2 1e-9\n3 0 1 2\n3 0 2 3\n").unwrap();
        let mut bytes = Vec::new();
        write_mesh_to(&mut bytes, MeshFormat::Off, &mesh, None).unwrap();
        let (back, _) = read_mesh_bytes(&bytes, MeshFormat::Off, Path::new("rt.off")).unwrap();
        assert_eq!(back, mesh);
    }

    #[test]
    fn corpus_off_files() {
        let Some(dir) = corpus_dir() else { return };
        let (mesh, report) = read_mesh(&dir.join("meshes/block.off")).unwrap();
        assert_eq!((mesh.vertex_count(), mesh.face_count()), (2132, 4272));
        assert_eq!(report.nonmanifold_edges, 0);
        let (mesh, report) = read_mesh(&dir.join("meshes/crank.off")).unwrap();
        assert_eq!(
            (mesh.vertex_count(), mesh.face_count()),
            (49986, 100028),
            "{report}"
        );
        assert_eq!(report.nonmanifold_edges, 24, "{report}");
    }
}
