//! Known-answer and property tests of the subdivision engine (reference checklist §7).

use std::collections::BTreeMap;

use glam::{DMat3, DVec3};

use super::masks::{crease_limit_weights, eclass, vclass};
use super::test_support::{self, load_corpus};
use super::*;
use crate::mesh::{Axis, BoundarySurface, PatchKind};

mod accuracy;

fn v3(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

fn tetrahedron() -> ControlMesh {
    let mut m = ControlMesh::new();
    for p in [
        v3(1., 1., 1.),
        v3(1., -1., -1.),
        v3(-1., 1., -1.),
        v3(-1., -1., 1.),
    ] {
        m.push_vertex(p);
    }
    let g = m.push_group("t", PatchKind::Closed);
    for f in [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]] {
        m.push_face(&f, g);
    }
    m
}

/// Tiny deterministic pseudo-random numbers in [0, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// (nx+1) x (ny+1) grid, each square split by the diagonal (i,j)-(i+1,j+1).
fn grid(nx: usize, ny: usize, z: impl Fn(usize, usize) -> f64) -> ControlMesh {
    let mut m = ControlMesh::new();
    for j in 0..=ny {
        for i in 0..=nx {
            m.push_vertex(v3(i as f64, j as f64, z(i, j)));
        }
    }
    let g = m.push_group("grid", PatchKind::Closed);
    let id = |i: usize, j: usize| (i + (nx + 1) * j) as u32;
    for j in 0..ny {
        for i in 0..nx {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            m.push_face(&[a, b, c], g);
            m.push_face(&[a, c, d], g);
        }
    }
    m
}

fn close(a: DVec3, b: DVec3, tol: f64) -> bool {
    (a - b).length() <= tol
}

// ---------------------------------------------------------------------------------------
// Numbering (reference §1)

#[test]
fn tetrahedron_numbering_and_positions() {
    let m = tetrahedron();
    let r = Refinement::new(&m, 3).unwrap();
    let l0 = r.level(0);
    assert_eq!(
        l0.edges(),
        &[[0, 1], [1, 2], [2, 0], [0, 3], [3, 1], [2, 3]]
    );
    let fe: Vec<[u32; 3]> = (0..4).map(|f| l0.face_edges(f)).collect();
    assert_eq!(fe, vec![[0, 1, 2], [3, 4, 0], [2, 5, 3], [4, 5, 1]]);
    let l1 = r.level(1);
    let faces: Vec<[u32; 3]> = (0..8).map(|f| l1.triangle(f)).collect();
    assert_eq!(
        faces,
        vec![
            [0, 4, 6],
            [4, 1, 5],
            [6, 5, 2],
            [4, 5, 6],
            [0, 7, 4],
            [7, 3, 8],
            [4, 8, 1],
            [7, 8, 4]
        ]
    );
    assert_eq!(
        &l1.edges()[..14],
        &[
            [0, 4],
            [4, 1],
            [1, 5],
            [5, 2],
            [2, 6],
            [6, 0],
            [0, 7],
            [7, 3],
            [3, 8],
            [8, 1],
            [2, 9],
            [9, 3],
            [4, 6],
            [5, 4]
        ]
    );
    // counts (V, E, F) and Euler characteristic
    let counts: Vec<(usize, usize, usize)> = (0..=3)
        .map(|j| {
            let l = r.level(j);
            (l.vertex_count(), l.edge_count(), l.face_count())
        })
        .collect();
    assert_eq!(
        counts,
        vec![(4, 6, 4), (10, 24, 16), (34, 96, 64), (130, 384, 256)]
    );
    // every face's edges match its corner pairs, every edge has 2 faces
    for j in 0..=3 {
        let l = r.level(j);
        let mut uses = vec![0; l.edge_count()];
        for f in 0..l.face_count() {
            let c = l.triangle(f);
            for (s, &e) in l.face_edges(f).iter().enumerate() {
                let [a, b] = l.edges()[e as usize];
                let (x, y) = (c[s], c[(s + 1) % 3]);
                assert!((a, b) == (x, y) || (a, b) == (y, x), "level {j} face {f}");
                uses[e as usize] += 1;
            }
        }
        assert!(uses.iter().all(|&u| u == 2));
    }
    let p = r.positions_at(&m.positions, 1).unwrap();
    let q = 0.25;
    let want = [
        v3(q, q, q),
        v3(q, -q, -q),
        v3(-q, q, -q),
        v3(-q, -q, q),
        v3(0.5, 0., 0.),
        v3(0., 0., -0.5),
        v3(0., 0.5, 0.),
        v3(0., 0., 0.5),
        v3(0., -0.5, 0.),
        v3(-0.5, 0., 0.),
    ];
    for (i, w) in want.iter().enumerate() {
        assert!(close(p[i], *w, 1e-15), "v{i}: {:?} vs {w:?}", p[i]);
    }
}

#[test]
fn lod_extraction_formula_matches_levels() {
    let m = tetrahedron();
    let r = Refinement::new(&m, 4).unwrap();
    let n = 4;
    let fine = r.level(n);
    for mm in 0..=n {
        let lm = r.level(mm);
        for g in 0..lm.face_count() {
            for c in 0..3 {
                let f = lod_corner_face(g, n, mm, c);
                assert_eq!(
                    fine.triangle(f)[c],
                    lm.triangle(g)[c],
                    "level {mm} face {g}"
                );
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Masks and limit points (reference §3-4)

#[test]
fn grid_exact_limit_points() {
    let z = [
        [0., 1., 0., 2.],
        [1., 3., 2., 0.],
        [0., 2., 4., 1.],
        [2., 0., 1., 0.],
    ];
    let m = grid(3, 3, |i, j| z[j][i]);
    let want = [
        (v3(1. / 5., 1. / 5., 2. / 5.), v3(0., 0., 0.)),
        (v3(49. / 48., 0., 11. / 16.), v3(49. / 48., 0., 11. / 16.)),
        (v3(95. / 48., 0., 11. / 24.), v3(95. / 48., 0., 11. / 24.)),
        (v3(14. / 5., 1. / 5., 6. / 5.), v3(3., 0., 2.)),
        (v3(0., 49. / 48., 11. / 16.), v3(0., 49. / 48., 11. / 16.)),
        (v3(1., 1., 7. / 3.), v3(1., 1., 7. / 3.)),
        (v3(2., 1., 7. / 4.), v3(2., 1., 7. / 4.)),
        (v3(3., 49. / 48., 11. / 24.), v3(3., 49. / 48., 11. / 24.)),
        (v3(0., 95. / 48., 11. / 24.), v3(0., 95. / 48., 11. / 24.)),
        (v3(1., 2., 7. / 4.), v3(1., 2., 7. / 4.)),
        (v3(2., 2., 11. / 4.), v3(2., 2., 11. / 4.)),
        (v3(3., 95. / 48., 11. / 16.), v3(3., 95. / 48., 11. / 16.)),
        (v3(1. / 5., 14. / 5., 6. / 5.), v3(0., 3., 2.)),
        (v3(49. / 48., 3., 11. / 24.), v3(49. / 48., 3., 11. / 24.)),
        (v3(95. / 48., 3., 11. / 16.), v3(95. / 48., 3., 11. / 16.)),
        (v3(14. / 5., 14. / 5., 2. / 5.), v3(3., 3., 0.)),
    ];
    let r = Refinement::new(&m, 0).unwrap();
    let lim = r.limit_positions(&m.positions, 0).unwrap();
    for (v, (w, _)) in want.iter().enumerate() {
        assert!(close(lim[v], *w, 1e-14), "v{v}: {:?} vs {w:?}", lim[v]);
    }
    let mut mc = m.clone();
    mc.corners.extend([0, 3, 12, 15]);
    let r = Refinement::new(&mc, 0).unwrap();
    let lim = r.limit_positions(&mc.positions, 0).unwrap();
    for (v, (_, w)) in want.iter().enumerate() {
        assert!(
            close(lim[v], *w, 1e-14),
            "corner-tagged v{v}: {:?} vs {w:?}",
            lim[v]
        );
    }
    // stencils give the same limit points
    let st = r.stencils(0, true).unwrap();
    for (a, b) in st.apply(&mc.positions).iter().zip(&lim) {
        assert!(close(*a, *b, 1e-14));
    }
}

/// Table 1 rows by iterated curve subdivision of a unit impulse (reference §4.4.1): the
/// engine's crease rules on a polyline of typed vertices.
#[test]
fn table1_masks_by_iterated_polyline_subdivision() {
    use vclass::{CORNER, CREASE_NONREG as S, CREASE_REGULAR as R};
    // (l, c, r) -> (w_l, w_c, w_r)
    let rows = [
        ((R, R, R), (1. / 6., 4. / 6., 1. / 6.)),
        ((R, R, S), (1. / 6., 11. / 16., 7. / 48.)),
        ((S, R, S), (7. / 48., 17. / 24., 7. / 48.)),
        ((R, S, R), (1. / 5., 3. / 5., 1. / 5.)),
        ((R, S, S), (1. / 5., 5. / 8., 7. / 40.)),
        ((S, S, S), (7. / 40., 13. / 20., 7. / 40.)),
        ((R, R, CORNER), (1. / 6., 11. / 16., 7. / 48.)),
    ];
    for ((tl, tc, tr), (wl, wc, wr)) in rows {
        // polyline: corner R R R l c r R R R corner
        let mut types = vec![CORNER, R, R, R, tl, tc, tr, R, R, R, CORNER];
        let centre = 5;
        for (probe, want) in [(centre - 1, wl), (centre, wc), (centre + 1, wr)] {
            let mut vals: Vec<f64> = (0..types.len())
                .map(|i| (i == probe) as u8 as f64)
                .collect();
            let mut ty = types.clone();
            let mut c = centre;
            for _ in 0..40 {
                let n = vals.len();
                let mut nv = Vec::with_capacity(2 * n - 1);
                let mut nt = Vec::with_capacity(2 * n - 1);
                for i in 0..n {
                    let v = if ty[i] == CORNER {
                        vals[i]
                    } else {
                        0.75 * vals[i] + 0.125 * (vals[i - 1] + vals[i + 1])
                    };
                    nv.push(v);
                    nt.push(ty[i]);
                    if i + 1 < n {
                        let (wa, wb) = eclass::pair_weights(eclass::crease_rule(ty[i], ty[i + 1]));
                        nv.push(wa * vals[i] + wb * vals[i + 1]);
                        nt.push(R);
                    }
                }
                // keep a window of 11 vertices around c's descendant (index 2c)
                let c2 = 2 * c;
                let lo = c2 - 5;
                vals = nv[lo..lo + 11].to_vec();
                ty = nt[lo..lo + 11].to_vec();
                ty[0] = CORNER;
                ty[10] = CORNER;
                c = 5;
            }
            assert!(
                (vals[c] - want).abs() < 1e-9,
                "{tl}{tc}{tr} probe {probe}: {} vs {want}",
                vals[c]
            );
        }
        types.clear();
        // the closed-form recipe of §4.2 agrees
        let (ws, wcc) = crease_limit_weights(tc == R);
        let (la, _) = eclass::pair_weights(eclass::crease_rule(tc, tl)); // weight on c
        let (ra, _) = eclass::pair_weights(eclass::crease_rule(tc, tr));
        let w_c = wcc * 0.75 + ws * la + ws * ra;
        assert!((w_c - wc).abs() < 1e-12);
    }
}

#[test]
fn regular_crease_converges_to_cubic_bspline() {
    // 13 x 2 grid; the middle row is a sharp polyline (regular interior crease vertices).
    let mut rng = Lcg(7);
    let m0 = grid(12, 2, |_, _| 0.0);
    let mut m = m0.clone();
    for p in &mut m.positions {
        p.z = rng.next() * 2.0 - 1.0;
        p.y += 0.3 * (rng.next() - 0.5);
    }
    let row = |i: usize| (i + 13) as u32;
    for i in 0..12 {
        m.set_sharp(row(i), row(i + 1));
    }
    let n = 5;
    let r = Refinement::new(&m, n).unwrap();
    let p = r.positions(&m.positions).unwrap();
    let lim = r.limit_positions(&p, n).unwrap();
    let ctrl = |i: usize| m.positions[row(i) as usize];
    let bspline = |i: usize, t: f64| {
        // segment between ctrl(i) and ctrl(i+1)
        let b0 = (1.0 - t).powi(3) / 6.0;
        let b1 = (3.0 * t.powi(3) - 6.0 * t * t + 4.0) / 6.0;
        let b2 = (-3.0 * t.powi(3) + 3.0 * t * t + 3.0 * t + 1.0) / 6.0;
        let b3 = t.powi(3) / 6.0;
        ctrl(i - 1) * b0 + ctrl(i) * b1 + ctrl(i + 1) * b2 + ctrl(i + 2) * b3
    };
    let l0 = r.level(0);
    let ln = r.level(n);
    let span = 1usize << n;
    let mut checked = 0;
    for (e, &[a, b]) in l0.edges().iter().enumerate() {
        // crease edge (row(i), row(i+1)) with i in 3..=8: all of i-1..i+2 regular and away
        // from the boundary corners
        let (i, fwd) = if (13..=25).contains(&a) && b == a + 1 {
            ((a - 13) as usize, true)
        } else if (13..=25).contains(&b) && a == b + 1 {
            ((b - 13) as usize, false)
        } else {
            continue;
        };
        if !(3..=8).contains(&i) {
            continue;
        }
        for j in 0..=span {
            let vtx = if j == span {
                ln.edges()[e * span + span - 1][1]
            } else {
                ln.edges()[e * span + j][0]
            };
            let t = j as f64 / span as f64;
            let t = if fwd { t } else { 1.0 - t };
            let want = bspline(i, t);
            assert!(close(lim[vtx as usize], want, 1e-12), "edge {i} t {t}");
            // the subdivided (non-limit) points converge: within O(4^-n)
            assert!(close(p[vtx as usize], want, 2e-3));
            checked += 1;
        }
    }
    assert_eq!(checked, 6 * (span + 1));
}

#[test]
fn planar_mesh_stays_planar_and_corners_fixed() {
    let mut rng = Lcg(3);
    let mut m = grid(5, 4, |_, _| 0.0);
    let (u, w) = (
        v3(1.0, 0.2, 0.3).normalize(),
        v3(-0.1, 1.0, 0.5).normalize(),
    );
    let normal = u.cross(w).normalize();
    let origin = v3(0.3, -2.0, 5.0);
    for p in &mut m.positions {
        let (x, y) = (p.x + 0.3 * rng.next(), p.y + 0.3 * rng.next());
        *p = origin + u * x + w * y;
    }
    m.set_sharp(7, 8);
    m.set_sharp(8, 9);
    m.set_sharp(8, 14);
    m.corners.extend([0, 9, 20]);
    let n = 4;
    let r = Refinement::new(&m, n).unwrap();
    let p = r.positions(&m.positions).unwrap();
    for j in 0..=n {
        let pj = r.positions_at(&m.positions, j).unwrap();
        let lim = r.limit_positions(&pj, j).unwrap();
        for q in pj.iter().chain(&lim) {
            assert!((q - origin).dot(normal).abs() < 1e-12);
        }
    }
    for &c in &m.corners {
        assert_eq!(p[c as usize], m.positions[c as usize]);
    }
    // vertex 8 has 3 sharp edges: a corner by valence
    assert_eq!(p[8], m.positions[8]);
    // limit normals of a planar surface are the plane normal
    let nn = r.limit_normals(&p, n).unwrap();
    for (v, q) in nn.iter().enumerate() {
        assert!(
            q.dot(normal).abs() > 1.0 - 1e-9,
            "v{v} class {}: {q:?}",
            r.full(n).vclass[v]
        );
    }
}

/// A mixed test mesh: grid with random heights, an interior crease ending in a dart, an
/// interior crease through a corner tag, boundary creases.
fn mixed_mesh() -> ControlMesh {
    let mut rng = Lcg(11);
    let mut m = grid(6, 6, |_, _| 0.0);
    for p in &mut m.positions {
        p.z = rng.next();
        p.x += 0.2 * (rng.next() - 0.5);
    }
    let id = |i: u32, j: u32| i + 7 * j;
    // crease along row 3 from x=0 to x=4: ends at (4,3) as a dart
    for i in 0..4 {
        m.set_sharp(id(i, 3), id(i + 1, 3));
    }
    // a crease along column 2 crossing nothing, corner tag in the middle
    for j in 0..2 {
        m.set_sharp(id(5, j), id(5, j + 1));
    }
    m.corners.insert(id(5, 1));
    m.corners.insert(id(6, 6));
    m
}

#[test]
fn limit_points_invariant_across_levels() {
    let m = mixed_mesh();
    let r = Refinement::new(&m, 6).unwrap();
    let l0 = r.level(0);
    let classes: Vec<u8> = (0..l0.vertex_count())
        .map(|v| r.full(0).vclass[v])
        .collect();
    assert!(classes.contains(&vclass::DART));
    assert!(classes.contains(&vclass::CORNER));
    assert!(classes.contains(&vclass::CREASE_REGULAR));
    assert!(classes.contains(&vclass::CREASE_NONREG));
    let lim0 = r.limit_positions(&m.positions, 0).unwrap();
    for j in [1, 3, 6] {
        let pj = r.positions_at(&m.positions, j).unwrap();
        let limj = r.limit_positions(&pj, j).unwrap();
        for v in 0..lim0.len() {
            assert!(
                close(lim0[v], limj[v], 1e-12),
                "v{v} level {j}: {:?} {:?}",
                lim0[v],
                limj[v]
            );
        }
    }
    // limit stencils reproduce it
    let st = r.stencils(2, true).unwrap();
    let p2 = r.positions_at(&m.positions, 2).unwrap();
    let lim2 = r.limit_positions(&p2, 2).unwrap();
    assert!(st.exact.iter().all(|&e| e));
    for (a, b) in st.apply(&m.positions).iter().zip(&lim2) {
        assert!(close(*a, *b, 1e-12));
    }
    let st = r.stencils(3, false).unwrap();
    let p3 = r.positions_at(&m.positions, 3).unwrap();
    for (a, b) in st.apply(&m.positions).iter().zip(&p3) {
        assert!(close(*a, *b, 1e-12));
    }
    for i in 0..st.row_count() {
        let s: f64 = st.row(i).1.iter().sum();
        assert!((s - 1.0).abs() < 1e-12);
    }
}

#[test]
fn normals_invariant_across_levels() {
    let m = mixed_mesh();
    let r = Refinement::new(&m, 6).unwrap();
    let p1 = r.positions_at(&m.positions, 1).unwrap();
    let p6 = r.positions(&m.positions).unwrap();
    let n1 = r.limit_normals(&p1, 1).unwrap();
    let n6 = r.limit_normals(&p6, 6).unwrap();
    let l1 = r.level_with_rings(1);
    let mut kinds = BTreeMap::new();
    for v in 0..l1.nv {
        // skip sectors of two triangles (reference §5.2: unresolved) and darts' neighbours
        let ring = l1.ring(v);
        let c = l1.vclass[v];
        let boundary = l1.edge_faces[ring[0] as usize][1] == topology::NONE;
        let nt = if boundary { ring.len() - 1 } else { ring.len() };
        if c == vclass::CREASE_NONREG && nt == 2 || c == vclass::CORNER && nt <= 2 {
            continue;
        }
        let ang = n1[v].dot(n6[v]).clamp(-1.0, 1.0).acos().to_degrees();
        assert!(ang < 1e-4, "vertex {v} class {c}: {ang} degrees");
        *kinds.entry(c).or_insert(0) += 1;
    }
    assert!(kinds.len() >= 4, "{kinds:?}");
    // smooth normals of a sphere-like closed mesh point outward
    let t = tetrahedron();
    let r = Refinement::new(&t, 2).unwrap();
    let p = r.positions(&t.positions).unwrap();
    let nn = r.limit_normals(&p, 2).unwrap();
    for (q, nq) in p.iter().zip(&nn) {
        assert!(q.dot(*nq) > 0.0);
    }
}

#[test]
fn corner_normals_split_at_creases() {
    // a roof: two planes meeting at a sharp ridge along y = 2
    let mut m = grid(6, 4, |_, j| -(j as f64 - 2.0).abs() * 0.7);
    let id = |i: u32, j: u32| i + 7 * j;
    for i in 0..6 {
        m.set_sharp(id(i, 2), id(i + 1, 2));
    }
    let n = 2;
    let r = Refinement::new(&m, n).unwrap();
    let p = r.positions(&m.positions).unwrap();
    let cn = r.limit_corner_normals(&p, n).unwrap();
    let vn = r.limit_normals(&p, n).unwrap();
    let lv = r.level(n);
    let left = v3(0.0, 0.7, 1.0).normalize(); // plane z = 0.7 (y - 2), y < 2
    let right = v3(0.0, -0.7, 1.0).normalize();
    let mut split = 0;
    for f in 0..lv.face_count() {
        let tri = lv.triangle(f);
        let centroid_y: f64 = tri.iter().map(|&v| p[v as usize].y).sum::<f64>() / 3.0;
        let want = if centroid_y < 2.0 { right } else { left };
        let want = if want.z < 0.0 { -want } else { want };
        for c in 0..3 {
            let got = cn[3 * f + c];
            assert!(
                got.dot(want) > 1.0 - 1e-9,
                "face {f} corner {c}: {got:?} vs {want:?}"
            );
            if (got - vn[tri[c] as usize]).length() > 1e-6 {
                split += 1;
            }
        }
    }
    assert!(split > 0);
}

// ---------------------------------------------------------------------------------------
// Boundary patches (cylinder / cone)

/// Two rings of `n` points (angles jittered) joined by belt quads in one Cylinder or Cone
/// group, closed by planar n-gon caps; ring edges sharp. Returns the mesh and the frame
/// (origin, axis). `r(h)` gives the radius at height h along the axis.
fn belt_mesh(n: usize, cone: bool, closed_belt: bool) -> (ControlMesh, DVec3, DVec3) {
    let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.4, -0.7, 1.1);
    let origin = v3(1.5, -0.5, 2.0);
    let axis = rot * DVec3::Z;
    let (h0, h1) = if cone { (1.0, 2.5) } else { (0.0, 3.0) };
    let radius = |h: f64| if cone { 0.6 * h } else { 2.0 };
    let mut rng = Lcg(5);
    let mut m = ControlMesh::new();
    let surf = if cone {
        BoundarySurface::Cone {
            axis: Axis {
                origin,
                direction: axis * 3.0,
            },
        }
    } else {
        BoundarySurface::Cylinder {
            axis: Axis {
                origin: origin + axis * 0.7,
                direction: -axis,
            },
        }
    };
    let cap0 = m.push_group("cap0", PatchKind::Boundary(BoundarySurface::Plane));
    let belt = m.push_group("belt", PatchKind::Boundary(surf));
    let cap1 = m.push_group("cap1", PatchKind::Boundary(BoundarySurface::Plane));
    let (e1, e2) = (rot * DVec3::X, rot * DVec3::Y);
    for (k, h) in [h0, h1].into_iter().enumerate() {
        for i in 0..n {
            let th = std::f64::consts::TAU * (i as f64 + 0.35 * (rng.next() - 0.5)) / n as f64
                + 0.2 * k as f64;
            let (s, c) = th.sin_cos();
            m.push_vertex(origin + axis * h + (e1 * c + e2 * s) * radius(h));
        }
    }
    let b = |i: usize| (i % n) as u32;
    let t = |i: usize| (n + i % n) as u32;
    let quads = if closed_belt { n } else { n / 2 };
    for i in 0..quads {
        m.push_face(&[b(i), b(i + 1), t(i + 1), t(i)], belt);
    }
    if closed_belt {
        let bottom: Vec<u32> = (0..n).rev().map(b).collect();
        m.push_face(&bottom, cap0);
        let top: Vec<u32> = (0..n).map(t).collect();
        m.push_face(&top, cap1);
        for i in 0..n {
            m.set_sharp(b(i), b(i + 1));
            m.set_sharp(t(i), t(i + 1));
        }
    } else {
        // trimmed patch: open mesh (boundary edges are creases), corners at the ends
        m.corners.extend([b(0), t(0), b(quads), t(quads)]);
    }
    (m, origin, axis)
}

fn surface_error(p: DVec3, origin: DVec3, axis: DVec3, cone: bool) -> f64 {
    let d = p - origin;
    let h = d.dot(axis);
    let r = (d - axis * h).length();
    if cone {
        // distance to the cone r = 0.6 h, relative to the local radius
        let k: f64 = 0.6;
        ((r - k * h) / (1.0 + k * k).sqrt()).abs() / (k * h).abs().max(1e-9)
    } else {
        (r - 2.0).abs() / 2.0
    }
}

#[test]
fn cylinder_and_cone_patches_stay_on_their_surfaces() {
    for cone in [false, true] {
        for closed_belt in [true, false] {
            let (m, origin, axis) = belt_mesh(8, cone, closed_belt);
            let n = 3;
            let r = Refinement::new(&m, n).unwrap();
            let p = r.positions(&m.positions).unwrap();
            let lim = r.limit_positions(&p, n).unwrap();
            let ln = r.level(n);
            let mut worst: f64 = 0.0;
            for f in 0..ln.face_count() {
                if ln.face_group(f) != 1 {
                    continue;
                }
                for v in ln.triangle(f) {
                    worst = worst.max(surface_error(p[v as usize], origin, axis, cone));
                    worst = worst.max(surface_error(lim[v as usize], origin, axis, cone));
                }
            }
            assert!(worst < 1e-3, "cone {cone} closed {closed_belt}: {worst}");
            assert!(worst < 1e-10, "exact by construction: {worst}");
            // cap faces stay planar
            if closed_belt {
                for (g, k) in [(0u32, 0usize), (2, 1)] {
                    let h = (m.positions[k * 8] - origin).dot(axis);
                    for f in 0..ln.face_count() {
                        if ln.face_group(f) == g {
                            for v in ln.triangle(f) {
                                assert!(((p[v as usize] - origin).dot(axis) - h).abs() < 1e-12);
                            }
                        }
                    }
                }
            }
            // the same control mesh refined as closed Loop patches leaves the surface:
            // the test can fail.
            let mut mc = m.clone();
            for g in &mut mc.groups {
                g.patch = PatchKind::Closed;
            }
            let rc = Refinement::new(&mc, n).unwrap();
            let pc = rc.positions(&mc.positions).unwrap();
            let worst_c = (0..rc.level(n).face_count())
                .filter(|&f| rc.level(n).face_group(f) == 1)
                .flat_map(|f| rc.level(n).triangle(f))
                .map(|v| surface_error(pc[v as usize], origin, axis, cone))
                .fold(0.0, f64::max);
            assert!(
                worst_c > 1e-3,
                "closed-patch refinement unexpectedly exact: {worst_c}"
            );
            // and the boundary-patch surface is watertight
            check_closed_or_boundary(ln.triangles(), |a, b| {
                let lv = r.level(n);
                boundary_edge(&lv, a, b)
            });
        }
    }
}

/// An open 4 x 3 grid of quads in one boundary patch on `surface`, its control points at
/// the parameters `point(a, b)` for `a`, `b` in 0..=1 (jittered), the patch boundary a
/// crease with corners at the grid's corners.
fn framed_grid(surface: BoundarySurface, point: impl Fn(f64, f64) -> DVec3) -> ControlMesh {
    let (nu, nv) = (4u32, 3u32);
    let mut rng = Lcg(11);
    let mut m = ControlMesh::new();
    let g = m.push_group("patch", PatchKind::Boundary(surface));
    for j in 0..=nv {
        for i in 0..=nu {
            let mut jitter = |k: u32, n: u32| {
                let inner = k > 0 && k < n;
                (k as f64 + if inner { 0.3 * (rng.next() - 0.5) } else { 0.0 }) / n as f64
            };
            let (a, b) = (jitter(i, nu), jitter(j, nv));
            m.push_vertex(point(a, b));
        }
    }
    let id = |i: u32, j: u32| j * (nu + 1) + i;
    for j in 0..nv {
        for i in 0..nu {
            m.push_face(&[id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)], g);
        }
    }
    m.corners
        .extend([id(0, 0), id(nu, 0), id(nu, nv), id(0, nv)]);
    m
}

/// Largest `error` of the level-3 points and limit points of `m` refined as it is, and of
/// its points refined with every patch closed.
fn framed_errors(m: &ControlMesh, error: impl Fn(DVec3) -> f64) -> (f64, f64) {
    let n = 3;
    let r = Refinement::new(m, n).unwrap();
    let p = r.positions(&m.positions).unwrap();
    let lim = r.limit_positions(&p, n).unwrap();
    let worst = p.iter().chain(&lim).map(|&q| error(q)).fold(0.0, f64::max);
    let mut mc = m.clone();
    for g in &mut mc.groups {
        g.patch = PatchKind::Closed;
    }
    let rc = Refinement::new(&mc, n).unwrap();
    let pc = rc.positions(&mc.positions).unwrap();
    let worst_closed = pc.iter().map(|&q| error(q)).fold(0.0, f64::max);
    (worst, worst_closed)
}

#[test]
fn sphere_and_torus_patches_stay_on_their_surfaces() {
    let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.5, -0.3, 0.8);
    let centre = v3(0.4, -1.0, 2.0);
    let (e1, e2, d) = (rot * DVec3::X, rot * DVec3::Y, rot * DVec3::Z);
    // A sphere patch 100 x 70 degrees wide, its axis tilted from the frame it was made in.
    let radius = 1.7;
    let sphere = framed_grid(
        BoundarySurface::Sphere {
            axis: Axis {
                origin: centre,
                direction: (d + e1 * 0.3) * 2.0,
            },
        },
        |a, b| {
            let (lon, lat) = (-0.9 + 1.75 * a, -0.6 + 1.2 * b);
            centre
                + (e1 * lon.cos() + e2 * lon.sin()) * (radius * lat.cos())
                + d * (radius * lat.sin())
        },
    );
    let (worst, worst_closed) =
        framed_errors(&sphere, |q| ((q - centre).length() - radius).abs() / radius);
    assert!(worst < 1e-10, "sphere patch off the sphere: {worst}");
    assert!(
        worst_closed > 1e-3,
        "closed refinement unexpectedly exact: {worst_closed}"
    );
    // A torus fillet: a quarter turn about the tube, across the seam of the angle about the
    // axis (u from 160 to 250 degrees).
    let (major, minor) = (3.0, 0.8);
    let torus = framed_grid(
        BoundarySurface::Torus {
            axis: Axis {
                origin: centre,
                direction: d,
            },
            major_radius: major,
        },
        |a, b| {
            let (u, v) = (2.8 + 1.6 * a, -0.2 + 1.6 * b);
            let around = e1 * u.cos() + e2 * u.sin();
            centre + around * (major + minor * v.cos()) + d * (minor * v.sin())
        },
    );
    let tube = |q: DVec3| {
        let x = q - centre;
        let h = x.dot(d);
        let s = (x - d * h).length();
        (((s - major).powi(2) + h * h).sqrt() - minor).abs() / minor
    };
    let (worst, worst_closed) = framed_errors(&torus, tube);
    assert!(worst < 1e-10, "torus patch off the torus: {worst}");
    assert!(
        worst_closed > 1e-3,
        "closed refinement unexpectedly exact: {worst_closed}"
    );
}

/// Uniform subdivision with boundary patches output as the dense grid.
fn subdivide_dense(m: &ControlMesh, level: u32) -> (ControlMesh, Option<Vec<DVec3>>) {
    subdivide(
        m,
        level,
        &SubdivOptions {
            boundary_patches: BoundaryPatchOutput::Dense,
            ..Default::default()
        },
    )
    .unwrap()
}

/// A cone patch made of an apex fan of 7 triangles (half-angle atan 0.6, tilted axis) under a
/// planar cap polygon; `jitter` moves the rim points off even angular spacing. Returns the
/// mesh, the cone and cap groups, the apex and the axis direction.
fn cone_with_cap(jitter: f64) -> (ControlMesh, u32, u32, DVec3, DVec3) {
    let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.3, 0.2, -0.4);
    let apex = v3(0.2, 0.1, -0.3);
    let axis = rot * DVec3::Z;
    let mut m = ControlMesh::new();
    let cone = m.push_group(
        "cone",
        PatchKind::Boundary(BoundarySurface::Cone {
            axis: Axis {
                origin: apex,
                direction: axis,
            },
        }),
    );
    let cap = m.push_group("cap", PatchKind::Boundary(BoundarySurface::Plane));
    let n = 7;
    m.push_vertex(apex);
    for i in 0..n {
        let th = std::f64::consts::TAU * (i as f64 + jitter * (i % 3) as f64) / n as f64;
        let (s, c) = th.sin_cos();
        m.push_vertex(apex + axis * 2.0 + (rot * v3(c, s, 0.0)) * 1.2);
    }
    for i in 0..n {
        let (a, b) = (1 + i as u32, 1 + ((i + 1) % n) as u32);
        m.push_face(&[0, b, a], cone);
        m.set_sharp(a, b);
    }
    let capv: Vec<u32> = (1..=n as u32).collect();
    m.push_face(&capv, cap);
    m.corners.insert(0);
    (m, cone, cap, apex, axis)
}

#[test]
fn cone_patch_with_apex() {
    let (m, cone, _, apex, axis) = cone_with_cap(0.2);
    let r = Refinement::new(&m, 3).unwrap();
    let p = r.positions(&m.positions).unwrap();
    let l3 = r.level(3);
    let cone_vertices: std::collections::BTreeSet<u32> = (0..l3.face_count())
        .filter(|&f| l3.face_group(f) == cone)
        .flat_map(|f| l3.triangle(f))
        .collect();
    assert!(cone_vertices.len() > 100);
    for &v in &cone_vertices {
        let d = p[v as usize] - apex;
        let h = d.dot(axis);
        let rr = (d - axis * h).length();
        assert!(
            (rr - 0.6 * h).abs() < 1e-12 * (1.0 + h),
            "v{v}: r {rr} h {h}"
        );
    }
    assert_eq!(p[0], apex);
}

// ---------------------------------------------------------------------------------------
// Watertightness, LOD

fn boundary_edge(l: &LevelView<'_>, a: u32, b: u32) -> bool {
    // slow lookup, fine for tests
    l.edges()
        .iter()
        .enumerate()
        .any(|(e, &[x, y])| ((x, y) == (a, b) || (x, y) == (b, a)) && l.edge_is_boundary(e))
}

/// Every undirected edge is used by exactly two faces with opposite directions, or once and
/// then `on_boundary` must accept it.
fn check_closed_or_boundary(tris: &[u32], on_boundary: impl Fn(u32, u32) -> bool) {
    let mut directed: Vec<(u32, u32)> = Vec::with_capacity(tris.len());
    for t in tris.chunks(3) {
        assert!(
            t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
            "degenerate triangle {t:?}"
        );
        for s in 0..3 {
            directed.push((t[s], t[(s + 1) % 3]));
        }
    }
    directed.sort_unstable();
    for w in directed.windows(2) {
        assert_ne!(w[0], w[1], "directed edge {:?} used twice", w[0]);
    }
    let mut undirected: Vec<(u32, u32)> = directed
        .iter()
        .map(|&(a, b)| (a.min(b), a.max(b)))
        .collect();
    undirected.sort_unstable();
    let mut i = 0;
    while i < undirected.len() {
        let mut j = i;
        while j < undirected.len() && undirected[j] == undirected[i] {
            j += 1;
        }
        let (a, b) = undirected[i];
        match j - i {
            2 => {}
            1 => assert!(on_boundary(a, b), "open edge ({a}, {b})"),
            k => panic!("edge ({a}, {b}) used {k} times"),
        }
        i = j;
    }
}

fn flat(t: &[[u32; 3]]) -> Vec<u32> {
    t.iter().flatten().copied().collect()
}

#[test]
fn corpus_models_are_watertight_uniform_and_lod() {
    let models = [
        ("tess/screw_coarse.obj", 4),
        ("tess/four_cone_coarse.obj", 4),
        ("tess/block_fillet3_coarse.obj", 4),
        ("tess/bug3883_xr2-ct-214_plate_coarse.obj", 3),
        ("tess/abc_00000050_coarse.obj", 3),
        ("meshes/fandisk.obj", 3),
    ];
    let mut rng = Lcg(99);
    for (name, max) in models {
        let Some(m) = load_corpus(name) else { continue };
        let r = Refinement::new(&m, max).unwrap();
        let p = r.positions(&m.positions).unwrap();
        assert!(p.iter().all(|q| q.is_finite()));
        for j in 1..=max {
            let l = r.level(j);
            check_closed_or_boundary(l.triangles(), |_, _| false);
        }
        // mixed-level LOD with random per-face levels
        let levels: Vec<u8> = (0..r.base_face_count())
            .map(|_| (rng.next() * (max + 1) as f64) as u8)
            .collect();
        let lod = lod::extract(&r, &p, None, &levels, Default::default()).unwrap();
        check_closed_or_boundary(&flat(&lod.triangles), |_, _| false);
        eprintln!(
            "{name}: level {max} {} triangles; LOD {} triangles",
            r.level(max).face_count(),
            lod.triangles.len()
        );
    }
}

#[test]
fn boundary_patch_lod_is_watertight_and_on_surface() {
    for cone in [false, true] {
        let (m, origin, axis) = belt_mesh(8, cone, true);
        let mut rng = Lcg(17);
        for round in 0..20 {
            // round 0: one level everywhere (nothing is gap-filled)
            let levels: Vec<u8> = (0..m.face_count())
                .map(|_| {
                    if round == 0 {
                        3
                    } else {
                        (rng.next() * 4.0) as u8
                    }
                })
                .collect();
            let lod = subdivide_adaptive(
                &m,
                &levels,
                &SubdivOptions {
                    limit: true,
                    ..Default::default()
                },
            )
            .unwrap();
            check_closed_or_boundary(&flat(&lod.triangles), |_, _| false);
            // vertices are exactly on the surface unless gap filling moved them onto a coarse
            // chord (or they are stitch centroids): those are within the chord sagitta of
            // the 8-gon (about 8% of the radius)
            let (mut exact, mut moved) = (0, 0);
            for (t, &g) in lod.triangles.iter().zip(&lod.face_groups) {
                if g == 1 {
                    for &v in t {
                        let err = surface_error(lod.positions[v as usize], origin, axis, cone);
                        assert!(err < 0.2, "{err}");
                        if err < 1e-9 {
                            exact += 1;
                        } else {
                            moved += 1;
                        }
                    }
                }
            }
            if round == 0 {
                assert_eq!(moved, 0);
            }
            assert!(exact > 0, "{exact} {moved}");
            lod.to_control_mesh(&m.groups).validate().unwrap();
            let nn = lod.normals.as_ref().unwrap();
            assert!(nn.iter().all(|n| (n.length() - 1.0).abs() < 1e-9));
        }
    }
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let Some(m) = load_corpus("tess/block_fillet3_coarse.obj") else {
        return;
    };
    let r = Refinement::new(&m, 3).unwrap();
    let p = r.positions(&m.positions).unwrap();
    let lim = r.limit_positions(&p, 3).unwrap();
    let nn = r.limit_normals(&p, 3).unwrap();
    #[cfg(feature = "parallel")]
    {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let r1 = pool.install(|| Refinement::new(&m, 3).unwrap());
        let (p1, l1, n1) = pool.install(|| {
            let p1 = r1.positions(&m.positions).unwrap();
            let l1 = r1.limit_positions(&p1, 3).unwrap();
            let n1 = r1.limit_normals(&p1, 3).unwrap();
            (p1, l1, n1)
        });
        assert_eq!(p, p1);
        assert_eq!(lim, l1);
        assert_eq!(nn, n1);
        assert_eq!(r.level(3).triangles(), r1.level(3).triangles());
    }
    // positions_into with reused buffers equals positions
    let (mut out, mut scratch) = (Vec::new(), Vec::new());
    for lvl in [3, 1, 2, 0] {
        r.positions_into(&m.positions, lvl, &mut out, &mut scratch)
            .unwrap();
        assert_eq!(out, r.positions_at(&m.positions, lvl).unwrap());
    }
    let _ = (lim, nn);
}

#[test]
fn empty_and_isolated_vertices() {
    let m = ControlMesh::new();
    let r = Refinement::new(&m, 2).unwrap();
    assert_eq!(r.positions(&[]).unwrap().len(), 0);
    let mut m = tetrahedron();
    m.push_vertex(v3(5., 5., 5.));
    let (out, nn) = subdivide(
        &m,
        2,
        &SubdivOptions {
            limit: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(out.positions[4], v3(5., 5., 5.));
    assert_eq!(nn.unwrap()[4], DVec3::ZERO);
}

/// Every coarse tessellation in the corpus refines (manifold, consistently oriented) to a
/// watertight level 2, also as a random mixed-level LOD.
#[test]
fn all_corpus_tessellations_refine_watertight() {
    let Some(dir) = test_support::corpus_dir() else {
        eprintln!("corpus not found; skipping");
        return;
    };
    let Ok(entries) = std::fs::read_dir(dir.join("tess")) else {
        return;
    };
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with("_coarse.obj"))
        .collect();
    names.sort();
    let mut rng = Lcg(5);
    for name in &names {
        let Some(m) = load_corpus(&format!("tess/{name}")) else {
            continue;
        };
        let r = Refinement::new(&m, 2).unwrap_or_else(|e| panic!("{name}: {e}"));
        let p = r.positions(&m.positions).unwrap();
        check_closed_or_boundary(r.level(2).triangles(), |_, _| false);
        let levels: Vec<u8> = (0..r.base_face_count())
            .map(|_| (rng.next() * 3.0) as u8)
            .collect();
        let lod = r.extract_lod(&p, None, &levels).unwrap();
        check_closed_or_boundary(&flat(&lod.triangles), |_, _| false);
    }
    assert!(names.len() >= 10, "{names:?}");
}

#[test]
fn gap_filling_puts_fine_vertices_on_coarse_chords() {
    let mut rng = Lcg(1);
    let mut m = grid(2, 1, |_, _| 0.0);
    for p in &mut m.positions {
        p.z = rng.next();
    }
    m.corners.extend([0, 2, 3, 5]);
    let n = 4;
    let r = Refinement::new(&m, n).unwrap();
    let p = r.positions(&m.positions).unwrap();
    let nb = r.base_face_count();
    for la in 0..=n as u8 {
        for lb in 0..=n as u8 {
            let levels: Vec<u8> = (0..nb).map(|k| if k % 2 == 0 { la } else { lb }).collect();
            let lod = lod::extract(&r, &p, None, &levels, Default::default()).unwrap();
            check_closed_or_boundary(&flat(&lod.triangles), |a, b| {
                // open edges only on the grid's outer boundary
                let (pa, pb) = (lod.positions[a as usize], lod.positions[b as usize]);
                (pa.x - pb.x).abs() < 1e-12 && (pa.x.abs() < 1e-12 || (pa.x - 2.0).abs() < 1e-12)
                    || (pa.y - pb.y).abs() < 1e-12
                        && (pa.y.abs() < 1e-12 || (pa.y - 1.0).abs() < 1e-12)
            });
            // the fine side's vertices on the shared base edge 0-4 sit on the coarse chords
            let e = r
                .level(0)
                .edges()
                .iter()
                .position(|&[a, b]| (a, b) == (0, 4) || (a, b) == (4, 0))
                .unwrap();
            let (lc, lf) = (la.min(lb) as usize, la.max(lb) as usize);
            let span = 1usize << n;
            let ln = r.level(n);
            let xj = |j: usize| {
                if j == span {
                    ln.edges()[e * span + span - 1][1]
                } else {
                    ln.edges()[e * span + j][0]
                }
            };
            let s = 1usize << (n as usize - lc);
            let step = 1usize << (n as usize - lf);
            for j in (0..=span).step_by(step) {
                let j0 = j / s * s;
                let want = if j % s == 0 {
                    p[xj(j) as usize]
                } else {
                    let t = (j - j0) as f64 / s as f64;
                    p[xj(j0) as usize] * (1.0 - t) + p[xj(j0 + s) as usize] * t
                };
                assert!(
                    lod.positions.iter().any(|&q| close(q, want, 1e-12)),
                    "levels {la} {lb} j {j}"
                );
                if j % s != 0 && !close(want, p[xj(j) as usize], 1e-9) {
                    assert!(!lod
                        .positions
                        .iter()
                        .any(|&q| close(q, p[xj(j) as usize], 1e-12)));
                }
            }
            // every output vertex on an interior base edge lies on the segment of the coarser
            // side: equivalently, the output surface has no cracks: the conforming check above
            // plus: all triangles of the stitched side are non-degenerate
            for t in &lod.triangles {
                let [a, b, c] = t.map(|i| lod.positions[i as usize]);
                assert!((b - a).cross(c - a).length() > 1e-12, "levels {la} {lb}");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// API, errors

#[test]
fn subdivide_keeps_groups_sharp_edges_corners() {
    let m = mixed_mesh();
    let (out, normals) = subdivide(
        &m,
        2,
        &SubdivOptions {
            limit: true,
            ..Default::default()
        },
    )
    .unwrap();
    out.validate().unwrap();
    assert_eq!(out.face_count(), m.face_count() * 16);
    assert_eq!(out.sharp_edges.len(), m.sharp_edges.len() * 4);
    assert_eq!(out.corners, m.corners);
    assert_eq!(normals.unwrap().len(), out.vertex_count());
    // re-subdividing the output once more equals level 3 of the input (sharp flags kept)
    // for the non-limit positions
    let (o2, _) = subdivide(&m, 2, &SubdivOptions::default()).unwrap();
    let (o3, _) = subdivide(&o2, 1, &SubdivOptions::default()).unwrap();
    let r = Refinement::new(&m, 3).unwrap();
    let p3 = r.positions(&m.positions).unwrap();
    // same vertex numbering is not expected (different level-0 edge order), compare sets
    let mut a: Vec<[i64; 3]> = o3
        .positions
        .iter()
        .map(|q| (*q * 1e9).round().as_i64vec3().to_array())
        .collect();
    let mut b: Vec<[i64; 3]> = p3
        .iter()
        .map(|q| (*q * 1e9).round().as_i64vec3().to_array())
        .collect();
    a.sort();
    b.sort();
    assert_eq!(a.len(), b.len());
    let diff = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert!(diff <= a.len() / 1000, "{diff} of {} differ", a.len());
}

#[test]
fn rejects_bad_meshes() {
    // non-manifold edge
    let mut m = tetrahedron();
    m.push_vertex(v3(0., 0., 5.));
    m.push_face(&[0, 1, 4], 0);
    assert!(matches!(Refinement::new(&m, 1), Err(Error::Mesh(_))));
    // inconsistent orientation
    let mut m = tetrahedron();
    let fv = &mut m.face_vertices;
    fv.swap(0, 1);
    assert!(matches!(Refinement::new(&m, 1), Err(Error::Mesh(_))));
    // unknown sharp edge (vertex 4 is isolated)
    let mut m = tetrahedron();
    m.push_vertex(v3(0., 0., 5.));
    m.set_sharp(0, 4);
    assert!(matches!(Refinement::new(&m, 1), Err(Error::Mesh(_))));
    // face cap
    let m = tetrahedron();
    assert!(matches!(
        Refinement::with_max_faces(&m, 3, 100),
        Err(Error::LimitsExceeded { .. })
    ));
    assert!(matches!(Refinement::new(&m, 40), Err(Error::Parameter(_))));
    // zero axis
    let (mut m, _, _) = belt_mesh(6, false, true);
    m.groups[1].patch = PatchKind::Boundary(BoundarySurface::Cylinder {
        axis: Axis {
            origin: DVec3::ZERO,
            direction: DVec3::ZERO,
        },
    });
    assert!(matches!(Refinement::new(&m, 1), Err(Error::Mesh(_))));
    // wrong control count
    let m = tetrahedron();
    let r = Refinement::new(&m, 1).unwrap();
    assert!(r.positions(&m.positions[..3]).is_err());
    // non-manifold vertex (two tetrahedra sharing a vertex) is rejected
    let mut m = tetrahedron();
    let off = m.vertex_count() as u32;
    for p in [v3(3., 3., 3.), v3(3., 1., 1.), v3(1., 3., 1.)] {
        m.push_vertex(p);
    }
    for f in [
        [0, off, off + 1],
        [0, off + 2, off],
        [0, off + 1, off + 2],
        [off, off + 2, off + 1],
    ] {
        m.push_face(&f, 0);
    }
    assert!(matches!(Refinement::new(&m, 1), Err(Error::Mesh(_))));
}

#[test]
fn polygons_are_fan_triangulated() {
    let (m, _, _) = belt_mesh(6, false, true);
    let r = Refinement::new(&m, 1).unwrap();
    // 6 quads -> 12 triangles, two hexagons -> 4 each
    assert_eq!(r.base_face_count(), 20);
    assert_eq!(r.level(0).triangle(0), [0, 1, 7]);
    assert_eq!(r.level(0).triangle(1), [0, 7, 6]);
    assert_eq!(r.base_control_face(1), 0);
    assert_eq!(r.base_control_face(19), 7);
}

// ---------------------------------------------------------------------------------------
// Properties on random meshes

mod properties {
    use super::*;
    use proptest::prelude::*;

    /// A random grid mesh with random heights, sharp edges and corner tags.
    fn random_mesh(
        seed: u64,
        nx: usize,
        ny: usize,
        sharp_pct: u32,
        corner_pct: u32,
    ) -> ControlMesh {
        let mut rng = Lcg(seed);
        let mut m = grid(nx, ny, |_, _| 0.0);
        for p in &mut m.positions {
            p.x += 0.3 * (rng.next() - 0.5);
            p.y += 0.3 * (rng.next() - 0.5);
            p.z = rng.next();
        }
        let edges: Vec<(u32, u32)> = m
            .faces()
            .flat_map(|f| (0..3).map(move |i| crate::mesh::edge_key(f[i], f[(i + 1) % 3])))
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        for (a, b) in edges {
            if rng.next() * 100.0 < sharp_pct as f64 {
                m.set_sharp(a, b);
            }
        }
        for v in 0..m.vertex_count() as u32 {
            if rng.next() * 100.0 < corner_pct as f64 {
                m.corners.insert(v);
            }
        }
        m
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        #[test]
        fn limit_invariance_affinity_and_stencils(
            seed in 0u64..1_000_000,
            nx in 2usize..6,
            ny in 2usize..6,
            sharp_pct in 0u32..40,
            corner_pct in 0u32..15,
        ) {
            let m = random_mesh(seed, nx, ny, sharp_pct, corner_pct);
            let r = Refinement::new(&m, 3).unwrap();
            // limit points do not depend on the level they are computed from
            let lim0 = r.limit_positions(&m.positions, 0).unwrap();
            let p3 = r.positions(&m.positions).unwrap();
            let lim3 = r.limit_positions(&p3, 3).unwrap();
            for v in 0..lim0.len() {
                prop_assert!(close(lim0[v], lim3[v], 1e-11), "v{}: {:?} {:?}", v, lim0[v], lim3[v]);
            }
            // affine invariance: refining moved control points = moving refined points
            let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.3, 1.2, -0.4) * 1.7;
            let shift = v3(3.0, -1.0, 0.5);
            let moved: Vec<DVec3> = m.positions.iter().map(|&q| rot * q + shift).collect();
            let pm = r.positions(&moved).unwrap();
            for (a, b) in pm.iter().zip(&p3) {
                prop_assert!(close(*a, rot * *b + shift, 1e-11));
            }
            // stencils are the same linear map, with affine rows
            let st = r.stencils(3, false).unwrap();
            prop_assert!(st.exact.iter().all(|&e| e));
            for (a, b) in st.apply(&m.positions).iter().zip(&p3) {
                prop_assert!(close(*a, *b, 1e-11));
            }
            for i in 0..st.row_count() {
                let (_, w) = st.row(i);
                prop_assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                prop_assert!(w.iter().all(|&x| x >= 0.0));
            }
            // every refined level is a valid, consistently oriented surface
            for j in 1..=3 {
                check_closed_or_boundary(r.level(j).triangles(), |_, _| true);
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Sparse output of boundary patches (spec §8)

/// A planar convex n-gon as one Plane group (open mesh: its edges are creases).
fn plane_ngon(n: usize) -> ControlMesh {
    let mut m = ControlMesh::new();
    let g = m.push_group("plane", PatchKind::Boundary(BoundarySurface::Plane));
    let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.3, 0.5, -0.2);
    for i in 0..n {
        let th = std::f64::consts::TAU * i as f64 / n as f64;
        m.push_vertex(rot * v3(th.cos() * (1.0 + 0.1 * i as f64), th.sin(), 0.0));
    }
    let poly: Vec<u32> = (0..n as u32).collect();
    m.push_face(&poly, g);
    m
}

/// Vertices used by the triangles of group `g`, and whether each undirected edge of those
/// triangles is used once (border of the group) or twice.
fn group_vertices_and_border(out: &ControlMesh, g: u32) -> (Vec<u32>, BTreeMap<(u32, u32), u32>) {
    let mut verts = Vec::new();
    let mut edges = BTreeMap::new();
    for (f, t) in out.faces().enumerate() {
        if out.face_groups[f] != g {
            continue;
        }
        for k in 0..3 {
            verts.push(t[k]);
            *edges
                .entry(crate::mesh::edge_key(t[k], t[(k + 1) % 3]))
                .or_insert(0) += 1;
        }
    }
    verts.sort_unstable();
    verts.dedup();
    (verts, edges)
}

#[test]
fn plane_patch_has_no_interior_vertices() {
    // n-gon fan: two 2-faces and n-4 1-faces; a triangle is a 3-face.
    for n in [3usize, 4, 6, 9] {
        let m = plane_ngon(n);
        for level in 0..=4u32 {
            let (out, _) = subdivide(&m, level, &SubdivOptions::default()).unwrap();
            out.validate().unwrap();
            let tris = out.face_count();
            let nb = n << level; // boundary vertices after `level` splits
            assert_eq!(out.vertex_count(), nb, "n {n} level {level}");
            // a triangulated disk without interior vertices has V - 2 triangles
            assert_eq!(tris, nb - 2, "n {n} level {level}");
            let (verts, edges) = group_vertices_and_border(&out, 0);
            assert_eq!(verts.len(), nb);
            // every vertex is on the border (used-once edges) of the patch
            let mut on_border = vec![false; out.vertex_count()];
            for (&(a, b), &c) in &edges {
                assert!(c == 1 || c == 2);
                if c == 1 {
                    on_border[a as usize] = true;
                    on_border[b as usize] = true;
                }
            }
            assert!(on_border.iter().all(|&b| b), "n {n} level {level}");
            check_closed_or_boundary(&out.face_vertices, |a, b| edges[&(a.min(b), a.max(b))] == 1);
            // the border is the dense output's border, point for point
            let (dense, _) = subdivide_dense(&m, level);
            assert_eq!(dense.face_count(), (n - 2) << (2 * level));
            let mut a: Vec<[i64; 3]> = out
                .positions
                .iter()
                .map(|q| (*q * 1e12).round().as_i64vec3().to_array())
                .collect();
            let (dv, dedges) = group_vertices_and_border(&dense, 0);
            let mut border_dense: Vec<[i64; 3]> = dv
                .iter()
                .filter(|&&v| {
                    dedges
                        .iter()
                        .any(|(&(x, y), &c)| c == 1 && (x == v || y == v))
                })
                .map(|&v| {
                    (dense.positions[v as usize] * 1e12)
                        .round()
                        .as_i64vec3()
                        .to_array()
                })
                .collect();
            a.sort();
            border_dense.sort();
            assert_eq!(a, border_dense, "n {n} level {level}");
            // triangles are counter-clockwise like the control face (positive area along
            // the face normal)
            let nrm = (m.positions[1] - m.positions[0]).cross(m.positions[2] - m.positions[0]);
            for t in out.faces() {
                let [p0, p1, p2] = [0, 1, 2].map(|k| out.positions[t[k] as usize]);
                assert!((p1 - p0).cross(p2 - p0).dot(nrm) > 0.0);
            }
        }
    }
}

/// A cylinder or cone belt whose two rings have the same control angles (rulings), closed by
/// planar caps, as the fitting encoder emits it: triangle pairs whose diagonals alternate.
fn ruled_belt(n: usize, cone: bool) -> (ControlMesh, DVec3, DVec3) {
    let (mut m, origin, axis) = belt_mesh(n, cone, true);
    let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.4, -0.7, 1.1);
    let (e1, e2) = (rot * DVec3::X, rot * DVec3::Y);
    let (h0, h1) = if cone { (1.0, 2.5) } else { (0.0, 3.0) };
    let radius = |h: f64| if cone { 0.6 * h } else { 2.0 };
    let mut rng = Lcg(8);
    let ths: Vec<f64> = (0..n)
        .map(|i| std::f64::consts::TAU * (i as f64 + 0.35 * (rng.next() - 0.5)) / n as f64)
        .collect();
    for (k, h) in [h0, h1].into_iter().enumerate() {
        for (i, th) in ths.iter().enumerate() {
            let (s, c) = th.sin_cos();
            m.positions[k * n + i] = origin + axis * h + (e1 * c + e2 * s) * radius(h);
        }
    }
    // triangulate the belt quads explicitly, alternating the diagonal
    let belt = 1u32;
    let mut out = ControlMesh::new();
    out.positions = m.positions.clone();
    out.groups = m.groups.clone();
    let b = |i: usize| (i % n) as u32;
    let t = |i: usize| (n + i % n) as u32;
    for i in 0..n {
        if i % 2 == 0 {
            out.push_face(&[b(i), b(i + 1), t(i)], belt);
            out.push_face(&[b(i + 1), t(i + 1), t(i)], belt);
        } else {
            out.push_face(&[b(i), b(i + 1), t(i + 1)], belt);
            out.push_face(&[b(i), t(i + 1), t(i)], belt);
        }
    }
    for f in 0..m.face_count() {
        if m.face_groups[f] != belt {
            out.push_face(m.face(f), m.face_groups[f]);
        }
    }
    out.sharp_edges = m.sharp_edges.clone();
    (out, origin, axis)
}

#[test]
fn belt_output_follows_rulings_and_stays_on_the_surface() {
    for cone in [false, true] {
        let n = 8;
        let (m, origin, axis) = ruled_belt(n, cone);
        for level in 1..=4u32 {
            let (out, _) = subdivide(&m, level, &SubdivOptions::default()).unwrap();
            out.validate().unwrap();
            check_closed_or_boundary(&out.face_vertices, |_, _| false);
            let belt_tris = out.face_groups.iter().filter(|&&g| g == 1).count();
            // each belt quad: a zipper of 2 * 2^level triangles
            assert_eq!(belt_tris, (2 * n) << level, "cone {cone} level {level}");
            let (verts, _) = group_vertices_and_border(&out, 1);
            assert_eq!(verts.len(), (2 * n) << level);
            let h_of = |v: u32| (out.positions[v as usize] - origin).dot(axis);
            let h0 = h_of(0);
            for &v in &verts {
                let err = surface_error(out.positions[v as usize], origin, axis, cone);
                assert!(err < 1e-3, "cone {cone}: {err}");
                assert!(err < 1e-10, "cone {cone}: exact by construction: {err}");
            }
            let radial = |v: u32| {
                let d = out.positions[v as usize] - origin;
                (d - axis * d.dot(axis)).normalize()
            };
            // every belt triangle has one edge along a ring and one along a ruling (same
            // angle about the axis); its third edge is the diagonal of a planar quad
            let mut rulings = std::collections::BTreeSet::new();
            for (f, t) in out.faces().enumerate() {
                if out.face_groups[f] != 1 {
                    continue;
                }
                let (mut ring, mut ruling) = (0, 0);
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    if (h_of(a) - h_of(b)).abs() < 1e-9 {
                        ring += 1;
                    } else if radial(a).dot(radial(b)) > 1.0 - 1e-12 {
                        ruling += 1;
                        rulings.insert(crate::mesh::edge_key(a, b));
                        assert!((h_of(a).min(h_of(b)) - h0).abs() < 1e-9);
                    }
                }
                assert_eq!((ring, ruling), (1, 1), "cone {cone} level {level}: {t:?}");
            }
            assert_eq!(rulings.len(), n << level);
            // sparse and dense output agree on the belt's border
            let (dense, _) = subdivide_dense(&m, level);
            assert!(dense.face_count() > out.face_count());
            check_closed_or_boundary(&dense.face_vertices, |_, _| false);
        }
    }
}

/// Group `g`'s output triangles as corner positions rounded to 1e-9 (a mask sums its
/// points in ring order, so the last bits follow the numbering), each rotated to start at its
/// smallest corner, sorted: equal for equal surfaces whatever the numbering.
fn group_triangle_positions(out: &ControlMesh, g: u32) -> Vec<[[i64; 3]; 3]> {
    let mut tris: Vec<[[i64; 3]; 3]> = out
        .faces()
        .zip(&out.face_groups)
        .filter(|&(_, &fg)| fg == g)
        .map(|(t, _)| {
            let mut c = [0, 1, 2].map(|k| {
                out.positions[t[k] as usize]
                    .to_array()
                    .map(|x| (x * 1e9).round() as i64)
            });
            let first = (0..3).min_by_key(|&k| c[k]).unwrap();
            c.rotate_left(first);
            c
        })
        .collect();
    tris.sort_unstable();
    tris
}

/// [`belt_mesh`]'s closed belt with each quad split into two triangles along a random
/// diagonal, each triangle starting at a random corner: faces that prefer different partners.
fn randomly_split_belt(n: usize, cone: bool) -> ControlMesh {
    let m = belt_mesh(n, cone, true).0;
    let mut out = ControlMesh::new();
    out.positions = m.positions.clone();
    out.groups = m.groups.clone();
    let mut rng = Lcg(17);
    for f in 0..m.face_count() {
        let q = m.face(f);
        if m.face_groups[f] != 1 {
            out.push_face(q, m.face_groups[f]);
            continue;
        }
        let d = usize::from(rng.next() < 0.5);
        for mut t in [
            [q[d], q[d + 1], q[(d + 2) % 4]],
            [q[d], q[(d + 2) % 4], q[(d + 3) % 4]],
        ] {
            t.rotate_left((rng.next() * 3.0) as usize % 3);
            out.push_face(&t, 1);
        }
    }
    out.sharp_edges = m.sharp_edges.clone();
    out
}

/// The belt quads a cylinder or cone group is output with do not depend on the numbering of
/// its faces (the decoder sees the file's order, the encoder measured its own): a closed
/// belt pairs completely and keeps the same quad sides (its rulings, when it has them) in
/// every order.
#[test]
fn belt_quads_do_not_depend_on_the_face_order() {
    for cone in [false, true] {
        let n = 8;
        for m in [ruled_belt(n, cone).0, randomly_split_belt(n, cone)] {
            let level = 2;
            let (reference, _) = subdivide(&m, level, &SubdivOptions::default()).unwrap();
            let want = group_triangle_positions(&reference, 1);
            assert_eq!(want.len(), (2 * n) << level, "cone {cone}: sparse belt");
            let count = m.face_count();
            let mut rng = Lcg(31);
            for trial in 0..40 {
                let mut order: Vec<usize> = (0..count).collect();
                if trial == 0 {
                    order.rotate_left(1);
                } else if trial == 1 {
                    order.reverse();
                } else {
                    for i in (1..count).rev() {
                        order.swap(i, (rng.next() * (i + 1) as f64) as usize % (i + 1));
                    }
                }
                let permuted = test_support::with_face_order(&m, &order);
                let (out, _) = subdivide(&permuted, level, &SubdivOptions::default()).unwrap();
                assert_eq!(
                    group_triangle_positions(&out, 1),
                    want,
                    "cone {cone}, order {order:?}"
                );
            }
            // Vertices renumbered and corners rotated too.
            let renumbered = test_support::renumbered(&m);
            let (out, _) = subdivide(&renumbered, level, &SubdivOptions::default()).unwrap();
            assert_eq!(
                group_triangle_positions(&out, 1),
                want,
                "cone {cone}, renumbered"
            );
        }
    }
}

/// Boundary patches next to closed patches, with and without sharp edges between them:
/// uniform levels 1-4 and random mixed LOD are watertight, plane triangles use only points
/// on their control triangle's edges.
#[test]
fn sparse_patches_with_closed_neighbours_are_watertight() {
    let mut rng = Lcg(23);
    for sharp in [true, false] {
        // the tetrahedron split 1-to-4 linearly: the 4 children of face 0 are one planar
        // Plane patch, the rest one closed patch
        let t = tetrahedron();
        let r1 = Refinement::new(&t, 1).unwrap();
        let mut m = ControlMesh::new();
        m.positions = t.positions.clone();
        for &[a, b] in r1.level(0).edges() {
            m.positions
                .push((t.positions[a as usize] + t.positions[b as usize]) * 0.5);
        }
        let closed = m.push_group("closed", PatchKind::Closed);
        let plane = m.push_group("plane", PatchKind::Boundary(BoundarySurface::Plane));
        for f in 0..r1.level(1).face_count() {
            m.push_face(&r1.level(1).triangle(f), if f < 4 { plane } else { closed });
        }
        if sharp {
            m.sharpen_group_boundaries();
            m.corners.extend([0, 1, 2]);
        }
        for level in 1..=4u32 {
            let (out, _) = subdivide(&m, level, &SubdivOptions::default()).unwrap();
            check_closed_or_boundary(&out.face_vertices, |_, _| false);
            let (dense, _) = subdivide_dense(&m, level);
            // 4 plane triangles: the centre one is a 0-face (1 triangle), the corner ones
            // 2-faces (2^(m+1) - 1)
            let plane_tris = out.face_groups.iter().filter(|&&g| g == plane).count();
            assert_eq!(plane_tris, 1 + 3 * ((2 << level) - 1), "level {level}");
            assert_eq!(
                out.face_count() - plane_tris,
                dense.face_count() - (4 << (2 * level))
            );
            // plane vertices lie on the edges of the big control triangle
            let (verts, _) = group_vertices_and_border(&out, plane);
            let corners: Vec<DVec3> = [0u32, 1, 2].map(|v| m.positions[v as usize]).to_vec();
            for &v in &verts {
                let p = out.positions[v as usize];
                let on_edge = (0..3).any(|s| {
                    let (a, b) = (corners[s], corners[(s + 1) % 3]);
                    let d = (b - a).normalize();
                    let w = p - a;
                    (w - d * w.dot(d)).length() < 1e-9
                });
                assert!(on_edge, "level {level}: plane vertex {v} inside the face");
            }
        }
        let r = Refinement::new(&m, 3).unwrap();
        let p = r.positions(&m.positions).unwrap();
        for _ in 0..20 {
            let levels: Vec<u8> = (0..r.base_face_count())
                .map(|_| (rng.next() * 4.0) as u8)
                .collect();
            for mode in [BoundaryPatchOutput::Sparse, BoundaryPatchOutput::Dense] {
                let lod = r.extract_lod_with(&p, None, &levels, mode).unwrap();
                check_closed_or_boundary(&flat(&lod.triangles), |_, _| false);
            }
        }
    }
}

#[test]
fn belt_lod_is_watertight() {
    let mut rng = Lcg(31);
    for cone in [false, true] {
        let (m, _, _) = ruled_belt(8, cone);
        let r = Refinement::new(&m, 4).unwrap();
        let p = r.positions(&m.positions).unwrap();
        for _ in 0..30 {
            let levels: Vec<u8> = (0..r.base_face_count())
                .map(|_| (rng.next() * 5.0) as u8)
                .collect();
            let lod = r.extract_lod(&p, None, &levels).unwrap();
            check_closed_or_boundary(&flat(&lod.triangles), |_, _| false);
            lod.to_control_mesh(&m.groups).validate().unwrap();
        }
    }
}

/// A cone whose faces are an apex fan (1-faces sharing vertices, so no belt quads) is
/// output densely; its planar cap sparsely; together watertight.
#[test]
fn unpaired_cone_group_is_dense_and_watertight() {
    let n = 7;
    let (m, cone, cap, _, _) = cone_with_cap(0.0);
    for level in 1..=4u32 {
        let (out, _) = subdivide(&m, level, &SubdivOptions::default()).unwrap();
        check_closed_or_boundary(&out.face_vertices, |_, _| false);
        let count = |g: u32| out.face_groups.iter().filter(|&&x| x == g).count();
        assert_eq!(count(cone), n << (2 * level));
        assert_eq!(count(cap), (n << level) - 2);
    }
}

// ---------------------------------------------------------------------------------------
// The finest level read through the level before

/// Meshes with creases, darts, corners, mesh boundaries and cylinder/cone frames.
fn connectivity_meshes() -> Vec<ControlMesh> {
    let mut meshes = vec![tetrahedron(), mixed_mesh()];
    meshes.push(belt_mesh(6, false, true).0);
    meshes.push(belt_mesh(5, true, false).0);
    meshes.push(cone_with_cap(0.2).0);
    meshes.push(ruled_belt(6, true).0);
    meshes.push(plane_ngon(7));
    meshes.extend(load_corpus("tess/four_cone_coarse.obj"));
    meshes
}

/// Every query [`next_level::NextLevel`] answers equals the built level's arrays.
#[test]
fn next_level_answers_as_the_built_level() {
    use next_level::{Connectivity, NextLevel};
    for m in connectivity_meshes() {
        let r = Refinement::new(&m, 3).unwrap();
        for j in 0..3u32 {
            let next = NextLevel {
                l: r.level_with_rings(j as usize),
                base: &r.base,
                j,
            };
            let built = r.level_with_rings(j as usize + 1);
            assert_eq!(next.vertex_count(), built.nv);
            for v in 0..built.nv {
                assert_eq!(next.vertex_class(v), built.vertex_class(v), "class of {v}");
                assert_eq!(next.vertex_frame(v), built.vertex_frame(v), "frame of {v}");
                let ring: Vec<u32> = next.ring_edges(v).collect();
                assert_eq!(ring, built.ring(v), "ring of {v}");
                assert_eq!(next.ring_edges(v).len(), ring.len());
            }
            for e in 0..built.ne() {
                assert_eq!(next.edge_class(e), built.edge_class(e), "class of edge {e}");
                assert_eq!(next.edge_frame(e), built.edge_frame(e), "frame of edge {e}");
                assert_eq!(next.edge_ends(e), built.edges[e]);
                let faces = next.edge_faces(e);
                assert_eq!(faces, built.edge_faces[e]);
                for f in faces.into_iter().filter(|&f| f != topology::NONE) {
                    assert_eq!(
                        next.opposite_vertex(f, e as u32),
                        built.opposite(f, e as u32)
                    );
                }
            }
        }
    }
}

/// Limit positions of the finest level are the same bits whether its connectivity is built
/// or read through the level before.
#[test]
fn finest_limit_positions_without_the_finest_level() {
    for m in connectivity_meshes() {
        let r = Refinement::new(&m, 3).unwrap();
        let p = r.positions(&m.positions).unwrap();
        let through_level_2 = r.limit_positions(&p, 3).unwrap();
        assert!(r.finest.get().is_none(), "the finest level was built");
        let _ = r.level(3).edge_count();
        let built = r.limit_positions(&p, 3).unwrap();
        let bits = |q: &[DVec3]| -> Vec<[u64; 3]> {
            q.iter().map(|x| x.to_array().map(f64::to_bits)).collect()
        };
        assert_eq!(bits(&through_level_2), bits(&built));
    }
}

/// A [`UniformSurface`] hands out, group by group, the triangles [`subdivide`] outputs, with
/// the same corner positions bit for bit.
#[test]
fn uniform_surface_groups_are_the_subdivided_output() {
    let bits = |p: DVec3| p.to_array().map(f64::to_bits);
    for m in connectivity_meshes() {
        for level in 0..=3u32 {
            let opts = SubdivOptions {
                limit: true,
                normals: false,
                ..Default::default()
            };
            let (out, _) = subdivide(&m, level, &opts).unwrap();
            let surface = UniformSurface::new(&m, level, DEFAULT_MAX_FACES).unwrap();
            let n_groups = out.face_groups.iter().map(|&g| g as usize + 1).max();
            assert_eq!(surface.group_count(), n_groups.unwrap_or(0));
            let mut tris = Vec::new();
            for g in 0..surface.group_count() {
                let expected: Vec<[u64; 3]> = (0..out.face_count())
                    .filter(|&f| out.face_groups[f] as usize == g)
                    .flat_map(|f| out.face(f).to_vec())
                    .map(|v| bits(out.positions[v as usize]))
                    .collect();
                surface.group_triangles(g, &mut tris);
                let got: Vec<[u64; 3]> = tris
                    .iter()
                    .flatten()
                    .map(|&v| bits(surface.positions()[v as usize]))
                    .collect();
                assert_eq!(got, expected, "level {level} group {g}");
            }
        }
    }
}
