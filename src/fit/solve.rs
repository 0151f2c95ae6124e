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
use crate::subdiv::{LevelView, Refinement};

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

/// Step 4: least-squares fit of the Cartesian crease curves, then of closed-patch interiors.
pub(super) fn fit_geometry(
    built: &mut Built,
    mesh: &ControlMesh,
    net: &CurveNetwork,
    plans: &[GroupPlan],
    group_surfaces: &[Option<TriangleSurface>],
    exact: &[Option<ExactSurface>],
) -> Result<()> {
    let control = &mut built.control;
    let refinement = Refinement::new(control, LEVEL)?;
    let stencils = refinement.stencils(LEVEL, true)?;
    let view = refinement.level(LEVEL);
    let nv_l = view.vertex_count();
    let base = refinement.level(0);
    let base_edges = base.edges();
    let SampleSources {
        chain: sample_chain,
        multi_chain,
        group: sample_group,
        mixed,
    } = SampleSources::new(&view, base_edges, &built.edge_chain);
    // Unknowns.
    let nc = control.vertex_count();
    let mut on_sharp = vec![false; nc];
    for &(a, b) in &control.sharp_edges {
        on_sharp[a as usize] = true;
        on_sharp[b as usize] = true;
    }
    let chain_frame_of = |c: usize| chain_frame(&net.chains[c].groups, plans);
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
    // Stage 1: Cartesian chains. Stage 2: closed interiors.
    for stage in 0..2 {
        let mut col = vec![usize::MAX; nc];
        let mut unknowns = Vec::new();
        for v in 0..nc {
            let movable = if stage == 0 {
                // Interior control point of a Cartesian chain.
                !control.corners.contains(&(v as u32))
                    && on_sharp[v]
                    && sample_chain
                        .get(v)
                        .copied()
                        .flatten()
                        .is_some_and(|c| chain_frame_of(c).is_none())
                    && !multi_chain[v]
            } else {
                !on_sharp[v]
                    && !mixed[v]
                    && sample_group[v]
                        .is_some_and(|g| matches!(plans[g as usize].kind, PatchKind::Closed))
            };
            if movable {
                col[v] = unknowns.len();
                unknowns.push(v);
            }
        }
        if unknowns.is_empty() {
            continue;
        }
        let chain_points: BTreeMap<usize, Vec<DVec3>> = if stage == 0 {
            net.chains
                .iter()
                .enumerate()
                .map(|(i, c)| {
                    (
                        i,
                        c.vertices
                            .iter()
                            .map(|&v| mesh.positions[v as usize])
                            .collect(),
                    )
                })
                .collect()
        } else {
            BTreeMap::new()
        };
        for _iteration in 0..4 {
            let level = refinement.positions_at(&control.positions, LEVEL)?;
            let limit = refinement.limit_positions(&level, LEVEL)?;
            let mut rows = Vec::new();
            for s in 0..nv_l {
                let target = if stage == 0 {
                    match sample_chain[s] {
                        Some(c) if !multi_chain[s] && chain_frame_of(c).is_none() => {
                            // On the edge's polyline, then onto the exact surfaces of
                            // its faces where the input knows them all: the polyline
                            // sags from the CAD edge by up to its chord.
                            let on_line = closest_on_polyline(limit[s], &chain_points[&c]);
                            chain_exact[c]
                                .as_deref()
                                .and_then(|surfaces| onto_all(surfaces, on_line))
                                .unwrap_or(on_line)
                        }
                        _ => continue,
                    }
                } else {
                    match sample_group[s] {
                        Some(g) if !mixed[s] && sample_chain[s].is_none() => {
                            match &group_surfaces[g as usize] {
                                Some(surface)
                                    if matches!(plans[g as usize].kind, PatchKind::Closed) =>
                                {
                                    // On the face's facets, then onto its exact surface
                                    // where the input knows it: the facets sag from the
                                    // CAD surface by up to their chord, and the error is
                                    // measured against the CAD surface too.
                                    let on_facets = surface.closest_point(limit[s]).point;
                                    match exact.get(g as usize).copied().flatten() {
                                        Some(e) => e.project(on_facets),
                                        None => on_facets,
                                    }
                                }
                                _ => continue,
                            }
                        }
                        _ => continue,
                    }
                };
                let (idx, w) = stencils.row(s);
                let row: Vec<(usize, f64)> = idx
                    .iter()
                    .zip(w)
                    .filter(|(&k, _)| col[k as usize] != usize::MAX)
                    .map(|(&k, &w)| (col[k as usize], w))
                    .collect();
                if !row.is_empty() {
                    rows.push((row, target - limit[s]));
                }
            }
            let delta = solve_blocks(&rows, unknowns.len());
            for (k, &v) in unknowns.iter().enumerate() {
                if delta[k].is_finite() {
                    control.positions[v] += delta[k];
                }
            }
        }
    }
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
