//! Fitting encoder: turns a tessellated CAD model into subdivision patches.
//!
//! This first half does not need subdivision: [`segment`] splits an ungrouped mesh into
//! CAD-face-like regions, [`primitives`] fits analytic surfaces, and [`curves`] extracts
//! the boundary curve network (corners + chains) shared by adjacent patches.

mod adjacency;
mod allowance;
mod build;
mod chains;
mod classify;
pub mod curves;
pub mod decimate;
pub mod domain;
pub mod encoder;
mod exact;
mod linalg;
mod measure;
mod plan;
pub mod primitives;
mod quantise;
mod reference;
mod refine;
mod rounds;
pub mod segment;
mod solve;

#[cfg(test)]
pub(crate) mod test_support;

/// Maps `f` over `items` (in parallel with the `parallel` feature), results in order.
pub(crate) fn map_ordered<T: Sync, R: Send>(
    items: &[T],
    f: impl Fn(&T) -> R + Sync + Send,
) -> Vec<R> {
    crate::subdiv::par::map_heavy(items.len(), |i| f(&items[i]))
}

#[cfg(test)]
mod robustness_tests {
    use glam::DVec3;
    use proptest::prelude::*;

    use crate::mesh::{ControlMesh, PatchKind};

    /// Arbitrary small meshes (non-manifold, inconsistently oriented, degenerate triangles,
    /// duplicate positions): segmentation and curve extraction return Ok or a typed error,
    /// never panic.
    fn arb_mesh() -> impl Strategy<Value = ControlMesh> {
        (4usize..24, 1usize..5).prop_flat_map(|(nv, ng)| {
            (
                proptest::collection::vec((0i32..4, 0i32..4, 0i32..4), nv),
                proptest::collection::vec(
                    (0..nv as u32, 0..nv as u32, 0..nv as u32, 0..ng as u32),
                    1..20,
                ),
                Just(ng),
            )
                .prop_map(|(pos, tris, ng)| {
                    let mut m = ControlMesh::new();
                    for (x, y, z) in pos {
                        m.push_vertex(DVec3::new(x as f64, y as f64, z as f64));
                    }
                    for g in 0..ng {
                        m.push_group(format!("g{g}"), PatchKind::Closed);
                    }
                    for (a, b, c, g) in tris {
                        if a != b && b != c && a != c {
                            m.push_face(&[a, b, c], g);
                        }
                    }
                    m
                })
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]
        #[test]
        fn never_panics(m in arb_mesh()) {
            let _ = super::segment::segment(&m, &Default::default());
            let _ = super::curves::build_curve_network(&m, &Default::default());
            if let Ok((seg, _)) = super::segment::segment(&m, &Default::default()) {
                let _ = super::curves::build_curve_network(&seg, &Default::default());
            }
        }
    }
}
