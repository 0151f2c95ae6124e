//! A decoded surface with no edge longer than a given length, for solvers that need an
//! element size.
//!
//! Every edge longer than `max_edge` is split at its midpoint, in passes: each triangle is
//! replaced by the pattern its split edges ask for (one split edge: two triangles, two:
//! three, three: four), and an edge is split once for both triangles beside it, so the mesh
//! stays conforming: watertight where it was, and a boundary between two CAD faces split at
//! the same points on both sides. The new vertices lie on the edges they split, so the
//! surface itself does not move and the decode's accuracy holds. Sharp edges are split into
//! sharp halves, corners stay vertices and every triangle keeps its group. Lawson flips
//! inside each group (never across a sharp edge or a group boundary, never making an edge
//! longer than `max_edge`) then exchange the thin halves that bisection leaves for better
//! shaped triangles wherever two triangles lie in one plane.
//!
//! This bounds edge length only: the smallest angle is improved by the flips, not
//! guaranteed.

use std::collections::HashMap;

use glam::DVec3;

use super::flips::flip_to_well_shaped_within;
use crate::error::{Error, Result};
use crate::mesh::{edge_key, ControlMesh};

/// Relative flatness (of the mesh's diagonal) within which two triangles count as one plane
/// for the flips: the halves of a bisected triangle, up to rounding.
const COPLANAR: f64 = 1e-12;

/// `mesh` (with its per-vertex `normals`, if any) with every edge at most `max_edge` long;
/// see the module docs. Refused with `Error::LimitsExceeded` before a pass would make more
/// than `max_faces` triangles, and with `Error::Parameter` for a `max_edge` that is not a
/// positive length.
pub fn split_to_max_edge(
    mesh: &ControlMesh,
    normals: Option<&[DVec3]>,
    max_edge: f64,
    max_faces: u64,
) -> Result<(ControlMesh, Option<Vec<DVec3>>)> {
    if !(max_edge > 0.0 && max_edge.is_finite()) {
        return Err(Error::Parameter(format!(
            "the longest edge must be a positive length, got {max_edge}"
        )));
    }
    let mut positions = mesh.positions.clone();
    let mut normals = normals.map(<[DVec3]>::to_vec);
    let mut tris = Vec::with_capacity(mesh.face_count());
    let mut groups = Vec::with_capacity(mesh.face_count());
    for (f, face) in mesh.faces().enumerate() {
        for k in 1..face.len().saturating_sub(1) {
            tris.push([face[0], face[k], face[k + 1]]);
            groups.push(mesh.face_groups[f]);
        }
    }
    let mut sharp = mesh.sharp_edges.clone();
    loop {
        let mids = split_points(&tris, &positions, max_edge);
        if mids.is_empty() {
            break;
        }
        let new_tris: u64 = tris
            .iter()
            .map(|t| 1 + (0..3).filter(|&s| mids.contains_key(&side(t, s))).count() as u64)
            .sum();
        if new_tris > max_faces {
            return Err(Error::LimitsExceeded {
                what: "triangles of the mesh split to the longest edge",
                value: new_tris,
                limit: max_faces,
            });
        }
        let new_vertices = positions.len() as u64 + mids.len() as u64;
        if new_vertices > u64::from(u32::MAX) {
            return Err(Error::LimitsExceeded {
                what: "vertices of the mesh split to the longest edge",
                value: new_vertices,
                limit: u64::from(u32::MAX),
            });
        }
        // Midpoints numbered in the order the triangles meet their edges: the same output
        // for the same input.
        let mut order: Vec<((u32, u32), u32)> = mids.into_iter().collect();
        order.sort_unstable_by_key(|&(_, m)| m);
        let base = positions.len() as u32;
        let mut mid_of = HashMap::with_capacity(order.len());
        for (i, &((a, b), _)) in order.iter().enumerate() {
            let m = base + i as u32;
            positions.push(0.5 * (positions[a as usize] + positions[b as usize]));
            if let Some(n) = normals.as_mut() {
                let sum = n[a as usize] + n[b as usize];
                n.push(sum.try_normalize().unwrap_or(n[a as usize]));
            }
            if sharp.remove(&(a, b)) {
                sharp.insert(edge_key(a, m));
                sharp.insert(edge_key(m, b));
            }
            mid_of.insert((a, b), m);
        }
        let (mut next, mut next_groups) = (
            Vec::with_capacity(new_tris as usize),
            Vec::with_capacity(new_tris as usize),
        );
        for (t, g) in tris.iter().zip(&groups) {
            let (pieces, n) = split_triangle(*t, &mid_of, &positions);
            next.extend_from_slice(&pieces[..n]);
            next_groups.extend(std::iter::repeat_n(*g, n));
        }
        tris = next;
        groups = next_groups;
    }
    let flippable = vec![true; mesh.groups.len()];
    let deviation = COPLANAR * mesh.diagonal();
    flip_to_well_shaped_within(
        &positions, &mut tris, &groups, &flippable, &sharp, deviation, max_edge,
    );
    let out = ControlMesh {
        positions,
        face_offsets: (0..=tris.len() as u32).map(|i| 3 * i).collect(),
        face_vertices: tris.iter().flatten().copied().collect(),
        face_groups: groups,
        groups: mesh.groups.clone(),
        sharp_edges: sharp,
        corners: mesh.corners.clone(),
    };
    Ok((out, normals))
}

/// The undirected edge of `t` from corner `s` to the next.
fn side(t: &[u32; 3], s: usize) -> (u32, u32) {
    edge_key(t[s], t[(s + 1) % 3])
}

/// The edges longer than `max_edge`, each with a number giving the order the triangles
/// first meet them in.
fn split_points(tris: &[[u32; 3]], positions: &[DVec3], max_edge: f64) -> HashMap<(u32, u32), u32> {
    let mut mids = HashMap::new();
    for t in tris {
        for s in 0..3 {
            let (a, b) = side(t, s);
            if positions[a as usize].distance(positions[b as usize]) > max_edge {
                let next = mids.len() as u32;
                mids.entry((a, b)).or_insert(next);
            }
        }
    }
    mids
}

/// The triangles that replace `t` once its edges in `mid_of` are split at their midpoints,
/// with `t`'s orientation: the first `n` of the array.
fn split_triangle(
    t: [u32; 3],
    mid_of: &HashMap<(u32, u32), u32>,
    positions: &[DVec3],
) -> ([[u32; 3]; 4], usize) {
    let mid = |s: usize| mid_of.get(&side(&t, s)).copied();
    match [mid(0), mid(1), mid(2)] {
        [None, None, None] => ([t; 4], 1),
        [Some(m0), Some(m1), Some(m2)] => {
            let [a, b, c] = t;
            ([[a, m0, m2], [m0, b, m1], [m2, m1, c], [m0, m1, m2]], 4)
        }
        split => {
            let count = split.iter().flatten().count();
            // Rotate so that the split edges come first: (a, b) split, and with two splits
            // (b, c) as well.
            let r = (0..3)
                .find(|&r| {
                    (0..count).all(|k| split[(r + k) % 3].is_some())
                        && (count..3).all(|k| split[(r + k) % 3].is_none())
                })
                .unwrap_or(0);
            let [a, b, c] = [t[r], t[(r + 1) % 3], t[(r + 2) % 3]];
            let m0 = split[r].unwrap_or(a);
            if count == 1 {
                return ([[a, m0, c], [m0, b, c], t, t], 2);
            }
            let m1 = split[(r + 1) % 3].unwrap_or(b);
            // The quad a, m0, m1, c is cut along its shorter diagonal.
            let p = |v: u32| positions[v as usize];
            if p(a).distance_squared(p(m1)) <= p(m0).distance_squared(p(c)) {
                ([[m0, b, m1], [a, m0, m1], [a, m1, c], t], 3)
            } else {
                ([[m0, b, m1], [a, m0, c], [m0, m1, c], t], 3)
            }
        }
    }
}
