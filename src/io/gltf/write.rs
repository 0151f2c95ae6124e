//! glTF writer: one triangle primitive per body with the CAD face as a per-vertex feature id,
//! and the sharp edges as a line primitive (see the [module docs](super) for the layout).
//!
//! A CAD viewer draws a part in one or two calls per body instead of one per CAD face, and
//! still knows which face a picked triangle belongs to: `_FEATURE_ID_0` holds the face (group)
//! index, `EXT_mesh_features` declares it, and an `EXT_structural_metadata` property table
//! holds the face names, row `i` for group `i`.

use std::io::{self, Write};

use glam::DVec3;
use serde_json::{json, Value};

use super::super::{fan_triangles, WriteOptions};
use crate::mesh::ControlMesh;

/// `bufferView.target` of vertex attributes and of indices.
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
/// Accessor component types.
const BYTE: u32 = 5120;
const SHORT: u32 = 5122;
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_INT: u32 = 5125;
const FLOAT: u32 = 5126;
/// Largest magnitude of a normalized signed 16-bit and 8-bit component.
const I16_MAX: f64 = 32767.0;
const I8_MAX: f64 = 127.0;
/// Feature ids above this are not exact in the `FLOAT` attribute that holds them.
const MAX_FLOAT_ID: usize = 1 << 24;

/// Writes `mesh` as a `.glb`. The document is laid out first (every buffer view's offset
/// and length follow from the counts); the binary chunk is then written straight from the
/// mesh's arrays, with no copy of it in memory.
pub fn write_glb(
    out: &mut dyn Write,
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
    opts: &WriteOptions,
) -> io::Result<()> {
    let bodies = bodies(mesh);
    let (mut document, bin) = build_document(mesh, &bodies, normals, opts)?;
    if bin.len > 0 {
        document["buffers"] = json!([{ "byteLength": bin.len }]);
    }
    let mut json = serde_json::to_vec(&document).map_err(io::Error::other)?;
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let bin_len = bin.len.next_multiple_of(4);
    // A file without a buffer has no BIN chunk.
    let bin_chunk = if bin.len == 0 { 0 } else { 8 + bin_len };
    let total = 12 + 8 + json.len() + bin_chunk;
    let too_large = || io::Error::other("mesh too large for a .glb file");
    let total = u32::try_from(total).map_err(|_| too_large())?;
    let mut w = Sink::new(out);
    w.put(b"glTF")?;
    w.put(&2u32.to_le_bytes())?;
    w.put(&total.to_le_bytes())?;
    w.put(&(json.len() as u32).to_le_bytes())?;
    w.put(b"JSON")?;
    w.put(&json)?;
    if bin.len > 0 {
        w.put(&(bin_len as u32).to_le_bytes())?;
        w.put(b"BIN\0")?;
        bin.write(&mut w, bin_len)?;
    }
    w.flush()
}

/// Writes `mesh` as a self-contained `.gltf`: the same document as [`write_glb`], with the
/// buffer embedded as a base64 `data:` URI (a third larger than `.glb`).
pub fn write_gltf(
    out: &mut dyn Write,
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
    opts: &WriteOptions,
) -> io::Result<()> {
    let bodies = bodies(mesh);
    let (mut document, bin) = build_document(mesh, &bodies, normals, opts)?;
    if bin.len > 0 {
        // base64 needs the bytes in one piece.
        let mut bytes = Vec::with_capacity(bin.len);
        let mut sink = Sink::new(&mut bytes);
        bin.write(&mut sink, bin.len)?;
        sink.flush()?;
        drop(sink);
        document["buffers"] = json!([{
            "byteLength": bin.len,
            "uri": format!("data:application/octet-stream;base64,{}", super::base64_encode(&bytes)),
        }]);
    }
    let mut w = super::super::buffered(out);
    serde_json::to_writer(&mut w, &document).map_err(io::Error::other)?;
    w.write_all(b"\n")?;
    w.flush()
}

/// The buffered output of the binary chunk, counting the bytes written so that each buffer
/// view is checked to be as long as the document says.
struct Sink<'w> {
    w: io::BufWriter<&'w mut dyn Write>,
    written: usize,
}

impl<'w> Sink<'w> {
    fn new(out: &'w mut dyn Write) -> Self {
        Sink {
            w: super::super::buffered(out),
            written: 0,
        }
    }

    #[inline]
    fn put(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.written += bytes.len();
        self.w.write_all(bytes)
    }

    fn zeros(&mut self, n: usize) -> io::Result<()> {
        for _ in 0..n {
            self.put(&[0])?;
        }
        Ok(())
    }

    fn flush(&mut self) -> io::Result<()> {
        self.w.flush()
    }
}

/// One connected component of the mesh, with its vertices split by CAD face.
struct Body {
    /// `(vertex, group)` of each vertex written, sorted: a vertex used by faces of several
    /// groups is written once per group, because a vertex has one feature id. Sorting by the
    /// mesh's vertex index first keeps the mesh's vertex order, so a reader that merges the
    /// copies again gets the vertices back in their order.
    copies: Vec<(u32, u32)>,
    /// Fan-triangulated faces, as indices into `copies`.
    triangles: Vec<u32>,
    /// Sharp edges, as index pairs into `copies`.
    lines: Vec<u32>,
}

/// The distinct groups of the faces around each vertex, in increasing order: `groups[start[v]
/// ..start[v + 1]]` for vertex `v`.
struct VertexGroups {
    start: Vec<u32>,
    groups: Vec<u32>,
}

impl VertexGroups {
    fn new(mesh: &ControlMesh) -> VertexGroups {
        let nv = mesh.vertex_count();
        // Counting sort of the face corners by vertex, then each vertex's few groups sorted
        // and deduplicated in place: linear in the corners, where sorting all `(vertex,
        // group)` pairs is not.
        let mut start = vec![0u32; nv + 1];
        for &v in &mesh.face_vertices {
            start[v as usize + 1] += 1;
        }
        for v in 0..nv {
            start[v + 1] += start[v];
        }
        let mut cursor = start.clone();
        let mut all = vec![0u32; mesh.face_vertices.len()];
        for (f, face) in mesh.faces().enumerate() {
            for &v in face {
                all[cursor[v as usize] as usize] = mesh.face_groups[f];
                cursor[v as usize] += 1;
            }
        }
        let mut groups = Vec::with_capacity(all.len());
        let mut out_start = Vec::with_capacity(nv + 1);
        out_start.push(0u32);
        for v in 0..nv {
            let around = &mut all[start[v] as usize..start[v + 1] as usize];
            around.sort_unstable();
            let first = groups.len();
            for &g in around.iter() {
                if groups.len() == first || groups.last() != Some(&g) {
                    groups.push(g);
                }
            }
            out_start.push(groups.len() as u32);
        }
        VertexGroups {
            start: out_start,
            groups,
        }
    }

    fn of(&self, v: u32) -> &[u32] {
        &self.groups[self.start[v as usize] as usize..self.start[v as usize + 1] as usize]
    }
}

/// The bodies of `mesh`: connected components of its faces through shared vertices, in the
/// order of their first face. Solids of an assembly that touch keep separate vertices (the
/// readers do not weld inside closed surfaces), so they are separate bodies.
fn bodies(mesh: &ControlMesh) -> Vec<Body> {
    let nv = mesh.vertex_count();
    let mut parent: Vec<u32> = (0..nv as u32).collect();
    fn root(parent: &mut [u32], mut v: u32) -> u32 {
        while parent[v as usize] != v {
            let up = parent[parent[v as usize] as usize];
            parent[v as usize] = up;
            v = up;
        }
        v
    }
    for face in mesh.faces() {
        let a = root(&mut parent, face[0]);
        for &v in &face[1..] {
            let b = root(&mut parent, v);
            if a != b {
                parent[b as usize] = a;
            }
        }
    }
    let mut body_of_root = vec![u32::MAX; nv];
    let mut body_of_face = Vec::with_capacity(mesh.face_count());
    let mut out: Vec<Body> = Vec::new();
    for face in mesh.faces() {
        let r = root(&mut parent, face[0]) as usize;
        if body_of_root[r] == u32::MAX {
            body_of_root[r] = out.len() as u32;
            out.push(Body {
                copies: Vec::new(),
                triangles: Vec::new(),
                lines: Vec::new(),
            });
        }
        body_of_face.push(body_of_root[r]);
    }
    // Copies in vertex order, then group order: each body's list comes out sorted.
    let around = VertexGroups::new(mesh);
    let mut first_copy = vec![0u32; nv];
    for v in 0..nv as u32 {
        let groups = around.of(v);
        if groups.is_empty() {
            continue;
        }
        let body = &mut out[body_of_root[root(&mut parent, v) as usize] as usize];
        first_copy[v as usize] = body.copies.len() as u32;
        body.copies.extend(groups.iter().map(|&g| (v, g)));
    }
    for (f, face) in mesh.faces().enumerate() {
        let g = mesh.face_groups[f];
        let body = &mut out[body_of_face[f] as usize];
        for t in fan_triangles(face) {
            for v in t {
                // Every (vertex, group) of the body's faces is among the copies.
                let k = around.of(v).iter().position(|&h| h == g).unwrap_or(0);
                body.triangles.push(first_copy[v as usize] + k as u32);
            }
        }
    }
    for &(a, b) in &mesh.sharp_edges {
        if a as usize >= nv || b as usize >= nv {
            continue;
        }
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        let body = body_of_root[ra as usize];
        if ra != rb || body == u32::MAX || around.of(a).is_empty() || around.of(b).is_empty() {
            continue; // not an edge of any face: nothing to draw it along
        }
        let body = &mut out[body as usize];
        body.lines
            .extend([first_copy[a as usize], first_copy[b as usize]]);
    }
    out
}

/// Writes the bytes of one buffer view into the binary chunk.
type Fill<'a> = Box<dyn Fn(&mut Sink<'_>) -> io::Result<()> + 'a>;

/// The layout of the binary buffer: its buffer views, and for each the function that writes
/// its bytes.
#[derive(Default)]
struct Bin<'a> {
    /// Bytes so far (the end of the last view).
    len: usize,
    views: Vec<Value>,
    /// `(offset, bytes written by fill, fill)` of each view.
    fills: Vec<(usize, usize, Fill<'a>)>,
}

impl<'a> Bin<'a> {
    /// Appends a buffer view of `len` bytes, which `fill` writes, starting at a multiple of
    /// 8 bytes (the alignment of the largest component type). Returns its index.
    fn view(
        &mut self,
        target: Option<u32>,
        stride: Option<usize>,
        len: usize,
        fill: impl Fn(&mut Sink<'_>) -> io::Result<()> + 'a,
    ) -> usize {
        let start = self.len.next_multiple_of(8);
        // A buffer view holds at least one byte.
        self.len = start + len.max(1);
        let mut view = json!({
            "buffer": 0, "byteOffset": start, "byteLength": self.len - start
        });
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        if let Some(s) = stride {
            view["byteStride"] = json!(s);
        }
        self.views.push(view);
        self.fills.push((start, len, Box::new(fill)));
        self.views.len() - 1
    }

    /// Writes the buffer, zero-padded to `padded_len` bytes.
    fn write(&self, w: &mut Sink<'_>, padded_len: usize) -> io::Result<()> {
        let base = w.written;
        for (start, len, fill) in &self.fills {
            w.zeros(base + start - w.written)?;
            let before = w.written;
            fill(w)?;
            if w.written - before != *len {
                return Err(io::Error::other(
                    "glTF buffer view written with a length other than its declared one",
                ));
            }
        }
        w.zeros(base + padded_len - w.written)
    }
}

/// Maps positions to normalized 16-bit integers: `q = (p - center) / half * 32767`, so that
/// the node transform `translation = center`, `scale = half` gives the positions back. One
/// uniform scale for all axes keeps normals unchanged by the node transform.
#[derive(Clone, Copy)]
struct Quantizer {
    center: [f32; 3],
    half: f32,
}

impl Quantizer {
    fn new(positions: &[DVec3]) -> Quantizer {
        let lo = positions.iter().fold(DVec3::INFINITY, |a, &p| a.min(p));
        let hi = positions.iter().fold(DVec3::NEG_INFINITY, |a, &p| a.max(p));
        if positions.is_empty() {
            return Quantizer {
                center: [0.0; 3],
                half: 1.0,
            };
        }
        let center = ((lo + hi) * 0.5).to_array().map(|c| c as f32);
        // The half extent from the f32 center the reader sees, rounded up in f32 so that
        // every position maps into [-1, 1].
        let c = DVec3::from(center.map(f64::from));
        let h = (hi - c).max(c - lo).max_element();
        let mut half = h as f32;
        if f64::from(half) < h {
            half = f32::from_bits(half.to_bits() + 1);
        }
        if !(half > 0.0 && half.is_finite()) {
            half = 1.0;
        }
        Quantizer { center, half }
    }

    fn quantize(&self, p: DVec3) -> [i16; 3] {
        let c = DVec3::from(self.center.map(f64::from));
        ((p - c) / f64::from(self.half) * I16_MAX)
            .to_array()
            .map(|x| x.round().clamp(-I16_MAX, I16_MAX) as i16)
    }
}

/// A unit normal for the validator's unit-length rule: `n` normalized, or +Z where `n` has
/// no direction (a degenerate vertex).
fn unit(n: DVec3) -> DVec3 {
    let u = n.normalize_or_zero();
    if u == DVec3::ZERO {
        DVec3::Z
    } else {
        u
    }
}

/// Accessors and buffer views of one body's vertices: `(POSITION, NORMAL, _FEATURE_ID_0)`.
fn vertex_accessors<'a>(
    body: &'a Body,
    mesh: &'a ControlMesh,
    normals: Option<&'a [DVec3]>,
    quant: Option<Quantizer>,
    bin: &mut Bin<'a>,
    accessors: &mut Vec<Value>,
) -> (usize, Option<usize>, usize) {
    let count = body.copies.len();
    let at = |&(v, _): &(u32, u32)| mesh.positions[v as usize];
    let position = if let Some(q) = quant {
        let (mut lo, mut hi) = ([i16::MAX; 3], [i16::MIN; 3]);
        for p in body.copies.iter().map(|c| q.quantize(at(c))) {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        // 6 bytes padded to 8: vertex attribute elements start at multiples of 4.
        let view = bin.view(Some(ARRAY_BUFFER), Some(8), 8 * count, move |w| {
            let mut record = [0u8; 8];
            for c in &body.copies {
                for (k, x) in q.quantize(at(c)).into_iter().enumerate() {
                    record[2 * k..2 * k + 2].copy_from_slice(&x.to_le_bytes());
                }
                w.put(&record)?;
            }
            Ok(())
        });
        json!({ "bufferView": view, "componentType": SHORT, "normalized": true,
                "count": count, "type": "VEC3", "min": lo, "max": hi })
    } else {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in body.copies.iter().map(|c| at(c).as_vec3().to_array()) {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let view = bin.view(Some(ARRAY_BUFFER), None, 12 * count, move |w| {
            for c in &body.copies {
                w.put(&vec3_bytes(at(c)))?;
            }
            Ok(())
        });
        json!({ "bufferView": view, "componentType": FLOAT, "count": count, "type": "VEC3",
                "min": lo, "max": hi })
    };
    accessors.push(position);
    let position = accessors.len() - 1;

    let normal = normals.map(|normals| {
        let accessor = if quant.is_some() {
            let view = bin.view(Some(ARRAY_BUFFER), Some(4), 4 * count, move |w| {
                for &(v, _) in &body.copies {
                    let mut record = [0u8; 4];
                    for (k, c) in unit(normals[v as usize]).to_array().into_iter().enumerate() {
                        record[k] = (c * I8_MAX).round().clamp(-I8_MAX, I8_MAX) as i8 as u8;
                    }
                    w.put(&record)?;
                }
                Ok(())
            });
            json!({ "bufferView": view, "componentType": BYTE, "normalized": true,
                    "count": count, "type": "VEC3" })
        } else {
            let view = bin.view(Some(ARRAY_BUFFER), None, 12 * count, move |w| {
                for &(v, _) in &body.copies {
                    w.put(&vec3_bytes(unit(normals[v as usize])))?;
                }
                Ok(())
            });
            json!({ "bufferView": view, "componentType": FLOAT, "count": count, "type": "VEC3" })
        };
        accessors.push(accessor);
        accessors.len() - 1
    });

    // Feature ids are group indices: 16-bit while they fit, else float (exact to 2^24).
    // Either takes 4 bytes a vertex, since attribute elements start at multiples of 4.
    let small = mesh.groups.len() <= usize::from(u16::MAX);
    let view = bin.view(
        Some(ARRAY_BUFFER),
        small.then_some(4),
        4 * count,
        move |w| {
            for &(_, g) in &body.copies {
                if small {
                    let [a, b] = (g as u16).to_le_bytes();
                    w.put(&[a, b, 0, 0])?;
                } else {
                    w.put(&(g as f32).to_le_bytes())?;
                }
            }
            Ok(())
        },
    );
    let component = if small { UNSIGNED_SHORT } else { FLOAT };
    accessors.push(json!({ "bufferView": view, "componentType": component,
                           "count": count, "type": "SCALAR" }));
    (position, normal, accessors.len() - 1)
}

/// `p` as three little-endian f32.
fn vec3_bytes(p: DVec3) -> [u8; 12] {
    let mut out = [0u8; 12];
    for (k, c) in p.to_array().into_iter().enumerate() {
        out[4 * k..4 * k + 4].copy_from_slice(&(c as f32).to_le_bytes());
    }
    out
}

/// An index accessor (16-bit where the body's vertex count allows, else 32-bit; the largest
/// value of either type is reserved for primitive restart) and its buffer view.
fn index_accessor<'a>(
    indices: &'a [u32],
    vertex_count: usize,
    bin: &mut Bin<'a>,
    accessors: &mut Vec<Value>,
) -> usize {
    let small = vertex_count < usize::from(u16::MAX);
    let size = if small { 2 } else { 4 };
    let view = bin.view(
        Some(ELEMENT_ARRAY_BUFFER),
        None,
        size * indices.len(),
        move |w| {
            for &i in indices {
                if small {
                    w.put(&(i as u16).to_le_bytes())?;
                } else {
                    w.put(&i.to_le_bytes())?;
                }
            }
            Ok(())
        },
    );
    let component = if small { UNSIGNED_SHORT } else { UNSIGNED_INT };
    accessors.push(json!({ "bufferView": view, "componentType": component,
                           "count": indices.len(), "type": "SCALAR" }));
    accessors.len() - 1
}

/// The `EXT_structural_metadata` root extension: a schema with one class, `cad_face`, whose
/// one property is the face name, and a property table with one row per group.
fn face_table<'a>(mesh: &'a ControlMesh, bin: &mut Bin<'a>) -> Value {
    let total: usize = mesh.groups.iter().map(|g| g.name.len()).sum();
    let values = bin.view(None, None, total, move |w| {
        for g in &mesh.groups {
            w.put(g.name.as_bytes())?;
        }
        Ok(())
    });
    let offsets = bin.view(None, None, 4 * (mesh.groups.len() + 1), move |w| {
        let mut end = 0u32;
        w.put(&end.to_le_bytes())?;
        for g in &mesh.groups {
            end += g.name.len() as u32;
            w.put(&end.to_le_bytes())?;
        }
        Ok(())
    });
    json!({
        "schema": {
            "id": "scode_cad",
            "classes": {
                "cad_face": {
                    "name": "CAD face",
                    "description": "A face of the CAD model's boundary representation.",
                    "properties": {
                        "name": {
                            "description": "The face's name (its group in the mesh).",
                            "type": "STRING",
                            "required": true
                        }
                    }
                }
            }
        },
        "propertyTables": [{
            "name": "cad_faces",
            "class": "cad_face",
            "count": mesh.groups.len(),
            "properties": {
                "name": { "values": values, "stringOffsets": offsets, "stringOffsetType": "UINT32" }
            }
        }]
    })
}

/// The glTF document (without `buffers`) and the layout of the binary buffer it indexes.
fn build_document<'a>(
    mesh: &'a ControlMesh,
    bodies: &'a [Body],
    normals: Option<&'a [DVec3]>,
    opts: &WriteOptions,
) -> io::Result<(Value, Bin<'a>)> {
    if mesh.groups.len() > MAX_FLOAT_ID {
        return Err(io::Error::other(format!(
            "{} groups: glTF feature ids hold at most {MAX_FLOAT_ID}",
            mesh.groups.len()
        )));
    }
    let total_names: usize = mesh.groups.iter().map(|g| g.name.len()).sum();
    if u32::try_from(total_names).is_err() {
        return Err(io::Error::other(
            "group names too long for a glTF property table",
        ));
    }
    let asset =
        json!({ "version": "2.0", "generator": concat!("scode ", env!("CARGO_PKG_VERSION")) });
    if mesh.face_count() == 0 {
        // Nothing to draw: the asset alone (glTF allows no empty arrays).
        return Ok((json!({ "asset": asset }), Bin::default()));
    }
    let quant = opts.quantize.then(|| Quantizer::new(&mesh.positions));
    let mut bin = Bin::default();
    let mut accessors = Vec::new();
    let mut meshes = Vec::new();
    for (b, body) in bodies.iter().enumerate() {
        let (position, normal, feature) =
            vertex_accessors(body, mesh, normals, quant, &mut bin, &mut accessors);
        let count = body.copies.len();
        let triangles = index_accessor(&body.triangles, count, &mut bin, &mut accessors);
        let mut groups: Vec<u32> = body.copies.iter().map(|&(_, g)| g).collect();
        groups.sort_unstable();
        groups.dedup();
        let mut attributes = json!({ "POSITION": position, "_FEATURE_ID_0": feature });
        if let Some(n) = normal {
            attributes["NORMAL"] = json!(n);
        }
        let mut primitives = vec![json!({
            "attributes": attributes,
            "indices": triangles,
            "mode": 4,
            "material": 0,
            "extensions": { "EXT_mesh_features": { "featureIds": [{
                "featureCount": groups.len(),
                "attribute": 0,
                "propertyTable": 0,
                "label": "cad_face"
            }]}}
        })];
        if !body.lines.is_empty() {
            let lines = index_accessor(&body.lines, count, &mut bin, &mut accessors);
            primitives.push(json!({
                "attributes": { "POSITION": position },
                "indices": lines,
                "mode": 1,
                "material": 1
            }));
        }
        meshes.push(json!({ "name": format!("body_{b}"), "primitives": primitives }));
    }
    let metadata = face_table(mesh, &mut bin);

    let mut nodes = vec![json!({
        "name": "model",
        "children": (1..=meshes.len()).collect::<Vec<_>>()
    })];
    if let Some(q) = &quant {
        nodes[0]["translation"] = json!(q.center);
        nodes[0]["scale"] = json!([q.half, q.half, q.half]);
    }
    nodes.extend((0..meshes.len()).map(|m| json!({ "name": format!("body_{m}"), "mesh": m })));
    let mut used = vec!["EXT_mesh_features", "EXT_structural_metadata"];
    let mut required = Vec::new();
    if quant.is_some() {
        used.push("KHR_mesh_quantization");
        required.push("KHR_mesh_quantization");
    }
    let mut document = json!({
        "asset": asset,
        "extensionsUsed": used,
        "extensions": { "EXT_structural_metadata": metadata },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": nodes,
        "meshes": meshes,
        "materials": [
            { "name": "surface", "pbrMetallicRoughness": {
                "baseColorFactor": [0.8, 0.8, 0.82, 1.0], "metallicFactor": 0.1,
                "roughnessFactor": 0.6 } },
            { "name": "edges", "pbrMetallicRoughness": {
                "baseColorFactor": [0.05, 0.05, 0.05, 1.0], "metallicFactor": 0.0,
                "roughnessFactor": 1.0 } }
        ],
        "accessors": accessors,
        "bufferViews": std::mem::take(&mut bin.views),
    });
    if !required.is_empty() {
        document["extensionsRequired"] = json!(required);
    }
    Ok((document, bin))
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::io::{read_mesh_bytes, write_mesh_to_with, MeshFormat};
    use crate::mesh::PatchKind;
    use std::path::Path;

    /// The JSON and BIN chunks of a `.glb`.
    pub(in crate::io::gltf) fn split_glb(bytes: &[u8]) -> (Value, Vec<u8>) {
        let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        let json = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
        let bin = bytes[20 + json_len + 8..].to_vec();
        (json, bin)
    }

    /// A `.glb` of `json` and `bin` (the inverse of [`split_glb`]).
    pub(in crate::io::gltf) fn join_glb(json: &Value, bin: &[u8]) -> Vec<u8> {
        let mut j = serde_json::to_vec(json).unwrap();
        while j.len() % 4 != 0 {
            j.push(b' ');
        }
        let mut out = b"glTF".to_vec();
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&((12 + 8 + j.len() + 8 + bin.len()) as u32).to_le_bytes());
        out.extend_from_slice(&(j.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&j);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(bin);
        out
    }

    /// Accessor `a`'s components as f64 (as stored: normalized integers not mapped).
    fn components(doc: &Value, bin: &[u8], a: usize) -> Vec<f64> {
        let acc = &doc["accessors"][a];
        let view = &doc["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        let dims = match acc["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC3" => 3,
            t => panic!("{t}"),
        };
        let size = match acc["componentType"].as_u64().unwrap() as u32 {
            BYTE => 1,
            SHORT | UNSIGNED_SHORT => 2,
            _ => 4,
        };
        let stride = view["byteStride"]
            .as_u64()
            .map_or(size * dims, |s| s as usize);
        let start = view["byteOffset"].as_u64().unwrap() as usize
            + acc["byteOffset"].as_u64().unwrap_or(0) as usize;
        let mut out = Vec::new();
        for i in 0..acc["count"].as_u64().unwrap() as usize {
            for c in 0..dims {
                let b = &bin[start + i * stride + c * size..];
                out.push(match acc["componentType"].as_u64().unwrap() as u32 {
                    BYTE => f64::from(b[0] as i8),
                    SHORT => f64::from(i16::from_le_bytes([b[0], b[1]])),
                    UNSIGNED_SHORT => f64::from(u16::from_le_bytes([b[0], b[1]])),
                    UNSIGNED_INT => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    _ => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                });
            }
        }
        out
    }

    /// Two bodies: a tetrahedron whose faces are in groups `lid` and `base` with sharp edges
    /// between them, and apart from it a quad in `plate` with a triangle in `lid` (a group in
    /// both bodies); the group `unused` has no faces.
    pub(in crate::io::gltf) fn two_bodies() -> ControlMesh {
        let mut m = ControlMesh::new();
        for p in [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [5.0, 0.0, 0.0],
            [6.0, 0.0, 0.0],
            [6.0, 1.0, 0.0],
            [5.0, 1.0, 0.0],
            [7.0, 0.5, 0.0],
        ] {
            m.push_vertex(DVec3::from(p));
        }
        let lid = m.push_group("lid", PatchKind::default());
        let base = m.push_group("base", PatchKind::default());
        let plate = m.push_group("plate", PatchKind::default());
        m.push_group("unused", PatchKind::default());
        m.push_face(&[0, 2, 1], lid);
        m.push_face(&[0, 1, 3], lid);
        m.push_face(&[1, 2, 3], base);
        m.push_face(&[0, 3, 2], base);
        m.push_face(&[4, 5, 6, 7], plate);
        m.push_face(&[5, 8, 6], lid);
        for (a, b) in [(1, 2), (1, 3), (0, 3), (0, 2)] {
            m.set_sharp(a, b);
        }
        m
    }

    fn glb(mesh: &ControlMesh, normals: Option<&[DVec3]>, quantize: bool) -> Vec<u8> {
        let mut bytes = Vec::new();
        write_mesh_to_with(
            &mut bytes,
            MeshFormat::Glb,
            mesh,
            normals,
            &WriteOptions { quantize },
        )
        .unwrap();
        bytes
    }

    #[test]
    fn one_triangle_primitive_per_body_with_face_ids_and_an_edge_primitive() {
        let mesh = two_bodies();
        let bytes = glb(&mesh, None, false);
        gltf::Gltf::from_slice(&bytes).unwrap();
        let (doc, bin) = split_glb(&bytes);
        assert_eq!(
            doc["extensionsUsed"],
            json!(["EXT_mesh_features", "EXT_structural_metadata"])
        );
        assert!(doc.get("extensionsRequired").is_none());
        assert_eq!(doc["nodes"][0]["children"], json!([1, 2]));
        let meshes = doc["meshes"].as_array().unwrap();
        assert_eq!(meshes.len(), 2);

        // Body 0: the tetrahedron, every vertex in both groups, so written twice.
        let prims = meshes[0]["primitives"].as_array().unwrap();
        assert_eq!(prims.len(), 2);
        let (tri, lines) = (&prims[0], &prims[1]);
        assert_eq!(tri["mode"], 4);
        assert_eq!(
            tri["extensions"]["EXT_mesh_features"]["featureIds"][0],
            json!({ "featureCount": 2, "attribute": 0, "propertyTable": 0, "label": "cad_face" })
        );
        let acc = |p: &Value, key: &str| p["attributes"][key].as_u64().unwrap() as usize;
        let positions = components(&doc, &bin, acc(tri, "POSITION"));
        let ids = components(&doc, &bin, acc(tri, "_FEATURE_ID_0"));
        assert_eq!(positions.len(), 8 * 3);
        assert_eq!(ids, [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0]);
        let triangles = components(&doc, &bin, tri["indices"].as_u64().unwrap() as usize);
        let face_ids: Vec<f64> = triangles
            .chunks(3)
            .map(|t| {
                let id = ids[t[0] as usize];
                assert!(t.iter().all(|&v| ids[v as usize] == id), "{t:?}");
                id
            })
            .collect();
        assert_eq!(face_ids, [0.0, 0.0, 1.0, 1.0]);
        // The edge primitive runs over the same vertices, along the four sharp edges.
        assert_eq!(lines["mode"], 1);
        assert_eq!(acc(lines, "POSITION"), acc(tri, "POSITION"));
        let ends = components(&doc, &bin, lines["indices"].as_u64().unwrap() as usize);
        let at = |i: f64| &positions[3 * i as usize..3 * i as usize + 3];
        let mut drawn: Vec<[Vec<f64>; 2]> = ends
            .chunks(2)
            .map(|e| {
                let mut pair = [at(e[0]).to_vec(), at(e[1]).to_vec()];
                pair.sort_by(|a, b| a.partial_cmp(b).unwrap());
                pair
            })
            .collect();
        drawn.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let mut sharp: Vec<[Vec<f64>; 2]> = mesh
            .sharp_edges
            .iter()
            .map(|&(a, b)| {
                let p = |v: u32| mesh.positions[v as usize].to_array().to_vec();
                let mut pair = [p(a), p(b)];
                pair.sort_by(|a, b| a.partial_cmp(b).unwrap());
                pair
            })
            .collect();
        sharp.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_eq!(drawn, sharp);

        // Body 1: the quad and the triangle, two faces; no sharp edges, no edge primitive.
        let prims = meshes[1]["primitives"].as_array().unwrap();
        assert_eq!(prims.len(), 1);
        assert_eq!(
            prims[0]["extensions"]["EXT_mesh_features"]["featureIds"][0]["featureCount"],
            2
        );
        let ids = components(&doc, &bin, acc(&prims[0], "_FEATURE_ID_0"));
        assert_eq!(ids, [2.0, 0.0, 2.0, 0.0, 2.0, 2.0, 0.0]);

        // The property table: one row per group, empty ones too.
        let meta = &doc["extensions"]["EXT_structural_metadata"];
        assert_eq!(
            meta["schema"]["classes"]["cad_face"]["properties"]["name"]["type"],
            "STRING"
        );
        let table = &meta["propertyTables"][0];
        assert_eq!(table["count"], 4);
        let view = |key: &str| {
            let v =
                &doc["bufferViews"][table["properties"]["name"][key].as_u64().unwrap() as usize];
            let start = v["byteOffset"].as_u64().unwrap() as usize;
            &bin[start..start + v["byteLength"].as_u64().unwrap() as usize]
        };
        let (values, offsets) = (view("values"), view("stringOffsets"));
        let offsets: Vec<usize> = offsets
            .chunks(4)
            .map(|b| u32::from_le_bytes(b.try_into().unwrap()) as usize)
            .collect();
        let names: Vec<&str> = offsets
            .windows(2)
            .map(|w| std::str::from_utf8(&values[w[0]..w[1]]).unwrap())
            .collect();
        assert_eq!(names, ["lid", "base", "plate", "unused"]);
    }

    /// Reading the file back merges the vertices split by face: the same mesh (positions
    /// rounded to f32), faces, groups (empty ones aside) and sharp edges.
    #[test]
    fn the_reader_gets_faces_groups_and_sharp_edges_back() {
        let mesh = two_bodies();
        for format in [MeshFormat::Glb, MeshFormat::Gltf] {
            let mut bytes = Vec::new();
            write_mesh_to_with(&mut bytes, format, &mesh, None, &WriteOptions::default()).unwrap();
            let (back, report) = read_mesh_bytes(&bytes, format, Path::new("t.glb")).unwrap();
            assert!(report.unchanged(), "{report}");
            assert_eq!(back.positions, mesh.positions);
            let names: Vec<_> = back.groups.iter().map(|g| g.name.as_str()).collect();
            assert_eq!(names, ["lid", "base", "plate"]);
            assert_eq!(back.face_groups, [0, 0, 1, 1, 2, 2, 0]);
            assert_eq!(back.face_count(), 7);
            assert_eq!(back.sharp_edges, mesh.sharp_edges);
        }
    }

    #[test]
    fn quantized_positions_and_normals() {
        let mut mesh = two_bodies();
        for p in &mut mesh.positions {
            *p = *p * 1000.0 + DVec3::new(-3.0e4, 2.5e3, 17.0);
        }
        let normals: Vec<DVec3> = mesh
            .positions
            .iter()
            .enumerate()
            .map(|(i, _)| DVec3::new(1.0, i as f64, -2.0))
            .collect();
        let bytes = glb(&mesh, Some(&normals), true);
        let (doc, bin) = split_glb(&bytes);
        assert_eq!(doc["extensionsRequired"], json!(["KHR_mesh_quantization"]));
        let tri = &doc["meshes"][0]["primitives"][0];
        let pos = &doc["accessors"][tri["attributes"]["POSITION"].as_u64().unwrap() as usize];
        assert_eq!(
            (pos["componentType"].as_u64(), pos["normalized"].as_bool()),
            (Some(5122), Some(true))
        );
        let n = tri["attributes"]["NORMAL"].as_u64().unwrap() as usize;
        assert_eq!(doc["accessors"][n]["componentType"], 5120);
        for (i, c) in components(&doc, &bin, n).chunks(3).enumerate() {
            let written = DVec3::new(c[0], c[1], c[2]) / 127.0;
            assert!((written.length() - 1.0).abs() < 0.02, "{written}");
            let v =
                (0..mesh.vertex_count()).find(|&v| normals[v].normalize().distance(written) < 0.02);
            assert!(v.is_some(), "normal {i}");
        }
        let step = doc["nodes"][0]["scale"][0].as_f64().unwrap() / 32767.0;
        let (back, _) = read_mesh_bytes(&bytes, MeshFormat::Glb, Path::new("q.glb")).unwrap();
        assert_eq!(back.vertex_count(), mesh.vertex_count());
        for (a, b) in back.positions.iter().zip(&mesh.positions) {
            assert!(
                (*a - *b).abs().max_element() <= 0.5 * step * 1.0001,
                "{a} {b}"
            );
        }
        let names: Vec<_> = back.groups.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names, ["lid", "base", "plate"]);
        assert_eq!(back.sharp_edges, mesh.sharp_edges);
    }

    /// A mesh without faces is a valid file without scenes, which the reader refuses
    /// as it refuses any file without faces.
    #[test]
    fn a_mesh_without_faces_is_a_file_without_scenes() {
        let mut mesh = ControlMesh::new();
        mesh.push_vertex(DVec3::ONE);
        for quantize in [false, true] {
            let bytes = glb(&mesh, None, quantize);
            let doc = gltf::Gltf::from_slice(&bytes).unwrap();
            assert_eq!((doc.meshes().len(), doc.buffers().len()), (0, 0));
            let e = read_mesh_bytes(&bytes, MeshFormat::Glb, Path::new("e.glb")).unwrap_err();
            assert!(e.to_string().contains("no faces"), "{e}");
        }
    }

    /// Past 65535 groups the feature ids are floats (exact integers to 2^24).
    #[test]
    fn many_groups_take_float_feature_ids() {
        let n = 70_000u32;
        let mut mesh = ControlMesh::new();
        for i in 0..n + 2 {
            mesh.push_vertex(DVec3::new(f64::from(i / 2), f64::from(i % 2), 0.0));
        }
        for i in 0..n {
            let g = mesh.push_group(format!("g{i}"), PatchKind::default());
            let t = if i % 2 == 0 {
                [i, i + 1, i + 2]
            } else {
                [i + 1, i, i + 2]
            };
            mesh.push_face(&t, g);
        }
        let bytes = glb(&mesh, None, false);
        let (doc, _) = split_glb(&bytes);
        let tri = &doc["meshes"][0]["primitives"][0];
        let ids = tri["attributes"]["_FEATURE_ID_0"].as_u64().unwrap() as usize;
        assert_eq!(doc["accessors"][ids]["componentType"], FLOAT);
        assert_eq!(
            doc["accessors"][tri["indices"].as_u64().unwrap() as usize]["componentType"],
            UNSIGNED_INT
        );
        let (back, _) = read_mesh_bytes(&bytes, MeshFormat::Glb, Path::new("t.glb")).unwrap();
        assert_eq!(back.groups.len(), n as usize);
        assert_eq!(back.groups[69_999].name, "g69999");
        assert!(back
            .face_groups
            .iter()
            .enumerate()
            .all(|(f, &g)| g == f as u32));
    }
}
