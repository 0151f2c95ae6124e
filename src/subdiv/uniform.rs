//! A uniform limit surface handed out group by group, for callers that consume one CAD face
//! at a time (the encoder's error measurement).

use glam::DVec3;

use super::next_level::NextLevel;
use super::sparse::{Chains, SparsePlan, UniformFaces};
use super::topology::{Base, Level};
use super::{limit_positions_of, Refinement};
use crate::error::Result;
use crate::mesh::{Buckets, ControlMesh};

/// The level-n limit surface [`super::subdivide`] outputs (sparse boundary patches, limit
/// positions), as the limit positions of every level-n vertex and what makes a group's
/// triangles on demand ([`UniformFaces`]): level 0, the faces of level n-1 and the vertex
/// counts of the levels. A model's finest level has four times the triangles of the level
/// before, so its triangle and connectivity arrays are the largest part of a refinement;
/// here none of them exists, and the rest of the refinement is dropped once the positions
/// are evaluated.
pub struct UniformSurface {
    /// Limit positions of the level-n vertices, by level-n id.
    positions: Vec<DVec3>,
    l0: Level,
    base: Base,
    /// Level n-1 with only its faces, face edges and vertex count (`None` for n = 0).
    last: Option<Level>,
    level_nv: Vec<usize>,
    n: u32,
    plan: Option<SparsePlan>,
    /// Base faces of each group, in order.
    group_faces: Buckets,
}

impl UniformSurface {
    /// The limit surface of `mesh` at `level` (`Error::LimitsExceeded` beyond `max_faces`
    /// triangles before sparse output).
    pub fn new(mesh: &ControlMesh, level: u32, max_faces: u64) -> Result<UniformSurface> {
        let r = Refinement::with_max_faces(mesh, level, max_faces)?;
        let mut p = Vec::new();
        r.positions_into(&mesh.positions, level, &mut p, &mut Vec::new())?;
        let level_nv = r.level_nv();
        if level == 0 {
            let positions = r.limit_positions(&p, 0)?;
            let Refinement {
                mut levels, base, ..
            } = r;
            return Ok(Self::assemble(
                positions,
                levels.swap_remove(0),
                base,
                None,
                level_nv,
                0,
            ));
        }
        // From here on only level n-1 (whose next level's limit masks give the positions,
        // and whose faces' children are the dense faces' triangles) and level 0 are read.
        let Refinement {
            mut levels,
            base,
            tables,
            ..
        } = r;
        let mut last = levels.pop().expect("levels 0..n-1 are built");
        let l0 = if level == 1 {
            last.clone()
        } else {
            levels.swap_remove(0)
        };
        drop(levels);
        let next = NextLevel {
            l: &last,
            base: &base,
            j: level - 1,
        };
        let positions = limit_positions_of(&next, &tables, &base, &p);
        drop(p);
        let last = Level {
            nv: last.nv,
            faces: std::mem::take(&mut last.faces),
            face_edges: std::mem::take(&mut last.face_edges),
            ..Default::default()
        };
        Ok(Self::assemble(
            positions,
            l0,
            base,
            Some(last),
            level_nv,
            level,
        ))
    }

    /// The surface of level-`n` limit `positions`, given level 0 and level n-1 (faces, face
    /// edges and vertex count only).
    fn assemble(
        positions: Vec<DVec3>,
        l0: Level,
        base: Base,
        last: Option<Level>,
        level_nv: Vec<usize>,
        n: u32,
    ) -> UniformSurface {
        let plan = SparsePlan::new(&l0, &base);
        let n_groups = base
            .group
            .iter()
            .map(|&g| g as usize + 1)
            .max()
            .unwrap_or(0);
        let group_faces = Buckets::new(n_groups, || {
            base.group.iter().enumerate().map(|(k, &g)| (g, k as u32))
        });
        UniformSurface {
            positions,
            l0,
            base,
            last,
            level_nv,
            n,
            plan,
            group_faces,
        }
    }

    /// Limit positions by level-n vertex id (the ids [`UniformSurface::group_triangles`]
    /// returns).
    pub fn positions(&self) -> &[DVec3] {
        &self.positions
    }

    /// One more than the largest group that has triangles.
    pub fn group_count(&self) -> usize {
        self.group_faces.keys()
    }

    /// The triangles of group `g` (level-n vertex ids), in the order [`super::subdivide`]
    /// outputs them; `out` is cleared first.
    #[cfg(feature = "internals")]
    pub fn group_triangles(&self, g: usize, out: &mut Vec<[u32; 3]>) {
        out.clear();
        self.visit_group_triangles(g, |t| {
            out.extend_from_slice(t);
            true
        });
    }

    /// Calls `f` with the triangles of group `g` as [`UniformSurface::group_triangles`] lists
    /// them, a base face's at a time, until it returns false (a comparison can stop at the
    /// first difference without making the rest); returns whether it saw them all.
    pub fn visit_group_triangles(&self, g: usize, mut f: impl FnMut(&[[u32; 3]]) -> bool) -> bool {
        let faces = UniformFaces {
            l0: &self.l0,
            base: &self.base,
            last: self.last.as_ref(),
            level_nv: &self.level_nv,
            n: self.n,
            plan: self.plan.as_ref(),
        };
        let (mut flat, mut tris) = (Vec::new(), Vec::new());
        let mut bufs = Chains::default();
        for &k in self.group_faces.of(g) {
            flat.clear();
            faces.emit(k as usize, &mut bufs, &mut flat);
            tris.clear();
            tris.extend(flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]));
            if !f(&tris) {
                return false;
            }
        }
        true
    }
}
