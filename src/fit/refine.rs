//! Step 6 of the fit, after a measurement: more control points where the decoded surface is
//! out of tolerance (thresholds lowered and chains refined near the failures), and, once the
//! model is within tolerance, fewer again where it ended far within it ([`Relaxation`]).

use std::collections::BTreeMap;

use glam::DVec3;

use super::chains::{closest_on_polyline, Chains};
use super::classify::Faces;
use super::curves::CurveNetwork;
use super::encoder::FitReport;
use super::measure::Measurement;
use super::plan::{chain_frame_owner, kind_name, GroupPlan, Plan, INITIAL_CLOSED_COST};
use crate::mesh::{BoundarySurface, ControlMesh, PatchKind};

/// How much a failing closed patch's decimation threshold shrinks per round.
const CLOSED_COST_STEP: f64 = 0.35;

/// A converged closed patch whose worst excess is below this fraction of the tolerance was
/// refined further than it needed: its last refinement step divided its threshold by
/// 1/[`CLOSED_COST_STEP`] (about 2.9x its control faces) when it may have been a few
/// percent over.
const RELAX_BELOW: f64 = 0.6;

/// How much a relaxed patch's decimation thresholds grow: half a refinement step back.
const RELAX_STEP: f64 = 1.690_308_509_457_033; // 1 / sqrt(CLOSED_COST_STEP)

/// The state a relaxation round starts from, to restore the groups it breaks.
///
/// Refinement only ever adds control points, in steps sized for convergence, so a patch
/// a little over the tolerance in one round often ends far within it (a sphere patch 1.1-1.5
/// tol off can end with more than twice the control faces it needs). Once the
/// model is within tolerance, one round coarsens such patches again; where that fails, the
/// converged thresholds come back and the model is measured again; the smaller model within
/// tolerance is kept.
pub(super) struct Relaxation {
    /// Relaxed groups, ascending.
    pub groups: Vec<usize>,
    /// Plans and per-vertex cost factors before relaxing.
    pub plans: Vec<GroupPlan>,
    pub vertex_cost: Vec<f64>,
    /// By group: the input vertices whose cost factor was raised.
    pub vertices: Vec<Vec<u32>>,
    /// Whether this is the round after a failed relaxation.
    pub verifying: bool,
}

/// Raises the decimation thresholds of refined closed patches whose excess is below
/// [`RELAX_BELOW`] tolerances (see [`Relaxation`]).
pub(super) fn relax_refined_groups(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    group_excess: &[(f64, DVec3, &str)],
    tol: f64,
    plans: &mut [GroupPlan],
    vertex_cost: &mut [f64],
) -> Relaxation {
    let saved_plans = plans.to_vec();
    let saved_cost = vertex_cost.to_vec();
    let mut vertices = vec![Vec::new(); plans.len()];
    for (t, &g) in tris.iter().zip(&mesh.face_groups) {
        vertices[g as usize].extend(t.iter().copied());
    }
    let mut groups = Vec::new();
    for (g, plan) in plans.iter_mut().enumerate() {
        let vs = &mut vertices[g];
        if !matches!(plan.kind, PatchKind::Closed)
            || plan.failures == 0
            || group_excess.get(g).is_none_or(|e| e.0 >= RELAX_BELOW * tol)
        {
            vs.clear();
            continue;
        }
        vs.sort_unstable();
        vs.dedup();
        vs.retain(|&v| vertex_cost[v as usize] < 1.0);
        let lowered_locally = !vs.is_empty();
        for &v in vs.iter() {
            vertex_cost[v as usize] = (vertex_cost[v as usize] * RELAX_STEP).min(1.0);
        }
        if plan.cost_factor < INITIAL_CLOSED_COST {
            plan.cost_factor = (plan.cost_factor * RELAX_STEP).min(INITIAL_CLOSED_COST);
        } else if !lowered_locally {
            continue;
        }
        groups.push(g);
    }
    Relaxation {
        groups,
        plans: saved_plans,
        vertex_cost: saved_cost,
        vertices,
        verifying: false,
    }
}

/// How far a round's refinement reaches along the chains of the failing groups.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum ChainReach {
    /// Every chain of a failing group.
    All,
    /// Only the chains near where a group fails (see [`chains_near_failures`]).
    NearFailures,
}

/// A failing boundary patch whose excess stays above this fraction of its previous
/// failure's becomes a closed patch.
const BOUNDARY_STALL_RATIO: f64 = 0.9;

/// A closed patch whose excess did not shrink this many times in a row is faceted (see
/// [`GroupPlan::faceted`]): refining it further has stopped paying.
const FACETED_AFTER_STALLS: u32 = 2;

/// Facets every group of `plan` out of tolerance in `measured` that is not faceted yet, and
/// makes closed the patches whose frames shape their creases; returns how many it faceted.
/// The fit's last resort when its rounds stop gaining.
pub(super) fn facet_failing(
    chains: &Chains,
    measured: &Measurement,
    tol: f64,
    plan: &mut Plan,
    report: &mut FitReport,
) -> usize {
    let failing: Vec<usize> = (0..plan.groups.len())
        .filter(|&g| {
            let group = &plan.groups[g];
            measured.group_excess[g].0 > tol && group.facetable && !group.faceted
        })
        .collect();
    for &g in &failing {
        let group = &mut plan.groups[g];
        group.kind = PatchKind::Closed;
        group.faceted = true;
    }
    if !failing.is_empty() {
        report.notes.push(format!(
            "  {} groups still beyond tolerance faceted (their input facets as control faces)",
            failing.len()
        ));
    }
    close_frame_owners(chains, &failing, &mut plan.groups, report);
    failing.len()
}

/// Refines the plan of every group out of tolerance in `measured` (the measurement of
/// `control`): a closed patch gets a lower decimation threshold (near its failures only with
/// `local_refinement`), a boundary patch that failed four times, or twice without its
/// excess shrinking (a plane: without its decoded surface changing), becomes a closed patch
/// (an axial one not in a round whose decode level was raised, `level_raised`: it is
/// measured at that level first), a closed patch that failed
/// [`FACETED_AFTER_STALLS`] times in a row without its excess shrinking, measured at the
/// last decode level the fit will try (`at_last_level`), is faceted, and the chains `reach`
/// selects get finer.
#[allow(clippy::too_many_arguments)]
pub(super) fn refine_failing(
    faces: &Faces,
    chains: &Chains,
    control: &ControlMesh,
    measured: &Measurement,
    reach: ChainReach,
    local_refinement: bool,
    at_last_level: bool,
    level_raised: bool,
    tol: f64,
    plan: &mut Plan,
    report: &mut FitReport,
) {
    let mesh = &faces.mesh;
    let bad_group: Vec<bool> = measured.group_excess.iter().map(|e| e.0 > tol).collect();
    let chain_refine = match reach {
        ChainReach::All => {
            let mut all = vec![false; chains.net.chains.len()];
            for g in (0..mesh.groups.len()).filter(|&g| bad_group[g]) {
                for &c in &chains.group_chains[g] {
                    all[c] = true;
                }
            }
            all
        }
        ChainReach::NearFailures => {
            let reach: Vec<f64> = (0..mesh.groups.len())
                .map(|g| {
                    if bad_group[g] && matches!(plan.groups[g].kind, PatchKind::Closed) {
                        0.5 * mean_group_edge(control, g as u32)
                    } else {
                        0.0
                    }
                })
                .collect();
            chains_near_failures(
                mesh,
                &chains.net,
                &chains.group_chains,
                &bad_group,
                &measured.bad_points,
                &plan.groups,
                &reach,
                tol,
            )
        }
    };
    let mut refitted_closed = Vec::new();
    for (g, bad) in bad_group.iter().enumerate() {
        if !bad {
            continue;
        }
        let group = &mut plan.groups[g];
        group.failures += 1;
        let excess = measured.group_excess[g].0;
        // A boundary patch whose excess did not shrink since its last failure gains nothing
        // from finer chains (its surface, not its outline, is off): closed at once. A plane
        // only once its decoded surface no longer changes (its measured excess, a function
        // of its triangles alone, is the same): its decoded points lie in its plane, so
        // while its chains still get finer they mend its outline, if more slowly than one
        // round's tenth around a tight curve or after a neighbour's finer chains moved it.
        let stalled = group.failures >= 2 && excess > BOUNDARY_STALL_RATIO * group.last_excess;
        let plane = matches!(group.kind, PatchKind::Boundary(BoundarySurface::Plane));
        let unchanged = excess == group.last_excess;
        let given_up = group.failures >= 4 || (stalled && (!plane || unchanged));
        group.last_excess = excess;
        if matches!(group.kind, PatchKind::Closed) {
            // Stalls count at the last decode level only: a finer level is the remedy for
            // a smooth patch's piecewise-linear error, tried before faceting.
            group.stalls = if stalled && at_last_level {
                group.stalls + 1
            } else {
                0
            };
            if group.stalls >= FACETED_AFTER_STALLS && group.facetable && !group.faceted {
                report.notes.push(format!(
                    "group {g} faceted: {FACETED_AFTER_STALLS} refinements as a closed patch came no nearer than {:.2} tol",
                    excess / tol
                ));
                group.faceted = true;
                refitted_closed.push(g);
                continue;
            }
            report.closed_refinements += 1;
            let radius = 2.0 * mean_group_edge(control, g as u32);
            let lowered = if !local_refinement {
                0
            } else {
                lower_cost_near(
                    mesh,
                    &faces.tris,
                    g as u32,
                    &measured.bad_points[g],
                    radius,
                    CLOSED_COST_STEP,
                    &mut plan.vertex_cost,
                )
            };
            if lowered == 0 {
                group.cost_factor *= CLOSED_COST_STEP;
            }
        } else if given_up
            && !(level_raised && matches!(group.kind, PatchKind::Boundary(s) if s.axis().is_some()))
        {
            // A curved analytic patch is measured at the finer level it asked for first
            // (see `Rounds::finer_level`) before it is given up for a closed one.
            report.notes.push(format!(
                "group {g} ({}) refitted as a closed patch",
                kind_name(&group.kind)
            ));
            group.kind = PatchKind::Closed;
            group.cost_factor = 2.0;
            refitted_closed.push(g);
        }
    }
    plan.refine_chains(&chain_refine);
    close_frame_owners(chains, &refitted_closed, &mut plan.groups, report);
}

/// A crease next to a cylinder or cone is interpolated in that patch's frame: on its
/// surface, but between control points off any other surface it bounds (a slanted plane
/// cuts a cone in a hyperbola, not in a curve affine in (theta, h, r)). A group that failed
/// as a boundary patch may fail because of such creases, and making it closed does not
/// change them: make the frame's owner closed too, so the crease becomes Cartesian and is
/// fitted to its polyline (e.g. a hexagon's sides next to its chamfer cones).
fn close_frame_owners(
    chains: &Chains,
    refitted_closed: &[usize],
    plans: &mut [GroupPlan],
    report: &mut FitReport,
) {
    for &g in refitted_closed {
        for &c in &chains.group_chains[g] {
            let Some(h) = chain_frame_owner(&chains.net.chains[c].groups, plans) else {
                continue;
            };
            let plan = &mut plans[h as usize];
            report.notes.push(format!(
                "group {h} ({}) refitted as a closed patch: its frame shapes a crease of group {g}",
                kind_name(&plan.kind)
            ));
            plan.kind = PatchKind::Closed;
            plan.cost_factor = 2.0;
        }
    }
}

/// Notes the groups out of tolerance in `measured` (how many, and the worst four).
pub(super) fn note_failures(
    mesh: &ControlMesh,
    plans: &[GroupPlan],
    measured: &Measurement,
    tol: f64,
    report: &mut FitReport,
) {
    let group_excess = &measured.group_excess;
    let mut worst_groups: Vec<usize> = (0..mesh.groups.len())
        .filter(|&g| group_excess[g].0 > tol)
        .collect();
    worst_groups.sort_by(|&a, &b| group_excess[b].0.total_cmp(&group_excess[a].0));
    let listed: Vec<String> = worst_groups
        .iter()
        .take(4)
        .map(|&g| {
            let (d, p, dir) = group_excess[g];
            format!(
                "group {g} '{}' ({}) {:.2} tol {dir} at ({:.4}, {:.4}, {:.4})",
                mesh.groups[g].name,
                kind_name(&plans[g].kind),
                d / tol,
                p.x,
                p.y,
                p.z
            )
        })
        .collect();
    report.notes.push(format!(
        "  {} groups beyond tolerance; worst: {}",
        worst_groups.len(),
        listed.join("; ")
    ));
}

/// Mean length of the edges of group `g`'s faces in a control mesh (0 without faces).
fn mean_group_edge(control: &ControlMesh, g: u32) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for f in 0..control.face_count() {
        if control.face_groups[f] != g {
            continue;
        }
        let face = control.face(f);
        for k in 0..face.len() {
            let (a, b) = (face[k], face[(k + 1) % face.len()]);
            sum += (control.positions[a as usize] - control.positions[b as usize]).length();
            n += 1;
        }
    }
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

/// Multiplies by `step` the decimation factor of group `g`'s input vertices within `radius`
/// of a point where its decoded surface was out of tolerance; returns how many. Refining a
/// closed patch only there, not everywhere, keeps the rest as coarse as it was fine
/// (a sphere corner patch that fails only at its three corners would otherwise triple its
/// control vertices in one round).
fn lower_cost_near(
    mesh: &ControlMesh,
    tris: &[[u32; 3]],
    g: u32,
    points: &[DVec3],
    radius: f64,
    step: f64,
    vertex_cost: &mut [f64],
) -> usize {
    if points.is_empty() || !(radius > 0.0 && radius.is_finite()) {
        return 0;
    }
    // Points hashed into cells of side `radius` (thinned to a quarter radius apart), so a
    // vertex looks at its 27 neighbouring cells only.
    let cell = |p: DVec3| -> (i64, i64, i64) {
        let c = (p / radius).floor();
        (c.x as i64, c.y as i64, c.z as i64)
    };
    let mut grid: BTreeMap<(i64, i64, i64), Vec<DVec3>> = BTreeMap::new();
    for &p in points {
        let list = grid.entry(cell(p)).or_default();
        if list.iter().all(|q| (*q - p).length() > 0.25 * radius) {
            list.push(p);
        }
    }
    let mut seen = std::collections::BTreeSet::new();
    for (t, &fg) in tris.iter().zip(&mesh.face_groups) {
        if fg == g {
            seen.extend(t.iter().copied());
        }
    }
    let mut lowered = 0;
    for v in seen {
        let p = mesh.positions[v as usize];
        let (cx, cy, cz) = cell(p);
        let near = (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dz| {
                    grid.get(&(cx + dx, cy + dy, cz + dz))
                        .is_some_and(|l| l.iter().any(|q| (*q - p).length() <= radius))
                })
            })
        });
        if near {
            vertex_cost[v as usize] *= step;
            lowered += 1;
        }
    }
    lowered
}

/// Points thinned to at most one per cell of side `cell` (first come first kept).
fn thin_points(points: &[DVec3], cell: f64) -> Vec<DVec3> {
    if !(cell > 0.0 && cell.is_finite()) {
        return points.to_vec();
    }
    let mut seen = std::collections::BTreeSet::new();
    points
        .iter()
        .copied()
        .filter(|p| {
            let c = (*p / cell).floor();
            seen.insert((c.x as i64, c.y as i64, c.z as i64))
        })
        .collect()
}

/// Which chains of the failing groups to refine: for each point where a group is out of
/// tolerance (thinned to one per 2 tol), the group's chains at most 1.5 times as far from it
/// as the nearest one, plus 2 tol (the nearest chain is what shapes a boundary patch's error
/// there), and for closed patches only chains within `reach[g]` of the point (farther, the
/// patch's interior is what is off).
#[allow(clippy::too_many_arguments)]
fn chains_near_failures(
    mesh: &ControlMesh,
    net: &CurveNetwork,
    group_chains: &[Vec<usize>],
    bad_group: &[bool],
    bad_points: &[Vec<DVec3>],
    plans: &[GroupPlan],
    reach: &[f64],
    tol: f64,
) -> Vec<bool> {
    let mut refine = vec![false; net.chains.len()];
    for (g, &bad) in bad_group.iter().enumerate() {
        if !bad || group_chains[g].is_empty() {
            continue;
        }
        let closed = matches!(plans[g].kind, PatchKind::Closed);
        let pts = thin_points(&bad_points[g], 2.0 * tol);
        if pts.is_empty() {
            // No located failure: refine them all.
            for &c in &group_chains[g] {
                refine[c] = true;
            }
            continue;
        }
        let lines: Vec<Vec<DVec3>> = group_chains[g]
            .iter()
            .map(|&c| {
                net.chains[c]
                    .vertices
                    .iter()
                    .map(|&v| mesh.positions[v as usize])
                    .collect()
            })
            .collect();
        for p in pts {
            let d: Vec<f64> = lines
                .iter()
                .map(|line| (closest_on_polyline(p, line) - p).length())
                .collect();
            let dmin = d.iter().copied().fold(f64::INFINITY, f64::min);
            for (k, &c) in group_chains[g].iter().enumerate() {
                let near = d[k] <= 1.5 * dmin + 2.0 * tol;
                if near && (!closed || d[k] <= reach[g]) {
                    refine[c] = true;
                }
            }
        }
    }
    refine
}
