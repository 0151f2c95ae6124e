//! Edge flips that make the triangles of plane patches well shaped.
//!
//! Sparse output triangulates a plane patch from its control triangles' corners and its
//! split edges' chains only (`sparse`): few triangles, but fans of slivers where a corner
//! sees a long chain. Inside a plane every triangulation of the same points is the same
//! surface, so the triangles can be exchanged for better shaped ones without moving
//! anything: flipping the shared edge of two triangles whose quad is convex, whenever that
//! raises the smaller of their six angles (Lawson's flips toward the Delaunay
//! triangulation). Edges between patches, sharp edges and the mesh boundary are never
//! flipped, so the output stays conforming and every patch keeps its outline.

use std::collections::HashMap;

use glam::DVec3;

use crate::mesh::edge_key;

/// Flips at most this many times per triangle: Lawson's flips end on their own (each raises
/// the smallest of the angles it changes, so the sorted angles of the mesh rise and no
/// triangulation repeats), this only bounds the work on contrived input.
const MAX_FLIPS_PER_TRIANGLE: usize = 16;

/// Smallest gain in the smaller angle (radians) that makes a flip worth it: ties and
/// rounding noise do not flip back and forth.
const MIN_GAIN: f64 = 1e-9;

/// Flips the edges shared by two triangles of a group for which `flippable[group]` is set
/// (never making an edge the mesh has elsewhere),
/// not listed in `fixed`, whose quad is convex and (nearly) planar (its fourth corner within
/// `max_deviation` of the plane of the other three, either way), while a flip raises the
/// smaller angle of the two triangles. Triangles keep their groups and orientation. Returns
/// how many edges it flipped.
pub(crate) fn flip_to_well_shaped(
    positions: &[DVec3],
    tris: &mut [[u32; 3]],
    groups: &[u32],
    flippable: &[bool],
    fixed: &std::collections::BTreeSet<(u32, u32)>,
    max_deviation: f64,
) -> usize {
    flip_to_well_shaped_within(
        positions,
        tris,
        groups,
        flippable,
        fixed,
        max_deviation,
        f64::INFINITY,
    )
}

/// [`flip_to_well_shaped`] that never makes an edge longer than `max_edge` (a mesh sized for
/// a solver keeps its size).
pub(crate) fn flip_to_well_shaped_within(
    positions: &[DVec3],
    tris: &mut [[u32; 3]],
    groups: &[u32],
    flippable: &[bool],
    fixed: &std::collections::BTreeSet<(u32, u32)>,
    max_deviation: f64,
    max_edge: f64,
) -> usize {
    let can = |t: usize| flippable.get(groups[t] as usize).copied().unwrap_or(false);
    // Edge -> the triangles on either side (and the slot of the edge in each).
    // Sized for the edges of a closed mesh (3 per 2 triangles) up front: growing it rehashes
    // every key again.
    let mut sides: HashMap<(u32, u32), [(u32, u8); 2]> =
        HashMap::with_capacity(tris.len() / 2 * 3 + 3);
    let none = (u32::MAX, 0u8);
    for (t, tri) in tris.iter().enumerate() {
        for s in 0..3 {
            let key = edge_key(tri[s], tri[(s + 1) % 3]);
            let e = sides.entry(key).or_insert([none, none]);
            let slot = usize::from(e[0].0 != u32::MAX);
            e[slot] = (t as u32, s as u8);
        }
    }
    let mut stack: Vec<(u32, u32)> = sides
        .iter()
        .filter(|(k, v)| v[1].0 != u32::MAX && !fixed.contains(k) && can(v[0].0 as usize))
        .map(|(&k, _)| k)
        .collect();
    stack.sort_unstable();
    let budget = tris.len().saturating_mul(MAX_FLIPS_PER_TRIANGLE);
    let mut flips = 0;
    while let Some(key) = stack.pop() {
        if flips == budget {
            break;
        }
        let Some(&[(t1, s1), (t2, s2)]) = sides.get(&key) else {
            continue;
        };
        if t2 == u32::MAX
            || groups[t1 as usize] != groups[t2 as usize]
            || !can(t1 as usize)
            || fixed.contains(&key)
        {
            continue;
        }
        let (t1, t2) = (t1 as usize, t2 as usize);
        // t1 = (a, b, c) with the edge a -> b, t2 = (b, a, d).
        let (a, b, c) = (
            tris[t1][s1 as usize],
            tris[t1][(s1 as usize + 1) % 3],
            tris[t1][(s1 as usize + 2) % 3],
        );
        let d = tris[t2][(s2 as usize + 2) % 3];
        if c == d || sides.contains_key(&edge_key(c, d)) {
            continue;
        }
        let p = |v: u32| positions[v as usize];
        if p(c).distance(p(d)) > max_edge {
            continue;
        }
        if !better_flipped(p(a), p(b), p(c), p(d), max_deviation) {
            continue;
        }
        flips += 1;
        tris[t1] = [a, d, c];
        tris[t2] = [d, b, c];
        sides.remove(&key);
        // Each outer edge now lies in the other one of the pair, or in another slot: point
        // its side that was t1 or t2 there, and queue it (its quad changed). The new
        // diagonal gets both sides.
        let diagonal = edge_key(c, d);
        for t in [t1, t2] {
            for s in 0..3 {
                let k = edge_key(tris[t][s], tris[t][(s + 1) % 3]);
                let side = (t as u32, s as u8);
                if k == diagonal {
                    let e = sides.entry(k).or_insert([none, none]);
                    let i = usize::from(e[0].0 != u32::MAX);
                    e[i] = side;
                    continue;
                }
                if let Some(e) = sides.get_mut(&k) {
                    if let Some(i) = (0..2).find(|&i| e[i].0 == t1 as u32 || e[i].0 == t2 as u32) {
                        e[i] = side;
                    }
                }
                if !fixed.contains(&k) {
                    stack.push(k);
                }
            }
        }
    }
    flips
}

/// Whether the triangles (a, d, c), (d, b, c) are a better pair than (a, b, c), (b, a, d):
/// the quad a, d, b, c is planar within `max_deviation`, convex (both new triangles face
/// the way the old ones do, with area), and the smaller of the six angles grows.
fn better_flipped(a: DVec3, b: DVec3, c: DVec3, d: DVec3, max_deviation: f64) -> bool {
    let n1 = (b - a).cross(c - a);
    let n2 = (a - b).cross(d - b);
    let n = n1 + n2;
    let (m1, m2) = ((d - a).cross(c - a), (b - d).cross(c - d));
    if m1.dot(n) <= 0.0 || m2.dot(n) <= 0.0 || n1.dot(n) <= 0.0 || n2.dot(n) <= 0.0 {
        return false;
    }
    let off = |normal: DVec3, origin: DVec3, q: DVec3| {
        let l = normal.length();
        if l > 0.0 {
            (q - origin).dot(normal).abs() / l
        } else {
            f64::INFINITY
        }
    };
    if off(n1, a, d) > max_deviation || off(n2, b, c) > max_deviation {
        return false;
    }
    let before = min_angle(a, b, c).min(min_angle(b, a, d));
    let after = min_angle(a, d, c).min(min_angle(d, b, c));
    after > before + MIN_GAIN
}

/// The smallest angle of triangle (a, b, c), in radians.
fn min_angle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let angle = |p: DVec3, q: DVec3, r: DVec3| (q - p).angle_between(r - p);
    angle(a, b, c).min(angle(b, c, a)).min(angle(c, a, b))
}
