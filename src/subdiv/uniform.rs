//! A uniform limit surface handed out group by group, for callers that consume one CAD face
//! at a time (the encoder's error measurement).

use glam::DVec3;

use super::sparse::{Chains, SparsePlan, UniformFaces};
use super::topology::{Base, Level};
use super::Refinement;
use crate::error::Result;
use crate::mesh::ControlMesh;

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
    /// Base faces of group g, in order: `group_faces[group_offsets[g]..group_offsets[g + 1]]`.
    group_offsets: Vec<u32>,
    group_faces: Vec<u32>,
}

impl UniformSurface {
    /// The limit surface of `mesh` at `level` (`Error::LimitsExceeded` beyond `max_faces`
    /// triangles before sparse output).
    pub fn new(mesh: &ControlMesh, level: u32, max_faces: u64) -> Result<UniformSurface> {
        let r = Refinement::with_max_faces(mesh, level, max_faces)?;
        let positions = {
            let (mut p, mut scratch) = (Vec::new(), Vec::new());
            r.positions_into(&mesh.positions, level, &mut p, &mut scratch)?;
            drop(scratch);
            r.limit_positions(&p, level)?
        };
        let level_nv = r.level_nv();
        let Refinement {
            mut levels, base, ..
        } = r;
        let last = (level > 0).then(|| {
            let l = &mut levels[level as usize - 1];
            let (faces, face_edges) = if level == 1 {
                // Level 0 is kept whole below.
                (l.faces.clone(), l.face_edges.clone())
            } else {
                (
                    std::mem::take(&mut l.faces),
                    std::mem::take(&mut l.face_edges),
                )
            };
            Level {
                nv: l.nv,
                faces,
                face_edges,
                ..Default::default()
            }
        });
        levels.truncate(1);
        let l0 = levels.pop().expect("a refinement has level 0");
        let plan = SparsePlan::new(&l0, &base);
        let n_groups = base
            .group
            .iter()
            .map(|&g| g as usize + 1)
            .max()
            .unwrap_or(0);
        let mut group_offsets = vec![0u32; n_groups + 1];
        for &g in &base.group {
            group_offsets[g as usize + 1] += 1;
        }
        for g in 0..n_groups {
            group_offsets[g + 1] += group_offsets[g];
        }
        let mut fill = group_offsets.clone();
        let mut group_faces = vec![0u32; base.group.len()];
        for (k, &g) in base.group.iter().enumerate() {
            group_faces[fill[g as usize] as usize] = k as u32;
            fill[g as usize] += 1;
        }
        Ok(UniformSurface {
            positions,
            l0,
            base,
            last,
            level_nv,
            n: level,
            plan,
            group_offsets,
            group_faces,
        })
    }

    /// Limit positions by level-n vertex id (the ids [`UniformSurface::group_triangles`]
    /// returns).
    pub fn positions(&self) -> &[DVec3] {
        &self.positions
    }

    /// One more than the largest group that has triangles.
    pub fn group_count(&self) -> usize {
        self.group_offsets.len() - 1
    }

    /// The triangles of group `g` (level-n vertex ids), in the order [`super::subdivide`]
    /// outputs them; `out` is cleared first.
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
        let Some(range) = self.group_offsets.get(g..g + 2) else {
            return true;
        };
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
        for &k in &self.group_faces[range[0] as usize..range[1] as usize] {
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
