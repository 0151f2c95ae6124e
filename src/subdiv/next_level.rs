//! The connectivity the masks read, as a trait: a built [`Level`] answers from its arrays,
//! [`NextLevel`] answers for the level after a built one by the index arithmetic of
//! `refine_level` and `build_rings`.
//!
//! The finest level's arrays are the largest of a refinement (four times the triangles of
//! the level before, and its edges, edge faces and rings besides), yet limit positions read
//! each of its vertices' rings once. [`NextLevel`] evaluates them from the level before
//! without materialising anything, in the same order as the built arrays, so the results
//! are bit-identical.

use super::masks::{eclass, vclass};
use super::topology::{edge_vertex_class, Base, Level, NONE};

/// What the subdivision and limit masks read of one level's connectivity.
pub(crate) trait Connectivity {
    /// The edges around a vertex, in ring order (see `Rings`).
    type Ring<'a>: Iterator<Item = u32> + ExactSizeIterator + Clone
    where
        Self: 'a;
    fn vertex_class(&self, v: usize) -> u8;
    fn edge_class(&self, e: usize) -> u8;
    /// Stored orientation `(a, b)` of edge `e`.
    fn edge_ends(&self, e: usize) -> [u32; 2];
    /// `[left, right]` faces of edge `e` (`right` is `NONE` on the mesh boundary).
    fn edge_faces(&self, e: usize) -> [u32; 2];
    /// Vertex of face `f` opposite to its edge `e`.
    fn opposite_vertex(&self, f: u32, e: u32) -> u32;
    /// Frame id (0 = Cartesian) of vertex `v` / edge `e`.
    fn vertex_frame(&self, v: usize) -> u16;
    fn edge_frame(&self, e: usize) -> u16;
    fn ring_edges(&self, v: usize) -> Self::Ring<'_>;
    /// The other end of edge `e` seen from `v`.
    #[inline]
    fn other_end(&self, e: u32, v: u32) -> u32 {
        let [a, b] = self.edge_ends(e as usize);
        a ^ b ^ v
    }
}

impl Connectivity for Level {
    type Ring<'a> = std::iter::Copied<std::slice::Iter<'a, u32>>;
    #[inline]
    fn vertex_class(&self, v: usize) -> u8 {
        self.vclass[v]
    }
    #[inline]
    fn edge_class(&self, e: usize) -> u8 {
        self.eclass[e]
    }
    #[inline]
    fn edge_ends(&self, e: usize) -> [u32; 2] {
        self.edges[e]
    }
    #[inline]
    fn edge_faces(&self, e: usize) -> [u32; 2] {
        self.edge_faces[e]
    }
    #[inline]
    fn opposite_vertex(&self, f: u32, e: u32) -> u32 {
        self.opposite(f, e)
    }
    #[inline]
    fn vertex_frame(&self, v: usize) -> u16 {
        self.vframe(v)
    }
    #[inline]
    fn edge_frame(&self, e: usize) -> u16 {
        self.eframe(e)
    }
    #[inline]
    fn ring_edges(&self, v: usize) -> Self::Ring<'_> {
        self.ring(v).iter().copied()
    }
}

/// The four children of face `f` of level `l` (corners, 12 ids), as `refine_faces` lays them
/// out: the three corner triangles, then the middle one.
#[inline]
pub(crate) fn child_faces(l: &Level, f: usize) -> [u32; 12] {
    let c = &l.faces[3 * f..3 * f + 3];
    let fe = &l.face_edges[3 * f..3 * f + 3];
    let nv = l.nv as u32;
    let (m0, m1, m2) = (nv + fe[0], nv + fe[1], nv + fe[2]);
    [c[0], m0, m2, m0, c[1], m1, m2, m1, c[2], m0, m1, m2]
}

/// "Half of e at x": the child of edge `e` of level `l` that touches its end `x`.
#[inline]
fn half(l: &Level, e: u32, x: u32) -> u32 {
    if l.edges[e as usize][0] == x {
        2 * e
    } else {
        2 * e + 1
    }
}

/// The edge ids of the four children of face `f` of level `l` (12 ids, `face_edges` order).
#[inline]
pub(crate) fn child_face_edges(l: &Level, f: usize) -> [u32; 12] {
    let c = &l.faces[3 * f..3 * f + 3];
    let fe = &l.face_edges[3 * f..3 * f + 3];
    let i0 = (2 * l.ne() + 3 * f) as u32;
    let (i1, i2) = (i0 + 1, i0 + 2);
    [
        half(l, fe[0], c[0]),
        i0,
        half(l, fe[2], c[0]),
        half(l, fe[0], c[1]),
        half(l, fe[1], c[1]),
        i1,
        i2,
        half(l, fe[1], c[2]),
        half(l, fe[2], c[2]),
        i1,
        i2,
        i0,
    ]
}

/// Level j+1 seen through level j: every query is a few reads of level j's arrays (which
/// must have their rings). Numbering as in `refine_level`: vertices `[0, nv)` are level j's,
/// `nv + e` the one on edge e; edges `2e, 2e + 1` are the halves of edge e, `2 ne + 3f + k`
/// the three inside face f; face `4f + k` is child k of face f.
#[derive(Clone, Copy)]
pub(crate) struct NextLevel<'a> {
    pub l: &'a Level,
    pub base: &'a Base,
    /// The level of `l`.
    pub j: u32,
}

/// The ring of a [`NextLevel`] vertex.
#[derive(Clone)]
pub(crate) enum NextRing<'a> {
    /// An old vertex: the halves at it of its level-j ring edges.
    Old {
        l: &'a Level,
        v: u32,
        edges: std::slice::Iter<'a, u32>,
    },
    /// A vertex on a level-j edge: `[toward b, two inside the left face, toward a, two
    /// inside the right face]` (four edges on the mesh boundary).
    New { edges: [u32; 6], next: u8, len: u8 },
}

impl Iterator for NextRing<'_> {
    type Item = u32;
    #[inline]
    fn next(&mut self) -> Option<u32> {
        match self {
            NextRing::Old { l, v, edges } => edges.next().map(|&e| half(l, e, *v)),
            NextRing::New { edges, next, len } => (*next < *len).then(|| {
                *next += 1;
                edges[*next as usize - 1]
            }),
        }
    }
    #[inline]
    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = match self {
            NextRing::Old { edges, .. } => edges.len(),
            NextRing::New { next, len, .. } => (*len - *next) as usize,
        };
        (n, Some(n))
    }
}

impl ExactSizeIterator for NextRing<'_> {}

impl NextLevel<'_> {
    pub fn vertex_count(&self) -> usize {
        self.l.nv + self.l.ne()
    }

    /// The level-j edge `e` splits into edges `2e, 2e + 1` and face `f` into edges
    /// `2 ne + 3f ..`: which one `e2` is.
    #[inline]
    fn split(&self, e2: usize) -> Result<(usize, usize), (usize, usize)> {
        let ne = self.l.ne();
        if e2 < 2 * ne {
            Ok((e2 / 2, e2 % 2))
        } else {
            Err(((e2 - 2 * ne) / 3, (e2 - 2 * ne) % 3))
        }
    }

    #[inline]
    fn in_boundary_patch(&self, f: usize) -> bool {
        self.base.boundary_patch[f >> (2 * self.j)]
    }

    /// Child of face `f` at its corner holding vertex `x` (`NONE` for no face).
    #[inline]
    fn corner_child(&self, f: u32, x: u32) -> u32 {
        if f == NONE {
            return NONE;
        }
        let c = &self.l.faces[3 * f as usize..3 * f as usize + 3];
        let k = if c[0] == x {
            0
        } else if c[1] == x {
            1
        } else {
            2
        };
        4 * f + k
    }
}

impl Connectivity for NextLevel<'_> {
    type Ring<'b>
        = NextRing<'b>
    where
        Self: 'b;

    #[inline]
    fn vertex_class(&self, v: usize) -> u8 {
        let l = self.l;
        if v < l.nv {
            return l.vclass[v];
        }
        edge_vertex_class(l.eclass[v - l.nv])
    }

    #[inline]
    fn edge_class(&self, e2: usize) -> u8 {
        let l = self.l;
        match self.split(e2) {
            Ok((e, h)) => {
                let c = l.eclass[e];
                if c & eclass::CREASE == 0 {
                    return c;
                }
                let flags = c & !eclass::RULE_MASK;
                let [a, b] = l.edges[e];
                let cm = vclass::CREASE_REGULAR;
                flags
                    | if h == 0 {
                        eclass::crease_rule(l.vclass[a as usize], cm)
                    } else {
                        eclass::crease_rule(cm, l.vclass[b as usize])
                    }
            }
            Err((f, _)) => {
                if self.in_boundary_patch(f) {
                    eclass::LINEAR
                } else {
                    eclass::SMOOTH
                }
            }
        }
    }

    #[inline]
    fn edge_ends(&self, e2: usize) -> [u32; 2] {
        let l = self.l;
        let nv = l.nv as u32;
        match self.split(e2) {
            Ok((e, h)) => {
                let [a, b] = l.edges[e];
                let m = nv + e as u32;
                if h == 0 {
                    [a, m]
                } else {
                    [m, b]
                }
            }
            Err((f, k)) => {
                let m = |s: usize| nv + l.face_edges[3 * f + s];
                match k {
                    0 => [m(0), m(2)],
                    1 => [m(1), m(0)],
                    _ => [m(2), m(1)],
                }
            }
        }
    }

    #[inline]
    fn edge_faces(&self, e2: usize) -> [u32; 2] {
        match self.split(e2) {
            Ok((e, h)) => {
                let x = self.l.edges[e][h];
                let [fl, fr] = self.l.edge_faces[e];
                [self.corner_child(fl, x), self.corner_child(fr, x)]
            }
            Err((f, k)) => {
                let f = f as u32;
                [4 * f + k as u32, 4 * f + 3]
            }
        }
    }

    #[inline]
    fn opposite_vertex(&self, f2: u32, e2: u32) -> u32 {
        let (f, k) = (f2 as usize / 4, f2 as usize % 4);
        let fe = child_face_edges(self.l, f);
        let fe = &fe[3 * k..3 * k + 3];
        let s = if fe[0] == e2 {
            0
        } else if fe[1] == e2 {
            1
        } else {
            2
        };
        child_faces(self.l, f)[3 * k + (s + 2) % 3]
    }

    #[inline]
    fn vertex_frame(&self, v: usize) -> u16 {
        let l = self.l;
        if l.vframe.is_empty() {
            0
        } else if v < l.nv {
            l.vframe[v]
        } else if l.eclass[v - l.nv] & eclass::CREASE != 0 {
            l.eframe[v - l.nv]
        } else {
            0
        }
    }

    #[inline]
    fn edge_frame(&self, e2: usize) -> u16 {
        if self.l.eframe.is_empty() {
            return 0;
        }
        match self.split(e2) {
            Ok((e, _)) => self.l.eframe[e],
            Err((f, _)) => {
                let b = f >> (2 * self.j);
                if self.base.boundary_patch[b] {
                    self.base.group_frame[self.base.group[b] as usize]
                } else {
                    0
                }
            }
        }
    }

    #[inline]
    fn ring_edges(&self, v: usize) -> NextRing<'_> {
        let l = self.l;
        if v < l.nv {
            return NextRing::Old {
                l,
                v: v as u32,
                edges: l.ring(v).iter(),
            };
        }
        let e = v - l.nv;
        let e32 = e as u32;
        let ne = l.ne() as u32;
        let interior = |f: u32| -> (u32, u32) {
            let fe = &l.face_edges[3 * f as usize..3 * f as usize + 3];
            let s = if fe[0] == e32 {
                0
            } else if fe[1] == e32 {
                1
            } else {
                2
            };
            let i0 = 2 * ne + 3 * f;
            (i0 + (s + 1) % 3, i0 + s)
        };
        let [fl, fr] = l.edge_faces[e];
        let (l1, l2) = interior(fl);
        if fr == NONE {
            NextRing::New {
                edges: [2 * e32 + 1, l1, l2, 2 * e32, 0, 0],
                next: 0,
                len: 4,
            }
        } else {
            let (r1, r2) = interior(fr);
            NextRing::New {
                edges: [2 * e32 + 1, l1, l2, 2 * e32, r1, r2],
                next: 0,
                len: 6,
            }
        }
    }
}
