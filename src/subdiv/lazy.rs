//! Positions, limit points and limit normals of chosen vertices only.
//!
//! A decode to an accuracy shows most base triangles at a coarse level and measures each at
//! one level finer, so it needs the limit points of a small share of a refinement's vertices.
//! Each level-`j` position depends on the level-`j - 1` positions of its mask (the vertex's
//! ring, or the ends and opposite corners of its edge), and the limit point and normal of a
//! vertex on its ring at the level it was born at (the limit masks are eigenvectors of the
//! subdivision, so any level gives the same point). [`LazyLimits`] evaluates, level by level,
//! exactly the positions the asked-for limit points depend on, into stores indexed by the
//! nested vertex ids ([`Paged`]) whose pages are allocated when first written, each charged to
//! the decode's budget first: only what is evaluated takes memory.

use glam::DVec3;

use crate::error::{Error, Result};

use super::masks::ValenceTables;
use super::next_level::{Connectivity, NextLevel};
use super::{eval, Refinement};

/// What a [`LazyLimits`] charges its pages to: bytes for a purpose, refused with an error
/// (`Error::LimitsExceeded`) when they do not fit.
pub(crate) type Charge<'c> = dyn FnMut(&'static str, u64) -> Result<()> + 'c;

/// Points by vertex id, in pages allocated when first written: a decode to an accuracy
/// writes a small share of a refinement's vertices, and only the pages written take memory.
/// Unwritten entries read as zero.
pub(crate) struct Paged {
    pages: Vec<Option<Box<[DVec3]>>>,
    len: usize,
}

/// Points per page of a [`Paged`] store.
pub(crate) const PAGE: u64 = 512;
/// Bytes charged per page.
pub(crate) const PAGE_BYTES: u64 = 24 * PAGE;
/// What the pages are charged for.
const PAGE_MEMORY: &str =
    "decode memory with subdivision to a tolerance: evaluated positions and limits (bytes)";

static ZERO: DVec3 = DVec3::ZERO;

impl Paged {
    fn new(len: usize) -> Self {
        Paged {
            pages: (0..len.div_ceil(PAGE as usize)).map(|_| None).collect(),
            len,
        }
    }

    /// Entries (written or not).
    pub fn len(&self) -> usize {
        self.len
    }

    /// Writes `p` at `i`, allocating its page when it has none, charged first; a refused
    /// charge leaves the entry unwritten and is kept in `failed` (nothing more is allocated
    /// after it).
    fn set(&mut self, i: usize, p: DVec3, charge: &mut Charge<'_>, failed: &mut Option<Error>) {
        let page = &mut self.pages[i / PAGE as usize];
        if page.is_none() {
            if failed.is_some() {
                return;
            }
            if let Err(e) = charge(PAGE_MEMORY, PAGE_BYTES) {
                *failed = Some(e);
                return;
            }
            *page = Some(vec![DVec3::ZERO; PAGE as usize].into_boxed_slice());
        }
        if let Some(page) = page {
            page[i % PAGE as usize] = p;
        }
    }
}

impl std::ops::Index<usize> for Paged {
    type Output = DVec3;

    fn index(&self, i: usize) -> &DVec3 {
        match &self.pages[i / PAGE as usize] {
            Some(page) => &page[i % PAGE as usize],
            None => &ZERO,
        }
    }
}

/// The first `.1` entries of a [`Paged`] store (the vertices of a coarser level than its
/// own: ids are nested).
pub(crate) struct Prefix<'p>(pub &'p Paged, pub usize);

impl std::ops::Index<usize> for Prefix<'_> {
    type Output = DVec3;

    fn index(&self, i: usize) -> &DVec3 {
        debug_assert!(i < self.1, "vertex {i} beyond the {} asked for", self.1);
        &self.0[i]
    }
}

impl super::lod::Points for Prefix<'_> {
    fn count(&self) -> usize {
        self.1.min(self.0.len())
    }
}

/// Limit points (and normals) of chosen vertices of a refinement, evaluated on demand.
pub(crate) struct LazyLimits<'a, 'c> {
    r: &'a Refinement,
    /// Vertex count of every level `0..=r.max_level()`.
    nv: Vec<usize>,
    /// Positions of every level, valid where `have` is set.
    pos: Vec<Paged>,
    have: Vec<Vec<u64>>,
    /// Limit points and normals by vertex id (any level's ids: they are nested).
    limit: Paged,
    normal: Paged,
    have_limit: Vec<u64>,
    have_normal: Vec<u64>,
    /// Vertices asked for and not evaluated yet, by the level they are born at, and the
    /// vertices of that level their limit masks (or rings) read; kept between batches so
    /// that their buffers are reused.
    todo: Vec<Vec<u32>>,
    support: Vec<Vec<u32>>,
    /// Whether the vertices in `todo` were asked for with their normals.
    todo_normals: bool,
    /// Entries in `todo` and `support` (at most about [`QUEUE_LIMIT`]).
    queued: usize,
    /// Where pages are charged, and the first charge it refused (then the values read are
    /// not all evaluated, and the caller stops: [`Self::check`]).
    charge: &'c mut Charge<'c>,
    failed: Option<Error>,
}

/// Queue entries after which [`LazyLimits::ask`] evaluates what is queued: the queues stay
/// a few megabytes whatever a caller asks for at once, so their memory is a fixed charge
/// (the result is the same whenever the queues are run).
pub(crate) const QUEUE_LIMIT: usize = 1 << 20;

/// Sets bit `i`; whether it was clear.
#[inline]
fn set(bits: &mut [u64], i: usize) -> bool {
    let (w, b) = (i / 64, 1u64 << (i % 64));
    let clear = bits[w] & b == 0;
    bits[w] |= b;
    clear
}

#[inline]
fn get(bits: &[u64], i: usize) -> bool {
    bits[i / 64] & (1u64 << (i % 64)) != 0
}

/// Appends the vertices of `c` that the limit point of `v` reads (its limit mask: on a crease
/// only the crease's neighbours) or, with `normal`, `v` and its whole ring.
fn support_into(
    c: &impl Connectivity,
    t: &ValenceTables,
    v: u32,
    normal: bool,
    out: &mut Vec<u32>,
) {
    if normal {
        out.push(v);
        out.extend(c.ring_edges(v as usize).map(|e| c.other_end(e, v)));
    } else {
        eval::limit_mask(c, t, v as usize, &mut |x, _| out.push(x));
    }
}

impl<'a, 'c> LazyLimits<'a, 'c> {
    /// Nothing evaluated yet but the control points (level 0), whose pages are charged to
    /// `charge` like every page after them. `r` must be built to level 1 at least.
    pub fn new(
        r: &'a Refinement,
        control: &[DVec3],
        charge: &'c mut Charge<'c>,
    ) -> LazyLimits<'a, 'c> {
        let top = r.max_level();
        debug_assert!(top >= 1);
        let nv: Vec<usize> = (0..=top).map(|j| r.level(j).vertex_count()).collect();
        let mut failed = None;
        let mut level0 = Paged::new(control.len());
        for (i, &p) in control.iter().enumerate() {
            level0.set(i, p, charge, &mut failed);
        }
        let mut pos = vec![level0];
        let mut have = vec![vec![u64::MAX; nv[0].div_ceil(64)]];
        for &n in &nv[1..] {
            pos.push(Paged::new(n));
            have.push(vec![0u64; n.div_ceil(64)]);
        }
        let last = nv[top as usize];
        LazyLimits {
            r,
            limit: Paged::new(last),
            normal: Paged::new(last),
            have_limit: vec![0u64; last.div_ceil(64)],
            have_normal: vec![0u64; last.div_ceil(64)],
            nv,
            pos,
            have,
            todo: vec![Vec::new(); top as usize + 1],
            support: vec![Vec::new(); top as usize + 1],
            todo_normals: false,
            queued: 0,
            charge,
            failed,
        }
    }

    /// Limit points by vertex id (of the finest level; valid where asked for).
    pub fn limit(&self) -> &Paged {
        &self.limit
    }

    /// Limit normals by vertex id (valid where asked for).
    pub fn normals(&self) -> &Paged {
        &self.normal
    }

    /// The charge a page was refused, if any: then some of the values asked for were not
    /// evaluated, and nothing read since is to be used.
    pub fn check(&mut self) -> Result<()> {
        match self.failed.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// Charges `bytes` for `what` to the same budget as the pages.
    pub fn charge(&mut self, what: &'static str, bytes: u64) -> Result<()> {
        self.check()?;
        (self.charge)(what, bytes)
    }

    /// Whether the limit point (and, with `normal`, the normal) of `v` is evaluated.
    pub fn has(&self, v: u32, normal: bool) -> bool {
        get(&self.have_limit, v as usize) && (!normal || get(&self.have_normal, v as usize))
    }

    /// The level vertex `v` is born at.
    fn birth(&self, v: u32) -> u32 {
        self.nv.iter().position(|&n| (v as usize) < n).unwrap_or(0) as u32
    }

    /// The last level, seen through the one before (its arrays are not built).
    fn finest(r: &'a Refinement) -> NextLevel<'a> {
        let top = r.max_level();
        NextLevel {
            l: r.full(top - 1),
            base: &r.base,
            j: top - 1,
        }
    }

    /// Evaluates the limit points of `verts` (and with `normals` their limit normals) that
    /// are not evaluated yet.
    pub fn evaluate(&mut self, verts: &[u32], normals: bool) {
        self.ask(verts, normals);
        self.run();
    }

    /// Queues the limit points of `verts` (and with `normals` their limit normals) that are
    /// neither evaluated nor queued yet, for [`Self::run`]. A caller with many vertices, most
    /// asked for several times, asks in small batches so that no array of the repeats is
    /// ever made. Every batch before a `run` asks with the same `normals`.
    pub fn ask(&mut self, verts: &[u32], normals: bool) {
        debug_assert!(
            self.todo.iter().all(Vec::is_empty) || self.todo_normals == normals,
            "one run evaluates normals for all of its vertices or for none"
        );
        self.todo_normals = normals;
        let top = self.r.max_level();
        for &v in verts {
            // Marked when queued, so that a vertex asked for many times is evaluated once.
            let i = v as usize;
            let limit = set(&mut self.have_limit, i);
            let normal = normals && set(&mut self.have_normal, i);
            if !(limit || normal) {
                continue;
            }
            let b = self.birth(v);
            self.todo[b as usize].push(v);
            let (r, ring) = (self.r, &mut self.support[b as usize]);
            let before = ring.len();
            if b < top {
                support_into(r.full(b), &r.tables, v, normals, ring);
            } else {
                support_into(&Self::finest(r), &r.tables, v, normals, ring);
            }
            self.queued += 1 + ring.len() - before;
            if self.queued > QUEUE_LIMIT {
                self.run();
            }
        }
    }

    /// Evaluates what [`Self::ask`] queued.
    pub fn run(&mut self) {
        self.queued = 0;
        let top = self.r.max_level();
        let normals = self.todo_normals;
        let mut support = std::mem::take(&mut self.support);
        for (b, ring) in support.iter_mut().enumerate() {
            self.positions(b as u32, ring);
            ring.clear();
        }
        self.support = support;
        let (t, base) = (&self.r.tables, &self.r.base);
        for (b, vs) in self.todo.iter_mut().enumerate() {
            let b = b as u32;
            let p = &self.pos[b as usize];
            for &v in vs.iter() {
                let i = v as usize;
                let (lim, nor) = if b < top {
                    let l = self.r.full(b);
                    (
                        eval::eval_limit(l, t, base, p, i),
                        normals.then(|| eval::eval_normal(l, t, base, b, p, i, None)),
                    )
                } else {
                    let l = Self::finest(self.r);
                    (
                        eval::eval_limit(&l, t, base, p, i),
                        normals.then(|| eval::eval_normal(&l, t, base, b, p, i, None)),
                    )
                };
                self.limit.set(i, lim, self.charge, &mut self.failed);
                if let Some(nn) = nor {
                    self.normal.set(i, nn, self.charge, &mut self.failed);
                }
            }
            vs.clear();
        }
    }

    /// Evaluates the level-`j` positions of `verts` and everything they depend on.
    fn positions(&mut self, j: u32, verts: &mut Vec<u32>) {
        if j == 0 {
            return;
        }
        let j = j as usize;
        let mut queue: Vec<Vec<u32>> = vec![Vec::new(); j + 1];
        queue[j] = std::mem::take(verts);
        queue[j].retain(|&v| set(&mut self.have[j], v as usize));
        let t = &self.r.tables;
        // The masks of level i's new positions read level i - 1, whose arrays are built.
        for i in (1..=j).rev() {
            let (lower, upper) = queue.split_at_mut(i);
            let (below, at) = (&mut lower[i - 1], &upper[0]);
            if i == 1 {
                break;
            }
            let l = self.r.full(i as u32 - 1);
            let (nv, have) = (self.nv[i - 1], &mut self.have[i - 1]);
            let mut emit = |x: u32, _: f64| {
                if set(have, x as usize) {
                    below.push(x);
                }
            };
            for &v in at {
                if (v as usize) < nv {
                    eval::vertex_mask(l, t, v as usize, &mut emit);
                } else {
                    eval::edge_mask(l, v as usize - nv, &mut emit);
                }
            }
        }
        let base = &self.r.base;
        for (i, vs) in queue.iter().enumerate().skip(1) {
            let l = self.r.full(i as u32 - 1);
            let nv = self.nv[i - 1];
            let (lower, upper) = self.pos.split_at_mut(i);
            let (src, dst) = (&lower[i - 1], &mut upper[0]);
            for &v in vs {
                let v = v as usize;
                let p = if v < nv {
                    eval::eval_vertex(l, t, base, src, v)
                } else {
                    eval::eval_edge(l, base, src, v - nv)
                };
                dst.set(v, p, self.charge, &mut self.failed);
            }
        }
        *verts = std::mem::take(&mut queue[j]);
        verts.clear();
    }
}
