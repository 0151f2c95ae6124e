//! Round-trip, robustness and property tests of the whole bitstream.

use super::*;
use crate::mesh::Axis;
use proptest::prelude::*;

use super::samples::*;

mod hostile;

fn cyclic_eq(a: &[u32], b: &[u32]) -> bool {
    a.len() == b.len() && (0..a.len()).any(|r| (0..a.len()).all(|i| a[(i + r) % a.len()] == b[i]))
}

/// Encodes, decodes and checks everything the round-trip guarantee promises.
pub(crate) fn check_round_trip(m: &ControlMesh, opts: &EncodeOptions) -> Vec<u8> {
    let (bytes, map) = encode_with_map(m, opts).unwrap();
    let d = decode(&bytes, &Limits::default()).unwrap();
    let out = &d.mesh;
    assert_eq!(out.vertex_count(), m.vertex_count());
    assert_eq!(out.face_count(), m.face_count());
    assert_eq!(out.groups.len(), m.groups.len());
    for f in 0..m.face_count() {
        let nf = map.face[f] as usize;
        let expected: Vec<u32> = m.face(f).iter().map(|&v| map.vertex[v as usize]).collect();
        assert!(
            cyclic_eq(&expected, out.face(nf)),
            "face {f}: {expected:?} vs {:?}",
            out.face(nf)
        );
        assert_eq!(out.face_groups[nf], map.group[m.face_groups[f] as usize]);
    }
    let step = d.header.quantization_step();
    for (g, grp) in m.groups.iter().enumerate() {
        let og = &out.groups[map.group[g] as usize];
        if opts.store_group_names {
            assert_eq!(og.name, grp.name);
        }
        match (grp.patch, og.patch) {
            (PatchKind::Closed, PatchKind::Closed) => {}
            (
                PatchKind::Boundary(BoundarySurface::Plane),
                PatchKind::Boundary(BoundarySurface::Plane),
            ) => {}
            (
                PatchKind::Boundary(BoundarySurface::Cylinder { axis: a }),
                PatchKind::Boundary(BoundarySurface::Cylinder { axis: b }),
            ) => {
                // The decoder's origin is another point of the same line (§9): within
                // rounding plus the direction's quantisation times the distance moved.
                let ad = a.direction.normalize();
                let off = b.origin - a.origin;
                let dist = (off - ad * off.dot(ad)).length();
                assert!(dist <= step + 3e-5 * off.length() + 1e-9, "{dist} {step}");
                assert!((ad - b.direction).length() < 1e-4);
            }
            (
                PatchKind::Boundary(BoundarySurface::Cone { axis: a }),
                PatchKind::Boundary(BoundarySurface::Cone { axis: b }),
            ) => {
                assert!((a.origin - b.origin).abs().max_element() <= step / 2.0 + 1e-9);
                assert!((a.direction.normalize() - b.direction).length() < 1e-4);
            }
            (x, y) => panic!("patch kind changed: {x:?} -> {y:?}"),
        }
    }
    let sharp: BTreeSet<(u32, u32)> = m
        .sharp_edges
        .iter()
        .map(|&(a, b)| edge_key(map.vertex[a as usize], map.vertex[b as usize]))
        .collect();
    assert_eq!(sharp, out.sharp_edges);
    let corners: BTreeSet<u32> = m.corners.iter().map(|&c| map.vertex[c as usize]).collect();
    assert_eq!(corners, out.corners);
    for (v, p) in m.positions.iter().enumerate() {
        let e = (out.positions[map.vertex[v] as usize] - *p)
            .abs()
            .max_element();
        assert!(
            e <= step / 2.0 * (1.0 + 1e-9) + 1e-12,
            "vertex {v} off by {e}, step {step}"
        );
    }
    // Determinism.
    assert_eq!(encode(m, opts).unwrap(), bytes);
    // Decoding is idempotent: re-encoding the decoded mesh reproduces it exactly.
    let again = decode(&encode(out, opts).unwrap(), &Limits::default()).unwrap();
    assert_eq!(again.mesh.face_count(), out.face_count());
    bytes
}

fn opts() -> EncodeOptions {
    EncodeOptions::default()
}

#[test]
fn small_meshes_round_trip() {
    for m in [
        tetrahedron(),
        cube(),
        open_box(),
        torus(4, 3),
        torus(9, 7),
        multi_group(),
        cad_part(),
    ] {
        let b = check_round_trip(&m, &opts());
        let c = check_round_trip(
            &m,
            &EncodeOptions {
                quantization_bits: 16,
                content: Content::ControlMesh { default_level: 3 },
                store_group_names: false,
                ..opts()
            },
        );
        assert!(c.len() > b.len() / 2);
    }
}

/// `EncodeOptions::grid_covers`: the grid covers the given box as well as the positions (so
/// two meshes encoded with one box share one grid), positions round-trip within half a step,
/// and a box that is not finite or not ordered is refused.
#[test]
fn a_given_box_is_covered_by_the_grid() {
    let m = torus(9, 7);
    let (lo, hi) = m.bounding_box().unwrap();
    let corners = [lo - DVec3::splat(3.0), hi + DVec3::new(1.0, 2.0, 5.0)];
    let covering = EncodeOptions {
        grid_covers: Some(corners),
        ..opts()
    };
    let bytes = check_round_trip(&m, &covering);
    let h = decode(&bytes, &Limits::default()).unwrap().header;
    for (i, &min) in h.bbox_min.iter().enumerate() {
        assert!(min <= corners[0][i], "{h:?}");
        assert!(min + h.bbox_extent >= corners[1][i], "{h:?}");
    }
    // A second mesh inside the box gets the same grid.
    let mut moved = m.clone();
    moved.positions[0] += DVec3::splat(0.5);
    let bytes2 = encode(&moved, &covering).unwrap();
    let h2 = decode(&bytes2, &Limits::default()).unwrap().header;
    assert_eq!((h.bbox_min, h.bbox_extent), (h2.bbox_min, h2.bbox_extent));
    for bad in [
        [DVec3::ONE, DVec3::ZERO],
        [DVec3::ZERO, DVec3::splat(f64::INFINITY)],
        [DVec3::splat(f64::NAN), DVec3::ONE],
    ] {
        let e = encode(
            &m,
            &EncodeOptions {
                grid_covers: Some(bad),
                ..opts()
            },
        );
        assert!(matches!(e, Err(Error::Parameter(_))), "{bad:?}: {e:?}");
    }
}

/// A step scale coarsens the grid without changing the bit count: every position is within
/// half the (scaled) step, the file is smaller, and a scale below 1 is refused.
#[test]
fn a_scaled_step_round_trips_and_shrinks_the_file() {
    let m = torus(9, 7);
    let plain = check_round_trip(&m, &opts());
    let scaled_opts = EncodeOptions {
        step_scale: std::f64::consts::SQRT_2,
        ..opts()
    };
    let scaled = check_round_trip(&m, &scaled_opts);
    assert!(
        scaled.len() < plain.len(),
        "{} vs {}",
        scaled.len(),
        plain.len()
    );
    let h = decode(&scaled, &Limits::default()).unwrap().header;
    let h0 = decode(&plain, &Limits::default()).unwrap().header;
    assert_eq!(h.quantization_bits, h0.quantization_bits);
    let ratio = h.quantization_step() / h0.quantization_step();
    assert!(
        (ratio - std::f64::consts::SQRT_2).abs() < 1e-3,
        "step ratio {ratio}"
    );
    for bad in [0.5, f64::NAN, f64::INFINITY] {
        let e = encode(
            &m,
            &EncodeOptions {
                step_scale: bad,
                ..opts()
            },
        );
        assert!(matches!(e, Err(Error::Parameter(_))), "{bad}: {e:?}");
    }
}

#[test]
fn sizes_of_small_meshes_are_small() {
    // Fixed overhead check: a tetrahedron must stay tiny.
    let b = encode(&tetrahedron(), &opts()).unwrap();
    assert!(b.len() <= 76, "tetrahedron takes {} bytes", b.len());
    let info = inspect(&b, &Limits::default()).unwrap();
    assert_eq!(info.total_bytes, b.len());
    assert_eq!(
        info.sections.iter().map(|s| s.stored_bytes).sum::<usize>(),
        b.len()
    );
    assert_eq!(info.label_count, 7);
    assert_eq!(info.component_count, 1);
}

#[test]
fn content_and_header_fields() {
    let m = multi_group();
    let b = encode(
        &m,
        &EncodeOptions {
            quantization_bits: 12,
            content: Content::ControlMesh { default_level: 4 },
            store_group_names: true,
            ..opts()
        },
    )
    .unwrap();
    let info = inspect(&b, &Limits::default()).unwrap();
    assert_eq!(
        info.header.content,
        Content::ControlMesh { default_level: 4 }
    );
    assert_eq!(info.header.quantization_bits, 12);
    assert_eq!(info.header.vertex_count, m.vertex_count() as u64);
    assert_eq!(info.header.face_count, m.face_count() as u64);
    assert_eq!(info.sharp_edge_count, 6);
    assert_eq!(info.corner_count, 4);
    let mut names = info.group_names.clone();
    names.sort();
    assert_eq!(names, vec!["rest", "side", "top"]);
    assert!(info.sections.iter().any(|s| s.name == "patches"));
}

#[test]
fn isolated_vertices_and_empty_mesh() {
    let mut m = cube();
    m.push_vertex(DVec3::new(5.0, 5.0, 5.0));
    m.push_vertex(DVec3::new(-1.0, 2.0, 0.5));
    m.corners.insert(9);
    check_round_trip(&m, &opts());
    let empty = ControlMesh::new();
    let b = encode(&empty, &opts()).unwrap();
    let d = decode(&b, &Limits::default()).unwrap();
    assert_eq!(d.mesh.face_count(), 0);
    assert_eq!(d.mesh.vertex_count(), 0);
    let mut points = ControlMesh::new();
    points.push_vertex(DVec3::ONE);
    points.push_vertex(DVec3::ONE);
    check_round_trip(&points, &opts());
}

#[test]
fn non_manifold_raw_meshes_are_cut_and_restored() {
    // Three triangles on one edge, and a bow-tie vertex.
    let pos = [
        [0., 0., 0.],
        [1., 0., 0.],
        [0.5, 1., 0.],
        [0.5, -1., 0.],
        [0.5, 0., 1.],
        [2., 1., 0.],
        [2., -1., 0.],
    ];
    let mut m = from_faces(
        &pos,
        &[vec![0, 1, 2], vec![1, 0, 3], vec![0, 1, 4], vec![1, 5, 6]],
    );
    m.set_sharp(0, 1);
    m.corners.insert(1);
    let b = check_round_trip(&m, &opts());
    let info = inspect(&b, &Limits::default()).unwrap();
    assert!(info.header.merged_vertex_count > 0);
    // The same mesh as a control mesh is refused.
    let e = encode(
        &m,
        &EncodeOptions {
            content: Content::ControlMesh { default_level: 2 },
            ..opts()
        },
    )
    .unwrap_err();
    assert!(matches!(e, Error::Mesh(_)), "{e}");
    assert!(e.to_string().contains("non-manifold"), "{e}");
}

#[test]
fn encoder_rejects_bad_input() {
    let m = cube();
    assert!(matches!(
        encode(
            &m,
            &EncodeOptions {
                quantization_bits: 3,
                ..opts()
            }
        ),
        Err(Error::Parameter(_))
    ));
    assert!(matches!(
        encode(
            &m,
            &EncodeOptions {
                quantization_bits: 25,
                ..opts()
            }
        ),
        Err(Error::Parameter(_))
    ));
    let mut bad = cube();
    bad.set_sharp(0, 7); // not an edge
    assert!(matches!(encode(&bad, &opts()), Err(Error::Mesh(_))));
    let mut bad = cube();
    bad.positions[0].x = f64::INFINITY;
    assert!(matches!(encode(&bad, &opts()), Err(Error::Mesh(_))));
}

/// Finite coordinates whose box overflows (near f64::MAX, or any beyond about 1e154, where
/// the diagonal overflows) are refused as a parameter error naming the two vertices, for a
/// raw and a control-mesh encode, instead of a file whose grid the decoder refuses; so is a
/// finite mesh whose given grid box overflows. Coordinates just below stay encodable.
#[test]
fn coordinates_whose_box_overflows_are_refused() {
    for (lo, hi) in [(-1.7e308, 1.7e308), (-1.0, 1.7e308), (-1e155, 1e155)] {
        let mut m = cube();
        m.positions[2].y = lo;
        m.positions[5].y = hi;
        for content in [Content::RawMesh, Content::ControlMesh { default_level: 2 }] {
            let e = encode(&m, &EncodeOptions { content, ..opts() }).unwrap_err();
            let Error::Parameter(msg) = &e else {
                panic!("{lo} .. {hi}: {e:?}")
            };
            assert!(msg.contains("coordinates too large"), "{msg}");
            assert!(
                msg.contains("vertex 2") && msg.contains("vertex 5"),
                "{msg}"
            );
        }
    }
    let e = encode(
        &cube(),
        &EncodeOptions {
            grid_covers: Some([DVec3::splat(-1.7e308), DVec3::splat(1.7e308)]),
            ..opts()
        },
    )
    .unwrap_err();
    assert!(
        matches!(&e, Error::Parameter(m) if m.contains("grid's box overflows")),
        "{e:?}"
    );
    let mut big = cube();
    big.positions[2].y = -1e150;
    big.positions[5].y = 1e150;
    let bytes = encode(&big, &opts()).unwrap();
    let d = decode(&bytes, &Limits::default()).unwrap();
    assert_eq!(d.mesh.vertex_count(), big.vertex_count());
}

#[test]
fn decoder_rejects_versions_trailing_bytes_and_limits() {
    let b = encode(&cube(), &opts()).unwrap();
    let mut v5 = b.clone();
    v5[4] = 5;
    let e = decode(&v5, &Limits::default()).unwrap_err().to_string();
    assert!(e.contains("major version 5"), "{e}");
    let mut trailing = b.clone();
    trailing.push(0);
    assert!(decode(&trailing, &Limits::default()).is_err());
    let mut bad_magic = b.clone();
    bad_magic[0] = b'X';
    assert!(decode(&bad_magic, &Limits::default()).is_err());
    let small = Limits {
        max_vertices: 7,
        ..Limits::default()
    };
    assert!(matches!(
        decode(&b, &small),
        Err(Error::LimitsExceeded { .. })
    ));
    let small = Limits {
        max_input_bytes: 10,
        ..Limits::default()
    };
    assert!(matches!(
        decode(&b, &small),
        Err(Error::LimitsExceeded { .. })
    ));
}

/// Every prefix errors; every single-bit flip errors (CRC on) or at least never panics
/// (CRC off). Shared with the spec-vector test.
pub(crate) fn check_corruptions(b: &[u8]) {
    for n in 0..b.len() {
        assert!(
            decode(&b[..n], &Limits::default()).is_err(),
            "prefix {n} decoded"
        );
    }
    let original = decode(b, &Limits::default()).unwrap();
    let lax = Limits {
        verify_checksums: false,
        ..Limits::default()
    };
    for i in 0..b.len() * 8 {
        let mut c = b.to_vec();
        c[i / 8] ^= 1 << (i % 8);
        assert!(
            decode(&c, &Limits::default()).is_err(),
            "bit flip {i} not detected"
        );
        if let Ok(d) = decode(&c, &lax) {
            // Without CRCs a flip may decode; it must then still be a valid mesh.
            d.mesh.validate().unwrap();
            let _ = d == original;
        }
    }
}

#[test]
fn corruptions_are_detected() {
    for m in [tetrahedron(), multi_group()] {
        let b = encode(&m, &opts()).unwrap();
        check_corruptions(&b);
    }
}

// ------------------------------------------------------------------------------------------
// Property tests: random small polygon meshes.

/// Parameters of a random mesh: components of quad grids (torus, cylinder or sheet), some
/// quads split into triangles or merged into hexagons, some faces deleted (holes, possibly
/// non-manifold vertices), random groups, sharp edges and corners.
#[derive(Clone, Debug)]
struct RandomMesh {
    comps: Vec<(u8, u32, u32)>,
    bits: Vec<u8>,
    qbits: u8,
}

fn random_mesh_strategy() -> impl Strategy<Value = RandomMesh> {
    (
        prop::collection::vec((0u8..3, 3u32..7, 3u32..7), 1..4),
        prop::collection::vec(any::<u8>(), 64..256),
        4u8..=24,
    )
        .prop_map(|(comps, bits, qbits)| RandomMesh { comps, bits, qbits })
}

fn make_random_mesh(r: &RandomMesh) -> ControlMesh {
    let mut m = ControlMesh::new();
    let mut bi = 0usize;
    let mut next = |n: u8| -> u8 {
        let b =
            r.bits[bi % r.bits.len()].wrapping_add(((bi / r.bits.len()) as u8).wrapping_mul(37));
        bi += 1;
        b % n
    };
    let ngroups = 1 + next(8) as u32;
    for g in 0..ngroups {
        let patch = match next(4) {
            0 => PatchKind::Closed,
            1 => PatchKind::Boundary(BoundarySurface::Plane),
            // Parallel axes, every other one on the same line.
            2 => PatchKind::Boundary(BoundarySurface::Cylinder {
                axis: Axis {
                    origin: DVec3::new(f64::from(g / 2), 1.0, f64::from(g)),
                    direction: DVec3::new(0.0, 0.0, if g % 3 == 0 { -1.0 } else { 1.0 }),
                },
            }),
            _ => PatchKind::Boundary(BoundarySurface::Cone {
                axis: Axis {
                    origin: DVec3::new(0.1, 0.2, g as f64),
                    direction: DVec3::new(1.0, 2.0, 3.0),
                },
            }),
        };
        m.push_group(format!("g{g}"), patch);
    }
    for (ci, &(kind, n, k)) in r.comps.iter().enumerate() {
        let base = m.vertex_count() as u32;
        let (wrap_i, wrap_j) = match kind {
            0 => (true, true),
            1 => (true, false),
            _ => (false, false),
        };
        let ni = if wrap_i { n } else { n + 1 };
        let nj = if wrap_j { k } else { k + 1 };
        for i in 0..ni {
            for j in 0..nj {
                let jitter = f64::from(next(200)) / 1000.0;
                m.push_vertex(DVec3::new(
                    i as f64 + 10.0 * ci as f64,
                    j as f64 + jitter,
                    (i * j) as f64 * 0.1 - jitter,
                ));
            }
        }
        let id = |i: u32, j: u32| base + (i % ni) * nj + (j % nj);
        let mut pending: Option<[u32; 4]> = None;
        for i in 0..n {
            for j in 0..k {
                let q = [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)];
                let g = u32::from(next(ngroups as u8));
                match next(8) {
                    0 => {} // hole
                    1 | 2 => {
                        m.push_face(&[q[0], q[1], q[2]], g);
                        m.push_face(&[q[0], q[2], q[3]], g);
                    }
                    3 if j + 1 < k && pending.is_none() => pending = Some(q),
                    _ => {
                        if let Some(p) = pending.take() {
                            if p[3] == q[0] && p[2] == q[1] {
                                // Merge the two quads into a hexagon.
                                m.push_face(&[p[0], p[1], p[2], q[2], q[3], p[3]], g);
                                continue;
                            }
                            m.push_face(&p, g);
                        }
                        m.push_face(&q, g);
                    }
                }
            }
            if let Some(p) = pending.take() {
                m.push_face(&p, 0);
            }
        }
    }
    // Drop unused grid vertices? No: they are isolated vertices, which must round-trip too.
    let edges: Vec<(u32, u32)> = {
        let mut e = BTreeSet::new();
        for f in m.faces() {
            for i in 0..f.len() {
                e.insert(edge_key(f[i], f[(i + 1) % f.len()]));
            }
        }
        e.into_iter().collect()
    };
    for e in edges {
        if next(5) == 0 {
            m.sharp_edges.insert(e);
        }
    }
    for v in 0..m.vertex_count() as u32 {
        if next(6) == 0 {
            m.corners.insert(v);
        }
    }
    m
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn random_meshes_round_trip(r in random_mesh_strategy()) {
        let m = make_random_mesh(&r);
        m.validate().unwrap();
        check_round_trip(&m, &EncodeOptions { quantization_bits: r.qbits, ..opts() });
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        let _ = decode(&bytes, &Limits { verify_checksums: false, ..Limits::default() });
        let mut framed = MAGIC.to_vec();
        framed.extend_from_slice(&[1, 0]);
        framed.extend_from_slice(&bytes);
        let _ = decode(&framed, &Limits { verify_checksums: false, ..Limits::default() });
    }
}

#[test]
fn inspect_accounts_for_group_bits() {
    let single = inspect(&encode(&cube(), &opts()).unwrap(), &Limits::default()).unwrap();
    assert_eq!(single.group_bits, 0.0, "one group costs nothing");
    let part = cad_part();
    assert!(part.groups.len() > 1);
    let bytes = encode(&part, &opts()).unwrap();
    let info = inspect(&bytes, &Limits::default()).unwrap();
    let conn = info
        .sections
        .iter()
        .find(|s| s.name == "connectivity")
        .unwrap();
    assert!(info.group_bits > 0.0);
    // The group symbols are part of the connectivity section's range-coded stream.
    assert!(info.group_bits / 8.0 < conn.stored_bytes as f64, "{info:?}");
}
