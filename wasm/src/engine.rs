//! The viewer's engine in plain Rust (no wasm-bindgen types, so it is tested natively):
//! decode a `.scode` file, refine its control mesh once to the finest level the viewer will
//! ever show, then per view choose a level per base triangle from its projected size
//! (S-CODE §4) and extract a crack-free triangle mesh as flat arrays ready for WebGL.
//!
//! Why refine once: with S-CODE's nested numbering the vertices of every coarser level are a
//! prefix of the finest level's vertices and their finest-level positions are already close to
//! the limit surface, so any level map is shown from one position array; a camera move costs
//! only the level choice and [`Refinement::extract_lod`] (gap filling + stitching), never a
//! new refinement.

use std::collections::HashMap;

use glam::{DVec3, Mat4, Vec3, Vec4};
use scode::codec::{decode, Content, Header, Limits};
use scode::mesh::{BoundarySurface, PatchKind};
use scode::subdiv::Refinement;
use scode::{ControlMesh, Error, Result};

const NONE: u32 = u32::MAX;

/// A decoded file: the control mesh, and its refinement once [`Model::refine`] ran.
pub struct Model {
    pub header: Header,
    pub mesh: ControlMesh,
    refined: Option<Refined>,
}

/// Everything precomputed at the finest level; shared by all extractions.
struct Refined {
    r: Refinement,
    /// Finest-level positions (vertex ids of every coarser level are a prefix).
    finest: Vec<DVec3>,
    /// Smooth normals per (finest vertex, group): sharp across CAD-face boundaries.
    normals: GroupNormals,
    /// `(v, -1, 0)` for finest vertex v: passed to `extract_lod` as its per-vertex
    /// "normals", which it carries through (gap-filled vertices keep theirs, stitching
    /// centroids get a normalised mean whose y is never -1), so each output vertex tells
    /// which finest vertex it is. Built on the first non-uniform extraction.
    vertex_tags: Vec<DVec3>,
    /// Level-0 triangles (control vertex ids, valid at every level).
    base_triangles: Vec<[u32; 3]>,
    /// Base edges drawn as lines (sharp or on the boundary) with their one or two faces.
    line_edges: Vec<LineEdge>,
    /// `vertex_count` of levels 0..=n (for the edge-vertex ids of the line polylines).
    level_vertex_counts: Vec<u32>,
    /// Level-0 edges in their stored orientation.
    base_edges: Vec<[u32; 2]>,
}

#[derive(Clone, Copy, Debug)]
struct LineEdge {
    edge: u32,
    faces: [u32; 2],
}

/// Key of a (vertex, group) pair in [`GroupNormals`]' side list.
fn key(v: u32, g: u32) -> u64 {
    (u64::from(v) << 32) | u64::from(g)
}

/// Unit normals at the finest level, one per (vertex, group) pair: each vertex has a primary
/// group (that of its first face) stored densely; the few vertices on CAD-face boundaries have
/// their other groups in a sorted side list. Area-weighted face normals of the finest
/// triangles, so shading is smooth inside a CAD face and sharp across its boundary; a plane
/// patch gets its one area-weighted normal everywhere (its belts of long thin triangles would
/// otherwise show the quantised control points' tiny tilts as streaks).
struct GroupNormals {
    primary_group: Vec<u32>,
    primary: Vec<Vec3>,
    /// `(vertex << 32) | group`, sorted: one u64 sort instead of a tuple sort keeps the
    /// module smaller.
    extra_keys: Vec<u64>,
    extra: Vec<Vec3>,
}

impl GroupNormals {
    fn build(
        nv: usize,
        triangles: &[u32],
        group_of: impl Fn(usize) -> u32,
        pos: &[DVec3],
        is_plane: &[bool],
    ) -> Self {
        let mut primary_group = vec![NONE; nv];
        let mut extra_keys = Vec::new();
        for (f, t) in triangles.chunks_exact(3).enumerate() {
            let g = group_of(f);
            for &v in t {
                let pg = &mut primary_group[v as usize];
                if *pg == NONE {
                    *pg = g;
                } else if *pg != g {
                    extra_keys.push(key(v, g));
                }
            }
        }
        extra_keys.sort_unstable();
        extra_keys.dedup();
        let mut acc = vec![DVec3::ZERO; nv];
        let mut acc_extra = vec![DVec3::ZERO; extra_keys.len()];
        let mut plane = vec![DVec3::ZERO; is_plane.len()];
        for (f, t) in triangles.chunks_exact(3).enumerate() {
            let g = group_of(f);
            let (a, b, c) = (pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]);
            let n = (b - a).cross(c - a);
            if let Some(p) = plane.get_mut(g as usize) {
                *p += n;
            }
            for &v in t {
                if primary_group[v as usize] == g {
                    acc[v as usize] += n;
                } else if let Ok(i) = extra_keys.binary_search(&key(v, g)) {
                    acc_extra[i] += n;
                }
            }
        }
        let unit = |n: DVec3, g: u32| {
            let n = match is_plane.get(g as usize) {
                Some(true) => plane[g as usize],
                _ => n,
            };
            n.normalize_or_zero().as_vec3()
        };
        GroupNormals {
            primary: acc
                .into_iter()
                .zip(&primary_group)
                .map(|(n, &g)| unit(n, g))
                .collect(),
            extra: acc_extra
                .into_iter()
                .zip(&extra_keys)
                .map(|(n, &k)| unit(n, k as u32))
                .collect(),
            primary_group,
            extra_keys,
        }
    }

    fn get(&self, v: u32, g: u32) -> Vec3 {
        if self.primary_group[v as usize] != g {
            if let Ok(i) = self.extra_keys.binary_search(&key(v, g)) {
                return self.extra[i];
            }
        }
        self.primary[v as usize]
    }
}

/// Flat arrays for WebGL: `positions`/`normals` 3 floats per vertex, `indices` 3 per
/// triangle, `groups` one CAD-face id per vertex (vertices on CAD-face boundaries are split
/// per group so normals are sharp there), `lines` 6 floats per segment of the sharp and
/// boundary curves.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshArrays {
    pub positions: Vec<f32>,
    pub normals: Vec<f32>,
    pub indices: Vec<u32>,
    pub groups: Vec<u32>,
    pub lines: Vec<f32>,
}

impl MeshArrays {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
    pub fn vertex_count(&self) -> usize {
        self.positions.len() / 3
    }
}

/// One vertex of an extracted mesh, before it is split per group.
#[derive(Clone, Copy)]
enum Source {
    Finest(u32),
    /// A stitching centroid at this position (normal from its fan).
    Centroid(DVec3),
}

impl Model {
    /// Decodes a file with the default limits.
    pub fn decode(bytes: &[u8]) -> Result<Model> {
        let d = decode(bytes, &Limits::default())?;
        Ok(Model {
            header: d.header,
            mesh: d.mesh,
            refined: None,
        })
    }

    /// Number of level-0 triangles (polygons fan-triangulated).
    pub fn base_triangle_count(&self) -> usize {
        self.mesh.faces().map(|f| f.len().saturating_sub(2)).sum()
    }

    /// Raw-mode files store the final surface: they are shown as stored (level 0 only).
    pub fn is_control_mesh(&self) -> bool {
        matches!(self.header.content, Content::ControlMesh { .. })
    }

    /// The highest level whose uniform refinement has at most `max_triangles` triangles
    /// (at most `MAX_LEVEL`; 0 for raw-mode files).
    pub fn level_for_budget(&self, max_triangles: f64) -> u32 {
        if !self.is_control_mesh() {
            return 0;
        }
        let base = self.base_triangle_count().max(1) as f64;
        let mut level = 0;
        while level < scode::subdiv::MAX_LEVEL
            && base * 4f64.powi(level as i32 + 1) <= max_triangles
        {
            level += 1;
        }
        level
    }

    /// Refinement level built by [`Model::refine`] (None before).
    pub fn max_level(&self) -> Option<u32> {
        self.refined.as_ref().map(|r| r.r.max_level())
    }

    /// Builds the refinement to `max_level` and the finest-level positions and normals.
    pub fn refine(&mut self, max_level: u32) -> Result<()> {
        if max_level > 0 && !self.is_control_mesh() {
            return Err(Error::Parameter(
                "a raw-mode file stores the final surface and is not subdivided".into(),
            ));
        }
        let r = Refinement::new(&self.mesh, max_level)?;
        let finest = r.positions(&self.mesh.positions)?;
        let n = max_level;
        let top = r.level(n);
        let is_plane: Vec<bool> = self
            .mesh
            .groups
            .iter()
            .map(|g| matches!(g.patch, PatchKind::Boundary(BoundarySurface::Plane)))
            .collect();
        let normals = GroupNormals::build(
            top.vertex_count(),
            top.triangles(),
            |f| top.face_group(f),
            &finest,
            &is_plane,
        );
        let l0 = r.level(0);
        let base_triangles: Vec<[u32; 3]> = (0..l0.face_count()).map(|f| l0.triangle(f)).collect();
        let base_edges = l0.edges().to_vec();
        let mut edge_faces = vec![[NONE; 2]; l0.edge_count()];
        for f in 0..l0.face_count() {
            for e in l0.face_edges(f) {
                let s = &mut edge_faces[e as usize];
                if s[0] == NONE {
                    s[0] = f as u32;
                } else {
                    s[1] = f as u32;
                }
            }
        }
        let line_edges = (0..l0.edge_count())
            .filter(|&e| l0.edge_is_sharp(e) || l0.edge_is_boundary(e))
            .map(|e| LineEdge {
                edge: e as u32,
                faces: edge_faces[e],
            })
            .collect();
        let level_vertex_counts = (0..=n).map(|m| r.level(m).vertex_count() as u32).collect();
        self.refined = Some(Refined {
            r,
            finest,
            normals,
            vertex_tags: Vec::new(),
            base_triangles,
            line_edges,
            level_vertex_counts,
            base_edges,
        });
        Ok(())
    }

    fn refined(&self) -> Result<&Refined> {
        self.refined
            .as_ref()
            .ok_or_else(|| Error::Parameter("refine() must run before extraction".into()))
    }

    /// Axis-aligned bounds of the finest-level surface (or of the control mesh before
    /// refinement): `[min, max]`.
    pub fn bounds(&self) -> [DVec3; 2] {
        let pts = match &self.refined {
            Some(r) => &r.finest[..],
            None => &self.mesh.positions[..],
        };
        pts.iter().fold(
            [DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)],
            |[lo, hi], &p| [lo.min(p), hi.max(p)],
        )
    }

    /// The whole surface at one level `m <= max_level`: the level's own triangles, no gap
    /// filling needed (the fast path of a uniform level map).
    pub fn extract_uniform(&self, m: u32) -> Result<MeshArrays> {
        let rf = self.refined()?;
        if m > rf.r.max_level() {
            return Err(Error::Parameter(format!(
                "level {m} requested, refinement built to {}",
                rf.r.max_level()
            )));
        }
        let lv = rf.r.level(m);
        let tris = lv.triangles();
        let mut out = build_arrays(
            rf,
            lv.vertex_count(),
            tris.len() / 3,
            |t| {
                (
                    [tris[3 * t], tris[3 * t + 1], tris[3 * t + 2]],
                    lv.face_group(t),
                )
            },
            Source::Finest,
        );
        out.lines = rf.lines(|_| m as u8);
        Ok(out)
    }

    /// The surface with base triangle k at level `levels[k]`, crack-free (the engine's gap
    /// filling and stitching).
    pub fn extract_levels(&mut self, levels: &[u8]) -> Result<MeshArrays> {
        {
            let rf = self.refined()?;
            if levels.len() != rf.base_triangles.len() {
                return Err(Error::Parameter(format!(
                    "{} levels given, the mesh has {} base triangles",
                    levels.len(),
                    rf.base_triangles.len()
                )));
            }
            if let Some(&m) = levels.first() {
                if levels.iter().all(|&l| l == m) {
                    return self.extract_uniform(m as u32);
                }
            }
        }
        let rf = self.refined.as_mut().expect("checked above");
        if rf.vertex_tags.is_empty() {
            rf.vertex_tags = (0..rf.finest.len())
                .map(|v| DVec3::new(v as f64, -1.0, 0.0))
                .collect();
        }
        let rf = &*rf;
        let lod =
            rf.r.extract_lod(&rf.finest, Some(&rf.vertex_tags), levels)?;
        let tags = lod
            .normals
            .as_deref()
            .ok_or_else(|| Error::Parameter("extract_lod returned no vertex tags".into()))?;
        let mut out = build_arrays(
            rf,
            lod.positions.len(),
            lod.triangles.len(),
            |t| (lod.triangles[t], lod.face_groups[t]),
            |v| {
                let tag = tags[v as usize];
                if tag.y == -1.0 {
                    Source::Finest(tag.x as u32)
                } else {
                    Source::Centroid(lod.positions[v as usize])
                }
            },
        );
        out.lines = rf.lines(|f| levels[f as usize]);
        Ok(out)
    }

    /// Level per base triangle for a view: `mvp` is the column-major model-view-projection
    /// matrix (WebGL convention), the viewport is `width` x `height` pixels, and each level
    /// halves edge lengths until the longest projected edge is at most `target_px` pixels
    /// (S-CODE §4: clip, project, size, level). Triangles outside the view frustum (with a
    /// margin for the surface bulging past its base triangle) get level 0; triangles crossing
    /// the camera plane get the finest level.
    pub fn view_levels(
        &self,
        mvp: &[f32; 16],
        width: f32,
        height: f32,
        target_px: f32,
    ) -> Result<Vec<u8>> {
        let rf = self.refined()?;
        let n = rf.r.max_level() as u8;
        let m = Mat4::from_cols_array(mvp);
        let rows = [m.row(0), m.row(1), m.row(2), m.row(3)];
        let planes: Vec<Vec4> = [
            rows[3] + rows[0],
            rows[3] - rows[0],
            rows[3] + rows[1],
            rows[3] - rows[1],
            rows[3] + rows[2],
            rows[3] - rows[2],
        ]
        .iter()
        .map(|p| *p / p.truncate().length().max(f32::MIN_POSITIVE))
        .collect();
        let target = target_px.max(0.5);
        Ok(rf
            .base_triangles
            .iter()
            .map(|t| {
                let p = t.map(|v| rf.finest[v as usize].as_vec3());
                let c = (p[0] + p[1] + p[2]) / 3.0;
                let radius = p.iter().map(|q| q.distance(c)).fold(0.0, f32::max) * 1.5;
                if planes
                    .iter()
                    .any(|pl| pl.truncate().dot(c) + pl.w < -radius)
                {
                    return 0;
                }
                let clip = p.map(|q| m * q.extend(1.0));
                if clip.iter().any(|q| q.w <= 1e-6) {
                    return n;
                }
                let s = clip.map(|q| {
                    glam::Vec2::new(
                        (q.x / q.w * 0.5 + 0.5) * width,
                        (q.y / q.w * 0.5 + 0.5) * height,
                    )
                });
                let longest = s[0]
                    .distance(s[1])
                    .max(s[1].distance(s[2]))
                    .max(s[2].distance(s[0]));
                if !longest.is_finite() {
                    return n;
                }
                let mut level = 0u8;
                let mut len = longest;
                while len > target && level < n {
                    len *= 0.5;
                    level += 1;
                }
                level
            })
            .collect())
    }
}

impl Refined {
    /// Segments of the sharp and boundary curves, each base edge at the coarser level of its
    /// two faces (where the finer side's vertices were moved onto the coarser chords).
    fn lines(&self, level_of_face: impl Fn(u32) -> u8) -> Vec<f32> {
        let n = self.r.max_level();
        let mut out = Vec::new();
        let mut chain: Vec<u32> = Vec::new();
        for le in &self.line_edges {
            let lc = le
                .faces
                .iter()
                .filter(|&&f| f != NONE)
                .map(|&f| level_of_face(f) as u32)
                .min()
                .unwrap_or(0)
                .min(n);
            // Vertices along the base edge at level lc: the new vertex of level-m edge
            // (e 2^m + i) is V_m + e 2^m + i and sits between chain[i] and chain[i + 1].
            let e = le.edge as usize;
            chain.clear();
            chain.extend_from_slice(&self.base_edges[e]);
            for m in 0..lc as usize {
                let base_id = self.level_vertex_counts[m] as usize + (e << m);
                let mut next = Vec::with_capacity(2 * chain.len() - 1);
                for (i, w) in chain.windows(2).enumerate() {
                    next.push(w[0]);
                    next.push((base_id + i) as u32);
                }
                next.push(chain[chain.len() - 1]);
                chain = next;
            }
            for w in chain.windows(2) {
                for &v in w {
                    let p = self.finest[v as usize].as_vec3();
                    out.extend_from_slice(&[p.x, p.y, p.z]);
                }
            }
        }
        out
    }
}

/// Builds the WebGL arrays from `count` triangles (corners + group), splitting vertices per
/// group so normals are sharp across CAD-face boundaries.
fn build_arrays(
    rf: &Refined,
    vertex_count: usize,
    count: usize,
    triangle: impl Fn(usize) -> ([u32; 3], u32),
    source: impl Fn(u32) -> Source,
) -> MeshArrays {
    let mut out = MeshArrays::default();
    out.indices.reserve(3 * count);
    // slot of (input vertex, its first group); other groups in `extra`
    let mut first: Vec<(u32, u32)> = vec![(NONE, NONE); vertex_count];
    // lookups only (slots are numbered in triangle order), so the map's order never leaks
    let mut extra: HashMap<(u32, u32), u32> = HashMap::new();
    let mut centroid_slots: Vec<u32> = Vec::new();
    for t in 0..count {
        let (tri, g) = triangle(t);
        for v in tri {
            let vi = v as usize;
            let (fg, fs) = first[vi];
            let slot = if fg == g {
                fs
            } else if fg == NONE || !extra.contains_key(&(v, g)) {
                let slot = out.groups.len() as u32;
                match source(v) {
                    Source::Finest(id) => {
                        let p = rf.finest[id as usize].as_vec3();
                        let nn = rf.normals.get(id, g);
                        out.positions.extend_from_slice(&[p.x, p.y, p.z]);
                        out.normals.extend_from_slice(&[nn.x, nn.y, nn.z]);
                    }
                    Source::Centroid(p) => {
                        let p = p.as_vec3();
                        out.positions.extend_from_slice(&[p.x, p.y, p.z]);
                        out.normals.extend_from_slice(&[0.0; 3]);
                        centroid_slots.push(slot);
                    }
                }
                out.groups.push(g);
                if fg == NONE {
                    first[vi] = (g, slot);
                } else {
                    extra.insert((v, g), slot);
                }
                slot
            } else {
                extra[&(v, g)]
            };
            out.indices.push(slot);
        }
    }
    if !centroid_slots.is_empty() {
        // A stitching centroid's normal: the mean of its fan neighbours' normals.
        let mut is_centroid = vec![false; out.groups.len()];
        for &s in &centroid_slots {
            is_centroid[s as usize] = true;
        }
        let mut acc = vec![Vec3::ZERO; out.groups.len()];
        for t in out.indices.chunks_exact(3) {
            for (i, &c) in t.iter().enumerate() {
                if is_centroid[c as usize] {
                    for &o in [t[(i + 1) % 3], t[(i + 2) % 3]].iter() {
                        let k = 3 * o as usize;
                        acc[c as usize] += Vec3::from_slice(&out.normals[k..k + 3]);
                    }
                }
            }
        }
        for &s in &centroid_slots {
            let nn = acc[s as usize].normalize_or_zero();
            out.normals[3 * s as usize..3 * s as usize + 3].copy_from_slice(&nn.to_array());
        }
    }
    out
}

#[cfg(test)]
mod tests;
