//! The fit's rounds: build a control mesh from the plan, fit its geometry, measure what the
//! decoder will make of it, and refine the plan where it fails, until the tolerance holds;
//! then coarsen once where it ended far within it ([`Relaxation`]).

use std::time::Instant;

use super::build::{build_topology, Built};
use super::chains::Chains;
use super::classify::Faces;
use super::decimate::FaceDecimator;
use super::domain::PlaneDomain;
use super::encoder::{with_faces_involved, FitError, FitOptions, FitReport, Reconstruct};
use super::exact::ExactSurface;
use super::measure::{ErrorMeter, Measurement};
use super::plan::Plan;
use super::reference::Facets;
use super::refine::{
    facet_failing, note_failures, refine_failing, relax_refined_groups, ChainReach, Relaxation,
};
use super::solve::{fit_geometry, SolveCache};
use crate::codec::Limits;
use crate::error::{Error, Result};
use crate::mesh::{ControlMesh, PatchKind};
use crate::subdiv::default_decode_bytes;

/// The decode level the fit starts at, and the finest it goes to. A model is stored for the
/// coarsest level that meets its tolerance: each level has four times the triangles of the
/// one before, for the fit to measure and for a decoder to make. Most CAD faces are met at
/// the first level with a few more control points; a face the fit cannot get within the
/// tolerance for the chord error between its decoded triangles' corners needs a finer one.
const FIRST_LEVEL: u8 = 3;
const LAST_LEVEL: u8 = 5;

/// When a round's worst excess on closed patches stays above this fraction of the previous
/// round's, or an axial patch's above this fraction of its excess when it last failed,
/// adding control points has stopped paying, and the fit moves to a finer decode level if
/// that face's failure is the chord error of its level (see `Rounds::finer_level_meeting`).
/// A lower ratio moves models to finer levels that the coarser one fits as well, at four
/// times the triangles to measure.
const STALL_RATIO: f64 = 0.85;

/// The share of a level's chord error that the next level keeps on a smooth surface
/// (triangles half the size stray a quarter as far from the surface between their corners).
const FINER_CHORD_SHARE: f64 = 0.25;

/// Rounds in a row whose worst excess is no better than [`NO_GAIN_RATIO`] of the best so far
/// after which the fit stops refining: a face refined down to the input's own vertices, or
/// facets no smooth surface comes nearer to, fail the same way round after round, and each
/// round costs a measurement.
const NO_GAIN_ROUNDS: usize = 3;
const NO_GAIN_RATIO: f64 = 0.98;

/// Rounds the fit may run beyond `FitOptions::max_rounds` to measure groups faceted at the
/// end of the rounds (each such round facets the groups still failing, so they end when none
/// is left to facet).
const FACETING_ROUNDS: usize = 3;

/// The finest decode level from [`FIRST_LEVEL`] up to `level` at which a decoder's default
/// memory budget holds the decode of `control` to its tolerance ([`default_decode_bytes`]);
/// `FIRST_LEVEL` if none does.
fn decodable_level(control: &ControlMesh, level: u8) -> u8 {
    let budget = Limits::default().max_memory;
    (FIRST_LEVEL..=level)
        .rev()
        .find(|&l| default_decode_bytes(control, l.into()) <= budget)
        .unwrap_or(FIRST_LEVEL)
}

/// The largest excess on a closed patch of `plan` in `measured`, and its group (0.0 when
/// none is closed).
fn worst_closed_excess(plan: &Plan, measured: &Measurement) -> (f64, usize) {
    (0..plan.groups.len())
        .filter(|&g| matches!(plan.groups[g].kind, PatchKind::Closed))
        .map(|g| (measured.group_excess[g].0, g))
        .fold((0.0, 0), |a, b| if b.0 > a.0 { b } else { a })
}

/// How many groups of `plan` are closed patches.
fn closed_count(plan: &Plan) -> usize {
    plan.groups
        .iter()
        .filter(|g| matches!(g.kind, PatchKind::Closed))
        .count()
}

/// A fitted model within reach of the output: its error, control mesh, decode level and
/// file size at the default quantisation.
pub(super) struct Candidate {
    pub err: FitError,
    pub control: ControlMesh,
    pub level: u8,
    pub bytes: usize,
    /// How many of its groups are faceted (see `GroupPlan::faceted`).
    pub faceted: usize,
}

/// What the rounds read and never change.
pub(super) struct Rounds<'a> {
    pub faces: &'a Faces,
    pub chains: &'a Chains,
    /// The input's facets, which the closed patches are fitted to.
    pub input: &'a Facets,
    /// By group: the face's exact surface, if the input knows it (empty: none).
    pub exact: &'a [Option<ExactSurface>],
    /// By group, where each plane face lies in its plane (empty: planes decimated freely).
    pub plane_domains: &'a [Option<PlaneDomain>],
    pub meter: &'a ErrorMeter<'a>,
    pub opts: &'a FitOptions,
    pub tol: f64,
    /// [`FitOptions::keep_planes_on_faces`], for groups from the input.
    pub keep_planes_on_faces: bool,
}

/// One round's model and its measurement.
struct Round {
    built: Built,
    /// The decode level it was measured at: the one asked, or a coarser one when a decoder
    /// could not make the model at that level within its default memory budget.
    level: u8,
    measured: Measurement,
    /// Size of the model's file at the default quantisation.
    bytes: usize,
}

/// What follows a round's measurement.
enum Next {
    /// The rounds are over.
    Stop,
    /// Build and measure the changed plan without refining it.
    Measure,
    /// Refine the plan where the model failed.
    Refine,
}

impl Rounds<'_> {
    /// Runs the rounds from `plan` and returns the model that converged (the best one when
    /// none met the tolerance), then the relaxed one if relaxing held the tolerance.
    pub fn run(
        &self,
        plan: &mut Plan,
        reconstruct: &mut Reconstruct<'_>,
        report: &mut FitReport,
    ) -> Result<Vec<Candidate>> {
        let (opts, tol) = (self.opts, self.tol);
        let mut best: Option<Candidate> = None;
        let mut relaxed_best: Option<Candidate> = None;
        let mut prev_worst: Option<f64> = None;
        // The decode level of the next round, and whether it can still get finer.
        let mut level = opts.default_level.unwrap_or(FIRST_LEVEL);
        let fixed_level = opts.default_level.is_some();
        // The finest level the fit may move to: coarser than `LAST_LEVEL` once a model was
        // too large to decode at a finer one (see `Rounds::round`).
        let mut ceiling = LAST_LEVEL;
        // Set once the model is within tolerance and refined patches are being coarsened again.
        let mut relaxing: Option<Relaxation> = None;
        let mut decimator = FaceDecimator::default();
        let mut solved = SolveCache::default();
        // The smallest worst excess of a failing round so far, and how many failing rounds
        // since came no nearer.
        let (mut nearest, mut no_gain) = (f64::INFINITY, 0);
        // Rounds allowed: `max_rounds`, and beyond it the rounds that measure faceted groups
        // (see `FACETING_ROUNDS`).
        let mut budget = opts.max_rounds.max(1);
        let mut next_round = 0;
        while next_round < budget {
            let round = next_round;
            next_round += 1;
            report.rounds = round + 1;
            let Round {
                built,
                level: measured_level,
                measured,
                bytes,
            } = self.round(
                plan,
                level,
                &mut decimator,
                &mut solved,
                reconstruct,
                report,
            )?;
            if measured_level < level {
                (level, ceiling) = (measured_level, measured_level);
            }
            let err = measured.error;
            let worst = err.max_excess;
            let ok = worst <= tol;
            let better = best.as_ref().is_none_or(|b| {
                let e = &b.err;
                let e_ok = e.max_excess <= tol;
                (ok && !e_ok) || (ok == e_ok && worst < e.max_excess)
            });
            let candidate = || Candidate {
                err,
                control: built.control.clone(),
                level,
                bytes,
                faceted: plan.groups.iter().filter(|g| g.faceted).count(),
            };
            if relaxing.is_none() && (better || ok) {
                best = Some(candidate());
            } else if relaxing.is_some() && ok {
                relaxed_best = Some(candidate());
            }
            if !ok && relaxing.is_none() {
                no_gain = if worst > NO_GAIN_RATIO * nearest {
                    no_gain + 1
                } else {
                    0
                };
                nearest = nearest.min(worst);
                // The last resort: the groups still failing become their input facets, and a
                // round measures them. At the end of the rounds this repeats while there are
                // failing groups to facet: faceting a group changes the chains it shares, so
                // a neighbour may fail next, and a model that can be held to the tolerance
                // is not given up a round early.
                let stuck = no_gain >= NO_GAIN_ROUNDS || round + 2 >= budget;
                if stuck
                    && round + 1 < opts.max_rounds.max(1) + FACETING_ROUNDS
                    && facet_failing(self.chains, &measured, tol, plan, report) > 0
                {
                    budget = budget.max(round + 2);
                    (nearest, no_gain) = (f64::INFINITY, 0);
                    continue;
                }
                if no_gain >= NO_GAIN_ROUNDS {
                    report.notes.push(format!(
                        "  stopped: {NO_GAIN_ROUNDS} rounds came no nearer than {:.2} tol",
                        nearest / tol
                    ));
                    break;
                }
            }
            let rounds_left = budget.saturating_sub(round + 1);
            match self.after_measurement(ok, rounds_left, &mut relaxing, &measured, plan, report) {
                Next::Stop => break,
                Next::Measure => continue,
                Next::Refine => {}
            }
            note_failures(&self.faces.mesh, &plan.groups, &measured, tol, report);
            let level_before = level;
            if !fixed_level {
                ceiling = decodable_level(&built.control, ceiling);
                level = self.finer_level(plan, &measured, level, ceiling, prev_worst);
                prev_worst = Some(worst_closed_excess(plan, &measured).0);
            }
            // Chains are refined only near where their groups fail (a plane with a hundred
            // holes failing at one of them keeps the other holes coarse); the last rounds,
            // and every round once the worst excess is within 1.5 tol, refine every chain of
            // a failing group: convergence first (near the tolerance, refining only near the
            // failures takes more rounds than it saves control points).
            let reach = if round + 4 >= budget || !self.keep_planes_on_faces || worst < 1.5 * tol {
                ChainReach::All
            } else {
                ChainReach::NearFailures
            };
            let closed_before = closed_count(plan);
            refine_failing(
                self.faces,
                self.chains,
                &built.control,
                &measured,
                reach,
                opts.local_refinement,
                fixed_level || level_before == ceiling,
                level != level_before,
                tol,
                plan,
                report,
            );
            // A patch refitted as a closed one, or a finer decode level, is a new start.
            if closed_count(plan) > closed_before || level != level_before {
                no_gain = 0;
            }
        }
        let Some(converged) = best else {
            return Err(Error::Mesh("fitting produced no control mesh".into()));
        };
        let mut candidates = vec![converged];
        candidates.extend(relaxed_best);
        Ok(candidates)
    }

    /// The decode level of the round after one measured at `level` (`measured`), up to
    /// `ceiling`; `prev_worst` is the worst excess on closed patches of the round before.
    ///
    /// When adding control points to closed patches stops paying (their worst excess stayed
    /// above [`STALL_RATIO`] of the round before) and what the worst of them misses by is the
    /// chord error of the level, one level finer (4x the triangles). When an analytic patch
    /// about an axis (cylinder, cone, sphere, torus) stops gaining (its excess shrank by less
    /// than `STALL_RATIO` since it last failed), its chord error is most of its excess (at
    /// least half) and a finer level's chord error would meet it, as many levels finer as it
    /// needs: its decoded points lie on its surface, so what fails it is its chord error, and
    /// the alternative, giving it up for a closed patch, costs far more control points. A
    /// patch whose excess is mostly not chord error is off for another reason (its outline,
    /// a neighbour), which no level removes, so it does not move the whole model to a level
    /// with four times the triangles. Planes have no chord error.
    fn finer_level(
        &self,
        plan: &Plan,
        measured: &Measurement,
        level: u8,
        ceiling: u8,
        prev_worst: Option<f64>,
    ) -> u8 {
        let tol = self.tol;
        let mut next = level;
        let (worst_closed, worst_group) = worst_closed_excess(plan, measured);
        if level < ceiling
            && worst_closed > tol
            && prev_worst.is_some_and(|p| worst_closed > STALL_RATIO * p)
            && self.finer_level_meeting(
                worst_closed,
                self.meter.chord_errors(&[worst_group])[0],
                level,
                ceiling,
            ) == Some(level + 1)
        {
            next = level + 1;
        }
        for (g, group) in plan.groups.iter().enumerate() {
            let excess = measured.group_excess[g].0;
            let stalled_axial = matches!(group.kind, PatchKind::Boundary(s) if s.axis().is_some())
                && excess > tol
                && group.failures > 0
                && excess > STALL_RATIO * group.last_excess;
            if !stalled_axial {
                continue;
            }
            let chord = self.meter.chord_errors(&[g])[0];
            if 2.0 * chord >= excess {
                if let Some(finer) = self.finer_level_meeting(excess, chord, level, ceiling) {
                    next = next.max(finer);
                }
            }
        }
        next
    }

    /// The coarsest decode level finer than `level` (up to `ceiling`) expected to bring a
    /// last measured group whose excess is `excess` and whose chord error is `chord` within
    /// the tolerance, if any.
    /// Each level halves the triangles' size, so on a smooth surface it leaves a quarter of
    /// the previous level's chord error ([`ErrorMeter::chord_errors`]); what is not chord
    /// error no level changes, so a finer level pays only where the chord error is most of
    /// the excess over the tolerance. Refining the control mesh, which also shortens the
    /// triangles, does the rest.
    fn finer_level_meeting(&self, excess: f64, chord: f64, level: u8, ceiling: u8) -> Option<u8> {
        let mut kept = 1.0;
        (level + 1..=ceiling).find(|_| {
            kept *= FINER_CHORD_SHARE;
            excess - (1.0 - kept) * chord <= self.tol
        })
    }

    /// Builds, fits and measures the plan's model at decode level `level`; or, unless the
    /// level is the caller's (`FitOptions::default_level`) and when a decoder's default
    /// memory budget cannot hold the model's decode at that level ([`default_decode_bytes`]),
    /// at the finest coarser one that it can, down to [`FIRST_LEVEL`]. A level finer than the
    /// file's readers can afford is no use, and the control mesh grows over the rounds after
    /// a level is chosen, so this is checked on every round's model.
    fn round(
        &self,
        plan: &Plan,
        mut level: u8,
        decimator: &mut FaceDecimator,
        solved: &mut SolveCache,
        reconstruct: &mut Reconstruct<'_>,
        report: &mut FitReport,
    ) -> Result<Round> {
        let mut t = Instant::now();
        let mut built = build_topology(
            self.faces,
            self.chains,
            plan,
            self.tol,
            self.plane_domains,
            decimator,
        );
        let t_top = t.elapsed().as_secs_f64();
        t = Instant::now();
        fit_geometry(
            &mut built,
            &self.faces.mesh,
            &self.chains.net,
            &plan.groups,
            &self.input.group_surfaces,
            self.exact,
            solved,
        )
        .map_err(|e| with_faces_involved(e, &built.control))?;
        let t_fit = t.elapsed().as_secs_f64();
        if self.opts.default_level.is_none() {
            let asked = level;
            level = decodable_level(&built.control, level);
            if level < asked {
                report.notes.push(format!(
                    "  level {asked} would need more than a decoder's default memory: measured at level {level}, the finest from now on"
                ));
            }
        }
        t = Instant::now();
        let (decoded, bytes) = reconstruct(&built.control, level, 0)
            .map_err(|e| with_faces_involved(e, &built.control))?;
        let t_write = t.elapsed().as_secs_f64();
        t = Instant::now();
        let measured = self
            .meter
            .measure(&decoded, level)
            .map_err(|e| with_faces_involved(e, &decoded))?;
        let err = measured.error;
        let tol = self.tol;
        report.timings.push(("topology", t_top));
        report.timings.push(("fit", t_fit));
        let t_measure = t.elapsed().as_secs_f64();
        report.timings.push(("write", t_write));
        report.timings.push(("measure", t_measure));
        report.notes.push(format!(
            "round {}: {} control vertices ({} of {} faces decimated anew{}), level {level}, max error {:.3e} ({:.2} tol; {:.2} tol vs {}), rms {:.3e}; {} of {} faces measured anew (build {:.2} s, fit {:.2} s, write {:.2} s, measure {:.2} s)",
            report.rounds,
            built.control.vertex_count(),
            built.decimation.faces_redone,
            self.faces.mesh.groups.len(),
            if built.decimation.whole_mesh { ", then the whole mesh as one" } else { "" },
            err.max,
            err.max / tol,
            err.max_excess / tol,
            report.reference.describe(),
            err.rms,
            measured.changed_groups,
            self.faces.mesh.groups.len(),
            t_top,
            t_fit,
            t_write,
            t_measure,
        ));
        Ok(Round {
            built,
            level,
            measured,
            bytes,
        })
    }

    /// Decides what follows a measurement (`ok`: within tolerance; `rounds_left`: how many
    /// more rounds are allowed) and starts, checks or ends a relaxation: a model within
    /// tolerance relaxes its refined closed patches once; when relaxing broke the tolerance,
    /// the relaxed groups that fail get their converged thresholds back and the model is
    /// measured once more. A relaxation starts only while both of those rounds are left:
    /// measured in the last round, one failing group of the dozens relaxed would throw the
    /// whole relaxation away, which is what a model that converges late mostly gets.
    fn after_measurement(
        &self,
        ok: bool,
        rounds_left: usize,
        relaxing: &mut Option<Relaxation>,
        measured: &Measurement,
        plan: &mut Plan,
        report: &mut FitReport,
    ) -> Next {
        let (faces, tol) = (self.faces, self.tol);
        match relaxing.take() {
            None if ok && (!self.opts.relax || rounds_left < 2) => Next::Stop,
            None if ok => {
                let relaxed = relax_refined_groups(
                    &faces.mesh,
                    &faces.tris,
                    &measured.group_excess,
                    tol,
                    &mut plan.groups,
                    &mut plan.vertex_cost,
                );
                if relaxed.groups.is_empty() {
                    return Next::Stop;
                }
                report.notes.push(format!(
                    "  within tolerance; {} refined closed patches far within it get a coarser threshold",
                    relaxed.groups.len()
                ));
                *relaxing = Some(relaxed);
                Next::Measure
            }
            None => Next::Refine,
            Some(r) if ok || r.verifying => Next::Stop,
            Some(mut r) => {
                // When a group that was not relaxed fails (relaxed patches moved vertices it
                // shares), restoring would give the converged model again: keep it.
                let failing: Vec<usize> = (0..faces.mesh.groups.len())
                    .filter(|&g| measured.group_excess[g].0 > tol)
                    .collect();
                if failing.iter().any(|g| r.groups.binary_search(g).is_err()) || rounds_left == 0 {
                    return Next::Stop;
                }
                for &g in &r.groups {
                    if failing.binary_search(&g).is_ok() {
                        plan.groups[g] = r.plans[g];
                        for &v in &r.vertices[g] {
                            plan.vertex_cost[v as usize] = r.vertex_cost[v as usize];
                        }
                    }
                }
                report.notes.push(format!(
                    "  relaxing failed in {} groups: their thresholds restored",
                    failing.len()
                ));
                r.verifying = true;
                *relaxing = Some(r);
                Next::Measure
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::test_support::grid_cube;

    /// The finest level a fit may use is the finest whose decode a decoder's default memory
    /// holds: a small control mesh keeps the finest level, larger ones get coarser levels,
    /// and one too large for any gets the first.
    #[test]
    fn decodable_level_is_the_finest_the_decode_memory_holds() {
        let budget = Limits::default().max_memory;
        let fits = |m: &ControlMesh, l: u8| default_decode_bytes(m, l.into()) <= budget;
        let mut levels = Vec::new();
        for n in [4, 16, 32, 64, 128] {
            let mesh = grid_cube(n);
            let l = decodable_level(&mesh, LAST_LEVEL);
            assert!(fits(&mesh, l) || l == FIRST_LEVEL, "n {n}: level {l}");
            assert!(l == LAST_LEVEL || !fits(&mesh, l + 1), "n {n}: level {l}");
            // A level asked below the finest that fits is kept.
            assert_eq!(
                decodable_level(&mesh, FIRST_LEVEL.max(l - 1)),
                FIRST_LEVEL.max(l - 1)
            );
            levels.push(l);
        }
        assert!(levels.windows(2).all(|w| w[1] <= w[0]), "{levels:?}");
        assert_eq!(levels.first(), Some(&LAST_LEVEL), "{levels:?}");
        assert_eq!(levels.last(), Some(&FIRST_LEVEL), "{levels:?}");
        assert!(!fits(&grid_cube(128), FIRST_LEVEL));
        assert!(levels.contains(&(LAST_LEVEL - 1)), "{levels:?}");
    }
}
