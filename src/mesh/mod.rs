//! Polygon mesh with CAD-face groups, sharp edges and corner vertices.
//!
//! [`ControlMesh`] is the contract between the encoder and the decoder: everything the
//! decoder needs to rebuild the surface and nothing else. The same type also carries input
//! tessellations (raw mode stores the input mesh itself as the control mesh), so readers,
//! the codec, subdivision and fitting all speak it.

#[cfg(any(feature = "encoder", feature = "internals"))]
mod analytic;
#[cfg(any(feature = "encoder", feature = "internals"))]
mod buckets;
mod tolerance;
pub mod topology;

#[cfg(any(feature = "encoder", feature = "internals"))]
pub use analytic::{AnalyticSurface, Residuals, SurfaceKind};
#[cfg(any(feature = "encoder", feature = "internals"))]
pub use buckets::Buckets;
pub use tolerance::Tolerance;

use std::collections::BTreeSet;

use glam::DVec3;

use crate::error::{Error, Result};

/// An axis in space: a point on it and a unit direction. For cones the origin is the apex.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Axis {
    pub origin: DVec3,
    pub direction: DVec3,
}

/// The analytic surface under a boundary patch: a surface with coordinates in which every
/// affine combination of points on it stays on it (Cartesian for a plane; angles about an
/// axis for the others), so a patch spanned by its boundary curves needs no interior control
/// vertices. Spheres and tori carry the frame the coordinates are taken in: a sphere's axis
/// is a choice of the encoder (its poles away from the patch), a torus's is the surface's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BoundarySurface {
    Plane,
    /// `axis.origin` is any point on the axis.
    Cylinder {
        axis: Axis,
    },
    /// `axis.origin` is the apex.
    Cone {
        axis: Axis,
    },
    /// `axis.origin` is the centre; longitude is measured about `axis.direction`, latitude
    /// from the plane perpendicular to it.
    Sphere {
        axis: Axis,
    },
    /// `axis.origin` is the centre, `axis.direction` the axis of revolution, `major_radius`
    /// the radius of the circle the tube is swept along.
    Torus {
        axis: Axis,
        major_radius: f64,
    },
}

impl BoundarySurface {
    /// The axis of a surface that has one (every kind but the plane).
    pub fn axis(&self) -> Option<Axis> {
        match *self {
            BoundarySurface::Plane => None,
            BoundarySurface::Cylinder { axis }
            | BoundarySurface::Cone { axis }
            | BoundarySurface::Sphere { axis }
            | BoundarySurface::Torus { axis, .. } => Some(axis),
        }
    }
}

/// How the decoder refines one CAD face (one group).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum PatchKind {
    /// Loop surface with Hoppe's crease rules over the group's faces (freeform faces, whole
    /// spheres and tori without boundary, and any group of a raw-mode mesh).
    #[default]
    Closed,
    /// Only boundary curves are subdivided; the interior is spanned by belts (S-CODE §4.2).
    Boundary(BoundarySurface),
}

/// One CAD face. Groups are stored once and faces point at them by index, because a CAD
/// model has tens to hundreds of faces but thousands of triangles.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Group {
    /// Name from the input (`g face_12` in OBJ); may be empty.
    pub name: String,
    pub patch: PatchKind,
}

/// A polygon mesh whose faces are grouped by CAD face, with sharp edges and corner tags.
///
/// Faces are stored as one flat index array plus offsets (CSR) rather than `Vec<Vec<u32>>`:
/// meshes hold any mix of triangles, quads and n-gons, and a flat array keeps 100k-face
/// inputs to two allocations. Sharp edges and corners are sparse, ordered sets so that
/// iteration order (and thus every encoder decision) is deterministic.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ControlMesh {
    /// Vertex positions in model units.
    pub positions: Vec<DVec3>,
    /// `face_offsets[f]..face_offsets[f + 1]` indexes `face_vertices` for face `f`;
    /// always has `face_count() + 1` entries, starting with 0.
    pub face_offsets: Vec<u32>,
    /// Vertex indices of all faces, counter-clockwise seen from outside.
    pub face_vertices: Vec<u32>,
    /// Group index (into `groups`) of each face.
    pub face_groups: Vec<u32>,
    /// CAD faces.
    pub groups: Vec<Group>,
    /// Sharp (crease) edges as `(min, max)` vertex pairs. Mesh-boundary edges are creases
    /// implicitly and need not be listed.
    pub sharp_edges: BTreeSet<(u32, u32)>,
    /// Corner vertices (B-rep vertices): fixed under subdivision.
    pub corners: BTreeSet<u32>,
}

/// Normalised key of an undirected edge.
#[inline]
pub fn edge_key(a: u32, b: u32) -> (u32, u32) {
    if a < b {
        (a, b)
    } else {
        (b, a)
    }
}

/// When the bounding box of `positions` has no finite diagonal, the vertices at the ends of
/// its longest side (the ones to name in an error).
#[cfg(any(feature = "encoder", feature = "internals"))]
pub(crate) fn overflowing_extent(positions: &[DVec3]) -> Option<(usize, usize)> {
    let &first = positions.first()?;
    let (mut lo, mut hi) = ([0usize; 3], [0usize; 3]);
    let (mut lo_p, mut hi_p) = (first, first);
    for (i, p) in positions.iter().enumerate() {
        for k in 0..3 {
            if p[k] < lo_p[k] {
                (lo_p[k], lo[k]) = (p[k], i);
            }
            if p[k] > hi_p[k] {
                (hi_p[k], hi[k]) = (p[k], i);
            }
        }
    }
    let size = hi_p - lo_p;
    if size.length().is_finite() {
        return None;
    }
    let k = (0..3)
        .max_by(|&a, &b| size[a].total_cmp(&size[b]))
        .unwrap_or(0);
    Some((lo[k], hi[k]))
}

impl ControlMesh {
    /// An empty mesh (no vertices, no faces, no groups).
    pub fn new() -> Self {
        ControlMesh {
            face_offsets: vec![0],
            ..Default::default()
        }
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    pub fn face_count(&self) -> usize {
        self.face_offsets.len().saturating_sub(1)
    }

    /// Vertex indices of face `f`.
    #[inline]
    pub fn face(&self, f: usize) -> &[u32] {
        &self.face_vertices[self.face_offsets[f] as usize..self.face_offsets[f + 1] as usize]
    }

    /// Iterates over all faces as vertex-index slices.
    pub fn faces(&self) -> impl Iterator<Item = &[u32]> + '_ {
        (0..self.face_count()).map(move |f| self.face(f))
    }

    /// Appends a vertex and returns its index.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn push_vertex(&mut self, p: DVec3) -> u32 {
        self.positions.push(p);
        (self.positions.len() - 1) as u32
    }

    /// Appends a face in group `group` and returns its index.
    pub fn push_face(&mut self, vertices: &[u32], group: u32) -> usize {
        if self.face_offsets.is_empty() {
            self.face_offsets.push(0);
        }
        self.face_vertices.extend_from_slice(vertices);
        self.face_offsets.push(self.face_vertices.len() as u32);
        self.face_groups.push(group);
        self.face_count() - 1
    }

    /// Appends a group and returns its index.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn push_group(&mut self, name: impl Into<String>, patch: PatchKind) -> u32 {
        self.groups.push(Group {
            name: name.into(),
            patch,
        });
        (self.groups.len() - 1) as u32
    }

    /// Marks the edge `a`-`b` sharp.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn set_sharp(&mut self, a: u32, b: u32) {
        self.sharp_edges.insert(edge_key(a, b));
    }

    #[cfg(test)]
    pub fn is_sharp(&self, a: u32, b: u32) -> bool {
        self.sharp_edges.contains(&edge_key(a, b))
    }

    /// Flags every edge shared by faces of two different groups sharp: the CAD-face
    /// boundaries of a tessellated B-rep are exactly the creases of its control mesh.
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn sharpen_group_boundaries(&mut self) {
        let mut first: std::collections::BTreeMap<(u32, u32), u32> = Default::default();
        let mut sharp = Vec::new();
        for f in 0..self.face_count() {
            let g = self.face_groups[f];
            let face = self.face(f);
            for k in 0..face.len() {
                let e = edge_key(face[k], face[(k + 1) % face.len()]);
                match first.get(&e) {
                    Some(&h) if h != g => sharp.push(e),
                    Some(_) => {}
                    None => {
                        first.insert(e, g);
                    }
                }
            }
        }
        self.sharp_edges.extend(sharp);
    }

    /// True when every face is a triangle.
    #[cfg(test)]
    pub fn is_triangle_mesh(&self) -> bool {
        self.faces().all(|f| f.len() == 3)
    }

    /// Axis-aligned bounding box `(min, max)` of the vertices; `None` when empty.
    pub fn bounding_box(&self) -> Option<(DVec3, DVec3)> {
        let first = *self.positions.first()?;
        Some(
            self.positions
                .iter()
                .fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))),
        )
    }

    /// Length of the bounding-box diagonal (0 for an empty mesh).
    pub fn diagonal(&self) -> f64 {
        self.bounding_box()
            .map(|(lo, hi)| (hi - lo).length())
            .unwrap_or(0.0)
    }

    /// An error ([`Error::Parameter`]) when the bounding box of the vertices has no finite
    /// diagonal, naming the vertices at the ends of its longest side. Every distance,
    /// tolerance and quantisation step of the encoder comes from coordinate differences
    /// (squared, for distances): finite coordinates near 1e154 or beyond make them infinite,
    /// and the encoded file would hold a grid the decoder refuses. (The mesh readers refuse
    /// such files when they read them, naming the line.)
    #[cfg(any(feature = "encoder", feature = "internals"))]
    pub fn check_extent(&self) -> Result<()> {
        let Some((lo, hi)) = overflowing_extent(&self.positions) else {
            return Ok(());
        };
        Err(Error::Parameter(format!(
            "coordinates too large: vertex {lo} at {:?} and vertex {hi} at {:?} span a \
             bounding box whose diagonal overflows f64 (scale the model down)",
            self.positions[lo].to_array(),
            self.positions[hi].to_array()
        )))
    }

    /// Checks the structural invariants every consumer relies on: offsets consistent, all
    /// indices in range, faces of degree >= 3 without repeated vertices, finite positions,
    /// sharp edges and corners referencing existing vertices. Does not check manifoldness
    /// (see the topology queries for that).
    pub fn validate(&self) -> Result<()> {
        let nv = self.positions.len();
        if self.face_offsets.first() != Some(&0) {
            return Err(Error::Mesh("face_offsets must start with 0".into()));
        }
        if self.face_groups.len() != self.face_count() {
            return Err(Error::Mesh(format!(
                "{} faces but {} face groups",
                self.face_count(),
                self.face_groups.len()
            )));
        }
        if *self.face_offsets.last().unwrap() as usize != self.face_vertices.len() {
            return Err(Error::Mesh(
                "face_offsets do not cover face_vertices".into(),
            ));
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::Mesh(format!(
                "vertex {i} has a non-finite coordinate"
            )));
        }
        // The last face that used each vertex: a repeated vertex is found in one pass, also
        // in a face of huge degree.
        let mut last_face = vec![u32::MAX; nv];
        for f in 0..self.face_count() {
            let (s, e) = (self.face_offsets[f], self.face_offsets[f + 1]);
            if e < s || (e - s) < 3 {
                return Err(Error::Mesh(format!("face {f} has fewer than 3 vertices")));
            }
            for &v in self.face(f) {
                let Some(last) = last_face.get_mut(v as usize) else {
                    return Err(Error::Mesh(format!(
                        "face {f} references vertex {v}, but there are only {nv} vertices"
                    )));
                };
                if *last == f as u32 {
                    return Err(Error::Mesh(format!("face {f} repeats vertex {v}")));
                }
                *last = f as u32;
            }
            if self.face_groups[f] as usize >= self.groups.len() {
                return Err(Error::Mesh(format!(
                    "face {f} is in group {}, but there are only {} groups",
                    self.face_groups[f],
                    self.groups.len()
                )));
            }
        }
        if let Some(&(a, b)) = self
            .sharp_edges
            .iter()
            .find(|&&(a, b)| b as usize >= nv || a >= b)
        {
            return Err(Error::Mesh(format!("sharp edge ({a}, {b}) is invalid")));
        }
        if let Some(&c) = self.corners.iter().find(|&&c| c as usize >= nv) {
            return Err(Error::Mesh(format!("corner vertex {c} does not exist")));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> ControlMesh {
        let mut m = ControlMesh::new();
        for p in [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
            m.push_vertex(DVec3::from(p));
        }
        let g = m.push_group("face_1", PatchKind::Boundary(BoundarySurface::Plane));
        m.push_face(&[0, 1, 2, 3], g);
        m
    }

    #[test]
    fn builds_and_validates() {
        let mut m = quad();
        m.set_sharp(2, 1);
        m.corners.insert(0);
        assert_eq!(m.face_count(), 1);
        assert_eq!(m.face(0), &[0, 1, 2, 3]);
        assert!(m.is_sharp(1, 2));
        assert!(!m.is_triangle_mesh());
        assert!((m.diagonal() - 2f64.sqrt()).abs() < 1e-12);
        m.validate().unwrap();
    }

    #[test]
    fn group_boundaries_become_sharp() {
        let mut m = quad();
        m.push_vertex(DVec3::new(2., 0., 0.));
        let g = m.push_group("face_2", PatchKind::Closed);
        m.push_face(&[1, 4, 2], g);
        m.sharpen_group_boundaries();
        assert_eq!(
            m.sharp_edges.iter().copied().collect::<Vec<_>>(),
            vec![(1, 2)]
        );
    }

    #[test]
    fn validate_rejects_bad_meshes() {
        let mut m = quad();
        m.face_vertices[3] = 9;
        assert!(m.validate().is_err());
        let mut m = quad();
        m.positions[0].x = f64::NAN;
        assert!(m.validate().is_err());
        let mut m = quad();
        m.face_vertices[3] = 0;
        assert!(m.validate().is_err());
        let mut m = quad();
        m.face_groups[0] = 3;
        assert!(m.validate().is_err());
        let mut m = quad();
        m.corners.insert(4);
        assert!(m.validate().is_err());
    }
}
