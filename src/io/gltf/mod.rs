//! glTF 2.0 reader and writer (`.glb` and `.gltf`).
//!
//! # Reading
//! The `gltf` crate (without its `import` feature) parses and validates the JSON; buffers are
//! resolved here: the GLB `BIN` chunk, external files in the `.gltf` file's folder or below
//! it (percent-encoded URIs are decoded; absolute paths, schemes, `..` and links out of the
//! folder are refused, and [`ReadOptions::external_files`] refuses external files
//! altogether), and base64 `data:` URIs. Accessor data is read here too, with
//! every offset, stride and count checked against the buffer, so malformed files give errors
//! rather than panics.
//!
//! The default scene (else the first scene) is traversed and node transforms are applied in
//! f64; a file without scenes reads every mesh untransformed. **Each primitive of each mesh
//! instance becomes one group**, named after its mesh (`mesh_<i>` if unnamed), with `#<k>`
//! appended when the mesh has several primitives and `@node<n>` when the mesh is instanced
//! more than once. Primitives that share a `POSITION` accessor under the same transform share
//! their vertices; everything else is welded like any other input. Triangle lists, strips and
//! fans are read; point and line primitives are skipped with a note. Quantised or compressed
//! geometry (`KHR_mesh_quantization`, Draco, meshopt) and sparse accessors are not supported.
//!
//! # Writing
//! `.glb` (binary container), or `.gltf` with the buffer embedded as a base64 `data:` URI.
//! One shared `POSITION` (and optional `NORMAL`) accessor, and one mesh with one triangle
//! primitive per non-empty group (fan-triangulated, `u32` indices), named after the group,
//! each under its own node of the single scene. glTF stores positions as f32, so positions
//! are rounded to f32; sharp edges and corners are not stored.

use std::borrow::Cow;
use std::collections::HashMap;
use std::io::{self, Write};
use std::path::{Component, Path};

use glam::{DMat4, DVec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;

use super::repair::RawMesh;
use super::{fan_triangles, ReadOptions};
use crate::error::{Error, Result};
use crate::mesh::ControlMesh;

/// Deepest node hierarchy followed (deeper usually means a cycle in a malformed file).
const MAX_NODE_DEPTH: usize = 64;
/// Most mesh instances read (guards against node graphs that share children exponentially).
const MAX_INSTANCES: usize = 100_000;

/// Parses a `.glb` or `.gltf` file with the default [`ReadOptions`]. `path` names the file
/// in errors and its folder holds the external buffer files.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawMesh> {
    parse_with(bytes, path, &ReadOptions::default())
}

/// [`parse`] with `opts` (whether external buffer files may be read at all).
pub fn parse_with(bytes: &[u8], path: &Path, opts: &ReadOptions) -> Result<RawMesh> {
    let input_err = |detail: String| Error::input(path, detail);
    let gltf =
        gltf::Gltf::from_slice(bytes).map_err(|e| input_err(format!("invalid glTF: {e}")))?;
    for ext in gltf.extensions_required() {
        if matches!(
            ext,
            "KHR_draco_mesh_compression" | "EXT_meshopt_compression" | "KHR_mesh_quantization"
        ) {
            return Err(input_err(format!(
                "glTF requires extension `{ext}`, which scode does not read"
            )));
        }
    }

    // Buffers, resolved once.
    let mut buffers: Vec<Cow<[u8]>> = Vec::new();
    for buffer in gltf.buffers() {
        let data: Cow<[u8]> = match buffer.source() {
            gltf::buffer::Source::Bin => Cow::Borrowed(gltf.blob.as_deref().ok_or_else(|| {
                input_err(format!(
                    "buffer {} refers to the GLB BIN chunk, but there is none",
                    buffer.index()
                ))
            })?),
            gltf::buffer::Source::Uri(uri) => Cow::Owned(load_uri(uri, path, opts)?),
        };
        if data.len() < buffer.length() {
            return Err(input_err(format!(
                "buffer {} declares {} bytes but holds {}",
                buffer.index(),
                buffer.length(),
                data.len()
            )));
        }
        buffers.push(data);
    }

    // Mesh instances: (mesh, world transform, node).
    let mut instances: Vec<(gltf::Mesh, DMat4, Option<usize>)> = Vec::new();
    let scene = gltf.default_scene().or_else(|| gltf.scenes().next());
    match scene {
        Some(scene) => {
            for node in scene.nodes() {
                visit(node, DMat4::IDENTITY, 0, &mut instances, path)?;
            }
        }
        None => instances.extend(gltf.meshes().map(|m| (m, DMat4::IDENTITY, None))),
    }
    let mut instance_count = vec![0usize; gltf.meshes().len()];
    for (mesh, _, _) in &instances {
        instance_count[mesh.index()] += 1;
    }

    let mut raw = RawMesh::new();
    // (POSITION accessor, transform bits) -> first vertex in `raw.positions`: primitives
    // sharing both share vertices. Lookup only; vertex order follows the file.
    let mut vertex_base: HashMap<(usize, [u64; 16]), (u32, usize)> = HashMap::new();
    let mut skipped_modes = 0usize;
    let mut transformed = false;
    let mut triangle = Vec::with_capacity(3);
    for (mesh, transform, node) in &instances {
        let n_prims = mesh.primitives().len();
        for (k, prim) in mesh.primitives().enumerate() {
            let what = format!("mesh {} primitive {k}", mesh.index());
            let mode = prim.mode();
            if !matches!(
                mode,
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                skipped_modes += 1;
                continue;
            }
            let positions = prim
                .get(&gltf::Semantic::Positions)
                .ok_or_else(|| input_err(format!("{what} has no POSITION attribute")))?;
            let key = (
                positions.index(),
                transform.to_cols_array().map(f64::to_bits),
            );
            let (base, count) = match vertex_base.get(&key) {
                Some(&b) => b,
                None => {
                    let points = read_vec3_f32(&positions, &buffers, &what, path)?;
                    let base = u32::try_from(raw.positions.len())
                        .map_err(|_| input_err("too many vertices".into()))?;
                    if *transform != DMat4::IDENTITY {
                        transformed = true;
                    }
                    for (i, p) in points.iter().enumerate() {
                        let local = DVec3::new(p[0].into(), p[1].into(), p[2].into());
                        let world = transform.transform_point3(local);
                        if !world.is_finite() {
                            return Err(input_err(format!(
                                "{what}: vertex {i} has a non-finite coordinate {p:?}"
                            )));
                        }
                        raw.positions.push(world);
                    }
                    vertex_base.insert(key, (base, points.len()));
                    (base, points.len())
                }
            };
            let indices: Vec<u32> = match prim.indices() {
                Some(acc) => read_indices(&acc, &buffers, &what, path)?,
                None => (0..count as u32).collect(),
            };
            if let Some(&bad) = indices.iter().find(|&&i| i as usize >= count) {
                return Err(input_err(format!(
                    "{what}: index {bad} out of range ({count} vertices)"
                )));
            }
            let mesh_name = mesh
                .name()
                .map(str::to_string)
                .unwrap_or_else(|| format!("mesh_{}", mesh.index()));
            let mut name = mesh_name;
            if n_prims > 1 {
                name = format!("{name}#{k}");
            }
            if instance_count[mesh.index()] > 1 {
                if let Some(n) = node {
                    name = format!("{name}@node{n}");
                }
            }
            let group = raw.group_names.len() as u32;
            raw.group_names.push(name);
            let n = indices.len();
            let corners = |t: usize| -> Option<[usize; 3]> {
                match mode {
                    Mode::Triangles => (3 * t + 2 < n).then_some([3 * t, 3 * t + 1, 3 * t + 2]),
                    Mode::TriangleStrip => (t + 2 < n).then(|| {
                        if t % 2 == 0 {
                            [t, t + 1, t + 2]
                        } else {
                            [t + 1, t, t + 2]
                        }
                    }),
                    _ => (t + 2 < n).then_some([0, t + 1, t + 2]),
                }
            };
            let mut t = 0;
            while let Some(c) = corners(t) {
                triangle.clear();
                triangle.extend(c.iter().map(|&i| base + indices[i]));
                raw.push_face(&triangle, group);
                t += 1;
            }
            if mode == Mode::Triangles && n % 3 != 0 {
                raw.notes.push(format!(
                    "{what}: {} trailing indices (not a whole triangle) ignored",
                    n % 3
                ));
            }
        }
    }
    raw.input_faces = raw.face_count();
    if skipped_modes > 0 {
        raw.notes.push(format!(
            "{skipped_modes} point/line primitives skipped (only triangles are read)"
        ));
    }
    if transformed {
        raw.notes
            .push("node transforms applied to vertex positions".to_string());
    }
    Ok(raw)
}

/// Collects mesh instances below `node` with their world transforms.
fn visit<'a>(
    node: gltf::Node<'a>,
    parent: DMat4,
    depth: usize,
    out: &mut Vec<(gltf::Mesh<'a>, DMat4, Option<usize>)>,
    path: &Path,
) -> Result<()> {
    if depth > MAX_NODE_DEPTH || out.len() > MAX_INSTANCES {
        return Err(Error::input(
            path,
            format!(
                "glTF node hierarchy deeper than {MAX_NODE_DEPTH} or more than {MAX_INSTANCES} \
                 mesh instances (cyclic node graph?)"
            ),
        ));
    }
    let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
    let world = parent * local;
    if let Some(mesh) = node.mesh() {
        out.push((mesh, world, Some(node.index())));
    }
    for child in node.children() {
        visit(child, world, depth + 1, out, path)?;
    }
    Ok(())
}

/// Loads a buffer URI: a base64 `data:` URI, or a file in the glTF file's folder (or below
/// it). A file named by an absolute path, a scheme (`file:`, `http://`), a `..` component
/// or a link leading out of the folder is refused: a `.gltf` from an upload would otherwise
/// copy any file the process can read (`/etc/passwd`) into the encoded output.
fn load_uri(uri: &str, path: &Path, opts: &ReadOptions) -> Result<Vec<u8>> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (meta, data) = rest
            .split_once(',')
            .ok_or_else(|| Error::input(path, "malformed data: URI (no comma)"))?;
        if !meta.ends_with(";base64") {
            return Err(Error::input(path, "only base64 data: URIs are supported"));
        }
        return base64_decode(data)
            .ok_or_else(|| Error::input(path, "data: URI is not valid base64"));
    }
    let refuse = |why: &str| Error::input(path, format!("buffer URI `{uri}` refused: {why}"));
    if !opts.external_files {
        return Err(refuse(
            "external buffer files are not read (ReadOptions::external_files is false)",
        ));
    }
    // A relative reference has no scheme, and a `:` in its first segment would be one
    // (`file:`, `http:`, a drive letter).
    if uri.contains(':') {
        return Err(refuse(
            "not a relative file name (it has a scheme or a drive)",
        ));
    }
    let relative = percent_decode(uri)
        .ok_or_else(|| Error::input(path, format!("buffer URI `{uri}` is malformed")))?;
    let relative = Path::new(&relative);
    for part in relative.components() {
        match part {
            Component::Normal(_) | Component::CurDir => {}
            Component::ParentDir => {
                return Err(refuse("`..` leads out of the glTF file's folder"));
            }
            Component::RootDir | Component::Prefix(_) => {
                return Err(refuse("absolute paths are not read"));
            }
        }
    }
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let file = folder.join(relative);
    // Links inside the folder may point out of it: compare where both really are.
    let real_folder = folder.canonicalize().map_err(|e| Error::io(folder, e))?;
    let real_file = file.canonicalize().map_err(|e| Error::io(&file, e))?;
    if !real_file.starts_with(&real_folder) {
        return Err(refuse(
            "it leads out of the glTF file's folder through a link",
        ));
    }
    std::fs::read(&real_file).map_err(|e| Error::io(file, e))
}

/// Decodes standard base64 (with or without `=` padding; whitespace not allowed).
fn base64_decode(text: &str) -> Option<Vec<u8>> {
    let text = text.trim_end_matches('=');
    let mut out = Vec::with_capacity(text.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0u32);
    for c in text.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

/// Decodes `%XX` escapes of a URI path.
fn percent_decode(uri: &str) -> Option<String> {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// The bytes of `accessor`'s elements: `(data, stride, element size)` after checking that
/// every element lies inside its buffer view and buffer.
fn accessor_bytes<'b>(
    accessor: &gltf::Accessor,
    buffers: &'b [Cow<[u8]>],
    elem_size: usize,
    what: &str,
    path: &Path,
) -> Result<(&'b [u8], usize)> {
    let err = |d: String| Error::input(path, format!("{what}: accessor {}: {d}", accessor.index()));
    if accessor.sparse().is_some() {
        return Err(err("sparse accessors are not supported".into()));
    }
    let view = accessor
        .view()
        .ok_or_else(|| err("has no bufferView (not supported)".into()))?;
    let buffer = buffers
        .get(view.buffer().index())
        .ok_or_else(|| err("buffer missing".into()))?;
    let view_end = view
        .offset()
        .checked_add(view.length())
        .filter(|&e| e <= buffer.len())
        .ok_or_else(|| err("bufferView exceeds its buffer".into()))?;
    let view_bytes = &buffer[view.offset()..view_end];
    let stride = view.stride().unwrap_or(elem_size);
    if stride < elem_size {
        return Err(err(format!(
            "byteStride {stride} is smaller than the element"
        )));
    }
    let count = accessor.count();
    if count == 0 {
        return Ok((&[], stride));
    }
    let needed = (count - 1)
        .checked_mul(stride)
        .and_then(|n| n.checked_add(elem_size))
        .and_then(|n| n.checked_add(accessor.offset()))
        .filter(|&n| n <= view_bytes.len())
        .ok_or_else(|| err(format!("{count} elements exceed the bufferView")))?;
    Ok((&view_bytes[accessor.offset()..needed], stride))
}

fn read_vec3_f32(
    accessor: &gltf::Accessor,
    buffers: &[Cow<[u8]>],
    what: &str,
    path: &Path,
) -> Result<Vec<[f32; 3]>> {
    if accessor.data_type() != DataType::F32
        || accessor.dimensions() != Dimensions::Vec3
        || accessor.normalized()
    {
        return Err(Error::input(
            path,
            format!("{what}: POSITION must be float VEC3 (quantised positions not supported)"),
        ));
    }
    let (bytes, stride) = accessor_bytes(accessor, buffers, 12, what, path)?;
    let f = |o: usize| f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    Ok((0..accessor.count())
        .map(|i| {
            let o = i * stride;
            [f(o), f(o + 4), f(o + 8)]
        })
        .collect())
}

fn read_indices(
    accessor: &gltf::Accessor,
    buffers: &[Cow<[u8]>],
    what: &str,
    path: &Path,
) -> Result<Vec<u32>> {
    let size = match accessor.data_type() {
        DataType::U8 => 1,
        DataType::U16 => 2,
        DataType::U32 => 4,
        other => {
            return Err(Error::input(
                path,
                format!("{what}: indices have component type {other:?}"),
            ))
        }
    };
    if accessor.dimensions() != Dimensions::Scalar {
        return Err(Error::input(
            path,
            format!("{what}: indices must be SCALAR"),
        ));
    }
    let (bytes, stride) = accessor_bytes(accessor, buffers, size, what, path)?;
    Ok((0..accessor.count())
        .map(|i| {
            let b = &bytes[i * stride..];
            match size {
                1 => u32::from(b[0]),
                2 => u32::from(u16::from_le_bytes([b[0], b[1]])),
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            }
        })
        .collect())
}

/// Writes `mesh` as a `.glb` (see the module docs for the layout).
pub fn write_glb(
    out: &mut dyn Write,
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
) -> io::Result<()> {
    let (mut document, mut bin) = build_document(mesh, normals);
    document["buffers"] = serde_json::json!([{ "byteLength": bin.len() }]);
    let mut json = serde_json::to_vec(&document).map_err(io::Error::other)?;
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let total =
        u32::try_from(total).map_err(|_| io::Error::other("mesh too large for a .glb file"))?;
    let mut w = io::BufWriter::new(out);
    w.write_all(b"glTF")?;
    w.write_all(&2u32.to_le_bytes())?;
    w.write_all(&total.to_le_bytes())?;
    w.write_all(&(json.len() as u32).to_le_bytes())?;
    w.write_all(b"JSON")?;
    w.write_all(&json)?;
    w.write_all(&(bin.len() as u32).to_le_bytes())?;
    w.write_all(b"BIN\0")?;
    w.write_all(&bin)?;
    w.flush()
}

/// Writes `mesh` as a self-contained `.gltf`: the same document as [`write_glb`], with the
/// buffer embedded as a base64 `data:` URI (a third larger than `.glb`).
pub fn write_gltf(
    out: &mut dyn Write,
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
) -> io::Result<()> {
    let (mut document, bin) = build_document(mesh, normals);
    document["buffers"] = serde_json::json!([{
        "byteLength": bin.len(),
        "uri": format!("data:application/octet-stream;base64,{}", base64_encode(&bin)),
    }]);
    let mut w = io::BufWriter::new(out);
    serde_json::to_writer(&mut w, &document).map_err(io::Error::other)?;
    w.write_all(b"\n")?;
    w.flush()
}

/// The glTF document (without `buffers`) and the binary buffer it indexes.
fn build_document(mesh: &ControlMesh, normals: Option<&[DVec3]>) -> (serde_json::Value, Vec<u8>) {
    let nv = mesh.vertex_count();
    let mut bin: Vec<u8> = Vec::new();
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &mesh.positions {
        let q = [p.x as f32, p.y as f32, p.z as f32];
        for a in 0..3 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
            bin.extend_from_slice(&q[a].to_le_bytes());
        }
    }
    let positions_len = bin.len();
    let mut views = vec![serde_json::json!({
        "buffer": 0, "byteOffset": 0, "byteLength": positions_len, "target": 34962
    })];
    let mut accessors = vec![serde_json::json!({
        "bufferView": 0, "componentType": 5126, "count": nv, "type": "VEC3",
        "min": lo, "max": hi
    })];
    let mut attributes = serde_json::json!({ "POSITION": 0 });
    if let Some(normals) = normals {
        let start = bin.len();
        for n in normals {
            for c in n.to_array() {
                bin.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
        views.push(serde_json::json!({
            "buffer": 0, "byteOffset": start, "byteLength": bin.len() - start, "target": 34962
        }));
        accessors.push(serde_json::json!({
            "bufferView": 1, "componentType": 5126, "count": nv, "type": "VEC3"
        }));
        attributes["NORMAL"] = serde_json::json!(1);
    }

    // Triangles per group, in face order.
    let mut per_group: Vec<Vec<u32>> = vec![Vec::new(); mesh.groups.len()];
    for (f, face) in mesh.faces().enumerate() {
        let tris = &mut per_group[mesh.face_groups[f] as usize];
        for t in fan_triangles(face) {
            tris.extend_from_slice(&t);
        }
    }
    let index_start = bin.len();
    let index_view = views.len();
    let mut meshes = Vec::new();
    for (g, tris) in per_group.iter().enumerate() {
        if tris.is_empty() {
            continue;
        }
        let offset = bin.len() - index_start;
        for &i in tris {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        accessors.push(serde_json::json!({
            "bufferView": index_view, "byteOffset": offset, "componentType": 5125,
            "count": tris.len(), "type": "SCALAR"
        }));
        meshes.push(serde_json::json!({
            "name": mesh.groups[g].name,
            "primitives": [{
                "attributes": attributes, "indices": accessors.len() - 1, "mode": 4
            }]
        }));
    }
    views.push(serde_json::json!({
        "buffer": 0, "byteOffset": index_start, "byteLength": bin.len() - index_start,
        "target": 34963
    }));
    let nodes: Vec<_> = (0..meshes.len())
        .map(|m| serde_json::json!({ "mesh": m }))
        .collect();
    let document = serde_json::json!({
        "asset": { "version": "2.0", "generator": concat!("scode ", env!("CARGO_PKG_VERSION")) },
        "scene": 0,
        "scenes": [{ "nodes": (0..meshes.len()).collect::<Vec<_>>() }],
        "nodes": nodes,
        "meshes": meshes,
        "accessors": accessors,
        "bufferViews": views,
    });
    (document, bin)
}

/// Standard base64 with `=` padding.
fn base64_encode(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                s.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{read_mesh, read_mesh_bytes, write_mesh_to, MeshFormat, ReadReport};
    use crate::mesh::PatchKind;

    fn read(bytes: &[u8], format: MeshFormat) -> Result<(ControlMesh, ReadReport)> {
        read_mesh_bytes(bytes, format, Path::new("t.glb"))
    }

    fn sample_mesh() -> ControlMesh {
        let mut m = ControlMesh::new();
        for p in [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.5, 0.5, 1.0 / 3.0],
        ] {
            m.push_vertex(DVec3::from(p));
        }
        let a = m.push_group("face_1", PatchKind::default());
        let b = m.push_group("unused", PatchKind::default());
        let c = m.push_group("face_2", PatchKind::default());
        let _ = b;
        m.push_face(&[0, 1, 2, 3], a);
        m.push_face(&[1, 4, 2], c);
        m.push_face(&[0, 4, 1], c);
        m
    }

    #[test]
    fn gltf_text_round_trip() {
        let mesh = sample_mesh();
        let mut bytes = Vec::new();
        write_mesh_to(&mut bytes, MeshFormat::Gltf, &mesh, None).unwrap();
        gltf::Gltf::from_slice(&bytes).unwrap();
        let (back, report) = read(&bytes, MeshFormat::Gltf).unwrap();
        assert!(report.unchanged(), "{report}");
        assert_eq!(back.face_count(), 4);
        assert_eq!(back.groups.len(), 2);
    }

    #[test]
    fn glb_round_trip_and_gltf_crate_accepts_it() {
        let mesh = sample_mesh();
        let normals: Vec<DVec3> = vec![DVec3::Z; 5];
        for n in [None, Some(normals.as_slice())] {
            let mut bytes = Vec::new();
            write_mesh_to(&mut bytes, MeshFormat::Glb, &mesh, n).unwrap();
            // The gltf crate validates the document and the GLB container.
            let doc = gltf::Gltf::from_slice(&bytes).unwrap();
            assert_eq!(doc.meshes().len(), 2);
            let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
            assert_eq!(prim.get(&gltf::Semantic::Normals).is_some(), n.is_some());
            assert_eq!(bytes.len() % 4, 0);

            let (back, report) = read(&bytes, MeshFormat::Glb).unwrap();
            assert!(report.unchanged(), "{report}");
            let names: Vec<_> = back.groups.iter().map(|g| g.name.as_str()).collect();
            assert_eq!(names, vec!["face_1", "face_2"]);
            let faces: Vec<Vec<u32>> = back.faces().map(<[u32]>::to_vec).collect();
            assert_eq!(
                faces,
                vec![vec![0, 1, 2], vec![0, 2, 3], vec![1, 4, 2], vec![0, 4, 1]]
            );
            assert_eq!(back.face_groups, vec![0, 0, 1, 1]);
            for (a, b) in back.positions.iter().zip(&mesh.positions) {
                assert_eq!(*a, b.as_vec3().as_dvec3());
            }
        }
    }

    /// A hand-made `.gltf` with an external `.bin`, a data: URI buffer, a node transform,
    /// a triangle strip, u16 indices and a strided position view.
    #[test]
    fn gltf_with_external_and_data_buffers() {
        let dir = std::env::temp_dir().join(format!("scode-gltf-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // Buffer 0 (external, name with a space): 4 positions with 4 bytes of padding each.
        let mut external = Vec::new();
        for p in [
            [0.0f32, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ] {
            for c in p {
                external.extend_from_slice(&c.to_le_bytes());
            }
            external.extend_from_slice(&[0; 4]);
        }
        std::fs::write(dir.join("my data.bin"), &external).unwrap();
        // Buffer 1 (data: URI): u16 strip indices 0 1 2 3.
        let idx: Vec<u8> = [0u16, 1, 2, 3]
            .iter()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        let b64 = base64_encode(&idx);
        let json = format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
            "nodes":[{{"children":[1],"translation":[10,0,0]}},{{"mesh":0,"scale":[2,2,2]}}],
            "meshes":[{{"name":"strip","primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"mode":5}}]}}],
            "accessors":[
              {{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
              {{"bufferView":1,"componentType":5123,"count":4,"type":"SCALAR"}}],
            "bufferViews":[{{"buffer":0,"byteLength":64,"byteStride":16}},{{"buffer":1,"byteLength":8}}],
            "buffers":[{{"uri":"my%20data.bin","byteLength":64}},
                       {{"uri":"data:application/octet-stream;base64,{b64}","byteLength":8}}]}}"#
        );
        let path = dir.join("model.gltf");
        std::fs::write(&path, &json).unwrap();
        let (mesh, report) = read_mesh(&path).unwrap();
        assert_eq!(mesh.face_count(), 2);
        assert_eq!(mesh.face(0), &[0, 1, 2]);
        assert_eq!(mesh.face(1), &[2, 1, 3]); // odd strip triangle flipped
        assert_eq!(mesh.positions[3], DVec3::new(12.0, 2.0, 0.0));
        assert_eq!(mesh.groups[0].name, "strip");
        assert!(report.repairs.iter().any(|r| r.contains("transform")));

        // Missing external file: an I/O error naming it.
        std::fs::remove_file(dir.join("my data.bin")).unwrap();
        let err = read_mesh(&path).unwrap_err().to_string();
        assert!(err.contains("my data.bin"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A `.gltf` whose one buffer is `uri` (a triangle's positions must be at its start).
    fn gltf_with_buffer_uri(uri: &str) -> String {
        format!(
            r#"{{"asset":{{"version":"2.0"}},
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
            "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
                "min":[0,0,0],"max":[1,1,0]}}],
            "bufferViews":[{{"buffer":0,"byteLength":36}}],
            "buffers":[{{"uri":"{uri}","byteLength":36}}]}}"#
        )
    }

    /// Buffer URIs may only name files in the glTF file's folder or below it: absolute
    /// paths, schemes, `..` (also percent-encoded) and links out of the folder are refused
    /// with the URI named, before anything outside is read; `external_files: false`
    /// refuses every file but keeps `data:` URIs.
    #[test]
    fn buffer_uris_stay_in_the_files_folder() {
        let root = std::env::temp_dir().join(format!("scode-gltf-uri-{}", std::process::id()));
        let dir = root.join("upload");
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        let triangle: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
            .iter()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        std::fs::write(dir.join("sub/tri.bin"), &triangle).unwrap();
        std::fs::write(root.join("secret.bin"), &triangle).unwrap();
        let read_uri = |uri: &str, opts: &ReadOptions| {
            let path = dir.join("model.gltf");
            std::fs::write(&path, gltf_with_buffer_uri(uri)).unwrap();
            crate::io::read_mesh_with(&path, opts).map(|(m, _)| m)
        };
        let default = ReadOptions::default();
        assert_eq!(read_uri("sub/tri.bin", &default).unwrap().face_count(), 1);
        assert_eq!(read_uri("./sub/tri.bin", &default).unwrap().face_count(), 1);
        let mut refused = vec![
            "/etc/passwd",
            "../secret.bin",
            "sub/../../secret.bin",
            "%2e%2e/secret.bin",
            "%2Fetc%2Fpasswd",
            "file:///etc/passwd",
            "file:../secret.bin",
            "C:/Windows/win.ini",
        ];
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(root.join("secret.bin"), dir.join("link.bin")).unwrap();
            std::os::unix::fs::symlink(&root, dir.join("up")).unwrap();
            refused.extend(["link.bin", "up/secret.bin"]);
        }
        for uri in refused {
            let e = read_uri(uri, &default).unwrap_err();
            assert!(matches!(e, Error::Input { .. }), "{uri}: {e}");
            let msg = e.to_string();
            assert!(
                msg.contains(&format!("buffer URI `{uri}` refused")) && msg.contains("model.gltf"),
                "{msg}"
            );
        }
        let none = ReadOptions {
            external_files: false,
        };
        let msg = read_uri("sub/tri.bin", &none).unwrap_err().to_string();
        assert!(msg.contains("external_files"), "{msg}");
        let data = format!(
            "data:application/octet-stream;base64,{}",
            base64_encode(&triangle)
        );
        assert_eq!(read_uri(&data, &none).unwrap().face_count(), 1);
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn base64_and_percent_decoding() {
        for data in [&b""[..], b"a", b"ab", b"abc", b"\x00\xff\x10\x80"] {
            assert_eq!(base64_decode(&base64_encode(data)).unwrap(), data);
        }
        assert!(base64_decode("ab$c").is_none());
        assert_eq!(percent_decode("a%20b%2Fc").unwrap(), "a b/c");
        assert!(percent_decode("a%2").is_none());
    }

    #[test]
    fn malformed_glb_is_an_error() {
        let mut bytes = Vec::new();
        write_mesh_to(&mut bytes, MeshFormat::Glb, &sample_mesh(), None).unwrap();
        // Truncated container, garbage, and an index out of range.
        assert!(read(&bytes[..bytes.len() - 8], MeshFormat::Glb).is_err());
        assert!(read(b"glTF\x02\0\0\0garbage", MeshFormat::Glb).is_err());
        assert!(read(b"{not json", MeshFormat::Gltf).is_err());
        let mut bad = bytes.clone();
        let n = bad.len();
        bad[n - 4..].copy_from_slice(&99u32.to_le_bytes()); // last index
        let msg = read(&bad, MeshFormat::Glb).unwrap_err().to_string();
        assert!(
            msg.contains("out of range") && msg.contains("t.glb"),
            "{msg}"
        );
        // NaN position.
        let mut nan = bytes.clone();
        let json_len = u32::from_le_bytes(nan[12..16].try_into().unwrap()) as usize;
        let bin_start = 20 + json_len + 8;
        nan[bin_start..bin_start + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        let msg = read(&nan, MeshFormat::Glb).unwrap_err().to_string();
        assert!(msg.contains("non-finite"), "{msg}");
    }
}
