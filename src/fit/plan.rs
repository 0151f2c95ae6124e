//! What the fit's rounds refine, group by group and chain by chain, and what each group's
//! plan implies for the chains around it.

use crate::mesh::{BoundarySurface, PatchKind};

/// A closed patch's first decimation threshold, in tolerances.
pub(super) const INITIAL_CLOSED_COST: f64 = 8.0;

/// Per-group state that the rounds refine.
#[derive(Clone, Copy, Debug)]
pub(super) struct GroupPlan {
    pub kind: PatchKind,
    /// Closed patches: decimation threshold as a multiple of the tolerance.
    pub cost_factor: f64,
    /// Rounds in which the group was out of tolerance.
    pub failures: u32,
    /// Its excess over the tolerance when it last failed (0 before).
    pub last_excess: f64,
    /// Failures in a row, as a closed patch, whose excess did not shrink.
    pub stalls: u32,
    /// The group is its input facets: every vertex kept as a corner, every edge sharp, so
    /// its decoded surface is the input itself. The last resort for a face no smooth patch
    /// gets within the tolerance of (facets whose chord error exceeds it, a face thinner
    /// than its outline's error).
    pub faceted: bool,
    /// Whether the group may be faceted: only when the tolerance is held to the input mesh
    /// itself (a face held to its exact surface is its facets' chord error away from them).
    pub facetable: bool,
}

impl GroupPlan {
    /// A group's plan before any round: its patch kind at the first threshold.
    pub fn new(kind: PatchKind) -> GroupPlan {
        GroupPlan {
            kind,
            cost_factor: INITIAL_CLOSED_COST,
            failures: 0,
            last_excess: 0.0,
            stalls: 0,
            faceted: false,
            facetable: true,
        }
    }
}

/// Everything a round's control mesh is built from besides the input, and the only state
/// the rounds change: one struct, so a relaxation can save it and restore parts of it.
#[derive(Clone, Debug)]
pub(super) struct Plan {
    /// By group.
    pub groups: Vec<GroupPlan>,
    /// Per input vertex, a factor on its closed patch's decimation threshold, lowered round
    /// by round where the patch's decoded surface is off (see `refine::lower_cost_near`).
    pub vertex_cost: Vec<f64>,
    /// Per chain, the distance its control points may leave it by.
    pub chain_tol: Vec<f64>,
    /// Per chain on a cylinder or cone, the largest angle between consecutive control
    /// points about the axis.
    pub chain_step: Vec<f64>,
}

impl Plan {
    /// The first round's plan: every chain at twice the tolerance and 60 degrees.
    pub fn new(groups: Vec<GroupPlan>, vertices: usize, chains: usize, tol: f64) -> Plan {
        Plan {
            groups,
            vertex_cost: vec![1.0; vertices],
            chain_tol: vec![2.0 * tol; chains],
            chain_step: vec![60f64.to_radians(); chains],
        }
    }

    /// Halves the tolerance of the chains marked in `refine` and narrows their angle step
    /// (to no less than 5 degrees).
    pub fn refine_chains(&mut self, refine: &[bool]) {
        for (c, &r) in refine.iter().enumerate() {
            if r {
                self.chain_tol[c] *= 0.5;
                self.chain_step[c] = (self.chain_step[c] * 0.6).max(5f64.to_radians());
            }
        }
    }
}

/// The chain's frame: the surface of the lowest-index framed group next to it.
pub(super) fn chain_frame(chain_groups: &[u32], plans: &[GroupPlan]) -> Option<BoundarySurface> {
    chain_frame_owner(chain_groups, plans).and_then(|g| match plans[g as usize].kind {
        PatchKind::Boundary(surface) => surface.axis().map(|_| surface),
        PatchKind::Closed => None,
    })
}

/// The group whose frame the decoder applies to the chain's crease (the lowest-index
/// boundary patch next to it on a cylinder, cone, sphere or torus), if any.
pub(super) fn chain_frame_owner(chain_groups: &[u32], plans: &[GroupPlan]) -> Option<u32> {
    chain_groups
        .iter()
        .copied()
        .find(|&g| match plans[g as usize].kind {
            PatchKind::Boundary(surface) => surface.axis().is_some(),
            PatchKind::Closed => false,
        })
}

/// The name notes and reports use for a patch kind.
pub(super) fn kind_name(k: &PatchKind) -> &'static str {
    match k {
        PatchKind::Closed => "closed",
        PatchKind::Boundary(BoundarySurface::Plane) => "plane",
        PatchKind::Boundary(BoundarySurface::Cylinder { .. }) => "cylinder",
        PatchKind::Boundary(BoundarySurface::Cone { .. }) => "cone",
        PatchKind::Boundary(BoundarySurface::Sphere { .. }) => "sphere",
        PatchKind::Boundary(BoundarySurface::Torus { .. }) => "torus",
    }
}
