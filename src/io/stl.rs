//! STL reader (ascii and binary) and binary writer.
//!
//! STL stores every triangle with its own three corner positions (f32) and no groups, so the
//! reader yields three vertices per triangle, all welded afterwards, in one unnamed group.
//!
//! Detection: a file whose size is exactly `84 + 50 × count` (count from bytes 80..84) is
//! binary even if its header starts with `solid` (several exporters do that); otherwise a
//! file starting with `solid` is ascii. Binary triangles are decoded here (50 fixed bytes
//! each, with a size check first); ascii goes through `stl_io`. The writer streams binary STL,
//! with polygons fan-triangulated and face normals computed from the geometry.

use std::io::Cursor;
#[cfg(feature = "internals")]
use std::io::{self, Write};
use std::path::Path;

use glam::DVec3;

#[cfg(feature = "internals")]
use super::fan_triangles;
use super::repair::RawMesh;
use crate::error::{Error, Result};
#[cfg(feature = "internals")]
use crate::mesh::ControlMesh;

const HEADER_LEN: usize = 80;
const TRIANGLE_LEN: usize = 50;

/// Parses an STL file into a [`RawMesh`] (three vertices per triangle).
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawMesh> {
    let mut raw = RawMesh::new();
    raw.group_names.push(String::new());
    let binary_count = bytes
        .get(HEADER_LEN..HEADER_LEN + 4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
    let is_exact_binary = binary_count
        .is_some_and(|n| (bytes.len() - HEADER_LEN - 4) as u64 == n as u64 * TRIANGLE_LEN as u64);
    let trimmed = bytes.trim_ascii_start();
    if !is_exact_binary && trimmed.starts_with(b"solid") {
        parse_ascii(trimmed, path, &mut raw)?;
    } else {
        let Some(count) = binary_count else {
            return Err(Error::input(
                path,
                format!(
                    "not an STL file: {} bytes, too short for a binary STL header",
                    bytes.len()
                ),
            ));
        };
        let available = (bytes.len() - HEADER_LEN - 4) / TRIANGLE_LEN;
        if count > available {
            return Err(Error::input(
                path,
                format!(
                    "binary STL announces {count} triangles but holds only {available} ({} bytes)",
                    bytes.len()
                ),
            ));
        }
        if count < available {
            raw.notes.push(format!(
                "{} bytes after the {count} triangles of the binary STL ignored",
                bytes.len() - HEADER_LEN - 4 - count * TRIANGLE_LEN
            ));
        }
        raw.positions.reserve(3 * count);
        let f32_at = |b: &[u8], o: usize| f32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
        for t in 0..count {
            let rec = &bytes[HEADER_LEN + 4 + t * TRIANGLE_LEN..][..TRIANGLE_LEN];
            for corner in 0..3 {
                let o = 12 + 12 * corner;
                let p = [f32_at(rec, o), f32_at(rec, o + 4), f32_at(rec, o + 8)];
                push_corner(&mut raw, p, t, path)?;
            }
        }
    }
    for t in 0..raw.positions.len() / 3 {
        let base = 3 * t as u32;
        raw.push_face(&[base, base + 1, base + 2], 0);
    }
    raw.input_faces = raw.face_count();
    Ok(raw)
}

fn push_corner(raw: &mut RawMesh, p: [f32; 3], triangle: usize, path: &Path) -> Result<()> {
    if !p.iter().all(|c| c.is_finite()) {
        return Err(Error::input(
            path,
            format!("STL triangle {triangle} has a non-finite vertex coordinate {p:?}"),
        ));
    }
    raw.positions
        .push(DVec3::new(p[0].into(), p[1].into(), p[2].into()));
    Ok(())
}

fn parse_ascii(bytes: &[u8], path: &Path, raw: &mut RawMesh) -> Result<()> {
    // stl_io wants the first line to be `solid <name>`; a bare `solid` line is valid STL too.
    let first_line_end = bytes
        .iter()
        .position(|&b| b == b'\n')
        .unwrap_or(bytes.len());
    let mut text = Vec::with_capacity(bytes.len() + 8);
    let first = bytes[..first_line_end].trim_ascii();
    text.extend_from_slice(first);
    if first == b"solid" {
        text.extend_from_slice(b" unnamed");
    }
    text.extend_from_slice(&bytes[first_line_end..]);
    let mut cursor = Cursor::new(text);
    let reader = stl_io::create_stl_reader(&mut cursor)
        .map_err(|e| Error::input(path, format!("invalid ascii STL: {e}")))?;
    for (t, triangle) in reader.enumerate() {
        let triangle = triangle
            .map_err(|e| Error::input(path, format!("invalid ascii STL at triangle {t}: {e}")))?;
        for v in triangle.vertices {
            push_corner(raw, v.0, t, path)?;
        }
    }
    Ok(())
}

/// Writes `mesh` as binary STL: polygons fan-triangulated, positions as f32, face normals
/// from the geometry (zero for degenerate triangles). Each 50-byte triangle record goes
/// straight from the mesh's arrays to the output.
#[cfg(feature = "internals")]
pub fn write(out: &mut dyn Write, mesh: &ControlMesh) -> io::Result<()> {
    let triangles: usize = mesh.faces().map(|f| f.len().saturating_sub(2)).sum();
    let count = u32::try_from(triangles)
        .map_err(|_| io::Error::other("too many triangles for binary STL"))?;
    let mut w = super::buffered(out);
    // A blank header: one starting with "solid" would pass for ascii STL in some readers.
    w.write_all(&[0u8; 80])?;
    w.write_all(&count.to_le_bytes())?;
    let mut record = [0u8; 50];
    for face in mesh.faces() {
        for [a, b, c] in fan_triangles(face) {
            let [pa, pb, pc] = [a, b, c].map(|v| mesh.positions[v as usize]);
            let normal = (pb - pa).cross(pc - pa).normalize_or_zero();
            for (k, p) in [normal, pa, pb, pc].into_iter().enumerate() {
                for (j, c) in p.to_array().into_iter().enumerate() {
                    let at = 12 * k + 4 * j;
                    record[at..at + 4].copy_from_slice(&(c as f32).to_le_bytes());
                }
            }
            w.write_all(&record)?;
        }
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{read_mesh_bytes, write_mesh_to, MeshFormat, ReadReport};
    use crate::mesh::PatchKind;

    fn read(bytes: &[u8]) -> Result<(ControlMesh, ReadReport)> {
        read_mesh_bytes(bytes, MeshFormat::Stl, Path::new("t.stl"))
    }

    /// Three faces of a tetrahedron plus a quad (fan-split on write); positions exact in f32.
    fn sample_mesh() -> ControlMesh {
        let mut m = ControlMesh::new();
        for p in [
            [0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.5, 0.5, 0.5],
        ] {
            m.push_vertex(DVec3::from(p));
        }
        let g = m.push_group("", PatchKind::default());
        m.push_face(&[0, 1, 2], g);
        m.push_face(&[0, 2, 3], g);
        m.push_face(&[0, 3, 1], g);
        m.push_face(&[1, 4, 3, 2], g);
        m
    }

    #[test]
    fn binary_round_trip_welds_and_fans() {
        let mesh = sample_mesh();
        let mut bytes = Vec::new();
        write_mesh_to(&mut bytes, MeshFormat::Stl, &mesh, None).unwrap();
        assert_eq!(bytes.len(), 84 + 50 * 5);
        let (back, report) = read(&bytes).unwrap();
        assert_eq!(back.positions, mesh.positions);
        let faces: Vec<Vec<u32>> = back.faces().map(<[u32]>::to_vec).collect();
        assert_eq!(
            faces,
            vec![
                vec![0, 1, 2],
                vec![0, 2, 3],
                vec![0, 3, 1],
                vec![1, 4, 3],
                vec![1, 3, 2]
            ]
        );
        assert_eq!(report.input_vertices, 15);
        assert_eq!(report.welded_vertices, 10);
        // Normal of the first triangle (0, 1, 2) points down.
        assert_eq!(&bytes[84..96], &[0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 128, 191]);
    }

    #[test]
    fn binary_with_solid_header_is_binary() {
        let mut bytes = Vec::new();
        write_mesh_to(&mut bytes, MeshFormat::Stl, &sample_mesh(), None).unwrap();
        bytes[..6].copy_from_slice(b"solid ");
        assert_eq!(read(&bytes).unwrap().0.face_count(), 5);
    }

    #[test]
    fn ascii() {
        let text = "solid\n\
            facet normal 0 0 -1\n outer loop\n  vertex 0 0 0\n  vertex 0 1 0\n  vertex 1 0 0\n endloop\nendfacet\n\
            facet normal 0 0 1\r\n outer loop\r\n  vertex 1 0 0\r\n  vertex 0 1 0\r\n  vertex 1 1 -0\r\n endloop\r\nendfacet\r\n\
            endsolid\n";
        let (mesh, report) = read(text.as_bytes()).unwrap();
        assert_eq!(mesh.vertex_count(), 4);
        assert_eq!(mesh.face(1), &[2, 1, 3]);
        assert_eq!(report.welded_vertices, 2);
        assert_eq!(report.boundary_edges, 4);
    }

    #[test]
    fn malformed_inputs_are_errors() {
        let mut bytes = Vec::new();
        write_mesh_to(&mut bytes, MeshFormat::Stl, &sample_mesh(), None).unwrap();
        // NaN in triangle 2.
        let mut nan = bytes.clone();
        let o = 84 + 2 * 50 + 12 + 4;
        nan[o..o + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        let msg = read(&nan).unwrap_err().to_string();
        assert!(msg.contains("triangle 2") && msg.contains("t.stl"), "{msg}");
        // Count larger than the data.
        let mut short = bytes.clone();
        short[80..84].copy_from_slice(&1000u32.to_le_bytes());
        let msg = read(&short).unwrap_err().to_string();
        assert!(msg.contains("1000"), "{msg}");
        // Too short, and zero triangles.
        assert!(read(&bytes[..40]).is_err());
        let mut empty = bytes[..84].to_vec();
        empty[80..84].copy_from_slice(&0u32.to_le_bytes());
        assert!(read(&empty).unwrap_err().to_string().contains("no "));
        // Broken ascii.
        for text in [
            "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0\n",
            "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 nan\n",
            "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\nendloop\n",
        ] {
            let err = read(text.as_bytes()).unwrap_err();
            assert!(err.to_string().contains("t.stl"), "{err}");
        }
    }
}
