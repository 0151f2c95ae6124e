//! A triangle mesh with a bounding-volume hierarchy answering closest-point queries.

use glam::DVec3;
use parry3d_f64::bounding_volume::Aabb;
use parry3d_f64::partitioning::{Bvh, BvhBuildStrategy, BvhNode};
use parry3d_f64::query::PointQueryWithLocation;
use parry3d_f64::shape::{TriMesh, TriMeshFlags};

use crate::error::{Error, Result};
#[cfg(feature = "internals")]
use crate::mesh::ControlMesh;

/// Result of a closest-point query.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ClosestPoint {
    /// The closest point on the surface.
    pub point: DVec3,
    /// Euclidean distance from the query point to `point`.
    pub distance: f64,
    /// Index of the triangle holding `point` (into [`TriangleSurface::triangles`]).
    pub triangle: u32,
    /// Barycentric coordinates of `point` in that triangle (sum to 1).
    pub barycentric: [f64; 3],
}

/// A triangle mesh prepared for closest-point queries.
///
/// Keeps its own copy of positions and triangles (parry's `TriMesh` owns its buffers and
/// builds a BVH over them) plus, for meshes built from polygons, the polygon each triangle
/// came from, so callers can map a hit back to the face of their `ControlMesh`.
pub struct TriangleSurface {
    index: Index,
    /// By triangle; `None` when every triangle is its own face (no array for the identity).
    #[cfg(feature = "internals")]
    source_face: Option<Vec<u32>>,
}

/// How the triangles are indexed for closest-point queries.
enum Index {
    /// One BVH leaf per triangle (parry's `TriMesh`): any triangle order.
    Triangles(TriMesh),
    /// One BVH leaf per run of up to `block` consecutive triangles. For meshes whose
    /// consecutive triangles are neighbours, such as subdivision output (the descendants of
    /// a face are consecutive), the tree has up to `block` times fewer leaves: much cheaper
    /// to build and shallower to search, for a few more triangle tests per leaf. A run ends
    /// early where its box would grow well beyond a typical triangle's (large triangles,
    /// such as the sparse output of planes, stay alone: a large box in a leaf is tested by
    /// every query near it).
    Blocks {
        positions: Vec<DVec3>,
        triangles: Vec<[u32; 3]>,
        bvh: Bvh,
        /// Leaf k holds triangles `runs[k]..runs[k + 1]`.
        runs: Vec<u32>,
    },
}

impl std::fmt::Debug for TriangleSurface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TriangleSurface")
            .field("vertices", &self.positions().len())
            .field("triangles", &self.triangles().len())
            .finish()
    }
}

impl TriangleSurface {
    /// Builds the BVH over `triangles` (indices into `positions`). Errors on an empty mesh,
    /// out-of-range indices or non-finite positions.
    pub fn new(positions: Vec<DVec3>, triangles: Vec<[u32; 3]>) -> Result<Self> {
        check_triangles(&positions, &triangles)?;
        let trimesh = TriMesh::with_flags(positions, triangles, TriMeshFlags::empty())
            .map_err(|e| Error::Mesh(format!("cannot build triangle BVH: {e:?}")))?;
        Ok(TriangleSurface {
            index: Index::Triangles(trimesh),
            #[cfg(feature = "internals")]
            source_face: None,
        })
    }

    /// Like [`TriangleSurface::new`], with one BVH leaf per `block` consecutive triangles
    /// (see `Index::Blocks`): for meshes whose triangle order is spatially coherent.
    pub fn with_blocks(
        positions: Vec<DVec3>,
        triangles: Vec<[u32; 3]>,
        block: usize,
    ) -> Result<Self> {
        check_triangles(&positions, &triangles)?;
        let block = block.max(1);
        let tri_box = |t: &[u32; 3]| {
            let p = t.map(|v| positions[v as usize]);
            (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]))
        };
        // Typical triangle size: the median box diagonal.
        let mut sizes: Vec<f64> = triangles
            .iter()
            .map(|t| {
                let (lo, hi) = tri_box(t);
                (hi - lo).length()
            })
            .collect();
        let mid = sizes.len() / 2;
        let typical = *sizes.select_nth_unstable_by(mid, f64::total_cmp).1;
        let limit = 4.0 * typical;
        let mut runs = vec![0u32];
        let mut leaves = Vec::new();
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for (i, t) in triangles.iter().enumerate() {
            let (tlo, thi) = tri_box(t);
            let count = i - *runs.last().unwrap_or(&0) as usize;
            let (mlo, mhi) = (lo.min(tlo), hi.max(thi));
            if count > 0 && (count >= block || (mhi - mlo).length() > limit) {
                leaves.push(Aabb::new(lo, hi));
                runs.push(i as u32);
                (lo, hi) = (tlo, thi);
            } else {
                (lo, hi) = (mlo, mhi);
            }
        }
        leaves.push(Aabb::new(lo, hi));
        runs.push(triangles.len() as u32);
        let bvh = Bvh::from_leaves(BvhBuildStrategy::Binned, &leaves);
        Ok(TriangleSurface {
            index: Index::Blocks {
                positions,
                triangles,
                bvh,
                runs,
            },
            #[cfg(feature = "internals")]
            source_face: None,
        })
    }

    /// Triangulates every face of `mesh` by a fan from its first vertex and builds the BVH.
    #[cfg(feature = "internals")]
    pub fn from_control_mesh(mesh: &ControlMesh) -> Result<Self> {
        let (triangles, source) = fan_triangulate(mesh)?;
        let mut surface = Self::new(mesh.positions.clone(), triangles)?;
        surface.source_face = Some(source);
        Ok(surface)
    }

    pub fn positions(&self) -> &[DVec3] {
        match &self.index {
            Index::Triangles(m) => m.vertices(),
            Index::Blocks { positions, .. } => positions,
        }
    }

    pub fn triangles(&self) -> &[[u32; 3]] {
        match &self.index {
            Index::Triangles(m) => m.indices(),
            Index::Blocks { triangles, .. } => triangles,
        }
    }

    /// Face of the source `ControlMesh` that triangle `t` was cut from (identity for
    /// [`TriangleSurface::new`]).
    #[cfg(feature = "internals")]
    pub fn source_face(&self, t: u32) -> u32 {
        self.source_face.as_ref().map_or(t, |s| s[t as usize])
    }

    /// Closest point on the surface to `p`.
    pub fn closest_point(&self, p: DVec3) -> ClosestPoint {
        self.closest_point_within(p, f64::MAX)
            .unwrap_or_else(|| self.brute_force_closest(p))
    }

    /// Closest point on the surface to `p` if it is within `max_dist`; `None` otherwise.
    /// A good bound makes the BVH traversal much cheaper for points far from the surface.
    pub fn closest_point_within(&self, p: DVec3, max_dist: f64) -> Option<ClosestPoint> {
        let trimesh = match &self.index {
            Index::Triangles(m) => m,
            Index::Blocks {
                positions,
                triangles,
                bvh,
                runs,
            } => return closest_in_blocks(positions, triangles, bvh, runs, p, max_dist),
        };
        let (proj, (tri, loc)) =
            trimesh.project_local_point_and_get_location_with_max_dist(p, false, max_dist)?;
        let barycentric = loc
            .barycentric_coordinates()
            .unwrap_or_else(|| self.barycentric_of(tri, proj.point));
        Some(ClosestPoint {
            point: proj.point,
            distance: (p - proj.point).length(),
            triangle: tri,
            barycentric,
        })
    }

    /// Distance from `p` to the surface.
    #[cfg(feature = "internals")]
    pub fn distance(&self, p: DVec3) -> f64 {
        self.closest_point(p).distance
    }

    /// Barycentric coordinates of a point lying on triangle `t` (least-squares for points
    /// slightly off it; vertex 0 for a degenerate triangle).
    pub fn barycentric_of(&self, t: u32, q: DVec3) -> [f64; 3] {
        let [a, b, c] = self.triangle_points(t);
        barycentric(a, b, c, q)
    }

    pub fn triangle_points(&self, t: u32) -> [DVec3; 3] {
        let tri = self.triangles()[t as usize];
        let v = self.positions();
        [v[tri[0] as usize], v[tri[1] as usize], v[tri[2] as usize]]
    }

    /// Linear scan, used only if the BVH returns nothing (non-finite query point).
    fn brute_force_closest(&self, p: DVec3) -> ClosestPoint {
        let mut best: Option<ClosestPoint> = None;
        for t in 0..self.triangles().len() as u32 {
            let [a, b, c] = self.triangle_points(t);
            let (q, bc) = closest_point_on_triangle(p, a, b, c);
            let d = (p - q).length();
            if best.as_ref().is_none_or(|b| d < b.distance) {
                best = Some(ClosestPoint {
                    point: q,
                    distance: d,
                    triangle: t,
                    barycentric: bc,
                });
            }
        }
        best.unwrap_or(ClosestPoint {
            point: p,
            distance: f64::NAN,
            triangle: 0,
            barycentric: [1.0, 0.0, 0.0],
        })
    }
}

/// The checks every surface's input passes: triangles exist, indices are in range, positions
/// are finite.
fn check_triangles(positions: &[DVec3], triangles: &[[u32; 3]]) -> Result<()> {
    if triangles.is_empty() {
        return Err(Error::Mesh("surface has no triangles".into()));
    }
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        return Err(Error::Mesh(format!(
            "vertex {i} has a non-finite coordinate"
        )));
    }
    let nv = positions.len();
    if let Some((t, tri)) = triangles
        .iter()
        .enumerate()
        .find(|(_, t)| t.iter().any(|&v| v as usize >= nv))
    {
        return Err(Error::Mesh(format!(
            "triangle {t} references vertex {tri:?}, but there are only {nv} vertices"
        )));
    }
    Ok(())
}

/// Closest point among blocked triangles (see `Index::Blocks`) within `max_dist`: the BVH
/// search runs on squared distances to the leaves' boxes, each leaf tests its triangles.
fn closest_in_blocks(
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    bvh: &Bvh,
    runs: &[u32],
    p: DVec3,
    max_dist: f64,
) -> Option<ClosestPoint> {
    let box_d2 = |node: &BvhNode, _best: f64| -> f64 {
        let q = p.clamp(node.mins(), node.maxs());
        (p - q).length_squared()
    };
    // Leaf cost: squared distance, with the hit (its `distance` filled in at the end).
    let leaf = |leaf: u32, best: f64| -> Option<(f64, ClosestPoint)> {
        let (start, end) = (*runs.get(leaf as usize)?, *runs.get(leaf as usize + 1)?);
        let start = start as usize;
        let mut found = None;
        let mut best = best;
        let run = triangles.get(start..end as usize)?;
        for (k, t) in run.iter().enumerate() {
            let [a, b, c] = t.map(|v| positions[v as usize]);
            // The triangle's box is a lower bound of its distance, a few operations against
            // the dozens of the exact test; most triangles of a leaf fail it once a near
            // hit is known.
            let q = p.max(a.min(b).min(c)).min(a.max(b).max(c));
            if (p - q).length_squared() >= best {
                continue;
            }
            let (q, bc) = closest_point_on_triangle(p, a, b, c);
            let d2 = (p - q).length_squared();
            if d2 < best {
                best = d2;
                found = Some((
                    d2,
                    ClosestPoint {
                        point: q,
                        distance: 0.0,
                        triangle: (start + k) as u32,
                        barycentric: bc,
                    },
                ));
            }
        }
        found
    };
    let max_d2 = if max_dist < f64::MAX.sqrt() {
        max_dist * max_dist
    } else {
        f64::MAX
    };
    let (_, (d2, hit)) = bvh.find_best(max_d2, box_d2, leaf)?;
    Some(ClosestPoint {
        distance: d2.sqrt(),
        ..hit
    })
}

/// Distance from `p` to the box `lo..hi` (0 inside): a lower bound of its distance to
/// anything in the box.
pub(crate) fn box_distance(lo: DVec3, hi: DVec3, p: DVec3) -> f64 {
    (lo - p).max(p - hi).max(DVec3::ZERO).length()
}

/// Fan triangulation of every face (first vertex as apex) with the source face of each
/// triangle. Errors when an index is out of range.
#[cfg(feature = "internals")]
pub(crate) fn fan_triangulate(mesh: &ControlMesh) -> Result<(Vec<[u32; 3]>, Vec<u32>)> {
    let nv = mesh.positions.len();
    let mut tris = Vec::with_capacity(mesh.face_vertices.len());
    let mut src = Vec::with_capacity(mesh.face_vertices.len());
    if mesh.face_offsets.windows(2).any(|w| w[1] < w[0])
        || mesh
            .face_offsets
            .last()
            .is_some_and(|&e| e as usize > mesh.face_vertices.len())
    {
        return Err(Error::Mesh("face offsets are inconsistent".into()));
    }
    for f in 0..mesh.face_count() {
        let face = mesh.face(f);
        if let Some(&v) = face.iter().find(|&&v| v as usize >= nv) {
            return Err(Error::Mesh(format!(
                "face {f} references vertex {v}, but there are only {nv} vertices"
            )));
        }
        for i in 1..face.len().saturating_sub(1) {
            tris.push([face[0], face[i], face[i + 1]]);
            src.push(f as u32);
        }
    }
    Ok((tris, src))
}

/// Barycentric coordinates of the projection of `q` onto the plane of (a, b, c).
pub(crate) fn barycentric(a: DVec3, b: DVec3, c: DVec3, q: DVec3) -> [f64; 3] {
    let (e0, e1, e2) = (b - a, c - a, q - a);
    let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (d20, d21) = (e2.dot(e0), e2.dot(e1));
    let den = d00 * d11 - d01 * d01;
    if den.abs() <= f64::EPSILON * d00 * d11 || den == 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let v = (d11 * d20 - d01 * d21) / den;
    let w = (d00 * d21 - d01 * d20) / den;
    [1.0 - v - w, v, w]
}

/// Exact closest point on triangle (a, b, c) to p, with its barycentric coordinates
/// (Ericson, Real-Time Collision Detection §5.1.5: Voronoi regions of vertices, edges and
/// face). Handles degenerate triangles (falls back to the closest edge).
pub fn closest_point_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, [f64; 3]) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + v * ab, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + w * ac, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + w * (c - b), [0.0, 1.0 - w, w]);
    }
    let sum = va + vb + vc;
    if sum.abs() < f64::MIN_POSITIVE || !sum.is_finite() {
        // Degenerate (collinear) triangle: best of the three edges.
        let cands = [
            closest_on_segment(p, a, b, [0, 1]),
            closest_on_segment(p, b, c, [1, 2]),
            closest_on_segment(p, a, c, [0, 2]),
        ];
        let mut best = cands[0];
        for c in &cands[1..] {
            if (p - c.0).length_squared() < (p - best.0).length_squared() {
                best = *c;
            }
        }
        return best;
    }
    let denom = 1.0 / sum;
    let v = vb * denom;
    let w = vc * denom;
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}

/// Parameter `t` in [0, 1] of the point of segment `a b` closest to `p` (0 when the segment
/// is a point).
pub fn segment_parameter(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let l2 = ab.length_squared();
    if l2 > 0.0 {
        ((p - a).dot(ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

fn closest_on_segment(p: DVec3, a: DVec3, b: DVec3, idx: [usize; 2]) -> (DVec3, [f64; 3]) {
    let ab = b - a;
    let t = segment_parameter(p, a, b);
    let mut bc = [0.0; 3];
    bc[idx[0]] += 1.0 - t;
    bc[idx[1]] += t;
    (a + t * ab, bc)
}
