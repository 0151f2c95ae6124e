//! The fit's error measurement: the decoded surface against the input (or a reference
//! tessellation of the same faces), both ways, per CAD face.
//!
//! A refinement round changes a few faces and leaves the others' decoded surfaces as they
//! were, so the measurement is kept per face ([`GroupDecoded`]): a face whose decoded
//! triangles did not change keeps its closest-point index, its samples and their distances to
//! the input, and only changed faces are subdivided, indexed, sampled and queried again.
//! "Did not change" is decided on the control mesh, before anything is subdivided: a face
//! bounded by sharp edges decodes to triangles that are a function of its own control faces
//! and of the classes and frames of their vertices and edges ([`crate::subdiv::support`]),
//! whose fingerprint is kept. The changed faces are subdivided on the control faces around
//! them alone, so a round that refits a few faces subdivides a few faces' worth, not the
//! model. When another face gains control points the control mesh is numbered anew; the
//! fingerprints describe faces by their corners' positions, so an unchanged face stays
//! unchanged, and its kept measurement is of the surface the decoder makes of it up to
//! last-bit roundings. The encoder's decisions stay a function of its inputs alone (the same
//! bytes on every run and thread count).
//!
//! The samples are those `scode info --against` takes of a file ([`ErrorMeter::new`]), so
//! the last measurement, of the control mesh the file stores, gives the file's figures: the
//! encoder prints them and holds the tolerance to them without measuring the file again.
//!
//! At a fine level the decoded surface has millions of triangles, so nothing holds all of
//! them twice: the surface is handed out face by face ([`UniformSurface`]), a changed face's
//! old index is dropped before its new one is built, and decoded samples are made as they
//! are measured.

use std::sync::Mutex;

use glam::DVec3;

use super::allowance::OwnFaces;
use super::encoder::FitError;
use super::map_ordered;
use crate::error::Result;
use crate::mesh::{edge_key, ControlMesh};
use crate::metrics::{
    box_distance, closest_points_near, closest_points_near_with, edge_spacing_for_tolerance,
    reference_samples, sample_density, space_filling_order, surface_area, DistanceOptions,
    EdgeSamples, SurfaceSample, TriangleSamples, TriangleSurface,
};
use crate::subdiv::par::for_each_heavy;
use crate::subdiv::support::Supports;
use crate::subdiv::{UniformSurface, DEFAULT_MAX_FACES};

/// Error of a decoded surface against the input, measured both ways.
pub(crate) struct Measurement {
    pub error: FitError,
    /// Per input group: largest excess over the chord allowance, where, and which way.
    pub group_excess: Vec<(f64, DVec3, &'static str)>,
    /// Per input group: the sample points (both ways) whose excess is over the tolerance,
    /// for refining closed patches where they fail.
    pub bad_points: Vec<Vec<DVec3>>,
    /// Faces whose decoded triangles changed since the previous measurement, which were
    /// indexed, sampled and measured again (the others kept their results).
    pub changed_groups: usize,
}

/// One face's decoded triangles and what was measured on them. Everything in it is a
/// function of the triangles' corners alone (and of the input, which never changes), so it
/// is reused while the face's support is unchanged ([`MeasureCache::supports`]).
struct GroupDecoded {
    /// Closest-point index over the face's decoded triangles; `None` for a face without any.
    surface: Option<TriangleSurface>,
    /// Bounding box of the corners: a point farther from it than a distance already found
    /// cannot find a nearer point on this face.
    lo: DVec3,
    hi: DVec3,
    /// Per decoded sample ([`GroupSamples`]): its excess over the input's chord allowance
    /// (see [`OwnFaces::excess`]) and its plain distance to the input. The points are not
    /// kept (a face at a fine level has millions of samples): [`GroupSamples`] makes any of
    /// them again.
    samples: Vec<[f64; 2]>,
    /// How many of `samples` are vertices and area-weighted points (the mean and RMS are
    /// theirs, but for the `shared` vertices; the rest are edge points, for the max).
    area_samples: usize,
    /// The vertices (sample indices, increasing) that an earlier face also holds: counted in
    /// its mean and RMS, not in this one's ([`first_groups`]).
    shared: Vec<u32>,
    /// The sample of largest excess (its excess and point), if any.
    worst: Option<(f64, DVec3)>,
    /// The samples whose excess is over the tolerance (index, point), in sample order.
    over_tolerance: Vec<(u32, DVec3)>,
}

impl GroupDecoded {
    /// Distance from `p` to the box (0 inside).
    fn box_distance(&self, p: DVec3) -> f64 {
        box_distance(self.lo, self.hi, p)
    }
}

/// The decoded samples of one face: its vertices, then its random points by area
/// ([`TriangleSamples`], a function of each triangle alone, so an unchanged face keeps its
/// points), then points along its thin triangles' long edges ([`EdgeSamples`]). Each is made
/// on its own, when needed, in an order where neighbours follow each other.
struct GroupSamples<'a> {
    /// The face's vertices (every one is a corner of its triangles).
    vertices: &'a [DVec3],
    random: TriangleSamples<'a>,
    /// Points along the long edges of its thin triangles, the slivers random points miss.
    edges: EdgeSamples<'a>,
}

impl<'a> GroupSamples<'a> {
    /// The samples of a face's `triangles` over its own `positions` (all of them corners).
    fn new(
        positions: &'a [DVec3],
        triangles: &'a [[u32; 3]],
        density: f64,
        seed: u64,
        spacing: f64,
    ) -> Self {
        GroupSamples {
            vertices: positions,
            random: TriangleSamples::new(positions, triangles, density, seed),
            edges: EdgeSamples::new(positions, triangles, spacing),
        }
    }

    fn len(&self) -> usize {
        self.vertices.len() + self.random.len() + self.edges.len()
    }

    fn point(&self, i: usize) -> DVec3 {
        let (nv, nr) = (self.vertices.len(), self.random.len());
        match self.vertices.get(i) {
            Some(&p) => p,
            None if i < nv + nr => self.random.get(i - nv).point,
            None => self.edges.get(i - nv - nr).point,
        }
    }
}

/// An input sample's distance to the decoded surface and the group holding its nearest
/// point.
#[derive(Clone, Copy)]
struct InHit {
    distance: f64,
    group: u32,
}

impl InHit {
    const NONE: InHit = InHit {
        distance: f64::INFINITY,
        group: u32::MAX,
    };
}

/// What the previous full measurement kept for the next one.
#[derive(Default)]
struct MeasureCache {
    /// By group: its decoded triangles and their measurement; `None` where nothing is kept
    /// (a group that changed in a measurement that stopped at its probe: its old results
    /// were dropped before the new ones were made, so that the two never take memory at
    /// once).
    groups: Vec<Option<GroupDecoded>>,
    /// The decode level and each group's support fingerprint ([`Supports::fingerprints`])
    /// of the control mesh `groups` were measured on.
    level: u8,
    supports: Vec<Option<u64>>,
    /// Input->decoded, per input sample: its distance and the group of its nearest decoded
    /// point. While that group is unchanged the distance is still reachable, so only changed
    /// groups can bring it down.
    in_hits: Vec<InHit>,
    /// Input samples that were worst last time, and decoded samples (group, index), probed
    /// first by [`ErrorMeter::measure_unless_over`].
    probe_in: Vec<usize>,
    probe_out: Vec<(u32, u32)>,
}

/// Measures decoded surfaces against one input: its samples, index and chord allowance are
/// built once and reused by every round.
pub(crate) struct ErrorMeter<'a> {
    mesh: &'a ControlMesh,
    /// Vertices and area-weighted points, then edge points ([`EdgeSamples`]).
    input_samples: Vec<SurfaceSample>,
    /// How many of `input_samples` come before the edge points (the mean and RMS are theirs).
    input_area_samples: usize,
    /// The input samples along a space-filling curve ([`space_filling_order`]): the order
    /// their queries run in, each bounded by the previous hit.
    input_order: Vec<u32>,
    input_surface: &'a TriangleSurface,
    chord: &'a [f64],
    /// Each input face on its own, for the decoded->input excess ([`OwnFaces::excess`]).
    own_faces: OwnFaces<'a>,
    /// The input is a B-rep's tessellation: the excess is the distance to the B-rep (as
    /// [`OwnFaces::against`] bounds it), which the reported distances are too; the plain
    /// distance to the facets is no distance the user can check.
    brep: bool,
    /// Random decoded samples per unit area and their seed ([`TriangleSamples`]): a face's
    /// points depend on its triangles alone, so an unchanged face keeps its samples.
    density: f64,
    seed: u64,
    /// Bounding box of each input group's triangles (which hold its samples): a lower
    /// bound of its samples' distances to any decoded face ([`search_orders`]).
    group_boxes: Vec<(DVec3, DVec3)>,
    tol: f64,
    /// Spacing of the points along decoded and input edges ([`EdgeSamples`]): the
    /// tolerance's ([`edge_spacing_for_tolerance`]), at least as dense as `scode info
    /// --against`'s.
    edge_spacing: f64,
    /// Behind a lock only so the meter can be shared by the parallel queries; one
    /// measurement at a time holds it.
    cache: Mutex<MeasureCache>,
}

/// Changed groups are subdivided in runs of at most this many level-n triangles each
/// ([`Supports::runs`]): a run's level-n surface (about 40 bytes a triangle) is what the
/// measurement holds beside the indexes at its peak. Each run also subdivides the ring of
/// faces around it and gives the parallel indexing fewer groups, so a model that fits in one
/// run is not cut.
const RUN_TRIANGLES: u64 = 1 << 23;

/// Input samples are measured in chunks of this many along their space-filling curve, each
/// query bounded by the previous one's hit ([`ErrorMeter::input_to_decoded`]); fixed, so the
/// answers do not depend on the thread count.
const IN_CHUNK: usize = 256;

/// How many of the worst samples of each direction a probe tests.
const PROBE_SAMPLES: usize = 2000;

/// Triangles of one leaf of a face's closest-point index (subdivision lists the
/// descendants of each control face together, so runs of output triangles are compact).
const LEAF_TRIANGLES: usize = 16;

/// The ids of the (up to) `k` largest of `values` (`(value, id)` pairs, ids increasing),
/// ties to the smaller id, in id order. A bounded heap, so millions of values need no array.
fn top_k<T: Ord + Copy>(values: impl Iterator<Item = (f64, T)>, k: usize) -> Vec<T> {
    /// Ordered so that the heap's greatest entry is the one to give up first: the smallest
    /// value, then the largest id.
    struct Kept<T>(f64, T);
    impl<T: Ord> Ord for Kept<T> {
        fn cmp(&self, other: &Self) -> std::cmp::Ordering {
            other.0.total_cmp(&self.0).then(self.1.cmp(&other.1))
        }
    }
    impl<T: Ord> PartialOrd for Kept<T> {
        fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
            Some(self.cmp(other))
        }
    }
    impl<T: Ord> PartialEq for Kept<T> {
        fn eq(&self, other: &Self) -> bool {
            self.cmp(other).is_eq()
        }
    }
    impl<T: Ord> Eq for Kept<T> {}
    let mut heap = std::collections::BinaryHeap::with_capacity(k + 1);
    for (v, id) in values {
        let x = Kept(v, id);
        if heap.len() < k {
            heap.push(x);
        } else if heap.peek().is_some_and(|worst| x < *worst) {
            // Usually not: most values are not among the largest.
            heap.pop();
            heap.push(x);
        }
    }
    let mut ids: Vec<T> = heap.into_iter().map(|x| x.1).collect();
    ids.sort_unstable();
    ids
}

impl<'a> ErrorMeter<'a> {
    /// A meter of `mesh` (triangulated: `triangles` are its faces), sampling both sides as
    /// `scode info --against` does with `opts` (its samples and seed; the edge spacing is
    /// the tolerance's, [`edge_spacing_for_tolerance`]): the input's vertices, random and
    /// edge points ([`reference_samples`]), the decoded surface's vertices, random points
    /// at the same density per unit of the input's area ([`TriangleSamples`]) and edge
    /// points. Its measurement of a file's control mesh is then the one `scode info
    /// --against` makes of the file, with edge points at least as dense.
    pub fn new(
        mesh: &'a ControlMesh,
        triangles: &[[u32; 3]],
        input_surface: &'a TriangleSurface,
        chord: &'a [f64],
        own_faces: OwnFaces<'a>,
        opts: &DistanceOptions,
        tol: f64,
    ) -> Self {
        let edge_spacing = edge_spacing_for_tolerance(tol, mesh.diagonal());
        let (mut input_samples, input_area_samples) =
            reference_samples(&mesh.positions, triangles, opts, edge_spacing);
        // A face with an exact surface is that surface: its facets' samples are moved onto
        // it, the points whose distance to the decoded surface the tolerance bounds.
        if !own_faces.exact.is_empty() {
            for s in &mut input_samples {
                let g = mesh.face_groups[s.triangle as usize] as usize;
                if let Some(Some(e)) = own_faces.exact.get(g) {
                    s.point = e.project(s.point);
                }
            }
        }
        let mut group_boxes = vec![(DVec3::INFINITY, DVec3::NEG_INFINITY); mesh.groups.len()];
        for (t, g) in triangles.iter().zip(&mesh.face_groups) {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            if let Some((lo, hi)) = group_boxes.get_mut(*g as usize) {
                *lo = lo.min(a).min(b).min(c);
                *hi = hi.max(a).max(b).max(c);
            }
        }
        let density = sample_density(opts, surface_area(&mesh.positions, triangles));
        let input_order = space_filling_order(input_samples.iter().map(|s| s.point));
        ErrorMeter {
            mesh,
            input_order,
            input_samples,
            input_area_samples,
            input_surface,
            chord,
            brep: !own_faces.exact.is_empty() || !own_faces.facet_chord.is_empty(),
            own_faces,
            density,
            seed: opts.seed,
            group_boxes,
            tol,
            edge_spacing,
            cache: Default::default(),
        }
    }

    /// `decoded` is the control mesh as the decoder sees it, with the input's group order.
    pub fn measure(&self, decoded: &ControlMesh, level: u8) -> Result<Measurement> {
        Ok(self
            .measure_unless_over(decoded, level, None)?
            .expect("no probe without a bound"))
    }

    /// By group of `groups`: an estimate of how far the last measured decoded triangles
    /// stray from the limit surface between their corners (their chord error; 0 for a face
    /// without triangles). Across each edge two triangles of a face turn by the angle `θ`
    /// between their normals over their mean height `h` above the edge: a surface that bends
    /// by `θ` over `h` stands off a chord of length `h` by about `h θ / 8` (a circular arc).
    /// The largest over the face's edges.
    pub fn chord_errors(&self, groups: &[usize]) -> Vec<f64> {
        let cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        groups
            .iter()
            .map(|&g| {
                cache
                    .groups
                    .get(g)
                    .and_then(Option::as_ref)
                    .and_then(|gd| gd.surface.as_ref())
                    .map_or(0.0, |s| chord_error(s.positions(), s.triangles()))
            })
            .collect()
    }

    /// The distance a sample reports, given its `excess` and its `plain` distance to the
    /// facets: the plain one, but against a B-rep the excess ([`ErrorMeter::brep`]).
    fn shown(&self, excess: f64, plain: f64) -> f64 {
        if self.brep {
            excess.max(0.0)
        } else {
            plain
        }
    }

    /// The excess of a decoded point of group `g` whose nearest input triangle is `hit`
    /// at `distance`.
    fn out_excess(&self, p: DVec3, g: usize, hit: u32, distance: f64) -> f64 {
        self.own_faces.excess(
            p,
            g,
            self.mesh.face_groups[hit as usize] as usize,
            distance - self.chord[hit as usize],
            self.chord,
        )
    }

    /// The decoded point nearest input sample `p`, searching the groups of `order` (the
    /// sample's input group's [`search_orders`] entry) while their lower bound is below the
    /// best distance so far; `best` is a distance to a point of the decoded surface already
    /// reached, if any: it is the answer unless a nearer point is found, whose position is
    /// then returned too.
    fn nearest_decoded(
        p: DVec3,
        groups: &[&GroupDecoded],
        order: &[(f64, u32)],
        best: Option<InHit>,
    ) -> (Option<InHit>, Option<DVec3>) {
        let (mut best, mut point) = (best, None);
        for &(bound, g) in order {
            let limit = best.map_or(f64::INFINITY, |b| b.distance);
            if bound > limit {
                break;
            }
            let gd = groups[g as usize];
            if gd.box_distance(p) > limit {
                continue;
            }
            let Some(s) = &gd.surface else { continue };
            let hit = if limit.is_finite() {
                s.closest_point_within(p, limit * (1.0 + 1e-9) + 1e-300)
            } else {
                Some(s.closest_point(p))
            };
            if let Some(h) = hit.filter(|h| h.distance < limit) {
                best = Some(InHit {
                    distance: h.distance,
                    group: g,
                });
                point = Some(h.point);
            }
        }
        (best, point)
    }

    /// Like [`ErrorMeter::measure`], but with `over = Some(max_cap)` first measures the
    /// samples that were worst last time and returns `None` as soon as one of them shows
    /// the full measurement would exceed the tolerance beyond the chord allowance or
    /// `max_cap` (exact: they are samples of the full measurement). A measurement that
    /// returns `None` keeps what the previous one kept, except, when it was an input sample
    /// that failed, for the groups that changed (their new indexes had been built by then).
    pub fn measure_unless_over(
        &self,
        decoded: &ControlMesh,
        level: u8,
        over: Option<f64>,
    ) -> Result<Option<Measurement>> {
        let n_groups = self.mesh.groups.len().max(decoded.groups.len());
        let support = Supports::new(decoded);
        let mut supports = support.fingerprints()?;
        supports.resize(n_groups, None);
        let mut cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        cache.groups.resize_with(n_groups, || None);
        let same_level = cache.level == level;
        let changed: Vec<usize> = (0..n_groups)
            .filter(|&g| {
                !same_level
                    || cache.groups[g].is_none()
                    || supports[g].is_none()
                    || cache.supports.get(g) != Some(&supports[g])
            })
            .collect();
        // Only the changed groups' triangles are read: their supports are subdivided alone
        // (the whole mesh when every group changed, or when one is not sharp-bounded).
        let subdivide = |groups: &[usize]| -> Result<Option<UniformSurface>> {
            if groups.is_empty() {
                return Ok(None);
            }
            let part = (groups.len() < n_groups)
                .then(|| support.submesh(groups))
                .flatten();
            let mesh = part.as_ref().unwrap_or(decoded);
            UniformSurface::new(mesh, u32::from(level), DEFAULT_MAX_FACES).map(Some)
        };
        if let Some(max_cap) = over {
            // The probe reads the probed groups alone: a failing probe (the common case
            // of a coarser quantisation, which moves every vertex) subdivides a few groups.
            let mut probed: Vec<usize> = cache
                .probe_out
                .iter()
                .map(|&(g, _)| g as usize)
                .filter(|g| changed.binary_search(g).is_ok())
                .collect();
            probed.dedup();
            let surface = subdivide(&probed)?;
            if self.decoded_probe_fails(&cache, &changed, surface.as_ref(), max_cap) {
                return Ok(None);
            }
        }
        // What changed groups kept is of no more use: dropped before their new indexes exist.
        for &g in &changed {
            cache.groups[g] = None;
        }
        // A run of groups at a time: the level-n surface of a part of the model is held
        // beside the indexes, not the whole model's.
        let mut fresh: Vec<GroupDecoded> = Vec::with_capacity(changed.len());
        for run in support.runs(&changed, level, RUN_TRIANGLES) {
            let Some(surface) = subdivide(run)? else {
                continue;
            };
            let owners = first_groups(&surface);
            let indexed = map_ordered(run, |&g| index_group(&surface, &owners, g));
            fresh.extend(indexed.into_iter().collect::<Result<Vec<_>>>()?);
        }
        let Some(in_hits) = self.input_to_decoded(&cache, &changed, &fresh, over) else {
            return Ok(None);
        };
        // Decoded->input for the changed groups' samples.
        for_each_heavy(&mut fresh, |k, gd| self.measure_decoded(changed[k], gd));
        for (gd, &g) in fresh.into_iter().zip(&changed) {
            cache.groups[g] = Some(gd);
        }
        let mut measurement = self.summarise(&in_hits, &mut cache);
        measurement.changed_groups = changed.len();
        cache.in_hits = in_hits;
        cache.level = level;
        cache.supports = supports;
        Ok(Some(measurement))
    }

    /// Whether one of the worst decoded samples of last time is over the tolerance or
    /// `max_cap`: an unchanged group's as measured, a changed group's at the same index
    /// measured now (on `surface`, before any index is built, so a failing probe leaves
    /// what was kept as it was).
    fn decoded_probe_fails(
        &self,
        cache: &MeasureCache,
        changed: &[usize],
        surface: Option<&UniformSurface>,
        max_cap: f64,
    ) -> bool {
        let mut probe: Vec<(usize, DVec3)> = Vec::new();
        // The probes are in (group, index) order.
        for run in cache.probe_out.chunk_by(|a, b| a.0 == b.0) {
            let g = run[0].0 as usize;
            if changed.binary_search(&g).is_ok() {
                let Some(surface) = surface else { continue };
                let local = localise(surface, g, None);
                if local.triangles.is_empty() {
                    continue;
                }
                let samples = GroupSamples::new(
                    &local.positions,
                    &local.triangles,
                    self.density,
                    self.seed,
                    self.edge_spacing,
                );
                let points = run
                    .iter()
                    .map(|x| x.1 as usize)
                    .filter(|&i| i < samples.len());
                probe.extend(points.map(|i| (g, samples.point(i))));
                continue;
            }
            let Some(kept) = cache.groups.get(g).and_then(Option::as_ref) else {
                continue;
            };
            for &(_, i) in run {
                if let Some(&[e, d]) = kept.samples.get(i as usize) {
                    if e > self.tol || d > max_cap {
                        return true;
                    }
                }
            }
        }
        let pts: Vec<DVec3> = probe.iter().map(|x| x.1).collect();
        let hits = closest_points_near(&pts, self.input_surface, 2.0 * self.tol);
        probe.iter().zip(&hits).any(|(&(g, p), h)| {
            self.out_excess(p, g, h.triangle, h.distance) > self.tol || h.distance > max_cap
        })
    }

    /// Input->decoded: per input sample, the nearest point of the decoded surface. While
    /// the group holding a sample's old nearest point is unchanged, that distance is still
    /// reached and only changed groups can be nearer. The samples are visited along a
    /// space-filling curve, in fixed chunks: within a chunk the previous sample's nearest
    /// point bounds the search (exactly as an unbounded search finds, the bound being a
    /// point of the surface). With `over = Some(max_cap)`, `None` when one of last time's
    /// worst samples fails.
    fn input_to_decoded(
        &self,
        cache: &MeasureCache,
        changed: &[usize],
        fresh: &[GroupDecoded],
        over: Option<f64>,
    ) -> Option<Vec<InHit>> {
        let groups: Vec<&GroupDecoded> = (0..cache.groups.len())
            .map(|g| match changed.binary_search(&g) {
                Ok(k) => &fresh[k],
                Err(_) => cache.groups[g]
                    .as_ref()
                    .expect("an unchanged group is kept"),
            })
            .collect();
        let n_in = self.input_samples.len();
        let reuse = cache.in_hits.len() == n_in;
        let all: Vec<usize> = (0..groups.len()).collect();
        let order_all = self.search_orders(&groups, &all);
        let order_changed = self.search_orders(&groups, changed);
        // Sample `i`'s distance, given a point of the surface and its group `prev` (the
        // nearest point of an earlier sample) whose distance bounds the search; and the
        // nearest point when the search found it.
        let in_hit = |i: usize, prev: Option<(DVec3, u32)>| -> (InHit, Option<DVec3>) {
            let s = &self.input_samples[i];
            let own = self.mesh.face_groups[s.triangle as usize] as usize;
            let prev = prev.map(|(q, group)| InHit {
                distance: (s.point - q).length(),
                group,
            });
            let nearer = |a: Option<InHit>, b: InHit| match a {
                Some(a) if a.distance <= b.distance => a,
                _ => b,
            };
            let hit = match cache.in_hits.get(i) {
                Some(&hit) if reuse && changed.binary_search(&(hit.group as usize)).is_err() => {
                    // A nearer `prev` is on a changed group (the unchanged ones are no nearer
                    // than `hit`), which the search covers.
                    let best = nearer(prev, hit);
                    Self::nearest_decoded(s.point, &groups, &order_changed[own], Some(best))
                }
                _ => Self::nearest_decoded(s.point, &groups, &order_all[own], prev),
            };
            (hit.0.unwrap_or(InHit::NONE), hit.1)
        };
        if let Some(max_cap) = over {
            let fails = |i: usize| {
                let d = in_hit(i, None).0.distance;
                d - self.chord[self.input_samples[i].triangle as usize] > self.tol || d > max_cap
            };
            if cache.probe_in.iter().any(|&i| fails(i)) {
                return None;
            }
        }
        let chunks: Vec<&[u32]> = self.input_order.chunks(IN_CHUNK).collect();
        let visited = map_ordered(&chunks, |chunk| {
            let mut prev: Option<(DVec3, u32)> = None;
            chunk
                .iter()
                .map(|&i| {
                    let (hit, point) = in_hit(i as usize, prev);
                    if let Some(q) = point.filter(|q| q.is_finite()) {
                        prev = Some((q, hit.group));
                    }
                    hit
                })
                .collect::<Vec<InHit>>()
        });
        let mut hits = vec![InHit::NONE; n_in];
        for (&i, hit) in self.input_order.iter().zip(visited.into_iter().flatten()) {
            hits[i as usize] = hit;
        }
        Some(hits)
    }

    /// Per input group, the decoded groups among `candidates` (ascending) with a surface,
    /// each with a lower bound of the distance from any of the input group's samples to it
    /// (box to box): the group itself first (its samples are usually nearest to its own
    /// decoded patch), then the others nearest first. A search along it stops at the first
    /// bound beyond the best distance found, so a sample tests a few groups, not all.
    fn search_orders(
        &self,
        groups: &[&GroupDecoded],
        candidates: &[usize],
    ) -> Vec<Vec<(f64, u32)>> {
        let box_gap = |(lo, hi): (DVec3, DVec3), gd: &GroupDecoded| {
            (gd.lo - hi).max(lo - gd.hi).max(DVec3::ZERO).length()
        };
        let own: Vec<usize> = (0..self.group_boxes.len()).collect();
        map_ordered(&own, |&own| {
            let mut order: Vec<(f64, u32)> = candidates
                .iter()
                .filter(|&&g| groups[g].surface.is_some())
                // Zero is a lower bound too: the own group sorts first.
                .map(|&g| {
                    (
                        if g == own {
                            0.0
                        } else {
                            box_gap(self.group_boxes[own], groups[g])
                        },
                        g as u32,
                    )
                })
                .collect();
            order.sort_unstable_by(|a, b| {
                let own_first = (b.1 as usize == own).cmp(&(a.1 as usize == own));
                a.0.total_cmp(&b.0).then(own_first).then(a.1.cmp(&b.1))
            });
            order
        })
    }

    /// Measures the samples of changed group `g` against the input.
    fn measure_decoded(&self, g: usize, gd: &mut GroupDecoded) {
        let Some(s) = &gd.surface else {
            return;
        };
        let samples = GroupSamples::new(
            s.positions(),
            s.triangles(),
            self.density,
            self.seed,
            self.edge_spacing,
        );
        let measured = closest_points_near_with(
            samples.len(),
            |i| samples.point(i),
            self.input_surface,
            2.0 * self.tol,
            |_, p, h| {
                let e = self.out_excess(p, g, h.triangle, h.distance);
                [e, self.shown(e, h.distance)]
            },
        );
        let (mut worst, mut over_tolerance) = (None, Vec::new());
        for (i, &[e, _]) in measured.iter().enumerate() {
            if worst.is_none_or(|w: (f64, DVec3)| e > w.0) {
                worst = Some((e, samples.point(i)));
            }
            if e > self.tol {
                over_tolerance.push((i as u32, samples.point(i)));
            }
        }
        gd.area_samples = samples.vertices.len() + samples.random.len();
        drop(samples);
        gd.samples = measured;
        gd.worst = worst;
        gd.over_tolerance = over_tolerance;
    }

    /// Statistics, per-group excesses and the next probes of one measurement (every group
    /// of `cache` measured).
    fn summarise(&self, in_hits: &[InHit], cache: &mut MeasureCache) -> Measurement {
        let groups: Vec<&GroupDecoded> = cache
            .groups
            .iter()
            .map(|g| g.as_ref().expect("every group is measured"))
            .collect();
        let stats = |d: &mut dyn Iterator<Item = f64>| -> (f64, f64, f64) {
            let (mut max, mut sq, mut sum, mut n) = (0.0f64, 0.0, 0.0, 0usize);
            for x in d {
                max = max.max(x);
                sq += x * x;
                sum += x;
                n += 1;
            }
            let n = n.max(1) as f64;
            (max, (sq / n).sqrt(), sum / n)
        };
        let area_in = self.input_area_samples.min(in_hits.len());
        let shown_in: Vec<f64> = self
            .input_samples
            .iter()
            .zip(in_hits)
            .map(|(s, h)| self.shown(h.distance - self.chord[s.triangle as usize], h.distance))
            .collect();
        let (_, rms_in, mean_in) = stats(&mut shown_in[..area_in].iter().copied());
        let max_in = shown_in.iter().copied().fold(0.0f64, f64::max);
        let (_, rms_out, mean_out) = stats(&mut groups.iter().flat_map(|g| {
            let mut shared = g.shared.iter().copied().peekable();
            g.samples[..g.area_samples.min(g.samples.len())]
                .iter()
                .enumerate()
                .filter(move |&(i, _)| shared.next_if_eq(&(i as u32)).is_none())
                .map(|(_, s)| s[1])
        }));
        let max_out = groups
            .iter()
            .flat_map(|g| g.samples.iter().map(|s| s[1]))
            .fold(0.0f64, f64::max);
        // Excess over the tolerance, beyond the input's chord allowance (zero unless the
        // fit allows for it), and
        // where it is.
        let n_groups = self.mesh.groups.len();
        let mut group_excess = vec![(0.0f64, DVec3::ZERO, "in"); n_groups];
        let mut bad_points = vec![Vec::new(); n_groups];
        let mut worst = 0.0f64;
        let mut excess_in = Vec::with_capacity(in_hits.len());
        for (s, &InHit { distance: d, .. }) in self.input_samples.iter().zip(in_hits) {
            let e = d - self.chord[s.triangle as usize];
            excess_in.push(e);
            worst = worst.max(e);
            let g = self.mesh.face_groups[s.triangle as usize] as usize;
            if e > group_excess[g].0 {
                group_excess[g] = (e, s.point, "input->decoded");
            }
            if e > self.tol {
                bad_points[g].push(s.point);
            }
        }
        for (g, gd) in groups.iter().enumerate() {
            let Some((e, p)) = gd.worst else { continue };
            worst = worst.max(e);
            if g < n_groups {
                if e > group_excess[g].0 {
                    group_excess[g] = (e, p, "decoded->input");
                }
                bad_points[g].extend(gd.over_tolerance.iter().map(|x| x.1));
            }
        }
        // The next probe: the worst samples by excess and by plain distance.
        let mut probe_in = top_k(excess_in.iter().copied().zip(0..), PROBE_SAMPLES);
        probe_in.extend(top_k(
            in_hits.iter().map(|h| h.distance).zip(0..),
            PROBE_SAMPLES / 4,
        ));
        probe_in.sort_unstable();
        probe_in.dedup();
        let out = |k: usize| {
            groups.iter().enumerate().flat_map(move |(g, gd)| {
                gd.samples
                    .iter()
                    .enumerate()
                    .map(move |(i, s)| (s[k], (g as u32, i as u32)))
            })
        };
        let mut probe_out = top_k(out(0), PROBE_SAMPLES);
        probe_out.extend(top_k(out(1), PROBE_SAMPLES / 4));
        probe_out.sort_unstable();
        probe_out.dedup();
        let changed_groups = groups.len();
        cache.probe_in = probe_in;
        cache.probe_out = probe_out;
        Measurement {
            error: FitError {
                max: max_in.max(max_out),
                rms: rms_in.max(rms_out),
                mean: mean_in.max(mean_out),
                max_excess: worst,
            },
            group_excess,
            bad_points,
            changed_groups,
        }
    }
}

/// A face's decoded triangles over its own vertices (shared corners merged, first use
/// first), and the box of its corners.
struct LocalTriangles {
    positions: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
    lo: DVec3,
    hi: DVec3,
    /// The local vertices a group before this one also holds (with `owners`), increasing.
    shared: Vec<u32>,
}

/// By vertex of `surface`, the first group holding it (`u32::MAX`: none): a vertex on the
/// boundary of two faces counts in the mean and RMS of the first one alone, as `scode info
/// --against` counts each decoded vertex once. Every triangle around a vertex of a face is
/// in the surface of its run ([`Supports::submesh`] keeps the faces around the face's
/// control vertices), so a face's vertices get the same owners in any run.
fn first_groups(surface: &UniformSurface) -> Vec<u32> {
    let mut owners = vec![u32::MAX; surface.positions().len()];
    for g in 0..surface.group_count() {
        surface.visit_group_triangles(g, |block| {
            for &v in block.iter().flatten() {
                if owners[v as usize] == u32::MAX {
                    owners[v as usize] = g as u32;
                }
            }
            true
        });
    }
    owners
}

/// Group `g`'s decoded triangles over its own vertices, and, with `owners`
/// ([`first_groups`]), which of them an earlier group holds.
fn localise(surface: &UniformSurface, g: usize, owners: Option<&[u32]>) -> LocalTriangles {
    let all = surface.positions();
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    let mut local: std::collections::HashMap<u32, u32, rustc_hash::FxBuildHasher> =
        Default::default();
    let mut positions = Vec::new();
    let mut shared = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    surface.visit_group_triangles(g, |block| {
        triangles.extend(block.iter().map(|t| {
            t.map(|v| {
                *local.entry(v).or_insert_with(|| {
                    let p = all[v as usize];
                    lo = lo.min(p);
                    hi = hi.max(p);
                    let id = positions.len() as u32;
                    if owners.is_some_and(|o| o.get(v as usize).is_some_and(|&f| f < g as u32)) {
                        shared.push(id);
                    }
                    positions.push(p);
                    id
                })
            })
        }));
        true
    });
    LocalTriangles {
        positions,
        triangles,
        lo,
        hi,
        shared,
    }
}

/// The chord error estimate of [`ErrorMeter::chord_errors`] for one face's triangles.
fn chord_error(positions: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    let corners = |t: &[u32; 3]| t.map(|v| positions[v as usize]);
    let mut edges: Vec<((u32, u32), u32)> = Vec::with_capacity(3 * triangles.len());
    for (k, t) in triangles.iter().enumerate() {
        for i in 0..3 {
            edges.push((edge_key(t[i], t[(i + 1) % 3]), k as u32));
        }
    }
    edges.sort_unstable();
    let mut worst = 0.0f64;
    for pair in edges.windows(2) {
        if pair[0].0 != pair[1].0 {
            continue;
        }
        let (a, b) = pair[0].0;
        let edge = positions[a as usize].distance(positions[b as usize]);
        // Twice the area and the unit normal.
        let [(a2, na), (b2, nb)] = [pair[0].1, pair[1].1].map(|k| {
            let c = corners(&triangles[k as usize]);
            let n = (c[1] - c[0]).cross(c[2] - c[0]);
            (n.length(), n.normalize_or_zero())
        });
        let (angle, height) = (na.angle_between(nb), (a2 + b2) / (2.0 * edge));
        if angle.is_finite() && height.is_finite() {
            worst = worst.max(height * angle / 8.0);
        }
    }
    worst
}

/// The closest-point index of group `g`'s decoded triangles ([`localise`]); no samples yet.
fn index_group(surface: &UniformSurface, owners: &[u32], g: usize) -> Result<GroupDecoded> {
    let LocalTriangles {
        mut positions,
        mut triangles,
        lo,
        hi,
        shared,
    } = localise(surface, g, Some(owners));
    // Kept until the face changes: without the slack of growing by pushes.
    positions.shrink_to_fit();
    triangles.shrink_to_fit();
    let surface = if triangles.is_empty() {
        None
    } else {
        Some(TriangleSurface::with_blocks(
            positions,
            triangles,
            LEAF_TRIANGLES,
        )?)
    };
    Ok(GroupDecoded {
        surface,
        lo,
        hi,
        shared,
        samples: Vec::new(),
        area_samples: 0,
        worst: None,
        over_tolerance: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::test_support::grid_cube;

    fn meter_parts(input: &ControlMesh) -> (Vec<[u32; 3]>, TriangleSurface, Vec<f64>) {
        let tris: Vec<[u32; 3]> = input.faces().map(|f| [f[0], f[1], f[2]]).collect();
        let surface = TriangleSurface::new(input.positions.clone(), tris.clone()).unwrap();
        let chord = vec![0.0; tris.len()];
        (tris, surface, chord)
    }

    /// A meter of `input` at tolerance 0.01 with 3000 random samples, its faces measured
    /// by their plain distance.
    fn meter_of<'a>(
        input: &'a ControlMesh,
        tris: &[[u32; 3]],
        surface: &'a TriangleSurface,
        chord: &'a [f64],
    ) -> ErrorMeter<'a> {
        let sampling = DistanceOptions {
            samples: crate::metrics::SampleCount::Total(3000),
            ..Default::default()
        };
        let own_faces = OwnFaces {
            surfaces: &[],
            triangles: &[],
            max_allowance: &[],
            exact: &[],
            facet_chord: &[],
        };
        ErrorMeter::new(input, tris, surface, chord, own_faces, &sampling, 0.01)
    }

    /// The chord error estimate of a cylinder cut into `n` strips around is the sagitta of
    /// one strip, `R (1 - cos(π / n))`, within a few percent; a plane has none.
    #[test]
    fn chord_error_is_the_sagitta_of_a_cylinder_and_zero_on_a_plane() {
        let (radius, n, rows) = (2.0, 24u32, 6u32);
        let mut positions = Vec::new();
        for r in 0..=rows {
            for k in 0..n {
                let a = std::f64::consts::TAU * f64::from(k) / f64::from(n);
                positions.push(DVec3::new(
                    radius * a.cos(),
                    radius * a.sin(),
                    f64::from(r) * 0.3,
                ));
            }
        }
        let id = |r: u32, k: u32| r * n + k % n;
        let mut triangles = Vec::new();
        for r in 0..rows {
            for k in 0..n {
                triangles.push([id(r, k), id(r, k + 1), id(r + 1, k + 1)]);
                triangles.push([id(r, k), id(r + 1, k + 1), id(r + 1, k)]);
            }
        }
        let sagitta = radius * (1.0 - (std::f64::consts::PI / f64::from(n)).cos());
        let estimate = chord_error(&positions, &triangles);
        assert!(
            (estimate / sagitta - 1.0).abs() < 0.05,
            "estimate {estimate}, sagitta {sagitta}"
        );
        let flat: Vec<DVec3> = positions
            .iter()
            .map(|p| DVec3::new(p.x, p.y, 0.0))
            .collect();
        let plane = [[0, 1, n + 1], [0, n + 1, n]];
        assert_eq!(chord_error(&flat, &plane), 0.0);
    }

    /// A measurement that reuses what the previous one kept gives exactly what a fresh
    /// meter gives, whether one face changed or all of them.
    #[test]
    fn kept_results_give_the_same_measurement_as_a_fresh_meter() {
        let input = grid_cube(6);
        let (tris, surface, chord) = meter_parts(&input);
        let meter = || meter_of(&input, &tris, &surface, &chord);
        // Sharp CAD-face boundaries, as every fitted control mesh has them.
        let mut first = grid_cube(2);
        first.sharpen_group_boundaries();
        // One vertex inside face 1 (z = 1) moved outwards: only that face changes.
        let mut one_face = first.clone();
        let v = (0..one_face.vertex_count())
            .find(|&v| (one_face.positions[v] - DVec3::new(0.5, 0.5, 1.0)).length() < 1e-9)
            .unwrap();
        one_face.positions[v].z += 0.05;
        let mut all_faces = first.clone();
        for p in &mut all_faces.positions {
            *p = (*p - DVec3::splat(0.5)) * 1.01 + DVec3::splat(0.5);
        }
        let kept = meter();
        let m0 = kept.measure(&first, 3).unwrap();
        assert_eq!(m0.changed_groups, 6);
        for next in [&one_face, &all_faces, &first] {
            let reused = kept.measure(next, 3).unwrap();
            let fresh = meter().measure(next, 3).unwrap();
            assert_eq!(reused.error, fresh.error);
            assert_eq!(reused.group_excess, fresh.group_excess);
            assert_eq!(reused.bad_points, fresh.bad_points);
        }
        let again = kept.measure(&one_face, 3).unwrap();
        assert!(
            (1..6).contains(&again.changed_groups),
            "{} faces measured anew",
            again.changed_groups
        );
        // A decoded sample that fails its probe leaves the kept results as they were.
        assert!(kept
            .measure_unless_over(&all_faces, 3, Some(0.0))
            .unwrap()
            .is_none());
        assert_eq!(kept.measure(&one_face, 3).unwrap().changed_groups, 0);
    }

    #[test]
    fn a_renumbered_control_mesh_keeps_every_measurement() {
        let input = grid_cube(6);
        let (tris, surface, chord) = meter_parts(&input);
        let meter = meter_of(&input, &tris, &surface, &chord);
        let mut first = grid_cube(2);
        first.sharpen_group_boundaries();
        for p in &mut first.positions {
            *p += DVec3::new(0.013, -0.007, 0.002) * (p.x * 3.1 + p.y * 1.7).sin();
        }
        let m0 = meter.measure(&first, 3).unwrap();
        let other = crate::subdiv::test_support::renumbered(&first);
        let m1 = meter.measure(&other, 3).unwrap();
        assert_eq!(m1.changed_groups, 0);
        assert_eq!(m1.error, m0.error);
        // A fresh measurement of the renumbered mesh takes the same samples (each triangle's
        // random points are its own): the same figures, up to the order of the sums.
        let fresh = meter_of(&input, &tris, &surface, &chord)
            .measure(&other, 3)
            .unwrap();
        assert_eq!(fresh.error.max, m0.error.max);
        assert!((fresh.error.rms - m0.error.rms).abs() <= 1e-12 * m0.error.rms);
        assert!((fresh.error.mean - m0.error.mean).abs() <= 1e-12 * m0.error.mean);
    }

    /// The bounded heap keeps the k largest values, ties to the smaller id, in id order.
    #[test]
    fn top_k_keeps_the_largest_values_first_ids_on_ties() {
        let values = [3.0, 1.0, 3.0, f64::NAN, 2.0, 3.0, -1.0];
        let ids = |k| top_k(values.iter().copied().zip(0..), k);
        assert_eq!(ids(0), Vec::<usize>::new());
        assert_eq!(ids(1), vec![3]);
        assert_eq!(ids(3), vec![0, 2, 3]);
        assert_eq!(ids(5), vec![0, 2, 3, 4, 5]);
        assert_eq!(ids(10), vec![0, 1, 2, 3, 4, 5, 6]);
    }
}
