//! glTF 2.0 reader and writer (`.glb` and `.gltf`).
//!
//! # Reading
//! The `gltf` crate (without its `import` feature) parses and validates the JSON (its
//! checks, except that `KHR_mesh_quantization` may be required); buffers are resolved here:
//! the GLB `BIN` chunk, external files in the `.gltf` file's folder or below
//! it (percent-encoded URIs are decoded; absolute paths, schemes, `..` and links out of the
//! folder are refused, and [`ReadOptions::external_files`] refuses external files
//! altogether), and base64 `data:` URIs. Accessor data is read here too, with
//! every offset, stride and count checked against the buffer before anything is allocated
//! for it, so malformed files give errors rather than panics.
//!
//! The default scene (else the first scene) is traversed and node transforms are applied in
//! f64; a file without scenes reads every mesh untransformed. Groups:
//! - A triangle primitive with feature ids (`EXT_mesh_features`: the first of its
//!   `featureIds` that names an attribute, `_FEATURE_ID_<n>`) gives **one group per feature
//!   id**; a triangle takes the id of its first vertex. With a property table
//!   (`EXT_structural_metadata`) ids index its rows: one group per row used, named by the
//!   table's `name` column when its class declares one as `STRING` (else `feature_<id>`),
//!   and shared by every primitive that uses the table. Ids outside the table, or equal to
//!   `nullFeatureId`, belong to the primitive's own group (below). Vertices of such a
//!   primitive with identical coordinates are one vertex: writers split vertices where the
//!   feature id changes, since a vertex has one id.
//! - **Any other triangle primitive of each mesh instance becomes one group**, named after
//!   its mesh (`mesh_<i>` if unnamed), with `#<k>` appended when the mesh has several
//!   primitives and `@node<n>` when the mesh is instanced more than once.
//!
//! Groups come in order of first appearance of their property table or primitive, and by
//! feature id within one (a file from this writer reads back in group order). Primitives
//! that share a `POSITION` accessor under the same transform share their vertices;
//! everything else is welded like any other input. Triangle lists, strips and fans are read.
//! **Line primitives** (lists, strips, loops) that share their `POSITION` accessor with a
//! triangle primitive under the same transform are **sharp edges** of that surface; other
//! line primitives and points are skipped with a note. Positions and normals may be
//! quantised (`KHR_mesh_quantization`: 8- and 16-bit integers, normalized or not); Draco
//! and meshopt compression and sparse accessors are not supported.
//!
//! # Writing
//! `.glb` (binary container), or `.gltf` with the buffer embedded as a base64 `data:` URI
//! ([`write_glb`], [`write_gltf`]). A CAD viewer draws one triangle primitive per **body**
//! (a connected component of the mesh through shared vertices; solids of an assembly that
//! touch keep separate vertices and stay separate bodies) and picks CAD faces by feature id:
//! - One node per body (`body_<i>`, under a root node `model`), each with one mesh of two
//!   primitives: triangles (fan-triangulated faces; `POSITION`, `NORMAL` when normals are
//!   given, `_FEATURE_ID_0` = group index, declared by `EXT_mesh_features` with
//!   `featureCount`, `attribute: 0` and `propertyTable: 0`; material `surface`) and, when
//!   the body has sharp edges, a `LINES` primitive over the same `POSITION` accessor
//!   (material `edges`). Corners are not stored.
//! - A vertex used by faces of several groups is written once per group (a vertex has one
//!   feature id), in the mesh's vertex order.
//! - `EXT_structural_metadata` holds the schema (class `cad_face` with a `STRING` property
//!   `name`) and a property table `cad_faces` with one row per group (empty ones too), so
//!   feature id `i` names group `i`.
//! - Indices are 16-bit where a body has fewer than 65535 vertices, else 32-bit; feature ids
//!   16-bit up to 65535 groups, else float.
//! - Positions are f32, or with [`WriteOptions::quantize`] normalized 16-bit integers under
//!   the root node's translation and uniform scale, normals then normalized 8-bit integers
//!   (`KHR_mesh_quantization`, required). Normals are written unit length (`+Z` where a
//!   normal has no direction).

use std::borrow::Cow;
use std::collections::HashMap;
use std::path::{Component, Path};
use std::rc::Rc;

use glam::{DMat4, DVec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use serde_json::Value;

use super::repair::RawMesh;
use super::ReadOptions;
#[cfg(all(doc, feature = "internals"))]
use super::WriteOptions;
use crate::error::{Error, Result};

#[cfg(feature = "internals")]
mod write;
#[cfg(feature = "internals")]
pub use write::{write_glb, write_gltf};

/// Deepest node hierarchy followed (deeper usually means a cycle in a malformed file).
const MAX_NODE_DEPTH: usize = 64;
/// Most mesh instances read (guards against node graphs that share children exponentially).
const MAX_INSTANCES: usize = 100_000;
/// Feature id of a vertex with no feature (`nullFeatureId`, negative or fractional ids).
const NO_FEATURE: u64 = u64::MAX;

/// Parses a `.glb` or `.gltf` file with the default [`ReadOptions`]. `path` names the file
/// in errors and its folder holds the external buffer files.
#[cfg(feature = "internals")]
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawMesh> {
    parse_with(bytes, path, &ReadOptions::default())
}

/// [`parse`] with `opts` (whether external buffer files may be read at all).
pub fn parse_with(bytes: &[u8], path: &Path, opts: &ReadOptions) -> Result<RawMesh> {
    let input_err = |detail: String| Error::input(path, detail);
    // The gltf crate subtracts the header's size from its total length unchecked (an
    // overflow panic in builds with overflow checks).
    if let Some(len) = bytes.strip_prefix(b"glTF").and_then(|b| b.get(4..8)) {
        let total = u32::from_le_bytes([len[0], len[1], len[2], len[3]]);
        if total < 12 {
            return Err(input_err(format!(
                "invalid glTF: the GLB header's total length {total} is less than the header's \
                 12 bytes"
            )));
        }
    }
    let gltf = gltf::Gltf::from_slice_without_validation(bytes)
        .map_err(|e| input_err(format!("invalid glTF: {e}")))?;
    for ext in gltf.extensions_required() {
        if matches!(
            ext,
            "KHR_draco_mesh_compression" | "EXT_meshopt_compression"
        ) {
            return Err(input_err(format!(
                "glTF requires extension `{ext}`, which scode does not read"
            )));
        }
    }
    validate(&gltf, path)?;

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
    let mut reader = Reader {
        doc: &gltf,
        buffers: &buffers,
        path,
        raw: RawMesh::new(),
        vertices: HashMap::new(),
        groups: Groups::default(),
        tables: HashMap::new(),
        instance_count: vec![0; gltf.meshes().len()],
        primitives: 0,
        skipped_primitives: 0,
        transformed: false,
    };
    for (mesh, _, _) in &instances {
        reader.instance_count[mesh.index()] += 1;
    }
    for (mesh, transform, node) in &instances {
        reader.read_instance(mesh, transform, *node)?;
    }
    Ok(reader.finish())
}

/// The `gltf` crate's validation of the document, except that it refuses every required
/// extension it does not implement itself, and `KHR_mesh_quantization` is read here.
fn validate(gltf: &gltf::Gltf, path: &Path) -> Result<()> {
    use gltf::json::validation::{Checked, Error as Invalid, Validate};
    let root = gltf.as_json();
    // The crate's validation reads the POSITION accessor without checking its index first.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (k, prim) in mesh.primitives.iter().enumerate() {
            let position = prim
                .attributes
                .get(&Checked::Valid(gltf::Semantic::Positions));
            if let Some(i) = position.filter(|i| i.value() >= root.accessors.len()) {
                return Err(Error::input(
                    path,
                    format!(
                        "invalid glTF: mesh {m} primitive {k}: POSITION accessor {} does not exist",
                        i.value()
                    ),
                ));
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(root, gltf::json::Path::new, &mut |at, e| {
        let at = at();
        let read_here = matches!(e, Invalid::Unsupported)
            && at.as_str().starts_with("extensionsRequired")
            && at.as_str().ends_with("\"KHR_mesh_quantization\"");
        if !read_here {
            errors.push(format!("{at}: {e}"));
        }
    });
    if errors.is_empty() {
        return Ok(());
    }
    let more = if errors.len() > 5 {
        format!(" (and {} more)", errors.len() - 5)
    } else {
        String::new()
    };
    errors.truncate(5);
    Err(Error::input(
        path,
        format!("invalid glTF: {}{more}", errors.join("; ")),
    ))
}

/// Where a group comes from, for its order: a property table (groups by feature id), or
/// one primitive (its own group, and its feature ids when it has no property table).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Family {
    Table(usize),
    Primitive(usize),
}

/// The groups met so far, numbered in order of appearance until [`Groups::order`].
#[derive(Default)]
struct Groups {
    index: HashMap<(Family, u64), u32>,
    keys: Vec<(Family, u64)>,
    names: Vec<String>,
    family_rank: HashMap<Family, usize>,
}

impl Groups {
    /// The group of `key`, created with the name `name()` when new.
    fn get(&mut self, key: (Family, u64), name: impl FnOnce() -> String) -> u32 {
        if let Some(&g) = self.index.get(&key) {
            return g;
        }
        let rank = self.family_rank.len();
        self.family_rank.entry(key.0).or_insert(rank);
        let g = self.keys.len() as u32;
        self.index.insert(key, g);
        self.keys.push(key);
        self.names.push(name());
        g
    }

    /// The final group of each provisional one, and the names in final order: families in
    /// order of appearance, groups of a family by id.
    fn order(self) -> (Vec<u32>, Vec<String>) {
        let mut order: Vec<usize> = (0..self.keys.len()).collect();
        order.sort_by_key(|&g| (self.family_rank[&self.keys[g].0], self.keys[g].1));
        let mut new_of_old = vec![0u32; order.len()];
        let mut names = vec![String::new(); order.len()];
        let mut old_names = self.names;
        for (new, &old) in order.iter().enumerate() {
            new_of_old[old] = new as u32;
            names[new] = std::mem::take(&mut old_names[old]);
        }
        (new_of_old, names)
    }
}

/// A primitive's feature ids: one per vertex ([`NO_FEATURE`] for none), and the property
/// table they index.
struct FeatureIds {
    ids: Vec<u64>,
    table: Option<usize>,
}

/// What a property table says about its rows.
struct Table {
    count: u64,
    /// The `name` column, when the table has one.
    names: Option<Vec<String>>,
}

/// The reader's state while it walks the mesh instances.
struct Reader<'a> {
    doc: &'a gltf::Document,
    buffers: &'a [Cow<'a, [u8]>],
    path: &'a Path,
    raw: RawMesh,
    /// (POSITION accessor, transform bits) -> the vertex in `raw.positions` of each of its
    /// elements: primitives sharing both share vertices. Lookup only; vertex order follows
    /// the file. Shared, not copied: files with one primitive per face (hundreds) over one
    /// accessor of a million vertices are common.
    vertices: HashMap<(usize, [u64; 16]), Rc<[u32]>>,
    groups: Groups,
    /// Property tables, each read once when a primitive first names it.
    tables: HashMap<usize, Table>,
    instance_count: Vec<usize>,
    /// Triangle primitives read so far (each is a [`Family`] of its own).
    primitives: usize,
    skipped_primitives: usize,
    transformed: bool,
}

impl Reader<'_> {
    fn err(&self, detail: String) -> Error {
        Error::input(self.path, detail)
    }

    /// Reads the primitives of one mesh instance: triangles first, so that line primitives
    /// listed before them still find the vertices they run along.
    fn read_instance(
        &mut self,
        mesh: &gltf::Mesh,
        transform: &DMat4,
        node: Option<usize>,
    ) -> Result<()> {
        let n_prims = mesh.primitives().len();
        let mesh_name = mesh
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| format!("mesh_{}", mesh.index()));
        for (k, prim) in mesh.primitives().enumerate() {
            if !matches!(
                prim.mode(),
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                continue;
            }
            let mut name = mesh_name.clone();
            if n_prims > 1 {
                name = format!("{name}#{k}");
            }
            if self.instance_count[mesh.index()] > 1 {
                if let Some(n) = node {
                    name = format!("{name}@node{n}");
                }
            }
            let what = format!("mesh {} primitive {k}", mesh.index());
            self.read_triangles(&prim, transform, &name, &what)?;
        }
        for (k, prim) in mesh.primitives().enumerate() {
            match prim.mode() {
                Mode::Lines | Mode::LineStrip | Mode::LineLoop => {
                    let what = format!("mesh {} primitive {k}", mesh.index());
                    self.read_lines(&prim, transform, &what)?;
                }
                Mode::Points => self.skipped_primitives += 1,
                _ => {}
            }
        }
        Ok(())
    }

    /// The vertices of `positions` under `transform` in `raw.positions`, read on first use.
    /// `merge`: vertices with identical coordinates become one (see the module docs).
    fn vertices_of(
        &mut self,
        positions: &gltf::Accessor,
        transform: &DMat4,
        merge: bool,
        what: &str,
    ) -> Result<Rc<[u32]>> {
        let key = (
            positions.index(),
            transform.to_cols_array().map(f64::to_bits),
        );
        if let Some(v) = self.vertices.get(&key) {
            return Ok(Rc::clone(v));
        }
        let points = read_vec3(positions, self.buffers, what, self.path)?;
        if *transform != DMat4::IDENTITY {
            self.transformed = true;
        }
        let mut world = Vec::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            let w = transform.transform_point3(*p);
            if !w.is_finite() {
                return Err(self.err(format!(
                    "{what}: vertex {i} has a non-finite coordinate {:?}",
                    p.to_array()
                )));
            }
            world.push(w);
        }
        let base = self.raw.positions.len();
        if base + world.len() > u32::MAX as usize {
            return Err(self.err("too many vertices".into()));
        }
        let map: Rc<[u32]> = if merge {
            let welded = super::weld::weld(&world);
            self.raw.positions.extend_from_slice(&welded.positions);
            welded.remap.iter().map(|&i| base as u32 + i).collect()
        } else {
            self.raw.positions.extend_from_slice(&world);
            (base as u32..(base + world.len()) as u32).collect()
        };
        self.vertices.insert(key, Rc::clone(&map));
        Ok(map)
    }

    /// The indices of `prim` (or `0..count` without indices), each checked against `count`.
    fn indices(&self, prim: &gltf::Primitive, count: usize, what: &str) -> Result<Vec<u32>> {
        let indices: Vec<u32> = match prim.indices() {
            Some(acc) => read_indices(&acc, self.buffers, what, self.path)?,
            None => (0..count as u32).collect(),
        };
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= count) {
            return Err(self.err(format!(
                "{what}: index {bad} out of range ({count} vertices)"
            )));
        }
        Ok(indices)
    }

    fn read_triangles(
        &mut self,
        prim: &gltf::Primitive,
        transform: &DMat4,
        name: &str,
        what: &str,
    ) -> Result<()> {
        let positions = prim
            .get(&gltf::Semantic::Positions)
            .ok_or_else(|| self.err(format!("{what} has no POSITION attribute")))?;
        let features = self.feature_ids(prim, what)?;
        if let Some(f) = &features {
            if f.ids.len() != positions.count() {
                return Err(self.err(format!(
                    "{what}: {} feature ids for {} vertices",
                    f.ids.len(),
                    positions.count()
                )));
            }
        }
        let vertices = self.vertices_of(&positions, transform, features.is_some(), what)?;
        let indices = self.indices(prim, vertices.len(), what)?;
        let family = Family::Primitive(self.primitives);
        self.primitives += 1;
        let mode = prim.mode();
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
            let triangle = c.map(|i| vertices[indices[i] as usize]);
            let feature = match &features {
                Some(f) => self.feature_group(f, indices[c[0]] as usize, family, name)?,
                None => None,
            };
            // The primitive's own group exists only once a triangle is in it.
            let group = match feature {
                Some(g) => g,
                None => self.groups.get((family, NO_FEATURE), || name.to_string()),
            };
            self.raw.push_face(&triangle, group);
            t += 1;
        }
        if mode == Mode::Triangles && n % 3 != 0 {
            self.raw.notes.push(format!(
                "{what}: {} trailing indices (not a whole triangle) ignored",
                n % 3
            ));
        }
        Ok(())
    }

    /// The group of vertex `v` of a primitive with feature ids `f`, or `None` when the
    /// vertex has no feature.
    fn feature_group(
        &mut self,
        f: &FeatureIds,
        v: usize,
        family: Family,
        name: &str,
    ) -> Result<Option<u32>> {
        let id = f.ids[v];
        if id == NO_FEATURE {
            return Ok(None);
        }
        let Some(t) = f.table else {
            let group = self
                .groups
                .get((family, id), || format!("{name}#feature{id}"));
            return Ok(Some(group));
        };
        if !self.tables.contains_key(&t) {
            let table = self.read_table(t)?;
            self.tables.insert(t, table);
        }
        let table = &self.tables[&t];
        if id >= table.count {
            return Ok(None);
        }
        let row = table.names.as_ref().map(|n| n[id as usize].clone());
        Ok(Some(self.groups.get((Family::Table(t), id), || {
            row.unwrap_or_else(|| format!("feature_{id}"))
        })))
    }

    /// Sharp edges from a line primitive over the vertices of a triangle primitive.
    fn read_lines(&mut self, prim: &gltf::Primitive, transform: &DMat4, what: &str) -> Result<()> {
        let Some(positions) = prim.get(&gltf::Semantic::Positions) else {
            self.skipped_primitives += 1;
            return Ok(());
        };
        let key = (
            positions.index(),
            transform.to_cols_array().map(f64::to_bits),
        );
        let Some(vertices) = self.vertices.get(&key).map(Rc::clone) else {
            self.skipped_primitives += 1;
            return Ok(());
        };
        let indices = self.indices(prim, vertices.len(), what)?;
        let n = indices.len();
        let pairs: Vec<(usize, usize)> = match prim.mode() {
            Mode::Lines => (0..n / 2).map(|i| (2 * i, 2 * i + 1)).collect(),
            Mode::LineStrip => (1..n).map(|i| (i - 1, i)).collect(),
            _ => (0..n)
                .filter(|_| n >= 2)
                .map(|i| (i, (i + 1) % n))
                .collect(),
        };
        for (i, j) in pairs {
            let (a, b) = (vertices[indices[i] as usize], vertices[indices[j] as usize]);
            if a != b {
                self.raw.sharp_edges.push([a, b]);
            }
        }
        Ok(())
    }

    /// The feature ids of `prim` from its `EXT_mesh_features` extension, if it names a
    /// feature id attribute.
    fn feature_ids(&self, prim: &gltf::Primitive, what: &str) -> Result<Option<FeatureIds>> {
        let Some(ext) = prim.extension_value("EXT_mesh_features") else {
            return Ok(None);
        };
        let bad = |d: &str| self.err(format!("{what}: EXT_mesh_features: {d}"));
        let sets = ext
            .get("featureIds")
            .and_then(Value::as_array)
            .ok_or_else(|| bad("no featureIds array"))?;
        let Some(set) = sets.iter().find(|s| s.get("attribute").is_some()) else {
            return Ok(None);
        };
        let index = |key: &str| -> Result<Option<u64>> {
            match set.get(key) {
                None => Ok(None),
                Some(v) => v
                    .as_u64()
                    .map(Some)
                    .ok_or_else(|| bad(&format!("`{key}` is not a non-negative integer"))),
            }
        };
        let attribute = index("attribute")?.unwrap_or(0);
        let table = index("propertyTable")?
            .map(|t| usize::try_from(t).map_err(|_| bad("propertyTable out of range")))
            .transpose()?;
        let null = index("nullFeatureId")?;
        let semantic = gltf::Semantic::Extras(format!("FEATURE_ID_{attribute}"));
        let accessor = prim
            .get(&semantic)
            .ok_or_else(|| bad(&format!("no attribute _FEATURE_ID_{attribute}")))?;
        let mut ids = read_ids(&accessor, self.buffers, what, self.path)?;
        if let Some(null) = null {
            for id in ids.iter_mut().filter(|id| **id == null) {
                *id = NO_FEATURE;
            }
        }
        Ok(Some(FeatureIds { ids, table }))
    }

    /// The bytes of buffer view `index`, checked against its buffer.
    fn view_bytes(&self, index: u64, what: &str) -> Result<&[u8]> {
        let view = usize::try_from(index)
            .ok()
            .and_then(|i| self.doc.views().nth(i))
            .ok_or_else(|| self.err(format!("{what}: bufferView {index} does not exist")))?;
        let buffer = self
            .buffers
            .get(view.buffer().index())
            .ok_or_else(|| self.err(format!("{what}: buffer missing")))?;
        let end = view
            .offset()
            .checked_add(view.length())
            .filter(|&e| e <= buffer.len())
            .ok_or_else(|| self.err(format!("{what}: bufferView {index} exceeds its buffer")))?;
        Ok(&buffer[view.offset()..end])
    }

    /// Property table `t` of `EXT_structural_metadata`: its row count, and its `name` column
    /// when the table's class declares `name` a `STRING`.
    fn read_table(&self, t: usize) -> Result<Table> {
        let what = format!("EXT_structural_metadata property table {t}");
        let bad = |d: &str| self.err(format!("{what}: {d}"));
        let root = self
            .doc
            .extension_value("EXT_structural_metadata")
            .ok_or_else(|| bad("named by feature ids, but the file has no such extension"))?;
        let table = root
            .get("propertyTables")
            .and_then(Value::as_array)
            .and_then(|a| a.get(t))
            .ok_or_else(|| bad("does not exist"))?;
        let count = table
            .get("count")
            .and_then(Value::as_u64)
            .ok_or_else(|| bad("`count` is not a non-negative integer"))?;
        let declared = table
            .get("class")
            .and_then(Value::as_str)
            .and_then(|c| root.get("schema")?.get("classes")?.get(c))
            .and_then(|c| c.get("properties")?.get("name")?.get("type")?.as_str());
        let column = table.get("properties").and_then(|p| p.get("name"));
        let (Some("STRING"), Some(column)) = (declared, column) else {
            return Ok(Table { count, names: None });
        };
        let view = |key: &str| -> Result<&[u8]> {
            let i = column
                .get(key)
                .and_then(Value::as_u64)
                .ok_or_else(|| bad(&format!("`name` has no `{key}` buffer view")))?;
            self.view_bytes(i, &what)
        };
        let values = view("values")?;
        let offsets = view("stringOffsets")?;
        let size = match column.get("stringOffsetType").and_then(Value::as_str) {
            Some("UINT8") => 1,
            Some("UINT16") => 2,
            None | Some("UINT32") => 4,
            Some("UINT64") => 8,
            Some(other) => return Err(bad(&format!("unknown stringOffsetType `{other}`"))),
        };
        // count + 1 offsets, checked against the bytes before anything is allocated.
        let needed = count
            .checked_add(1)
            .and_then(|n| n.checked_mul(size as u64))
            .filter(|&n| n <= offsets.len() as u64)
            .ok_or_else(|| {
                bad(&format!(
                    "{count} rows need more string offsets than its {} bytes hold",
                    offsets.len()
                ))
            })?;
        let offset = |i: usize| -> u64 {
            let b = &offsets[i * size..(i + 1) * size];
            let mut le = [0u8; 8];
            le[..size].copy_from_slice(b);
            u64::from_le_bytes(le)
        };
        let mut names = Vec::with_capacity(needed as usize / size - 1);
        for row in 0..count as usize {
            let (a, b) = (offset(row), offset(row + 1));
            if a > b || b > values.len() as u64 {
                return Err(bad(&format!(
                    "row {row}: string offsets {a}..{b} outside its {} bytes",
                    values.len()
                )));
            }
            let text = std::str::from_utf8(&values[a as usize..b as usize])
                .map_err(|_| bad(&format!("row {row}: name is not UTF-8")))?;
            names.push(text.to_string());
        }
        Ok(Table {
            count,
            names: Some(names),
        })
    }

    fn finish(mut self) -> RawMesh {
        let (new_of_old, names) = self.groups.order();
        for g in &mut self.raw.face_groups {
            *g = new_of_old[*g as usize];
        }
        self.raw.group_names = names;
        self.raw.input_faces = self.raw.face_count();
        if self.skipped_primitives > 0 {
            self.raw.notes.push(format!(
                "{} point primitives and line primitives not over triangles skipped",
                self.skipped_primitives
            ));
        }
        if self.transformed {
            self.raw
                .notes
                .push("node transforms applied to vertex positions".to_string());
        }
        self.raw
    }
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

/// The components of `accessor`'s elements as f64, `dims` per element: floats as stored,
/// integers as stored or, when normalized, mapped to [0, 1] / [-1, 1] as glTF defines.
fn read_components(
    accessor: &gltf::Accessor,
    buffers: &[Cow<[u8]>],
    dims: usize,
    what: &str,
    path: &Path,
) -> Result<Vec<f64>> {
    let normalized = accessor.normalized();
    let (size, scale): (usize, f64) = match accessor.data_type() {
        DataType::F32 if !normalized => (4, 1.0),
        DataType::I8 => (1, 127.0),
        DataType::U8 => (1, 255.0),
        DataType::I16 => (2, 32767.0),
        DataType::U16 => (2, 65535.0),
        other => {
            return Err(Error::input(
                path,
                format!(
                    "{what}: accessor {} has component type {other:?}{}, which this attribute \
                     cannot have",
                    accessor.index(),
                    if normalized { " (normalized)" } else { "" }
                ),
            ))
        }
    };
    let data_type = accessor.data_type();
    let (bytes, stride) = accessor_bytes(accessor, buffers, size * dims, what, path)?;
    let mut out = Vec::with_capacity(accessor.count() * dims);
    for i in 0..accessor.count() {
        for c in 0..dims {
            let o = i * stride + c * size;
            let b = &bytes[o..o + size];
            let v = match data_type {
                DataType::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                DataType::I8 => f64::from(b[0] as i8),
                DataType::U8 => f64::from(b[0]),
                DataType::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
                _ => f64::from(u16::from_le_bytes([b[0], b[1]])),
            };
            out.push(if normalized && data_type != DataType::F32 {
                (v / scale).max(-1.0)
            } else {
                v
            });
        }
    }
    Ok(out)
}

/// A `POSITION` accessor: float `VEC3`, or 8/16-bit integers (`KHR_mesh_quantization`).
fn read_vec3(
    accessor: &gltf::Accessor,
    buffers: &[Cow<[u8]>],
    what: &str,
    path: &Path,
) -> Result<Vec<DVec3>> {
    if accessor.dimensions() != Dimensions::Vec3 {
        return Err(Error::input(path, format!("{what}: POSITION must be VEC3")));
    }
    let c = read_components(accessor, buffers, 3, what, path)?;
    Ok(c.chunks_exact(3)
        .map(|p| DVec3::new(p[0], p[1], p[2]))
        .collect())
}

/// A feature id accessor (`SCALAR`, not normalized, any component type): one id per vertex,
/// [`NO_FEATURE`] where a value is negative or not a whole number.
fn read_ids(
    accessor: &gltf::Accessor,
    buffers: &[Cow<[u8]>],
    what: &str,
    path: &Path,
) -> Result<Vec<u64>> {
    if accessor.dimensions() != Dimensions::Scalar || accessor.normalized() {
        return Err(Error::input(
            path,
            format!("{what}: feature ids must be SCALAR and not normalized"),
        ));
    }
    if accessor.data_type() == DataType::U32 {
        let ids = read_indices(accessor, buffers, what, path)?;
        return Ok(ids.into_iter().map(u64::from).collect());
    }
    let values = read_components(accessor, buffers, 1, what, path)?;
    Ok(values
        .into_iter()
        .map(|v| {
            if v >= 0.0 && v.fract() == 0.0 && v < u32::MAX as f64 {
                v as u64
            } else {
                NO_FEATURE
            }
        })
        .collect())
}

/// An index accessor (or a 32-bit feature id accessor): unsigned 8/16/32-bit `SCALAR`s.
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

/// Standard base64 with `=` padding.
#[cfg(feature = "internals")]
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
    use super::write::tests::{join_glb, split_glb, two_bodies};
    use super::*;
    use crate::io::{read_mesh, read_mesh_bytes, write_mesh_to, MeshFormat, ReadReport};
    use crate::mesh::ControlMesh;
    use crate::mesh::PatchKind;
    use serde_json::json;

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
            assert_eq!(doc.meshes().len(), 1); // one body
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
        // A total length below the header's size (found by fuzzing: the gltf crate's
        // subtraction overflowed).
        let short = read(b"glTF\x02\0\0\0\x04\0\0\0\x10\0\0\0JSON{}", MeshFormat::Glb);
        assert!(
            matches!(&short, Err(Error::Input { detail, .. }) if detail.contains("total length 4")),
            "{short:?}"
        );
        assert!(read(b"{not json", MeshFormat::Gltf).is_err());
        let (doc, mut bin) = split_glb(&bytes);
        let indices = &doc["accessors"][doc["meshes"][0]["primitives"][0]["indices"]
            .as_u64()
            .unwrap() as usize];
        let at = doc["bufferViews"][indices["bufferView"].as_u64().unwrap() as usize]["byteOffset"]
            .as_u64()
            .unwrap() as usize;
        bin[at..at + 2].copy_from_slice(&99u16.to_le_bytes()); // first index
        let msg = read(&join_glb(&doc, &bin), MeshFormat::Glb)
            .unwrap_err()
            .to_string();
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

    /// A hand-made file as another writer might make it: feature ids without a property
    /// table (8-bit, padded to 4 bytes), a `nullFeatureId`, a line primitive listed before
    /// the triangles it runs along, one over other positions, and a point primitive.
    #[test]
    fn feature_ids_without_a_table_lines_and_points() {
        let mut bin = Vec::new();
        for p in [
            [0.0f32, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
            [2.0, 1.0, 0.0],
        ] {
            for c in p {
                bin.extend_from_slice(&c.to_le_bytes());
            }
        }
        for id in [1u8, 1, 1, 2, 9] {
            bin.extend_from_slice(&[id, 0, 0, 0]);
        }
        for i in [0u8, 1, 2, 3, 1, 2, 4, 2, 3] {
            bin.push(i);
        }
        for i in [0u8, 1, 1, 2] {
            bin.push(i);
        }
        let b64 = base64_encode(&bin);
        let json = format!(
            r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["EXT_mesh_features"],
            "meshes":[{{"name":"sheet","primitives":[
              {{"attributes":{{"POSITION":0}},"indices":3,"mode":1}},
              {{"attributes":{{"POSITION":0,"_FEATURE_ID_0":1}},"indices":2,
                "extensions":{{"EXT_mesh_features":{{"featureIds":[
                  {{"featureCount":2,"nullFeatureId":9}},
                  {{"featureCount":3,"attribute":0,"nullFeatureId":9}}]}}}}}},
              {{"attributes":{{"POSITION":4}},"mode":1}},
              {{"attributes":{{"POSITION":0}},"mode":0}}]}}],
            "accessors":[
              {{"bufferView":0,"componentType":5126,"count":5,"type":"VEC3","min":[0,0,0],"max":[2,1,0]}},
              {{"bufferView":1,"componentType":5121,"count":5,"type":"SCALAR"}},
              {{"bufferView":2,"componentType":5121,"count":9,"type":"SCALAR"}},
              {{"bufferView":3,"componentType":5121,"count":4,"type":"SCALAR"}},
              {{"bufferView":0,"componentType":5126,"count":2,"type":"VEC3","min":[0,0,0],"max":[1,0,0]}}],
            "bufferViews":[{{"buffer":0,"byteLength":60}},
              {{"buffer":0,"byteOffset":60,"byteLength":20,"byteStride":4}},
              {{"buffer":0,"byteOffset":80,"byteLength":9}},
              {{"buffer":0,"byteOffset":89,"byteLength":4}}],
            "buffers":[{{"uri":"data:application/octet-stream;base64,{b64}","byteLength":{}}}]}}"#,
            bin.len()
        );
        let (mesh, report) = read(json.as_bytes(), MeshFormat::Gltf).unwrap();
        let names: Vec<_> = mesh.groups.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names, ["sheet#1#feature1", "sheet#1#feature2", "sheet#1"]);
        assert_eq!(mesh.face_groups, [0, 1, 2]);
        assert_eq!(
            mesh.sharp_edges.iter().copied().collect::<Vec<_>>(),
            [(0, 1), (1, 2)]
        );
        assert!(
            report
                .repairs
                .iter()
                .any(|r| r.contains("2 point primitives and line primitives")),
            "{report}"
        );
    }

    /// A change to a file's JSON and BIN chunks.
    type Edit<'a> = dyn Fn(&mut Value, &mut Vec<u8>) + 'a;

    /// Malformed feature ids and property tables are input errors naming what is wrong, and
    /// a table's row count is checked against its bytes before anything is allocated.
    #[test]
    fn malformed_feature_metadata_is_an_input_error() {
        let mut bytes = Vec::new();
        write_mesh_to(&mut bytes, MeshFormat::Glb, &two_bodies(), None).unwrap();
        let (doc, bin) = split_glb(&bytes);
        let table = "/extensions/EXT_structural_metadata/propertyTables/0";
        let ids = "/meshes/0/primitives/0/extensions/EXT_mesh_features/featureIds/0";
        let name_view = |doc: &Value, key: &str| {
            doc.pointer(&format!("{table}/properties/name/{key}"))
                .unwrap()
                .as_u64()
                .unwrap() as usize
        };
        let cases: Vec<(Box<Edit<'_>>, &str)> = vec![
            (
                Box::new(|d, _| {
                    *d.pointer_mut(&format!("{table}/count")).unwrap() = json!(1u64 << 50)
                }),
                "string offsets",
            ),
            (
                Box::new(|d, _| {
                    *d.pointer_mut(&format!("{table}/properties/name/stringOffsets"))
                        .unwrap() = json!(999)
                }),
                "bufferView 999 does not exist",
            ),
            (
                Box::new(|d, _| {
                    *d.pointer_mut(&format!("{table}/properties/name/stringOffsetType"))
                        .unwrap() = json!("UINT128")
                }),
                "stringOffsetType",
            ),
            (
                Box::new(|d, b| {
                    let v = &d["bufferViews"][name_view(d, "values")];
                    b[v["byteOffset"].as_u64().unwrap() as usize] = 0xff;
                }),
                "not UTF-8",
            ),
            (
                Box::new(|d, b| {
                    // The last offset past the end of the names.
                    let v = &d["bufferViews"][name_view(d, "stringOffsets")];
                    let end = (v["byteOffset"].as_u64().unwrap()
                        + v["byteLength"].as_u64().unwrap()) as usize;
                    b[end - 4..end].copy_from_slice(&1000u32.to_le_bytes());
                }),
                "outside",
            ),
            (
                Box::new(|d, _| {
                    *d.pointer_mut(&format!("{ids}/propertyTable")).unwrap() = json!(3)
                }),
                "property table 3: does not exist",
            ),
            (
                Box::new(|d, _| *d.pointer_mut(&format!("{ids}/attribute")).unwrap() = json!(1)),
                "no attribute _FEATURE_ID_1",
            ),
            (
                Box::new(|d, _| *d.pointer_mut(&format!("{ids}/attribute")).unwrap() = json!(-1)),
                "`attribute` is not a non-negative integer",
            ),
            (
                Box::new(|d, _| {
                    let a = d["meshes"][0]["primitives"][0]["attributes"]["_FEATURE_ID_0"]
                        .as_u64()
                        .unwrap() as usize;
                    d["accessors"][a]["count"] = json!(3);
                }),
                "3 feature ids for 8 vertices",
            ),
            (
                Box::new(|d, _| {
                    d["extensionsRequired"] = json!(["KHR_mesh_quantization", "KHR_unknown"]);
                }),
                "KHR_unknown",
            ),
        ];
        for (edit, expected) in cases {
            let (mut d, mut b) = (doc.clone(), bin.clone());
            edit(&mut d, &mut b);
            let e = read(&join_glb(&d, &b), MeshFormat::Glb).unwrap_err();
            assert!(matches!(e, Error::Input { .. }), "{expected}: {e}");
            assert!(e.to_string().contains(expected), "{expected}: {e}");
        }
        // Without a `name` column the groups are named by id.
        let mut d = doc.clone();
        d.pointer_mut("/extensions/EXT_structural_metadata/schema/classes/cad_face/properties")
            .unwrap()
            .as_object_mut()
            .unwrap()
            .clear();
        let (mesh, _) = read(&join_glb(&d, &bin), MeshFormat::Glb).unwrap();
        let names: Vec<_> = mesh.groups.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names, ["feature_0", "feature_1", "feature_2"]);
    }

    /// Corrupted quantized files (byte flips, truncations) give `Ok` or `Err`, never a panic.
    #[test]
    fn corrupted_quantized_files_never_panic() {
        let mut clean = Vec::new();
        let mesh = two_bodies();
        let normals = vec![DVec3::Y; mesh.vertex_count()];
        crate::io::write_mesh_to_with(
            &mut clean,
            MeshFormat::Glb,
            &mesh,
            Some(&normals),
            &crate::io::WriteOptions { quantize: true },
        )
        .unwrap();
        read(&clean, MeshFormat::Glb).unwrap();
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as usize
        };
        for round in 0..600 {
            let mut bytes = clean.clone();
            if round % 3 == 0 {
                bytes.truncate(next() % clean.len());
            } else {
                for _ in 0..1 + round % 4 {
                    let i = next() % bytes.len();
                    bytes[i] = next() as u8;
                }
            }
            if let Ok((m, _)) = read(&bytes, MeshFormat::Glb) {
                m.validate().unwrap();
            }
        }
    }
}
