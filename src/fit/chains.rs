//! Step 2 of the fit: the curve network (corners, and the boundary chains between
//! them that adjacent faces share) and the control points each chain keeps: a few of its
//! vertices, Douglas-Peucker within the chain's tolerance; on cylinders and cones at most an
//! angle step apart about the axis.

use glam::DVec3;

use super::curves::{self, build_curve_network, CurveNetwork, CurveOptions};
use crate::error::Result;
use crate::mesh::{BoundarySurface, ControlMesh, Tolerance};
use crate::metrics::segment_parameter;

/// The curve network with what the rounds look up in it.
pub(super) struct Chains {
    pub net: CurveNetwork,
    /// Per chain, the length (in chains) of the shortest face boundary loop it is on: a chain
    /// on a loop of one or two chains needs interior control points.
    pub loop_len: Vec<usize>,
    /// Per group, the chains on its boundary.
    pub group_chains: Vec<Vec<usize>>,
}

impl Chains {
    /// The curve network of `mesh`'s groups, chains simplified within `tol`.
    pub fn new(mesh: &ControlMesh, tol: f64) -> Result<Chains> {
        let net = build_curve_network(
            mesh,
            &CurveOptions {
                simplify_tolerance: Tolerance::Absolute(tol),
                ..Default::default()
            },
        )?;
        let mut loop_len = vec![usize::MAX; net.chains.len()];
        for gl in &net.group_loops {
            for lp in &gl.loops {
                for lc in lp {
                    let c = lc.chain as usize;
                    loop_len[c] = loop_len[c].min(lp.len());
                }
            }
        }
        let mut group_chains: Vec<Vec<usize>> = vec![Vec::new(); mesh.groups.len()];
        for (ci, c) in net.chains.iter().enumerate() {
            for &g in &c.groups {
                group_chains[g as usize].push(ci);
            }
        }
        Ok(Chains {
            net,
            loop_len,
            group_chains,
        })
    }

    /// The positions of chain `c`'s vertices, in order.
    pub fn points(&self, mesh: &ControlMesh, c: usize) -> Vec<DVec3> {
        self.net.chains[c]
            .vertices
            .iter()
            .map(|&v| mesh.positions[v as usize])
            .collect()
    }
}

/// A point's coordinates on a framed chain's surface, as the decoder combines them
/// (`spec/subdivision.md` §5): cylinder and cone `(theta, h, r)`, sphere `(longitude,
/// latitude, r)`, torus `(u, v, rho)`; `None` for a plane.
fn frame_coords(surface: &BoundarySurface, p: DVec3) -> Option<[f64; 3]> {
    let axis = surface.axis()?;
    let (e1, e2) = axis.direction.any_orthonormal_pair();
    let d = p - axis.origin;
    let h = d.dot(axis.direction);
    let q = d - axis.direction * h;
    let theta = q.dot(e2).atan2(q.dot(e1));
    Some(match *surface {
        BoundarySurface::Sphere { .. } => [theta, h.atan2(q.length()), d.length()],
        BoundarySurface::Torus { major_radius, .. } => {
            let w = q.length() - major_radius;
            [theta, h.atan2(w), (w * w + h * h).sqrt()]
        }
        _ => [theta, h, q.length()],
    })
}

/// Douglas-Peucker on a polyline given as points; returns kept indices (ends included).
fn douglas_peucker(points: &[DVec3], tol: f64) -> Vec<usize> {
    curves::douglas_peucker(points, tol)
        .into_iter()
        .map(|i| i as usize)
        .collect()
}

/// Control points (indices into `chain.vertices`) of one chain.
pub(super) fn chain_controls(
    points: &[DVec3],
    frame: Option<BoundarySurface>,
    tol: f64,
    max_step: f64,
    min_interior: usize,
) -> Vec<usize> {
    let n = points.len();
    let mut keep: Vec<usize> = match frame {
        None => douglas_peucker(points, tol),
        Some(surface) => {
            // Unwrapped frame coordinates, angles scaled to lengths, then DP in that space,
            // plus at most `max_step` radians between consecutive control points (a plane's
            // straight interior edges leave an arc's end at up to half that angle from its
            // chord, so coarse arcs let plane triangles cut across a hole).
            let second_angular = matches!(
                surface,
                BoundarySurface::Sphere { .. } | BoundarySurface::Torus { .. }
            );
            let wrap = |mut d: f64| {
                while d > std::f64::consts::PI {
                    d -= std::f64::consts::TAU;
                }
                while d <= -std::f64::consts::PI {
                    d += std::f64::consts::TAU;
                }
                d
            };
            let mut prev: Option<[f64; 3]> = None;
            let mut unwrapped = [0.0; 2];
            let param: Vec<DVec3> = points
                .iter()
                .map(|&p| {
                    let c = frame_coords(&surface, p).unwrap_or_default();
                    if let Some(pc) = prev {
                        unwrapped[0] += wrap(c[0] - pc[0]);
                        unwrapped[1] += wrap(c[1] - pc[1]);
                    }
                    prev = Some(c);
                    let second = if second_angular { unwrapped[1] } else { c[1] };
                    DVec3::new(unwrapped[0], second, c[2])
                })
                .collect();
            let rmax = param.iter().map(|q| q.z).fold(0.0, f64::max);
            // The lengths of a radian in the first and second coordinates.
            let scale = match surface {
                BoundarySurface::Torus { major_radius, .. } => [major_radius + rmax, rmax],
                BoundarySurface::Sphere { .. } => [rmax, rmax],
                _ => [rmax, 1.0],
            };
            let scaled: Vec<DVec3> = param
                .iter()
                .map(|q| DVec3::new(q.x * scale[0], q.y * scale[1], q.z))
                .collect();
            let mut k = douglas_peucker(&scaled, tol);
            let mut out = vec![0];
            for w in k.windows(2) {
                let (a, b) = (w[0], w[1]);
                // The angle that turns most between a and b sets the pieces.
                let i = if second_angular
                    && (param[b].y - param[a].y).abs() > (param[b].x - param[a].x).abs()
                {
                    1
                } else {
                    0
                };
                let span = (param[b][i] - param[a][i]).abs();
                let pieces = (span / max_step).ceil().max(1.0) as usize;
                // Insert evenly spaced (in angle) chain vertices between a and b.
                for s in 1..pieces {
                    let target =
                        param[a][i] + (param[b][i] - param[a][i]) * s as f64 / pieces as f64;
                    let best = (a + 1..b)
                        .min_by(|&x, &y| {
                            (param[x][i] - target)
                                .abs()
                                .total_cmp(&(param[y][i] - target).abs())
                        })
                        .unwrap_or(a);
                    if best > *out.last().unwrap_or(&0) {
                        out.push(best);
                    }
                }
                out.push(b);
            }
            k = out;
            k.dedup();
            k
        }
    };
    // Short loops need interior points or the decimation would collapse them to a digon.
    let interior = keep.len().saturating_sub(2);
    if interior < min_interior && n > 2 {
        let want = min_interior.min(n - 2);
        keep = (0..want + 2).map(|i| i * (n - 1) / (want + 1)).collect();
        keep.dedup();
    }
    keep
}

/// Closest point to `p` on a polyline.
pub(super) fn closest_on_polyline(p: DVec3, line: &[DVec3]) -> DVec3 {
    let mut best = (f64::INFINITY, line[0]);
    for w in line.windows(2) {
        // `w[0] + t (w[1] - w[0])`, not `lerp` (which rounds differently).
        let q = w[0] + (w[1] - w[0]) * segment_parameter(p, w[0], w[1]);
        let d = (p - q).length_squared();
        if d < best.0 {
            best = (d, q);
        }
    }
    best.1
}
