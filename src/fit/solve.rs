//! Step 4 of the fit: control points placed so the *limit* surface computed by
//! [`crate::subdiv`] (the decoder's own rules) matches the input: first the Cartesian crease
//! curves against their chain polylines, then the interiors of closed patches against their
//! faces, by linearised least squares with re-projected targets (moved on to the faces' exact
//! surfaces where the input knows them: a STEP face's facets and edge polylines sag from the
//! CAD surface, which the error is measured against). Curves on cylinders and cones keep
//! their on-surface positions: the decoder's cylindrical rule keeps them exactly on the
//! surface.

use std::collections::BTreeMap;

use glam::DVec3;

use super::build::Built;
use super::chains::closest_on_polyline;
use super::curves::CurveNetwork;
use super::exact::{onto_all, ExactSurface};
use super::plan::{chain_frame, GroupPlan};
use crate::error::Result;
use crate::mesh::{edge_key, ControlMesh, PatchKind};
use crate::metrics::TriangleSurface;
use crate::subdiv::support::Supports;
use crate::subdiv::{LevelView, Refinement, SparseStencils};

/// What the previous fit solved, to be reused where nothing it read has changed. The fit's
/// unknowns fall into blocks that share no least-squares row ([`solve_blocks`]): a closed
/// patch's interior (its boundary is sharp), and a Cartesian chain's interior control points
/// (a crease curve reads only points on its creases). A block's solution is then a function
/// of the supports of the groups around it before the solve, which
/// [`Supports::fingerprints`] identifies: a block whose groups have the fingerprints they
/// had when it was solved gets the same control points without solving again. Refinement
/// rounds change a few patches at a time; the rest of the model is not re-projected and
/// re-solved every round.
#[derive(Default)]
pub(super) struct SolveCache {
    chains: SolvedBlocks,
    patches: SolvedBlocks,
}

/// Solved blocks by index (chain or group).
#[derive(Default)]
struct SolvedBlocks(Vec<Option<SolvedBlock>>);

/// One block's solve.
struct SolvedBlock {
    /// What identifies its inputs: the fingerprint of its groups' supports before the solve.
    fingerprint: u64,
    /// Each solved control point: its position before the solve (the bits of its
    /// coordinates; distinct within a fingerprinted group, so they name the point whatever
    /// the mesh's numbering) and after, sorted.
    moved: Vec<([u64; 3], DVec3)>,
}

/// The bits of a position's coordinates, a key that does not depend on vertex numbering.
fn position_key(p: DVec3) -> [u64; 3] {
    p.to_array().map(f64::to_bits)
}

impl SolvedBlocks {
    /// Moves the unknowns of every block (`unknowns[b]`) whose fingerprint is the one cached
    /// to their cached solution, and says which blocks were so reused.
    fn reuse(
        &self,
        positions: &mut [DVec3],
        fingerprints: &[Option<u64>],
        unknowns: &[Vec<usize>],
    ) -> Vec<bool> {
        let mut reused = vec![false; unknowns.len()];
        for (b, vertices) in unknowns.iter().enumerate() {
            let Some(Some(solved)) = self.0.get(b) else {
                continue;
            };
            if vertices.is_empty()
                || fingerprints.get(b).copied().flatten() != Some(solved.fingerprint)
            {
                continue;
            }
            let found: Option<Vec<DVec3>> = vertices
                .iter()
                .map(|&v| {
                    let key = position_key(positions[v]);
                    let k = solved.moved.binary_search_by(|e| e.0.cmp(&key)).ok()?;
                    Some(solved.moved[k].1)
                })
                .collect();
            if let Some(found) = found.filter(|f| f.len() == solved.moved.len()) {
                for (&v, p) in vertices.iter().zip(found) {
                    positions[v] = p;
                }
                reused[b] = true;
            }
        }
        reused
    }

    /// Keeps the solve of every block of `unknowns` not `reused`: `before` holds the
    /// positions of all control points before the solve, `after` after it.
    fn store(
        &mut self,
        fingerprints: &[Option<u64>],
        unknowns: &[Vec<usize>],
        reused: &[bool],
        before: &[DVec3],
        after: &[DVec3],
    ) {
        self.0.resize_with(unknowns.len(), || None);
        self.0.truncate(unknowns.len());
        for (b, vertices) in unknowns.iter().enumerate() {
            if reused[b] {
                continue;
            }
            self.0[b] = fingerprints
                .get(b)
                .copied()
                .flatten()
                .filter(|_| !vertices.is_empty())
                .map(|fingerprint| {
                    let mut moved: Vec<([u64; 3], DVec3)> = vertices
                        .iter()
                        .map(|&v| (position_key(before[v]), after[v]))
                        .collect();
                    moved.sort_unstable_by_key(|a| a.0);
                    SolvedBlock { fingerprint, moved }
                });
        }
    }
}

/// One value for the fingerprints of `groups` (`None` if one of them has none), in order.
fn combined_fingerprint(groups: &[u32], fingerprints: &[Option<u64>]) -> Option<u64> {
    groups.iter().try_fold(0x9E37_79B9_7F4A_7C15u64, |h, &g| {
        let f = fingerprints.get(g as usize).copied().flatten()?;
        Some((h ^ f).wrapping_mul(0xBF58_476D_1CE4_E5B9).rotate_left(31))
    })
}

/// Where each vertex of the refined level the fit samples lies: on which chain's crease
/// (the crease samples) and in which group (the interior samples). A vertex on two chains or
/// in two groups belongs to neither's fit.
struct SampleSources {
    chain: Vec<Option<usize>>,
    multi_chain: Vec<bool>,
    group: Vec<Option<u32>>,
    mixed: Vec<bool>,
}

impl SampleSources {
    /// `view` is level `LEVEL` of the control mesh whose edges are `base_edges`;
    /// `edge_chain` maps its sharp control edges to chains.
    fn new(
        view: &LevelView<'_>,
        base_edges: &[[u32; 2]],
        edge_chain: &BTreeMap<(u32, u32), usize>,
    ) -> SampleSources {
        let nv_l = view.vertex_count();
        let mut sample_chain: Vec<Option<usize>> = vec![None; nv_l];
        let mut multi_chain = vec![false; nv_l];
        let e0 = base_edges.len();
        for (e, ends) in view.edges().iter().enumerate() {
            if !view.edge_is_crease(e) || e >= e0 << LEVEL {
                continue;
            }
            let be = base_edges[e >> LEVEL];
            let Some(&c) = edge_chain.get(&edge_key(be[0], be[1])) else {
                continue;
            };
            for &v in ends {
                match sample_chain[v as usize] {
                    Some(old) if old != c => multi_chain[v as usize] = true,
                    _ => sample_chain[v as usize] = Some(c),
                }
            }
        }
        let mut sample_group: Vec<Option<u32>> = vec![None; nv_l];
        let mut mixed = vec![false; nv_l];
        for f in 0..view.face_count() {
            let g = view.face_group(f);
            for v in view.triangle(f) {
                match sample_group[v as usize] {
                    Some(old) if old != g => mixed[v as usize] = true,
                    _ => sample_group[v as usize] = Some(g),
                }
            }
        }
        SampleSources {
            chain: sample_chain,
            multi_chain,
            group: sample_group,
            mixed,
        }
    }
}

/// Level of the refined mesh whose vertices' limit positions the fit samples.
const LEVEL: u32 = 2;

/// A control mesh refined to the level whose vertices' limit positions the fit samples,
/// with the stencils of those positions and where each sample lies: what every least-squares
/// iteration of one stage reads.
struct Sampled {
    refinement: Refinement,
    stencils: SparseStencils,
    sources: SampleSources,
}

impl Sampled {
    fn new(control: &ControlMesh, edge_chain: &BTreeMap<(u32, u32), usize>) -> Result<Self> {
        let refinement = Refinement::new(control, LEVEL)?;
        let stencils = refinement.stencils(LEVEL, true)?;
        let sources = SampleSources::new(
            &refinement.level(LEVEL),
            refinement.level(0).edges(),
            edge_chain,
        );
        Ok(Sampled {
            refinement,
            stencils,
            sources,
        })
    }

    /// Moves the control points `unknowns` of `positions` by linearised least squares with
    /// re-projected targets: each iteration evaluates the limit positions of the samples and
    /// asks `target(sample, limit position)` where the sample should be (`None`: not
    /// fitted).
    fn solve(
        &self,
        positions: &mut [DVec3],
        unknowns: &[usize],
        target: impl Fn(usize, DVec3) -> Option<DVec3>,
    ) -> Result<()> {
        let mut col = vec![usize::MAX; positions.len()];
        for (k, &v) in unknowns.iter().enumerate() {
            col[v] = k;
        }
        for _iteration in 0..4 {
            let level = self.refinement.positions_at(positions, LEVEL)?;
            let limit = self.refinement.limit_positions(&level, LEVEL)?;
            let mut rows = Vec::new();
            for (s, &at) in limit.iter().enumerate() {
                let Some(target) = target(s, at) else {
                    continue;
                };
                let (idx, w) = self.stencils.row(s);
                let row: Vec<(usize, f64)> = idx
                    .iter()
                    .zip(w)
                    .filter(|(&k, _)| col.get(k as usize).is_some_and(|&c| c != usize::MAX))
                    .map(|(&k, &w)| (col[k as usize], w))
                    .collect();
                if !row.is_empty() {
                    rows.push((row, target - at));
                }
            }
            let delta = solve_blocks(&rows, unknowns.len());
            for (k, &v) in unknowns.iter().enumerate() {
                if delta[k].is_finite() {
                    positions[v] += delta[k];
                }
            }
        }
        Ok(())
    }
}

/// Step 4: least-squares fit of the Cartesian crease curves, then of closed-patch interiors.
pub(super) fn fit_geometry(
    built: &mut Built,
    mesh: &ControlMesh,
    net: &CurveNetwork,
    plans: &[GroupPlan],
    group_surfaces: &[Option<TriangleSurface>],
    exact: &[Option<ExactSurface>],
    cache: &mut SolveCache,
) -> Result<()> {
    let Built {
        control,
        edge_chain,
        ..
    } = built;
    let mut on_sharp = vec![false; control.vertex_count()];
    for &(a, b) in &control.sharp_edges {
        on_sharp[a as usize] = true;
        on_sharp[b as usize] = true;
    }
    fit_chains(
        control, edge_chain, &on_sharp, mesh, net, plans, exact, cache,
    )?;
    fit_closed_interiors(
        control,
        edge_chain,
        &on_sharp,
        plans,
        group_surfaces,
        exact,
        cache,
    )
}

/// The interior control points of the Cartesian chains (crease curves not held by a
/// cylinder or cone frame), fitted to their chains' polylines. Chains whose groups' supports
/// are the ones solved last time take that solution ([`SolveCache`]); the others are solved
/// on the submesh of their groups.
#[allow(clippy::too_many_arguments)]
fn fit_chains(
    control: &mut ControlMesh,
    edge_chain: &BTreeMap<(u32, u32), usize>,
    on_sharp: &[bool],
    mesh: &ControlMesh,
    net: &CurveNetwork,
    plans: &[GroupPlan],
    exact: &[Option<ExactSurface>],
    cache: &mut SolveCache,
) -> Result<()> {
    let cartesian = |c: usize| chain_frame(&net.chains[c].groups, plans).is_none();
    // The chain of each control point on one (as the refined level's crease samples see
    // it: the chain of its sharp edges, none when they belong to two).
    let nc = control.vertex_count();
    let mut vertex_chain: Vec<Option<usize>> = vec![None; nc];
    let mut multi_chain = vec![false; nc];
    for &(a, b) in &control.sharp_edges {
        let Some(&c) = edge_chain.get(&edge_key(a, b)) else {
            continue;
        };
        for v in [a as usize, b as usize] {
            match vertex_chain[v] {
                Some(old) if old != c => multi_chain[v] = true,
                _ => vertex_chain[v] = Some(c),
            }
        }
    }
    let mut by_chain = vec![Vec::new(); net.chains.len()];
    for v in 0..nc {
        let Some(c) = vertex_chain[v] else { continue };
        if !control.corners.contains(&(v as u32)) && on_sharp[v] && !multi_chain[v] && cartesian(c)
        {
            by_chain[c].push(v);
        }
    }
    let group_fingerprints = Supports::new(control).fingerprints()?;
    let fingerprints: Vec<Option<u64>> = net
        .chains
        .iter()
        .map(|c| combined_fingerprint(&c.groups, &group_fingerprints))
        .collect();
    let chain_points: Vec<Vec<DVec3>> = net
        .chains
        .iter()
        .map(|c| {
            c.vertices
                .iter()
                .map(|&v| mesh.positions[v as usize])
                .collect()
        })
        .collect();
    // Per chain: the exact surfaces of its faces, when every one of them has one.
    let chain_exact: Vec<Option<Vec<ExactSurface>>> = net
        .chains
        .iter()
        .map(|c| {
            let mut groups = c.groups.clone();
            groups.dedup();
            groups
                .iter()
                .map(|&g| exact.get(g as usize).copied().flatten())
                .collect()
        })
        .collect();
    solve_changed_blocks(
        control,
        edge_chain,
        &mut cache.chains,
        &fingerprints,
        &by_chain,
        |c| net.chains[c].groups.iter().map(|&g| g as usize).collect(),
        |sources, solving, s, at| {
            let c = sources.chain[s].filter(|&c| !sources.multi_chain[s] && solving[c])?;
            // On the edge's polyline, then onto the exact surfaces of its faces where the
            // input knows them all: the polyline sags from the CAD edge by up to its chord.
            let on_line = closest_on_polyline(at, &chain_points[c]);
            Some(
                chain_exact[c]
                    .as_deref()
                    .and_then(|surfaces| onto_all(surfaces, on_line))
                    .unwrap_or(on_line),
            )
        },
    )
}

/// The interior control points of the closed patches, fitted to their faces. Patches whose
/// support is the one solved last time take that solution ([`SolveCache`]); the others are
/// solved on the submesh around them (their surface there is the whole mesh's), so a round
/// that changed a few patches refines a few patches.
fn fit_closed_interiors(
    control: &mut ControlMesh,
    edge_chain: &BTreeMap<(u32, u32), usize>,
    on_sharp: &[bool],
    plans: &[GroupPlan],
    group_surfaces: &[Option<TriangleSurface>],
    exact: &[Option<ExactSurface>],
    cache: &mut SolveCache,
) -> Result<()> {
    let closed = |g: u32| {
        plans
            .get(g as usize)
            .is_some_and(|p| matches!(p.kind, PatchKind::Closed))
    };
    // The unknowns of each closed patch: the control points all of whose faces are its
    // own, off its sharp edges.
    let mut group_of: Vec<Option<u32>> = vec![None; control.vertex_count()];
    let mut mixed = vec![false; control.vertex_count()];
    for (f, &g) in control.face_groups.iter().enumerate() {
        for &v in control.face(f) {
            match group_of[v as usize] {
                Some(old) if old != g => mixed[v as usize] = true,
                _ => group_of[v as usize] = Some(g),
            }
        }
    }
    let mut interior = vec![Vec::new(); control.groups.len()];
    for v in 0..control.vertex_count() {
        if let Some(g) = group_of[v].filter(|&g| !on_sharp[v] && !mixed[v] && closed(g)) {
            interior[g as usize].push(v);
        }
    }
    let fingerprints = Supports::new(control).fingerprints()?;
    solve_changed_blocks(
        control,
        edge_chain,
        &mut cache.patches,
        &fingerprints,
        &interior,
        |g| vec![g],
        |sources, solving, s, at| {
            let g = sources.group[s].filter(|&g| {
                !sources.mixed[s] && sources.chain[s].is_none() && solving[g as usize]
            })?;
            // On the face's facets, then onto its exact surface where the input knows it:
            // the facets sag from the CAD surface by up to their chord, and the error is
            // measured against the CAD surface too.
            let on_facets = group_surfaces
                .get(g as usize)?
                .as_ref()?
                .closest_point(at)
                .point;
            Some(match exact.get(g as usize).copied().flatten() {
                Some(e) => e.project(on_facets),
                None => on_facets,
            })
        },
    )
}

/// Solves the blocks of unknowns `blocks` (`fingerprints` identifying their inputs) that
/// `solved` does not hold a solution of, on the submesh of their groups (`groups_of`), and
/// keeps their solutions. `target(sources, solving, sample, limit position)` is
/// [`Sampled::solve`]'s target, given where the samples of the mesh solved on lie and which
/// blocks are being solved.
fn solve_changed_blocks(
    control: &mut ControlMesh,
    edge_chain: &BTreeMap<(u32, u32), usize>,
    solved: &mut SolvedBlocks,
    fingerprints: &[Option<u64>],
    blocks: &[Vec<usize>],
    groups_of: impl Fn(usize) -> Vec<usize>,
    target: impl Fn(&SampleSources, &[bool], usize, DVec3) -> Option<DVec3>,
) -> Result<()> {
    let reused = solved.reuse(&mut control.positions, fingerprints, blocks);
    let solving: Vec<bool> = (0..blocks.len())
        .map(|b| !blocks[b].is_empty() && !reused[b])
        .collect();
    if !solving.contains(&true) {
        return Ok(());
    }
    let solved_now = || (0..blocks.len()).filter(|&b| solving[b]);
    let mut groups: Vec<usize> = solved_now().flat_map(&groups_of).collect();
    groups.sort_unstable();
    groups.dedup();
    let unknowns: Vec<usize> = solved_now()
        .flat_map(|b| blocks[b].iter().copied())
        .collect();
    let before = control.positions.clone();
    let part = Supports::new(control).submesh(&groups);
    let mesh = part.as_ref().unwrap_or(control);
    let sampled = Sampled::new(mesh, edge_chain)?;
    let mut positions = mesh.positions.clone();
    sampled.solve(&mut positions, &unknowns, |s, at| {
        target(&sampled.sources, &solving, s, at)
    })?;
    for &v in &unknowns {
        control.positions[v] = positions[v];
    }
    solved.store(fingerprints, blocks, &reused, &before, &control.positions);
    Ok(())
}

/// One least-squares row: (unknown, weight) pairs and the residual they should make up.
type Row = (Vec<(usize, f64)>, DVec3);

/// [`solve_increment`] for each independent block of `rows`: the unknowns that share rows
/// (a closed patch's interior, a chain's interior control points), each with its own
/// damping. A patch's solution then depends on its own rows alone, so a patch whose
/// topology, boundary and input did not change between rounds gets the same control points
/// (and keeps its measurement).
fn solve_blocks(rows: &[Row], n_unknowns: usize) -> Vec<DVec3> {
    // Union-find over the unknowns of each row.
    let mut parent: Vec<usize> = (0..n_unknowns).collect();
    fn root(parent: &mut [usize], mut k: usize) -> usize {
        while parent[k] != k {
            parent[k] = parent[parent[k]];
            k = parent[k];
        }
        k
    }
    for (row, _) in rows {
        if let Some(&(first, _)) = row.first() {
            for &(k, _) in &row[1..] {
                let (a, b) = (root(&mut parent, first), root(&mut parent, k));
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    // Blocks in order of their first unknown; local column of each unknown.
    let mut block_of = vec![usize::MAX; n_unknowns];
    let mut local = vec![0usize; n_unknowns];
    let mut sizes: Vec<usize> = Vec::new();
    for k in 0..n_unknowns {
        let r = root(&mut parent, k);
        if block_of[r] == usize::MAX {
            block_of[r] = sizes.len();
            sizes.push(0);
        }
        let b = block_of[r];
        block_of[k] = b;
        local[k] = sizes[b];
        sizes[b] += 1;
    }
    let mut block_rows: Vec<Vec<Row>> = vec![Vec::new(); sizes.len()];
    for (row, target) in rows {
        if let Some(&(first, _)) = row.first() {
            let local_row = row.iter().map(|&(k, w)| (local[k], w)).collect();
            block_rows[block_of[first]].push((local_row, *target));
        }
    }
    let blocks: Vec<usize> = (0..sizes.len()).collect();
    let solved = super::map_ordered(&blocks, |&b| {
        let rows = &block_rows[b];
        let mean_diag = rows
            .iter()
            .map(|(r, _)| r.iter().map(|(_, w)| w * w).sum::<f64>())
            .sum::<f64>()
            / sizes[b] as f64;
        solve_increment(rows, sizes[b], 1e-3 * mean_diag.max(1e-12))
    });
    (0..n_unknowns)
        .map(|k| solved[block_of[k]][local[k]])
        .collect()
}

/// Linearised least squares: find `delta` for the `unknowns` (control ids) minimising
/// `sum_r |sum_k w_rk delta_k - residual_r|^2 + mu |delta|^2`, by conjugate gradients on the
/// normal equations (three right-hand sides, one matrix, Jacobi-preconditioned).
fn solve_increment(rows: &[Row], n_unknowns: usize, mu: f64) -> Vec<DVec3> {
    let mut diag = vec![mu; n_unknowns];
    for (row, _) in rows {
        for &(k, w) in row {
            diag[k] += w * w;
        }
    }
    let apply = |x: &[DVec3], out: &mut Vec<DVec3>| {
        out.clear();
        out.extend(x.iter().map(|&v| v * mu));
        for (row, _) in rows {
            let s: DVec3 = row.iter().map(|&(k, w)| x[k] * w).sum();
            for &(k, w) in row {
                out[k] += s * w;
            }
        }
    };
    let mut b = vec![DVec3::ZERO; n_unknowns];
    for (row, r) in rows {
        for &(k, w) in row {
            b[k] += *r * w;
        }
    }
    // Componentwise CG (the three coordinates share the matrix but not the step sizes).
    let mut x = vec![DVec3::ZERO; n_unknowns];
    let mut r = b.clone();
    let mut z: Vec<DVec3> = r.iter().zip(&diag).map(|(v, d)| *v / *d).collect();
    let mut p = z.clone();
    let dot = |a: &[DVec3], b: &[DVec3]| -> DVec3 { a.iter().zip(b).map(|(u, v)| *u * *v).sum() };
    let mut rz = dot(&r, &z);
    let b_norm = dot(&b, &b);
    let mut ap = Vec::with_capacity(n_unknowns);
    for _ in 0..(4 * n_unknowns + 50).min(2000) {
        apply(&p, &mut ap);
        let pap = dot(&p, &ap);
        let alpha = DVec3::select(pap.cmpgt(DVec3::splat(1e-300)), rz / pap, DVec3::ZERO);
        for i in 0..n_unknowns {
            x[i] += p[i] * alpha;
            r[i] -= ap[i] * alpha;
        }
        let rr = dot(&r, &r);
        if rr.cmple(b_norm * 1e-20 + DVec3::splat(1e-300)).all() {
            break;
        }
        for i in 0..n_unknowns {
            z[i] = r[i] / diag[i];
        }
        let rz_new = dot(&r, &z);
        let beta = DVec3::select(rz.cmpgt(DVec3::splat(1e-300)), rz_new / rz, DVec3::ZERO);
        rz = rz_new;
        for i in 0..n_unknowns {
            p[i] = z[i] + p[i] * beta;
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cached_solve_is_reused_only_for_the_same_support_and_points() {
        let before = vec![DVec3::new(0.0, 0.0, 0.0), DVec3::X, DVec3::Y, DVec3::Z];
        let mut after = before.clone();
        after[1] += DVec3::splat(0.25);
        after[2] -= DVec3::splat(0.5);
        // Group 0 solved vertices 1 and 2; group 1 (vertex 3) has no fingerprint.
        let interior = vec![vec![1, 2], vec![3]];
        let mut cache = SolveCache::default();
        cache.patches.store(
            &[Some(7), None],
            &interior,
            &[false, false],
            &before,
            &after,
        );

        // Renumbered (the two points swapped), same fingerprint: reused, by position.
        let mut positions = vec![DVec3::ZERO, DVec3::Y, DVec3::X, DVec3::Z];
        let reused = cache
            .patches
            .reuse(&mut positions, &[Some(7), None], &interior);
        assert_eq!(reused, vec![true, false]);
        assert_eq!(positions[1], after[2]);
        assert_eq!(positions[2], after[1]);
        assert_eq!(positions[3], DVec3::Z);

        // Another fingerprint, or a point the cache does not hold: solved again.
        let mut positions = before.clone();
        assert_eq!(
            cache
                .patches
                .reuse(&mut positions, &[Some(8), None], &interior),
            vec![false, false]
        );
        assert_eq!(positions, before);
        let mut moved = before.clone();
        moved[2] = DVec3::new(0.0, 1.0, 1e-12);
        assert_eq!(
            cache.patches.reuse(&mut moved, &[Some(7), None], &interior),
            vec![false, false]
        );
        assert_eq!(moved[1], before[1]);
    }
}
