//! Segmentation of an ungrouped triangle mesh (STL, fandisk, ...) into CAD-face-like
//! regions, each classified as a primitive (plane, cylinder, cone, sphere, torus) or
//! freeform.
//!
//! Pipeline:
//! 1. Split at sharp edges (dihedral angle above `sharp_angle_deg`), mesh-boundary edges
//!    and non-manifold edges; flood-fill the rest into smooth components.
//! 2. A component that one primitive fits within `tolerance` (every vertex) is one region.
//! 3. Otherwise split it at curvature discontinuities by primitive-driven region growing:
//!    seeds in order of local flatness; each seed's 2-ring patch picks the simplest
//!    primitive that fits it; the region grows over faces whose vertices lie within
//!    `tolerance` of the primitive and whose normal agrees with it; when growth stalls the
//!    primitive is refitted on the region plus the rejected ring (and may be upgraded to a
//!    more general kind while the region is young). Faces no primitive region claims form
//!    freeform regions.
//! 4. Fragments smaller than `min_region_triangles` (from step 3 only; small components
//!    bounded by sharp edges are genuine faces) merge into the smooth neighbour sharing
//!    the most edges.
//!
//! Deterministic: seeds are ordered by (score, face index), adjacency comes from sorting,
//! and all maps are ordered.

use std::collections::{BTreeMap, VecDeque};

use glam::DVec3;

use super::adjacency::{face_normals_and_areas, EdgeTable};
use super::primitives::{fit_kind, refine, Primitive, PrimitiveFit, PrimitiveKind, Residuals};
use crate::error::{Error, Result};
use crate::mesh::{Axis, BoundarySurface, ControlMesh, Group, PatchKind};

/// Parameters of [`segment`].
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentOptions {
    /// Edges whose dihedral angle (between face normals) exceeds this are sharp.
    pub sharp_angle_deg: f64,
    /// Max distance of a vertex to its region's primitive, in model units; default
    /// `1e-3 * bounding-box diagonal`.
    pub tolerance: Option<f64>,
    /// Regions produced by splitting a smooth component that are smaller than this merge
    /// into a neighbour.
    pub min_region_triangles: usize,
    /// Max angle between a face normal and the primitive normal for the face to join a
    /// growing region.
    pub normal_angle_deg: f64,
    /// Primitive kinds to classify whole smooth components with, simplest first.
    pub kinds: Vec<PrimitiveKind>,
    /// Primitive kinds allowed when splitting a smooth component (the torus is left out by
    /// default: it fits many small pieces of freeform surfaces).
    pub split_kinds: Vec<PrimitiveKind>,
    /// At most this many vertices are used per fit (deterministic stride subsampling); the
    /// tolerance is then checked on all vertices.
    pub max_fit_points: usize,
    /// A growing region whose primitive had to be refitted more often than this to absorb
    /// its next ring is drifting along a freeform surface: it is dropped (its faces end
    /// up in a freeform region).
    pub max_refits: usize,
}

impl Default for SegmentOptions {
    fn default() -> Self {
        SegmentOptions {
            sharp_angle_deg: 30.0,
            tolerance: None,
            min_region_triangles: 12,
            normal_angle_deg: 20.0,
            kinds: PrimitiveKind::ALL.to_vec(),
            split_kinds: vec![
                PrimitiveKind::Plane,
                PrimitiveKind::Cylinder,
                PrimitiveKind::Cone,
                PrimitiveKind::Sphere,
            ],
            max_fit_points: 400,
            max_refits: 6,
        }
    }
}

/// What a region is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum RegionKind {
    Primitive(PrimitiveKind),
    Freeform,
}

/// One output region (= one group of the output mesh, same index).
#[derive(Clone, Debug, PartialEq)]
pub struct RegionInfo {
    pub kind: RegionKind,
    pub triangles: usize,
    pub area: f64,
    /// The fitted primitive (None for freeform regions).
    pub primitive: Option<Primitive>,
    /// Residuals of all the region's vertices to `primitive`.
    pub residuals: Option<Residuals>,
}

/// Summary of a segmentation.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentReport {
    /// Tolerance actually used (model units).
    pub tolerance: f64,
    /// Number of edges found sharp (dihedral angle), before grouping.
    pub sharp_edges: usize,
    /// Smooth components after splitting at sharp edges.
    pub smooth_components: usize,
    /// Regions in group order.
    pub regions: Vec<RegionInfo>,
}

impl SegmentReport {
    /// Number of regions of each kind.
    pub fn counts(&self) -> BTreeMap<RegionKind, usize> {
        let mut m = BTreeMap::new();
        for r in &self.regions {
            *m.entry(r.kind).or_insert(0) += 1;
        }
        m
    }

    /// One line: "25 regions: Plane 10, Cylinder 6, ... Freeform 3".
    pub fn summary(&self) -> String {
        let parts: Vec<String> = self
            .counts()
            .iter()
            .map(|(k, n)| match k {
                RegionKind::Primitive(p) => format!("{p:?} {n}"),
                RegionKind::Freeform => format!("Freeform {n}"),
            })
            .collect();
        format!("{} regions: {}", self.regions.len(), parts.join(", "))
    }
}

const UNLABELLED: u32 = u32::MAX;

/// Face states during splitting.
#[derive(Clone, Copy, PartialEq, Eq)]
enum FaceState {
    /// Not yet in a region, may seed one.
    Free,
    /// Was in a failed seed attempt: may join a region but never seeds one.
    Tried,
    /// In a region.
    Taken,
}

struct Region {
    faces: Vec<u32>,
    fit: Option<PrimitiveFit>,
    /// Made by splitting a smooth component (small ones are merged away).
    from_split: bool,
}

/// Scratch state shared by the segmentation steps. Per-vertex buffers are reused between
/// regions via generation stamps to keep 100k-triangle meshes fast.
struct Segmenter<'a> {
    mesh: &'a ControlMesh,
    opts: &'a SegmentOptions,
    tol: f64,
    cos_normal: f64,
    normals: Vec<DVec3>,
    areas: Vec<f64>,
    /// Smooth, manifold neighbours of every face (CSR).
    nbr_offsets: Vec<u32>,
    nbrs: Vec<u32>,
    vertex_stamp: Vec<u32>,
    vertex_slot: Vec<u32>,
    face_stamp: Vec<u32>,
    generation: u32,
}

impl<'a> Segmenter<'a> {
    fn neighbours(&self, f: u32) -> &[u32] {
        &self.nbrs[self.nbr_offsets[f as usize] as usize..self.nbr_offsets[f as usize + 1] as usize]
    }

    fn next_generation(&mut self) -> u32 {
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            self.vertex_stamp.iter_mut().for_each(|s| *s = 0);
            self.face_stamp.iter_mut().for_each(|s| *s = 0);
            self.generation = 1;
        }
        self.generation
    }

    /// Unique vertices of `faces` with area-weighted normals from those faces only (so
    /// normals do not bleed across region borders).
    fn points_and_normals(&mut self, faces: &[u32]) -> (Vec<DVec3>, Vec<DVec3>) {
        let gen = self.next_generation();
        let mut pts = Vec::new();
        let mut nrm: Vec<DVec3> = Vec::new();
        for &f in faces {
            let w = self.normals[f as usize] * self.areas[f as usize];
            for &v in self.mesh.face(f as usize) {
                let v = v as usize;
                if self.vertex_stamp[v] != gen {
                    self.vertex_stamp[v] = gen;
                    self.vertex_slot[v] = pts.len() as u32;
                    pts.push(self.mesh.positions[v]);
                    nrm.push(DVec3::ZERO);
                }
                nrm[self.vertex_slot[v] as usize] += w;
            }
        }
        for n in &mut nrm {
            *n = n.normalize_or_zero();
        }
        (pts, nrm)
    }

    /// Points and normals of `faces`, all and a deterministic subsample for fitting.
    #[allow(clippy::type_complexity)]
    fn fit_input(&mut self, faces: &[u32]) -> (Vec<DVec3>, Vec<DVec3>, Vec<DVec3>) {
        let (pts, nrm) = self.points_and_normals(faces);
        let max = self.opts.max_fit_points.max(16);
        if pts.len() > max {
            let stride = pts.len().div_ceil(max);
            let sub_p = pts.iter().step_by(stride).copied().collect();
            let sub_n = nrm.iter().step_by(stride).copied().collect();
            (pts, sub_p, sub_n)
        } else {
            (pts.clone(), pts, nrm)
        }
    }

    /// Refits `model` (same kind, started from it) to `faces`; `Some` if every vertex is
    /// within the tolerance.
    fn refine_faces(&mut self, faces: &[u32], model: &Primitive) -> Option<PrimitiveFit> {
        let (pts, sub_p, _) = self.fit_input(faces);
        let fit = refine(model, &sub_p)?;
        if fit.residuals.max > self.tol {
            return None;
        }
        let full = fit.primitive.residuals(&pts);
        (full.max <= self.tol).then_some(PrimitiveFit {
            primitive: fit.primitive,
            residuals: full,
        })
    }

    /// Fits every kind of `kinds` to `faces` and selects, among those that keep every
    /// vertex within the tolerance, the simplest one whose max residual is within
    /// `max(2 * best, 0.05 * tolerance)`. Choosing by "first within tolerance" alone would
    /// call a small piece of a coarse cone a plane; choosing the best residual alone would
    /// call a plane a huge cylinder.
    fn fit_faces(&mut self, faces: &[u32], kinds: &[PrimitiveKind]) -> Option<PrimitiveFit> {
        let (pts, sub_p, sub_n) = self.fit_input(faces);
        let mut fits: Vec<PrimitiveFit> = Vec::new();
        for &k in kinds {
            let Some(fit) = fit_kind(k, &sub_p, &sub_n) else {
                continue;
            };
            if fit.residuals.max > self.tol {
                continue;
            }
            let full = fit.primitive.residuals(&pts);
            if full.max <= self.tol {
                let fit = PrimitiveFit {
                    primitive: fit.primitive,
                    residuals: full,
                };
                // Within 5 % of the tolerance: no more general kind could be preferred
                // (see the selection rule below), so stop fitting.
                let good = full.max <= 0.05 * self.tol;
                fits.push(fit);
                if good {
                    break;
                }
            }
        }
        let best = fits
            .iter()
            .map(|f| f.residuals.max)
            .fold(f64::INFINITY, f64::min);
        let accept = (2.0 * best).max(0.05 * self.tol);
        fits.into_iter().find(|f| f.residuals.max <= accept)
    }

    fn face_fits(&self, model: &Primitive, f: u32) -> bool {
        let face = self.mesh.face(f as usize);
        let mut centroid = DVec3::ZERO;
        for &v in face {
            let p = self.mesh.positions[v as usize];
            if model.distance(p) > self.tol {
                return false;
            }
            centroid += p;
        }
        let n = self.normals[f as usize];
        if n == DVec3::ZERO {
            return true;
        }
        centroid /= face.len() as f64;
        n.dot(model.normal_at(centroid)).abs() >= self.cos_normal
    }

    /// Grows one primitive region from `seed` over faces not `Taken`. On failure returns
    /// the faces that were tried.
    fn grow(
        &mut self,
        seed: u32,
        state: &[FaceState],
    ) -> std::result::Result<(Vec<u32>, PrimitiveFit), Vec<u32>> {
        // Initial patch: BFS rings around the seed.
        let gen = self.next_generation();
        let mut patch = vec![seed];
        self.face_stamp[seed as usize] = gen;
        let mut ring_start = 0;
        for _ring in 0..3 {
            let ring_end = patch.len();
            for i in ring_start..ring_end {
                let f = patch[i];
                for k in 0..self.neighbours(f).len() {
                    let g = self.neighbours(f)[k];
                    if self.face_stamp[g as usize] != gen && state[g as usize] != FaceState::Taken {
                        self.face_stamp[g as usize] = gen;
                        patch.push(g);
                    }
                }
            }
            ring_start = ring_end;
            if patch.len() >= 16 {
                break;
            }
        }
        let split_kinds = self.opts.split_kinds.clone();
        let Some(mut model) = self.fit_faces(&patch, &split_kinds) else {
            return Err(patch);
        };
        let upgrade_limit = (4 * patch.len()).max(64);
        // Membership stamps: region = gen_r, rejected = gen_x.
        let in_region = self.next_generation();
        let mut region = vec![seed];
        self.face_stamp[seed as usize] = in_region;
        let mut rejected: Vec<u32> = Vec::new();
        let mut rejected_mark: BTreeMap<u32, ()> = BTreeMap::new();
        let mut queue: VecDeque<u32> = self.neighbours(seed).iter().copied().collect();
        let mut last_fit = patch.len();
        let mut refits = 0;
        for _round in 0..64 {
            while let Some(f) = queue.pop_front() {
                if self.face_stamp[f as usize] == in_region || state[f as usize] == FaceState::Taken
                {
                    continue;
                }
                if self.face_fits(&model.primitive, f) {
                    self.face_stamp[f as usize] = in_region;
                    region.push(f);
                    if rejected_mark.remove(&f).is_some() {
                        rejected.retain(|&x| x != f);
                    }
                    for &g in self.neighbours(f) {
                        if self.face_stamp[g as usize] != in_region
                            && state[g as usize] != FaceState::Taken
                        {
                            queue.push_back(g);
                        }
                    }
                } else if rejected_mark.insert(f, ()).is_none() {
                    rejected.push(f);
                }
            }
            if rejected.is_empty() {
                break;
            }
            // Try to absorb the rejected ring with a refit (maybe of a more general kind
            // while the region is young).
            let kinds: Vec<PrimitiveKind> = if region.len() <= upgrade_limit {
                split_kinds
                    .iter()
                    .copied()
                    .filter(|&k| k > model.primitive.kind())
                    .collect()
            } else {
                Vec::new()
            };
            let mut candidates = region.clone();
            candidates.extend_from_slice(&rejected);
            let size_before = region.len();
            let absorbed = self
                .refine_faces(&candidates, &model.primitive)
                .or_else(|| self.fit_faces(&candidates, &kinds));
            if let Some(m) = absorbed {
                // A true primitive is found in a few refits; a model that keeps drifting
                // ring after ring is following a freeform surface.
                refits += 1;
                if refits > self.opts.max_refits {
                    return Err(region);
                }
                model = m;
            } else if region.len() * 2 > last_fit * 3 {
                // Cannot absorb the ring: sharpen the model on the region alone once it
                // has grown, then re-test the ring.
                last_fit = region.len();
                match self.refine_faces(&region.clone(), &model.primitive) {
                    Some(m) => model = m,
                    None => break,
                }
            } else {
                break;
            }
            queue.extend(rejected.iter().copied());
            rejected.clear();
            rejected_mark.clear();
            // Process the queue; if nothing new joins, stop.
            let before = region.len();
            while let Some(f) = queue.pop_front() {
                if self.face_stamp[f as usize] == in_region || state[f as usize] == FaceState::Taken
                {
                    continue;
                }
                if self.face_fits(&model.primitive, f) {
                    self.face_stamp[f as usize] = in_region;
                    region.push(f);
                    for &g in self.neighbours(f) {
                        if self.face_stamp[g as usize] != in_region
                            && state[g as usize] != FaceState::Taken
                        {
                            queue.push_back(g);
                        }
                    }
                } else if rejected_mark.insert(f, ()).is_none() {
                    rejected.push(f);
                }
            }
            if region.len() == before && region.len() == size_before {
                break;
            }
        }
        // Final residuals over the region.
        let (pts, _) = self.points_and_normals(&region);
        model.residuals = model.primitive.residuals(&pts);
        Ok((region, model))
    }

    /// Splits one smooth component that no single primitive fits.
    fn split_component(&mut self, comp: &[u32], state: &mut [FaceState], out: &mut Vec<Region>) {
        let mut order: Vec<(f64, u32)> = comp
            .iter()
            .map(|&f| {
                let n = self.normals[f as usize];
                let worst = self
                    .neighbours(f)
                    .iter()
                    .map(|&g| 1.0 - n.dot(self.normals[g as usize]))
                    .fold(0.0, f64::max);
                (worst, f)
            })
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for &(_, seed) in &order {
            if state[seed as usize] != FaceState::Free {
                continue;
            }
            match self.grow(seed, state) {
                Ok((faces, fit)) if faces.len() >= self.opts.min_region_triangles => {
                    for &f in &faces {
                        state[f as usize] = FaceState::Taken;
                    }
                    out.push(Region {
                        faces,
                        fit: Some(fit),
                        from_split: true,
                    });
                }
                Ok((faces, _)) | Err(faces) => {
                    for &f in &faces {
                        if state[f as usize] == FaceState::Free {
                            state[f as usize] = FaceState::Tried;
                        }
                    }
                    if state[seed as usize] == FaceState::Free {
                        state[seed as usize] = FaceState::Tried;
                    }
                }
            }
        }
        // Leftovers: connected pieces become freeform (or primitive) regions.
        for &start in comp {
            if state[start as usize] == FaceState::Taken {
                continue;
            }
            let mut faces = vec![start];
            state[start as usize] = FaceState::Taken;
            let mut i = 0;
            while i < faces.len() {
                let f = faces[i];
                i += 1;
                for k in 0..self.neighbours(f).len() {
                    let g = self.neighbours(f)[k];
                    if state[g as usize] != FaceState::Taken {
                        state[g as usize] = FaceState::Taken;
                        faces.push(g);
                    }
                }
            }
            let kinds = self.opts.kinds.clone();
            let fit = self.fit_faces(&faces, &kinds);
            out.push(Region {
                faces,
                fit,
                from_split: true,
            });
        }
    }
}

/// Segments `mesh` (any input groups are ignored) into regions. Returns the mesh with one
/// group per region (`face_<i>`, patch kind from the region type), the group-boundary edges
/// whose dihedral angle is sharp added to `sharp_edges`, and a report.
pub fn segment(mesh: &ControlMesh, opts: &SegmentOptions) -> Result<(ControlMesh, SegmentReport)> {
    mesh.validate()?;
    if mesh.face_count() == 0 {
        return Err(Error::Mesh("cannot segment a mesh without faces".into()));
    }
    if !(opts.sharp_angle_deg > 0.0 && opts.sharp_angle_deg < 180.0) {
        return Err(Error::Parameter(format!(
            "sharp angle {} must be in (0, 180) degrees",
            opts.sharp_angle_deg
        )));
    }
    if !(opts.normal_angle_deg > 0.0 && opts.normal_angle_deg <= 90.0) {
        return Err(Error::Parameter(format!(
            "normal angle {} must be in (0, 90] degrees",
            opts.normal_angle_deg
        )));
    }
    let tol = opts.tolerance.unwrap_or(1e-3 * mesh.diagonal());
    if !(tol > 0.0 && tol.is_finite()) {
        return Err(Error::Parameter(format!(
            "segmentation tolerance {tol} must be positive (degenerate mesh?)"
        )));
    }
    let nf = mesh.face_count();
    let (normals, areas) = face_normals_and_areas(mesh);
    let edges = EdgeTable::new(mesh);
    let cos_sharp = opts.sharp_angle_deg.to_radians().cos();
    let is_sharp_pair = |normals: &[DVec3], f: u32, g: u32| {
        let (a, b) = (normals[f as usize], normals[g as usize]);
        a != DVec3::ZERO && b != DVec3::ZERO && a.dot(b) < cos_sharp
    };
    // Smooth manifold adjacency.
    let mut pairs: Vec<(u32, u32)> = Vec::new();
    let mut sharp_count = 0;
    for e in 0..edges.len() {
        let fs = edges.faces(e);
        if fs.len() != 2 {
            continue;
        }
        let (f, g) = (fs[0].0, fs[1].0);
        if f == g {
            continue;
        }
        if is_sharp_pair(&normals, f, g) {
            sharp_count += 1;
        } else {
            pairs.push((f, g));
            pairs.push((g, f));
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    let mut nbr_offsets = vec![0u32; nf + 1];
    for &(f, _) in &pairs {
        nbr_offsets[f as usize + 1] += 1;
    }
    for i in 0..nf {
        nbr_offsets[i + 1] += nbr_offsets[i];
    }
    let nbrs: Vec<u32> = pairs.iter().map(|p| p.1).collect();
    let mut seg = Segmenter {
        mesh,
        opts,
        tol,
        cos_normal: opts.normal_angle_deg.to_radians().cos(),
        normals,
        areas,
        nbr_offsets,
        nbrs,
        vertex_stamp: vec![0; mesh.vertex_count()],
        vertex_slot: vec![0; mesh.vertex_count()],
        face_stamp: vec![0; nf],
        generation: 0,
    };

    // 1. Smooth components.
    let mut comp_of = vec![UNLABELLED; nf];
    let mut components: Vec<Vec<u32>> = Vec::new();
    for start in 0..nf as u32 {
        if comp_of[start as usize] != UNLABELLED {
            continue;
        }
        let c = components.len() as u32;
        let mut faces = vec![start];
        comp_of[start as usize] = c;
        let mut i = 0;
        while i < faces.len() {
            let f = faces[i];
            i += 1;
            for &g in seg.neighbours(f) {
                if comp_of[g as usize] == UNLABELLED {
                    comp_of[g as usize] = c;
                    faces.push(g);
                }
            }
        }
        faces.sort_unstable();
        components.push(faces);
    }

    // 2-3. Classify or split each component.
    let mut regions: Vec<Region> = Vec::new();
    let mut state = vec![FaceState::Free; nf];
    let kinds = opts.kinds.clone();
    for comp in &components {
        if let Some(fit) = seg.fit_faces(comp, &kinds) {
            regions.push(Region {
                faces: comp.clone(),
                fit: Some(fit),
                from_split: false,
            });
        } else {
            seg.split_component(comp, &mut state, &mut regions);
        }
    }

    // 4. Merge small fragments from splitting into their best smooth neighbour.
    let mut label = vec![UNLABELLED; nf];
    for (r, reg) in regions.iter().enumerate() {
        for &f in &reg.faces {
            label[f as usize] = r as u32;
        }
    }
    loop {
        let small = regions
            .iter()
            .enumerate()
            .filter(|(_, r)| {
                r.from_split && !r.faces.is_empty() && r.faces.len() < opts.min_region_triangles
            })
            .min_by_key(|(i, r)| (r.faces.len(), *i))
            .map(|(i, _)| i);
        let Some(s) = small else { break };
        let mut shared: BTreeMap<u32, usize> = BTreeMap::new();
        for &f in &regions[s].faces {
            for &g in seg.neighbours(f) {
                let l = label[g as usize];
                if l != s as u32 {
                    *shared.entry(l).or_insert(0) += 1;
                }
            }
        }
        let Some((&target, _)) = shared.iter().max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
        else {
            regions[s].from_split = false; // isolated: keep
            continue;
        };
        let moved = std::mem::take(&mut regions[s].faces);
        for &f in &moved {
            label[f as usize] = target;
        }
        let t = target as usize;
        let keep = regions[t]
            .fit
            .as_ref()
            .is_some_and(|fit| moved.iter().all(|&f| seg.face_fits(&fit.primitive, f)));
        regions[t].faces.extend(moved);
        regions[t].faces.sort_unstable();
        if keep {
            let prim = regions[t].fit.as_ref().map(|f| f.primitive);
            if let Some(p) = prim {
                let (pts, _) = seg.points_and_normals(&regions[t].faces.clone());
                regions[t].fit = Some(PrimitiveFit {
                    primitive: p,
                    residuals: p.residuals(&pts),
                });
            }
        } else {
            let faces = regions[t].faces.clone();
            regions[t].fit = seg.fit_faces(&faces, &kinds);
        }
    }
    regions.retain(|r| !r.faces.is_empty());
    // Groups in order of their first face.
    regions.sort_by_key(|r| r.faces[0]);

    let mut out = mesh.clone();
    out.groups.clear();
    let mut infos = Vec::with_capacity(regions.len());
    for (i, r) in regions.iter().enumerate() {
        let patch = match r.fit.map(|f| f.primitive) {
            Some(Primitive::Plane { .. }) => PatchKind::Boundary(BoundarySurface::Plane),
            Some(Primitive::Cylinder { axis, .. }) => {
                PatchKind::Boundary(BoundarySurface::Cylinder { axis })
            }
            Some(Primitive::Cone { axis, .. }) => PatchKind::Boundary(BoundarySurface::Cone {
                axis: Axis {
                    origin: axis.origin,
                    direction: axis.direction,
                },
            }),
            _ => PatchKind::Closed,
        };
        out.groups.push(Group {
            name: format!("face_{i}"),
            patch,
        });
        for &f in &r.faces {
            out.face_groups[f as usize] = i as u32;
        }
        infos.push(RegionInfo {
            kind: r
                .fit
                .map(|f| RegionKind::Primitive(f.primitive.kind()))
                .unwrap_or(RegionKind::Freeform),
            triangles: r.faces.len(),
            area: r.faces.iter().map(|&f| seg.areas[f as usize]).sum(),
            primitive: r.fit.map(|f| f.primitive),
            residuals: r.fit.map(|f| f.residuals),
        });
    }
    for e in 0..edges.len() {
        let fs = edges.faces(e);
        if fs.len() == 2 {
            let (f, g) = (fs[0].0, fs[1].0);
            if out.face_groups[f as usize] != out.face_groups[g as usize]
                && is_sharp_pair(&seg.normals, f, g)
            {
                let (a, b) = edges.keys[e];
                out.set_sharp(a, b);
            }
        }
    }
    Ok((
        out,
        SegmentReport {
            tolerance: tol,
            sharp_edges: sharp_count,
            smooth_components: components.len(),
            regions: infos,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::test_support::load_corpus;

    fn describe(report: &SegmentReport) -> String {
        let mut s = report.summary();
        for (i, r) in report.regions.iter().enumerate() {
            s += &format!(
                "\n  face_{i}: {:?} {} tris, max res {:.2e}",
                r.kind,
                r.triangles,
                r.residuals.map(|r| r.max).unwrap_or(f64::NAN)
            );
        }
        s
    }

    #[test]
    #[ignore = "exploration: prints segmentations of corpus meshes"]
    fn explore_corpus() {
        let list = std::env::var("SCODE_EXPLORE").unwrap_or_else(|_| {
            "tess/four_cone_coarse.obj,meshes/fandisk.obj,meshes/block.off,meshes/rocker-arm.obj".into()
        });
        for name in list.split(',') {
            let Some(m) = load_corpus(name) else { return };
            let t = std::time::Instant::now();
            let (out, rep) = segment(
                &m,
                &SegmentOptions {
                    normal_angle_deg: 89.0,
                    ..Default::default()
                },
            )
            .unwrap();
            println!(
                "{name} ({:?}) tol {:.3e}: {}",
                t.elapsed(),
                rep.tolerance,
                describe(&rep)
            );
            if m.groups.len() > 1 {
                for g in 0..out.groups.len() {
                    let mut h = BTreeMap::new();
                    for f in 0..m.face_count() {
                        if out.face_groups[f] == g as u32 {
                            *h.entry(m.groups[m.face_groups[f] as usize].name.clone())
                                .or_insert(0) += 1;
                        }
                    }
                    println!("  region {g}: {h:?}");
                }
            }
        }
    }

    #[test]
    #[ignore = "exploration: region counts vs true CAD faces"]
    fn explore_grouped() {
        let Some(dir) = crate::fit::test_support::corpus_dir() else {
            return;
        };
        let mut names: Vec<String> = std::fs::read_dir(dir.join("tess"))
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().to_string()))
            .filter(|n| n.ends_with("_coarse.obj") || n.ends_with("_cadexport.obj"))
            .map(|n| format!("tess/{n}"))
            .collect();
        names.sort();
        names.push("abc/abc_00000006.obj".into());
        names.push("abc/abc_00007974_5.obj".into());
        for name in names {
            let Some(m) = load_corpus(&name) else { return };
            let t = std::time::Instant::now();
            let (_, rep) = segment(&m, &SegmentOptions::default()).unwrap();
            println!(
                "{name}: true {} faces, {} smooth comps -> {} ({:?})",
                m.groups.len(),
                rep.smooth_components,
                rep.summary(),
                t.elapsed()
            );
        }
    }
}
#[cfg(test)]
mod debug_tests {
    use super::*;
    use crate::fit::test_support::load_corpus;
    #[test]
    #[ignore]
    fn debug_four_cone() {
        let Some(m) = load_corpus("tess/four_cone_coarse.obj") else {
            return;
        };
        let faces: Vec<u32> = (0..m.face_count() as u32)
            .filter(|&f| m.face_groups[f as usize] == 1)
            .collect();
        let opts = SegmentOptions::default();
        let (normals, areas) = face_normals_and_areas(&m);
        let mut seg = Segmenter {
            mesh: &m,
            opts: &opts,
            tol: 0.1225,
            cos_normal: 0.9,
            normals,
            areas,
            nbr_offsets: vec![],
            nbrs: vec![],
            vertex_stamp: vec![0; m.vertex_count()],
            vertex_slot: vec![0; m.vertex_count()],
            face_stamp: vec![0; m.face_count()],
            generation: 0,
        };
        let (pts, nrm) = seg.points_and_normals(&faces);
        for k in PrimitiveKind::ALL {
            println!("{k:?}: {:?}", fit_kind(k, &pts, &nrm));
        }
        for f in &faces {
            let n = seg.normals[*f as usize];
            print!("{:.2} ", n.z);
        }
        println!();
    }
}
