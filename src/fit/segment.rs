//! Segmentation of an ungrouped triangle mesh (STL, fandisk, ...) into CAD-face-like
//! regions, each classified as a primitive (plane, cylinder, cone, sphere, torus) or
//! freeform.
//!
//! Pipeline:
//! 1. Split at sharp edges (dihedral angle above `sharp_angle_deg`), mesh-boundary edges
//!    and non-manifold edges; flood-fill the rest into smooth components.
//! 2. A component that one primitive fits within `tolerance` (every vertex) is one region.
//!    The kind is chosen as the simplest one whose max residual is within
//!    `max(2 * best, 0.05 * tolerance)` (so a coarse cone is not called a plane, and a
//!    plane is not called a huge cylinder).
//! 3. Otherwise the component is split at curvature discontinuities by primitive-driven
//!    region growing: seeds in order of local flatness; the seed's model comes from the
//!    smallest ring of faces around it that a primitive fits confidently; the region grows
//!    over faces whose vertices lie within `tolerance` of the primitive and whose normal
//!    agrees with it; when growth stalls the primitive is refitted (from the current one)
//!    on the region plus the rejected ring, and may be upgraded to a more general kind
//!    while the region is young. A model that needs too many refits is following a
//!    freeform surface and is dropped. Then pieces that are not confident primitives
//!    (residual above `confident_fraction * tolerance`) join a confident neighbour whose
//!    primitive fits them, or merge with each other into freeform regions.
//! 4. Tiny sharp-bounded components lying on an adjacent primitive (slivers) join it;
//!    fragments from step 3 smaller than `min_region_triangles` merge into the smooth
//!    neighbour that fits them (else the one sharing the most edges).
//! 5. Pieces of the same curved kind separated by moderately sharp edges (coarse facets,
//!    up to `facet_merge_angle_deg`) merge when one primitive fits the union confidently.
//!
//! Deterministic: seeds are ordered by (score, face index), adjacency comes from sorting,
//! and all maps are ordered.

use std::collections::{BTreeMap, VecDeque};

use glam::DVec3;

use super::adjacency::{face_normals_and_areas, EdgeTable};
use super::primitives::{fit_kind_within, refine, SurfaceFit};
use crate::error::{Error, Result};
use crate::mesh::{
    AnalyticSurface, Axis, BoundarySurface, ControlMesh, Group, PatchKind, Residuals, SurfaceKind,
    Tolerance,
};

/// Parameters of [`segment`].
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentOptions {
    /// Edges whose dihedral angle (between face normals) exceeds this are sharp.
    pub sharp_angle_deg: f64,
    /// Max distance of a vertex to its region's primitive; default
    /// [`Tolerance::DEFAULT`].
    pub tolerance: Tolerance,
    /// Regions produced by splitting a smooth component that are smaller than this merge
    /// into a neighbour.
    pub min_region_triangles: usize,
    /// Max angle between a face normal and the primitive normal for the face to join a
    /// growing region.
    pub normal_angle_deg: f64,
    /// AnalyticSurface kinds to classify whole smooth components with, simplest first.
    pub kinds: Vec<SurfaceKind>,
    /// AnalyticSurface kinds allowed when splitting a smooth component (the torus is left out by
    /// default: it fits many small pieces of freeform surfaces).
    pub split_kinds: Vec<SurfaceKind>,
    /// At most this many vertices are used per fit (deterministic stride subsampling); the
    /// tolerance is then checked on all vertices.
    pub max_fit_points: usize,
    /// A growing region whose primitive had to be refitted more often than this to absorb
    /// its next ring is drifting along a freeform surface: it is dropped (its faces end
    /// up in a freeform region).
    pub max_refits: usize,
    /// A primitive whose max residual is at most this fraction of the tolerance is
    /// "confident" (tessellations of real planes, cylinders... fit far below the
    /// tolerance); adjacent non-confident pieces of one smooth component are merged into
    /// one region (they are usually pieces of one freeform surface).
    pub confident_fraction: f64,
    /// Regions separated by edges no sharper than this (but sharper than
    /// `sharp_angle_deg`) merge when one primitive fits their union confidently: coarse
    /// tessellations of small cylinders and spheres have facets 45 degrees apart.
    pub facet_merge_angle_deg: f64,
}

impl Default for SegmentOptions {
    fn default() -> Self {
        SegmentOptions {
            sharp_angle_deg: 30.0,
            tolerance: Tolerance::DEFAULT,
            min_region_triangles: 12,
            normal_angle_deg: 20.0,
            kinds: SurfaceKind::ALL.to_vec(),
            split_kinds: vec![
                SurfaceKind::Plane,
                SurfaceKind::Cylinder,
                SurfaceKind::Cone,
                SurfaceKind::Sphere,
            ],
            max_fit_points: 400,
            max_refits: 6,
            confident_fraction: 0.25,
            facet_merge_angle_deg: 60.0,
        }
    }
}

/// What a region is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum RegionKind {
    Analytic(SurfaceKind),
    Freeform,
}

/// One output region (= one group of the output mesh, same index).
#[derive(Clone, Debug, PartialEq)]
pub struct RegionInfo {
    pub kind: RegionKind,
    pub triangles: usize,
    pub area: f64,
    /// The fitted surface (None for freeform regions).
    pub surface: Option<AnalyticSurface>,
    /// Residuals of all the region's vertices to `surface`.
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
                RegionKind::Analytic(p) => format!("{p:?} {n}"),
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

/// The growing edge of a region during flood fill: faces still to test, the region so far,
/// and the faces that failed the test (each listed once).
struct Front {
    queue: VecDeque<u32>,
    region: Vec<u32>,
    rejected: Vec<u32>,
    rejected_mark: BTreeMap<u32, ()>,
}

struct Region {
    faces: Vec<u32>,
    fit: Option<SurfaceFit>,
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
    /// Cosine of `sharp_angle_deg`.
    cos_sharp: f64,
    edges: EdgeTable,
    normals: Vec<DVec3>,
    areas: Vec<f64>,
    /// Smooth, manifold neighbours of every face (CSR).
    nbr_offsets: Vec<u32>,
    nbrs: Vec<u32>,
    /// Number of manifold edges found sharp.
    sharp_edges: usize,
    vertex_stamp: Vec<u32>,
    vertex_slot: Vec<u32>,
    face_stamp: Vec<u32>,
    /// Scratch region index per face (u32::MAX when unused).
    region_label: Vec<u32>,
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
    fn refine_faces(&mut self, faces: &[u32], model: &AnalyticSurface) -> Option<SurfaceFit> {
        let (pts, sub_p, _) = self.fit_input(faces);
        let fit = refine(model, &sub_p)?;
        if fit.residuals.max > self.tol {
            return None;
        }
        let full = fit.surface.residuals(&pts);
        (full.max <= self.tol).then_some(SurfaceFit {
            surface: fit.surface,
            residuals: full,
        })
    }

    /// Fits every kind of `kinds` to `faces` and selects, among those that keep every
    /// vertex within the tolerance, the simplest one whose max residual is within
    /// `max(2 * best, 0.05 * tolerance)`. Choosing by "first within tolerance" alone would
    /// call a small piece of a coarse cone a plane; choosing the best residual alone would
    /// call a plane a huge cylinder.
    fn fit_faces(&mut self, faces: &[u32], kinds: &[SurfaceKind]) -> Option<SurfaceFit> {
        let (pts, sub_p, sub_n) = self.fit_input(faces);
        let mut fits: Vec<SurfaceFit> = Vec::new();
        let mut cylinder: Option<SurfaceFit> = None;
        for &k in kinds {
            let Some(fit) = fit_kind_within(k, &sub_p, &sub_n, self.tol, cylinder) else {
                continue;
            };
            if k == SurfaceKind::Cylinder {
                cylinder = Some(fit);
            }
            if fit.residuals.max > self.tol {
                continue;
            }
            let full = fit.surface.residuals(&pts);
            if full.max <= self.tol {
                let fit = SurfaceFit {
                    surface: fit.surface,
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

    fn face_fits(&self, model: &AnalyticSurface, f: u32) -> bool {
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

    /// Takes faces from `front.queue` into the region while they fit `primitive`, queueing
    /// their neighbours; faces that do not fit are collected once in `front.rejected`.
    fn flood(
        &mut self,
        primitive: &AnalyticSurface,
        state: &[FaceState],
        in_region: u32,
        front: &mut Front,
    ) {
        while let Some(f) = front.queue.pop_front() {
            if self.face_stamp[f as usize] == in_region || state[f as usize] == FaceState::Taken {
                continue;
            }
            if self.face_fits(primitive, f) {
                self.face_stamp[f as usize] = in_region;
                front.region.push(f);
                if front.rejected_mark.remove(&f).is_some() {
                    front.rejected.retain(|&x| x != f);
                }
                for &g in self.neighbours(f) {
                    if self.face_stamp[g as usize] != in_region
                        && state[g as usize] != FaceState::Taken
                    {
                        front.queue.push_back(g);
                    }
                }
            } else if front.rejected_mark.insert(f, ()).is_none() {
                front.rejected.push(f);
            }
        }
    }

    /// Grows one primitive region from `seed` over faces not `Taken`. On failure returns
    /// the faces that were tried.
    fn grow(
        &mut self,
        seed: u32,
        state: &[FaceState],
    ) -> std::result::Result<(Vec<u32>, SurfaceFit), Vec<u32>> {
        // Initial model: fit growing BFS rings around the seed and stop at the first ring
        // whose best primitive is confident. Small patches first, so that a seed near a
        // curvature change (plane next to a fillet) picks the surface it lies on.
        let gen = self.next_generation();
        let mut patch = vec![seed];
        self.face_stamp[seed as usize] = gen;
        let mut ring_start = 0;
        let split_kinds = self.opts.split_kinds.clone();
        let mut model: Option<SurfaceFit> = None;
        for _ring in 0..4 {
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
            if patch.len() < 3 {
                continue;
            }
            let fit = self.fit_faces(&patch, &split_kinds);
            let confident = self.is_confident(&fit);
            if fit.is_some() {
                model = fit;
            }
            if confident || patch.len() >= 24 {
                break;
            }
        }
        let Some(mut model) = model else {
            return Err(patch);
        };
        let upgrade_limit = (4 * patch.len()).max(64);
        // Membership stamps: region = gen_r, rejected = gen_x.
        let in_region = self.next_generation();
        self.face_stamp[seed as usize] = in_region;
        let mut front = Front {
            queue: self.neighbours(seed).iter().copied().collect(),
            region: vec![seed],
            rejected: Vec::new(),
            rejected_mark: BTreeMap::new(),
        };
        let mut last_fit = patch.len();
        let mut refits = 0;
        // Each round floods the queue with the current model, then tries to absorb the
        // faces it rejected with a refit and queues them again; it ends when the rejected
        // ring is empty or a flood adds nothing.
        for round in 0..=64 {
            let before = front.region.len();
            self.flood(&model.surface, state, in_region, &mut front);
            if round > 0 && front.region.len() == before {
                break;
            }
            if front.rejected.is_empty() || round == 64 {
                break;
            }
            // Try to absorb the rejected ring with a refit (maybe of a more general kind
            // while the region is young).
            let kinds: Vec<SurfaceKind> = if front.region.len() <= upgrade_limit {
                split_kinds
                    .iter()
                    .copied()
                    .filter(|&k| k > model.surface.kind())
                    .collect()
            } else {
                Vec::new()
            };
            let mut candidates = front.region.clone();
            candidates.extend_from_slice(&front.rejected);
            let absorbed = self
                .refine_faces(&candidates, &model.surface)
                .or_else(|| self.fit_faces(&candidates, &kinds));
            if let Some(m) = absorbed {
                // A true primitive is found in a few refits; a model that keeps drifting
                // ring after ring is following a freeform surface.
                refits += 1;
                if refits > self.opts.max_refits {
                    return Err(front.region);
                }
                model = m;
            } else if front.region.len() * 2 > last_fit * 3 {
                // Cannot absorb the ring: sharpen the model on the region alone once it
                // has grown, then re-test the ring.
                last_fit = front.region.len();
                match self.refine_faces(&front.region.clone(), &model.surface) {
                    Some(m) => model = m,
                    None => break,
                }
            } else {
                break;
            }
            let ring = std::mem::take(&mut front.rejected);
            front.queue.extend(ring);
            front.rejected_mark.clear();
        }
        let region = front.region;
        // Final residuals over the region.
        let (pts, _) = self.points_and_normals(&region);
        model.residuals = model.surface.residuals(&pts);
        Ok((region, model))
    }

    fn is_confident(&self, fit: &Option<SurfaceFit>) -> bool {
        fit.is_some_and(|f| f.residuals.max <= self.opts.confident_fraction * self.tol)
    }

    /// Merges smoothly adjacent regions of `regions[first..]` (one split component) that
    /// are not confident primitives, then refits each merged region.
    fn merge_uncertain(&mut self, regions: &mut [Region], first: usize) {
        let n = regions.len() - first;
        if n < 2 {
            return;
        }
        for (i, r) in regions[first..].iter().enumerate() {
            for &f in &r.faces {
                self.region_label[f as usize] = i as u32;
            }
        }
        let mut parent: Vec<usize> = (0..n).collect();
        fn root(p: &mut [usize], mut i: usize) -> usize {
            while p[i] != i {
                p[i] = p[p[i]];
                i = p[i];
            }
            i
        }
        let mut uncertain: Vec<bool> = regions[first..]
            .iter()
            .map(|r| !self.is_confident(&r.fit) && !r.faces.is_empty())
            .collect();
        // An uncertain piece that a confident neighbour's primitive fits belongs to that
        // neighbour (e.g. a stretch of a cylinder first grown as a near-tolerance cone).
        let mut grown = vec![false; n];
        for i in 0..n {
            if !uncertain[i] {
                continue;
            }
            let mut shared: BTreeMap<usize, usize> = BTreeMap::new();
            for &f in &regions[first + i].faces {
                for &g in self.neighbours(f) {
                    let j = self.region_label[g as usize] as usize;
                    if j < n && j != i && !uncertain[j] && !regions[first + j].faces.is_empty() {
                        *shared.entry(j).or_insert(0) += 1;
                    }
                }
            }
            let mut order: Vec<(usize, usize)> = shared.into_iter().collect();
            order.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
            for (j, _) in order {
                let Some(fit) = regions[first + j].fit else {
                    continue;
                };
                if regions[first + i]
                    .faces
                    .iter()
                    .all(|&f| self.face_fits(&fit.surface, f))
                {
                    let moved = std::mem::take(&mut regions[first + i].faces);
                    for &f in &moved {
                        self.region_label[f as usize] = j as u32;
                    }
                    regions[first + j].faces.extend(moved);
                    grown[j] = true;
                    uncertain[i] = false;
                    break;
                }
            }
        }
        for j in 0..n {
            if grown[j] {
                let mut faces = std::mem::take(&mut regions[first + j].faces);
                faces.sort_unstable();
                if let Some(fit) = regions[first + j].fit.as_mut() {
                    let (pts, _) = self.points_and_normals(&faces);
                    fit.residuals = fit.surface.residuals(&pts);
                }
                regions[first + j].faces = faces;
            }
        }
        for i in 0..n {
            if !uncertain[i] {
                continue;
            }
            for &f in &regions[first + i].faces {
                for &g in self.neighbours(f) {
                    let j = self.region_label[g as usize] as usize;
                    if j < n && j != i && uncertain[j] {
                        let (a, b) = (root(&mut parent, i), root(&mut parent, j));
                        if a != b {
                            parent[a.max(b)] = a.min(b);
                        }
                    }
                }
            }
        }
        let kinds = self.opts.kinds.clone();
        let mut members = vec![0usize; n];
        for i in 0..n {
            let r = root(&mut parent, i);
            members[r] += 1;
            if r != i {
                let moved = std::mem::take(&mut regions[first + i].faces);
                regions[first + r].faces.extend(moved);
            }
        }
        for i in 0..n {
            if members[i] > 1 {
                let mut faces = std::mem::take(&mut regions[first + i].faces);
                faces.sort_unstable();
                regions[first + i].fit = self.fit_faces(&faces, &kinds);
                regions[first + i].faces = faces;
            }
        }
        for r in regions[first..].iter() {
            for &f in &r.faces {
                self.region_label[f as usize] = u32::MAX;
            }
        }
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
            let grown = self.grow(seed, state);
            match grown {
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
    let tol = checked_tolerance(mesh, opts)?;
    let mut seg = Segmenter::new(mesh, opts, tol);
    let components = seg.smooth_components();
    let mut regions = seg.classify_components(&components);
    seg.merge_small_regions(&mut regions);
    seg.merge_facets(&mut regions);
    // Groups in order of their first face.
    regions.sort_by_key(|r| r.faces[0]);
    let (out, infos) = seg.grouped_mesh(&regions);
    Ok((
        out,
        SegmentReport {
            tolerance: tol,
            sharp_edges: seg.sharp_edges,
            smooth_components: components.len(),
            regions: infos,
        },
    ))
}

/// Rejects meshes without faces and out-of-range options; returns the tolerance to use.
fn checked_tolerance(mesh: &ControlMesh, opts: &SegmentOptions) -> Result<f64> {
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
    opts.tolerance.checked(
        mesh.diagonal(),
        "segmentation tolerance (of a degenerate mesh?)",
    )
}

/// True when faces `f` and `g` meet at more than the sharp angle. Degenerate faces (zero
/// normal) have no reliable angle, so they are never sharp.
fn is_sharp_pair(normals: &[DVec3], cos_sharp: f64, f: u32, g: u32) -> bool {
    let (a, b) = (normals[f as usize], normals[g as usize]);
    a != DVec3::ZERO && b != DVec3::ZERO && a.dot(b) < cos_sharp
}

/// Neighbours of every face across its smooth manifold edges, as CSR (offsets, neighbours
/// sorted per face), and the number of manifold edges that are sharp.
fn smooth_adjacency(
    edges: &EdgeTable,
    normals: &[DVec3],
    cos_sharp: f64,
    nf: usize,
) -> (Vec<u32>, Vec<u32>, usize) {
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
        if is_sharp_pair(normals, cos_sharp, f, g) {
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
    (nbr_offsets, nbrs, sharp_count)
}

/// The boundary patch a region's primitive gives its group; everything but planes,
/// cylinders and cones is a closed patch.
fn patch_kind(primitive: Option<AnalyticSurface>) -> PatchKind {
    match primitive {
        Some(AnalyticSurface::Plane { .. }) => PatchKind::Boundary(BoundarySurface::Plane),
        Some(AnalyticSurface::Cylinder { axis, .. }) => {
            PatchKind::Boundary(BoundarySurface::Cylinder { axis })
        }
        Some(AnalyticSurface::Cone { axis, .. }) => PatchKind::Boundary(BoundarySurface::Cone {
            axis: Axis {
                origin: axis.origin,
                direction: axis.direction,
            },
        }),
        _ => PatchKind::Closed,
    }
}

/// Construction, the pipeline steps of [`segment`] (1-5 in the module documentation) and
/// the assembly of its output.
impl<'a> Segmenter<'a> {
    /// Computes face normals, the edge table and the smooth adjacency of `mesh`.
    fn new(mesh: &'a ControlMesh, opts: &'a SegmentOptions, tol: f64) -> Self {
        let nf = mesh.face_count();
        let (normals, areas) = face_normals_and_areas(mesh);
        let edges = EdgeTable::new(mesh);
        let cos_sharp = opts.sharp_angle_deg.to_radians().cos();
        let (nbr_offsets, nbrs, sharp_edges) = smooth_adjacency(&edges, &normals, cos_sharp, nf);
        Segmenter {
            mesh,
            opts,
            tol,
            cos_normal: opts.normal_angle_deg.to_radians().cos(),
            cos_sharp,
            edges,
            normals,
            areas,
            nbr_offsets,
            nbrs,
            sharp_edges,
            vertex_stamp: vec![0; mesh.vertex_count()],
            vertex_slot: vec![0; mesh.vertex_count()],
            face_stamp: vec![0; nf],
            region_label: vec![u32::MAX; nf],
            generation: 0,
        }
    }

    /// Step 1: the connected components of the smooth adjacency, each with ascending
    /// faces, in order of their lowest face.
    fn smooth_components(&self) -> Vec<Vec<u32>> {
        let nf = self.mesh.face_count();
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
                for &g in self.neighbours(f) {
                    if comp_of[g as usize] == UNLABELLED {
                        comp_of[g as usize] = c;
                        faces.push(g);
                    }
                }
            }
            faces.sort_unstable();
            components.push(faces);
        }
        components
    }

    /// Steps 2-3: a component that one primitive fits is one region; any other is split by
    /// region growing and its uncertain pieces merged.
    fn classify_components(&mut self, components: &[Vec<u32>]) -> Vec<Region> {
        let mut regions: Vec<Region> = Vec::new();
        let mut state = vec![FaceState::Free; self.mesh.face_count()];
        let kinds = self.opts.kinds.clone();
        for comp in components {
            if let Some(fit) = self.fit_faces(comp, &kinds) {
                regions.push(Region {
                    faces: comp.clone(),
                    fit: Some(fit),
                    from_split: false,
                });
            } else {
                let first = regions.len();
                self.split_component(comp, &mut state, &mut regions);
                self.merge_uncertain(&mut regions, first);
            }
        }
        regions
    }

    /// Step 4: slivers join the primitive they lie on, then fragments from splitting join
    /// their best smooth neighbour; emptied regions are dropped.
    fn merge_small_regions(&mut self, regions: &mut Vec<Region>) {
        let mut label = vec![UNLABELLED; self.mesh.face_count()];
        for (r, reg) in regions.iter().enumerate() {
            for &f in &reg.faces {
                label[f as usize] = r as u32;
            }
        }
        // Regions that grew need new residuals (`dirty`, their primitive still fits) or a
        // new fit (`refit`); both are recomputed once at the end: recomputing per merge
        // would be quadratic when many fragments join one region.
        let mut dirty = vec![false; regions.len()];
        let mut refit = vec![false; regions.len()];
        self.absorb_slivers(regions, &mut label, &mut dirty);
        self.merge_fragments(regions, &mut label, &mut dirty, &mut refit);
        self.update_grown_fits(regions, &dirty, &refit);
        regions.retain(|r| !r.faces.is_empty());
    }

    /// Tiny components bounded by sharp edges whose vertices all lie on an adjacent
    /// region's primitive are slivers with unreliable normals (common in decimated or
    /// exported tessellations): they join that region. Genuine small faces (a chamfer, a
    /// small boss top) are off the neighbours' surfaces and stay.
    fn absorb_slivers(&self, regions: &mut [Region], label: &mut [u32], dirty: &mut [bool]) {
        for s in 0..regions.len() {
            if regions[s].from_split
                || regions[s].faces.is_empty()
                || regions[s].faces.len() >= self.opts.min_region_triangles
            {
                continue;
            }
            for (t, _) in self.regions_across_edges(&regions[s].faces, s as u32, label) {
                let t = t as usize;
                let Some(fit) = regions[t].fit else { continue };
                if self.lies_on(&regions[s].faces, &fit.surface) {
                    let moved = std::mem::take(&mut regions[s].faces);
                    for &f in &moved {
                        label[f as usize] = t as u32;
                    }
                    regions[t].faces.extend(moved);
                    dirty[t] = true;
                    break;
                }
            }
        }
    }

    /// Regions other than `own` that share any edge (sharp ones included) with `faces`,
    /// with the number of shared face pairs, most shared first, then by region index.
    fn regions_across_edges(&self, faces: &[u32], own: u32, label: &[u32]) -> Vec<(u32, usize)> {
        let mesh = self.mesh;
        let mut shared: BTreeMap<u32, usize> = BTreeMap::new();
        for &f in faces {
            let base = mesh.face_offsets[f as usize] as usize;
            for k in 0..mesh.face(f as usize).len() {
                for &(g, _) in self.edges.faces(self.edges.face_edge[base + k] as usize) {
                    let l = label[g as usize];
                    if l != own && l != UNLABELLED {
                        *shared.entry(l).or_insert(0) += 1;
                    }
                }
            }
        }
        let mut order: Vec<(u32, usize)> = shared.into_iter().collect();
        order.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        order
    }

    /// True when every vertex of `faces` is within the tolerance of `primitive` (normals
    /// are not checked).
    fn lies_on(&self, faces: &[u32], primitive: &AnalyticSurface) -> bool {
        faces.iter().all(|&f| {
            self.mesh
                .face(f as usize)
                .iter()
                .all(|&v| primitive.distance(self.mesh.positions[v as usize]) <= self.tol)
        })
    }

    /// Merges fragments from splitting that are smaller than `min_region_triangles`,
    /// smallest first, into a smooth neighbour; an isolated fragment is kept. Marks the
    /// grown regions in `dirty` (fit kept) or `refit` (fit to be redone).
    fn merge_fragments(
        &self,
        regions: &mut [Region],
        label: &mut [u32],
        dirty: &mut [bool],
        refit: &mut [bool],
    ) {
        while let Some(s) = self.smallest_fragment(regions) {
            let Some((target, keep)) = self.fragment_target(regions, s, label) else {
                regions[s].from_split = false; // isolated: keep
                continue;
            };
            let moved = std::mem::take(&mut regions[s].faces);
            for &f in &moved {
                label[f as usize] = target;
            }
            let t = target as usize;
            regions[t].faces.extend(moved);
            if keep {
                dirty[t] = true;
            } else {
                refit[t] = true;
            }
        }
    }

    /// The smallest (then lowest-index) non-empty region from splitting that is below
    /// `min_region_triangles`.
    fn smallest_fragment(&self, regions: &[Region]) -> Option<usize> {
        regions
            .iter()
            .enumerate()
            .filter(|(_, r)| {
                r.from_split
                    && !r.faces.is_empty()
                    && r.faces.len() < self.opts.min_region_triangles
            })
            .min_by_key(|(i, r)| (r.faces.len(), *i))
            .map(|(i, _)| i)
    }

    /// The smooth neighbour fragment `s` should join and whether that neighbour's
    /// primitive fits it. Prefers a neighbour whose primitive already fits the fragment;
    /// among those (or among all if none fits), the one sharing the most edges, then the
    /// lowest index.
    fn fragment_target(&self, regions: &[Region], s: usize, label: &[u32]) -> Option<(u32, bool)> {
        let mut shared: BTreeMap<u32, usize> = BTreeMap::new();
        for &f in &regions[s].faces {
            for &g in self.neighbours(f) {
                let l = label[g as usize];
                if l != s as u32 && l != UNLABELLED {
                    *shared.entry(l).or_insert(0) += 1;
                }
            }
        }
        let fits_fragment = |r: &Region| {
            r.fit.as_ref().is_some_and(|fit| {
                regions[s]
                    .faces
                    .iter()
                    .all(|&f| self.face_fits(&fit.surface, f))
            })
        };
        let best = |want_fit: bool| {
            shared
                .iter()
                .filter(|(&l, _)| !want_fit || fits_fragment(&regions[l as usize]))
                .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
                .map(|(&l, _)| (l, want_fit))
        };
        best(true).or_else(|| best(false))
    }

    /// Recomputes the residuals of the `dirty` regions under their primitive, and refits
    /// the `refit` ones (refined from their primitive, else fitted afresh).
    fn update_grown_fits(&mut self, regions: &mut [Region], dirty: &[bool], refit: &[bool]) {
        let kinds = self.opts.kinds.clone();
        for t in 0..regions.len() {
            if regions[t].faces.is_empty() || !(dirty[t] || refit[t]) {
                continue;
            }
            let mut faces = std::mem::take(&mut regions[t].faces);
            faces.sort_unstable();
            let old = regions[t].fit.map(|f| f.surface);
            regions[t].fit = match old {
                Some(p) if !refit[t] => {
                    let (pts, _) = self.points_and_normals(&faces);
                    Some(SurfaceFit {
                        surface: p,
                        residuals: p.residuals(&pts),
                    })
                }
                Some(p) => self
                    .refine_faces(&faces, &p)
                    .or_else(|| self.fit_faces(&faces, &kinds)),
                None => None,
            };
            regions[t].faces = faces;
        }
    }

    /// Step 5: merges regions across moderately sharp edges when one primitive fits the
    /// union confidently and every face normal agrees with it (coarse facets of one
    /// surface). Each region merges at most once per round; rounds repeat while any merge
    /// happens.
    fn merge_facets(&mut self, regions: &mut Vec<Region>) {
        let cos_facet = self.opts.facet_merge_angle_deg.to_radians().cos();
        for _round in 0..8 {
            let candidates = self.facet_merge_candidates(regions, cos_facet);
            let mut touched = vec![false; regions.len()];
            let mut merged = false;
            for (a, b) in candidates {
                if touched[a] || touched[b] {
                    continue;
                }
                if self.merge_facet_pair(regions, a, b) {
                    touched[a] = true;
                    touched[b] = true;
                    merged = true;
                }
            }
            regions.retain(|r| !r.faces.is_empty());
            if !merged {
                break;
            }
        }
    }

    /// Pairs of adjacent regions (lower index first) whose shared edges are all no sharper
    /// than `cos_facet`, most shared edges first, then by index.
    fn facet_merge_candidates(&self, regions: &[Region], cos_facet: f64) -> Vec<(usize, usize)> {
        let mut label = vec![0u32; self.mesh.face_count()];
        for (r, reg) in regions.iter().enumerate() {
            for &f in &reg.faces {
                label[f as usize] = r as u32;
            }
        }
        // (region a < region b) -> (shared edges, min normal dot across them)
        let mut pairs: BTreeMap<(u32, u32), (usize, f64)> = BTreeMap::new();
        for e in 0..self.edges.len() {
            let fs = self.edges.faces(e);
            if fs.len() != 2 {
                continue;
            }
            let (f, g) = (fs[0].0 as usize, fs[1].0 as usize);
            let (a, b) = (label[f], label[g]);
            if a == b {
                continue;
            }
            let d = self.normals[f].dot(self.normals[g]);
            let entry = pairs.entry((a.min(b), a.max(b))).or_insert((0, 1.0));
            entry.0 += 1;
            entry.1 = entry.1.min(d);
        }
        let mut cands: Vec<((u32, u32), usize)> = pairs
            .into_iter()
            .filter(|(_, (_, d))| *d >= cos_facet)
            .map(|(k, (n, _))| (k, n))
            .collect();
        cands.sort_by(|x, y| y.1.cmp(&x.1).then(x.0.cmp(&y.0)));
        cands
            .into_iter()
            .map(|((a, b), _)| (a as usize, b as usize))
            .collect()
    }

    /// Moves region `b` into region `a` if both are pieces of the same curved kind and one
    /// primitive, refined from the larger piece's, fits the union confidently with every
    /// face normal agreeing. Returns whether they merged.
    fn merge_facet_pair(&mut self, regions: &mut [Region], a: usize, b: usize) -> bool {
        // Only pieces of the same curved kind (two strips of one coarse cylinder, two
        // patches of one sphere); a plane next to a plane across a sharp edge, or a
        // plane strip next to a curved piece, stays apart (ambiguous on facets).
        let (Some(fa), Some(fb)) = (regions[a].fit, regions[b].fit) else {
            return false;
        };
        let kind = fa.surface.kind();
        if kind == SurfaceKind::Plane || fb.surface.kind() != kind {
            return false;
        }
        let mut faces = regions[a].faces.clone();
        faces.extend_from_slice(&regions[b].faces);
        faces.sort_unstable();
        let start = if regions[a].faces.len() >= regions[b].faces.len() {
            fa.surface
        } else {
            fb.surface
        };
        let Some(fit) = self.refine_faces(&faces, &start) else {
            return false;
        };
        if !self.is_confident(&Some(fit)) || !faces.iter().all(|&f| self.face_fits(&fit.surface, f))
        {
            return false;
        }
        regions[a].faces = faces;
        regions[a].fit = Some(fit);
        regions[b].faces.clear();
        true
    }

    /// The input mesh with one group per region, in region order, its sharp group
    /// boundaries marked, and the report entry of each region.
    fn grouped_mesh(&self, regions: &[Region]) -> (ControlMesh, Vec<RegionInfo>) {
        let mut out = self.mesh.clone();
        out.groups.clear();
        let mut infos = Vec::with_capacity(regions.len());
        for (i, r) in regions.iter().enumerate() {
            out.groups.push(Group {
                name: format!("face_{i}"),
                patch: patch_kind(r.fit.map(|f| f.surface)),
            });
            for &f in &r.faces {
                out.face_groups[f as usize] = i as u32;
            }
            infos.push(self.region_info(r));
        }
        self.mark_sharp_group_boundaries(&mut out);
        (out, infos)
    }

    /// The report entry of one region.
    fn region_info(&self, r: &Region) -> RegionInfo {
        RegionInfo {
            kind: r
                .fit
                .map(|f| RegionKind::Analytic(f.surface.kind()))
                .unwrap_or(RegionKind::Freeform),
            triangles: r.faces.len(),
            area: r.faces.iter().map(|&f| self.areas[f as usize]).sum(),
            surface: r.fit.map(|f| f.surface),
            residuals: r.fit.map(|f| f.residuals),
        }
    }

    /// Adds to `out.sharp_edges` every manifold edge between two groups whose dihedral
    /// angle is sharp.
    fn mark_sharp_group_boundaries(&self, out: &mut ControlMesh) {
        let edges = &self.edges;
        for e in 0..edges.len() {
            let fs = edges.faces(e);
            if fs.len() == 2 {
                let (f, g) = (fs[0].0, fs[1].0);
                if out.face_groups[f as usize] != out.face_groups[g as usize]
                    && is_sharp_pair(&self.normals, self.cos_sharp, f, g)
                {
                    let (a, b) = edges.keys[e];
                    out.set_sharp(a, b);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::test_support::{grid_cube, load_corpus};

    /// An open strip: plane z = 0 (x in [-2, 0]), a quarter-cylinder fillet of radius 1
    /// (axis along y through (0, *, 1)) and the plane x = 1 (z in [1, 3]); all joins are
    /// tangent, so there is no sharp edge. Returns the mesh and the triangle counts
    /// (plane, fillet, plane).
    fn fillet_strip() -> (ControlMesh, [usize; 3]) {
        let mut profile: Vec<(f64, f64)> = Vec::new();
        let (n_plane, n_arc, m) = (8, 12, 6);
        for i in 0..n_plane {
            profile.push((-2.0 + 2.0 * i as f64 / n_plane as f64, 0.0));
        }
        for i in 0..n_arc {
            let t = -std::f64::consts::FRAC_PI_2
                + std::f64::consts::FRAC_PI_2 * i as f64 / n_arc as f64;
            profile.push((t.cos(), 1.0 + t.sin()));
        }
        for i in 0..=n_plane {
            profile.push((1.0, 1.0 + 2.0 * i as f64 / n_plane as f64));
        }
        let mut mesh = ControlMesh::new();
        let g = mesh.push_group("all", PatchKind::Closed);
        for j in 0..=m {
            for &(x, z) in &profile {
                mesh.push_vertex(DVec3::new(x, 2.0 * j as f64 / m as f64, z));
            }
        }
        let w = profile.len() as u32;
        for j in 0..m as u32 {
            for i in 0..w - 1 {
                let (a, b) = (j * w + i, j * w + i + 1);
                let (c, d) = (a + w, b + w);
                mesh.push_face(&[a, c, d], g);
                mesh.push_face(&[a, d, b], g);
            }
        }
        (mesh, [2 * n_plane * m, 2 * n_arc * m, 2 * n_plane * m])
    }

    #[test]
    fn cube_is_six_planes() {
        let m = grid_cube(5);
        let (out, rep) = segment(&m, &SegmentOptions::default()).unwrap();
        out.validate().unwrap();
        assert_eq!(rep.regions.len(), 6);
        assert_eq!(rep.smooth_components, 6);
        assert!(out
            .groups
            .iter()
            .all(|g| g.patch == PatchKind::Boundary(BoundarySurface::Plane)));
        // Every face of one input side lands in one group.
        for f in 0..m.face_count() {
            let same_side: Vec<usize> = (0..m.face_count())
                .filter(|&g| m.face_groups[g] == m.face_groups[f])
                .collect();
            assert!(same_side
                .iter()
                .all(|&g| out.face_groups[g] == out.face_groups[f]));
        }
        // All 12 cube edges (5 mesh edges each) are sharp.
        assert_eq!(out.sharp_edges.len(), 60);
        assert_eq!(rep.sharp_edges, 60);
        assert_eq!(out.groups[0].name, "face_0");
    }

    #[test]
    fn tangent_fillet_is_split_at_curvature_change() {
        let (m, counts) = fillet_strip();
        let (out, rep) = segment(&m, &SegmentOptions::default()).unwrap();
        assert_eq!(rep.smooth_components, 1);
        assert_eq!(rep.sharp_edges, 0);
        assert!(out.sharp_edges.is_empty());
        let mut got: Vec<(RegionKind, usize)> =
            rep.regions.iter().map(|r| (r.kind, r.triangles)).collect();
        got.sort();
        let mut want = vec![
            (RegionKind::Analytic(SurfaceKind::Plane), counts[0]),
            (RegionKind::Analytic(SurfaceKind::Plane), counts[2]),
            (RegionKind::Analytic(SurfaceKind::Cylinder), counts[1]),
        ];
        want.sort();
        assert_eq!(got, want, "{}", rep.summary());
        let cyl = rep
            .regions
            .iter()
            .find_map(|r| match r.surface {
                Some(AnalyticSurface::Cylinder { axis, radius }) => Some((axis, radius)),
                _ => None,
            })
            .unwrap();
        assert!((cyl.1 - 1.0).abs() < 1e-6);
        assert!(cyl.0.direction.dot(DVec3::Y).abs() > 1.0 - 1e-9);
        let off = cyl.0.origin - DVec3::new(0.0, 0.0, 1.0);
        assert!((off - off.dot(DVec3::Y) * DVec3::Y).length() < 1e-6);
        // The patch kind carries the axis.
        assert!(out.groups.iter().any(|g| matches!(
            g.patch,
            PatchKind::Boundary(BoundarySurface::Cylinder { .. })
        )));
        // Deterministic.
        let (out2, rep2) = segment(&m, &SegmentOptions::default()).unwrap();
        assert_eq!(out, out2);
        assert_eq!(rep, rep2);
    }

    #[test]
    fn rejects_bad_input() {
        let (m, _) = fillet_strip();
        let bad = |o: SegmentOptions| segment(&m, &o).is_err();
        assert!(bad(SegmentOptions {
            sharp_angle_deg: 0.0,
            ..Default::default()
        }));
        assert!(bad(SegmentOptions {
            sharp_angle_deg: f64::NAN,
            ..Default::default()
        }));
        assert!(bad(SegmentOptions {
            tolerance: Tolerance::Absolute(-1.0),
            ..Default::default()
        }));
        assert!(bad(SegmentOptions {
            normal_angle_deg: 120.0,
            ..Default::default()
        }));
        assert!(segment(&ControlMesh::new(), &SegmentOptions::default()).is_err());
        let mut broken = m.clone();
        broken.face_vertices[0] = 1_000_000;
        assert!(segment(&broken, &SegmentOptions::default()).is_err());
    }

    /// Segments a grouped corpus model while ignoring its groups and checks that regions
    /// and true CAD faces correspond one to one, with the right surface types.
    fn check_exact(name: &str, want: &[(RegionKind, usize)]) {
        let Some(m) = load_corpus(name) else { return };
        let (out, rep) = segment(&m, &SegmentOptions::default()).unwrap();
        let mut pairs: Vec<(u32, u32)> = (0..m.face_count())
            .map(|f| (m.face_groups[f], out.face_groups[f]))
            .collect();
        pairs.sort_unstable();
        pairs.dedup();
        assert_eq!(pairs.len(), m.groups.len(), "{name}: {}", rep.summary());
        assert_eq!(
            out.groups.len(),
            m.groups.len(),
            "{name}: {}",
            rep.summary()
        );
        let counts = rep.counts();
        for (k, n) in want {
            assert_eq!(counts.get(k), Some(n), "{name}: {}", rep.summary());
        }
    }

    #[test]
    fn corpus_models_with_exact_answers() {
        use SurfaceKind::*;
        let p = RegionKind::Analytic;
        check_exact(
            "abc/abc_00000006.obj",
            &[(p(Plane), 8), (p(Cone), 6), (p(Cylinder), 1)],
        );
        check_exact("tess/four_cone_coarse.obj", &[(p(Plane), 6), (p(Cone), 4)]);
        check_exact(
            "tess/block_fillet3_coarse.obj",
            &[(p(Plane), 6), (p(Cylinder), 3), (p(Sphere), 1)],
        );
        check_exact("tess/tr8_bv1_ec_coarse.obj", &[(p(Plane), 18)]);
    }

    #[test]
    fn fandisk_regions() {
        let Some(m) = load_corpus("meshes/fandisk.obj") else {
            return;
        };
        let (out, rep) = segment(&m, &SegmentOptions::default()).unwrap();
        out.validate().unwrap();
        let counts = rep.counts();
        let n = rep.regions.len();
        assert!((15..=35).contains(&n), "{}", rep.summary());
        assert!(counts
            .get(&RegionKind::Analytic(SurfaceKind::Plane))
            .is_some_and(|&c| c >= 5));
        assert!(counts
            .get(&RegionKind::Analytic(SurfaceKind::Cylinder))
            .is_some_and(|&c| c >= 3));
        // Every primitive region is within the tolerance.
        for r in &rep.regions {
            if let Some(res) = r.residuals {
                assert!(res.max <= rep.tolerance * (1.0 + 1e-9));
            }
        }
        // The segmentation feeds the curve network: its invariants hold.
        let net = crate::fit::curves::build_curve_network(&out, &Default::default()).unwrap();
        crate::fit::curves::tests::check_network(&out, &net, "fandisk segmentation");
        // Sharp edges only on group boundaries.
        let edges = EdgeTable::new(&out);
        for &(a, b) in &out.sharp_edges {
            let e = edges.find(a, b).unwrap();
            let fs = edges.faces(e);
            assert!(
                fs.len() == 2
                    && out.face_groups[fs[0].0 as usize] != out.face_groups[fs[1].0 as usize]
            );
        }
    }

    #[test]
    fn meshes_without_labels_segment_cleanly() {
        // Non-manifold (crank) and organic-looking (rocker arm) inputs: no errors, valid
        // output, every face in a group, curve network builds.
        for name in [
            "meshes/block.off",
            "meshes/crank.off",
            "meshes/rocker-arm.obj",
        ] {
            let Some(m) = load_corpus(name) else { return };
            let (out, rep) = segment(&m, &SegmentOptions::default()).unwrap();
            out.validate().unwrap();
            assert_eq!(out.groups.len(), rep.regions.len());
            assert_eq!(
                rep.regions.iter().map(|r| r.triangles).sum::<usize>(),
                m.face_count()
            );
            let net = crate::fit::curves::build_curve_network(&out, &Default::default());
            assert!(net.is_ok(), "{name}: {:?}", net.err());
            println!("{name}: {}", rep.summary());
        }
    }
}
