//! Decoding with a longest edge (`scode decode --max-edge H`, `DecodeOptions::max_edge`): on
//! corpus models, one of them read from STEP, the output has no edge longer than H, is as
//! watertight as the decode without it, covers the same surface, and keeps every group,
//! sharp edge and corner.

mod common;
use common::corpus_dir;

use std::collections::{BTreeMap, BTreeSet};

use glam::DVec3;
use scode::codec::Limits;
use scode::pipeline::{
    decode_surface, encode_fitted, sidecar_hints, DecodedSurface, ModelEncodeOptions,
    SurfaceOptions,
};
use scode::ControlMesh;

/// Edges used by one face, and edges used by more than two.
fn open_and_overused_edges(mesh: &ControlMesh) -> (usize, usize) {
    let mut count = BTreeMap::new();
    for f in mesh.faces() {
        for k in 0..f.len() {
            *count
                .entry(scode::mesh::edge_key(f[k], f[(k + 1) % f.len()]))
                .or_insert(0) += 1;
        }
    }
    (
        count.values().filter(|&&c| c == 1).count(),
        count.values().filter(|&&c| c > 2).count(),
    )
}

fn area(mesh: &ControlMesh) -> f64 {
    let p = |v: u32| mesh.positions[v as usize];
    mesh.faces()
        .flat_map(|f| (1..f.len() - 1).map(move |k| [f[0], f[k], f[k + 1]]))
        .map(|[a, b, c]| 0.5 * (p(b) - p(a)).cross(p(c) - p(a)).length())
        .sum()
}

/// The longest edge and the smallest angle (degrees) of the triangles of `mesh`.
fn longest_edge_and_smallest_angle(mesh: &ControlMesh) -> (f64, f64) {
    let (mut longest, mut smallest) = (0.0f64, 180.0f64);
    for f in mesh.faces() {
        assert_eq!(f.len(), 3, "a split surface is made of triangles");
        let q = [0, 1, 2].map(|k| mesh.positions[f[k] as usize]);
        for k in 0..3 {
            let (a, b, c) = (q[k], q[(k + 1) % 3], q[(k + 2) % 3]);
            longest = longest.max(a.distance(b));
            smallest = smallest.min((b - a).angle_between(c - a).to_degrees());
        }
    }
    (longest, smallest)
}

/// Whether sharp edges of `split` run from `a` to `b` along the segment between them.
fn sharp_chain(split: &ControlMesh, next: &BTreeMap<u32, Vec<u32>>, a: u32, b: u32) -> bool {
    let (pa, pb) = (split.positions[a as usize], split.positions[b as usize]);
    let on_segment = |p: DVec3| {
        let t = ((p - pa).dot(pb - pa) / pa.distance_squared(pb)).clamp(0.0, 1.0);
        p.distance(pa + t * (pb - pa)) <= 1e-9 * pa.distance(pb)
    };
    let mut at = a;
    let mut steps = 0;
    while at != b && steps <= split.vertex_count() {
        let here = split.positions[at as usize].distance(pb);
        let Some(&step) = next.get(&at).and_then(|n| {
            n.iter().find(|&&v| {
                let p = split.positions[v as usize];
                on_segment(p) && p.distance(pb) < here
            })
        }) else {
            return false;
        };
        at = step;
        steps += 1;
    }
    at == b
}

/// Decodes `bytes` as `scode decode` does by default, and with a longest edge of 1/40 of
/// the diagonal, and checks the split surface against the unsplit one.
fn check_max_edge(name: &str, bytes: &[u8]) {
    let limits = Limits::default();
    let decode = |max_edge| -> DecodedSurface {
        let opts = SurfaceOptions {
            max_edge,
            ..Default::default()
        };
        decode_surface(bytes, &limits, &opts).unwrap()
    };
    let whole = decode(None);
    let h = whole.mesh.diagonal() / 40.0;
    let split = decode(Some(h));
    let (mesh, out) = (&whole.mesh, &split.mesh);
    let (longest, smallest) = longest_edge_and_smallest_angle(out);
    println!(
        "{name}: {} triangles, with --max-edge {h:.4e} {} (longest edge {longest:.4e}, \
         smallest angle {smallest:.1} degrees)",
        mesh.face_count(),
        out.face_count()
    );
    assert!(longest <= h, "{name}: edge of {longest:.4e} over {h:.4e}");
    assert!(
        out.face_count() > mesh.face_count(),
        "{name}: nothing split"
    );
    // Watertight where the decode is: no edge opened, none shared by three faces.
    let (open, overused) = open_and_overused_edges(out);
    assert_eq!(overused, 0, "{name}: edges with more than two faces");
    assert_eq!(open, open_and_overused_edges(mesh).0, "{name}: open edges");
    // The same surface: new vertices lie on the edges they split.
    let (a, b) = (area(mesh), area(out));
    assert!((a - b).abs() <= 1e-9 * a, "{name}: area {a} became {b}");
    // Groups: the same ones have faces. Corners: the same vertices, unmoved.
    let used = |m: &ControlMesh| m.face_groups.iter().copied().collect::<BTreeSet<u32>>();
    assert_eq!(used(out), used(mesh), "{name}: groups");
    assert_eq!(out.groups, mesh.groups, "{name}: group names and patches");
    assert_eq!(out.corners, mesh.corners, "{name}: corners");
    for &c in &mesh.corners {
        assert_eq!(out.positions[c as usize], mesh.positions[c as usize]);
    }
    // Every sharp edge runs on as a chain of sharp edges between the same two vertices.
    assert!(
        !mesh.sharp_edges.is_empty(),
        "{name}: no sharp edges to keep"
    );
    let mut next: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for &(a, b) in &out.sharp_edges {
        next.entry(a).or_default().push(b);
        next.entry(b).or_default().push(a);
    }
    for &(a, b) in &mesh.sharp_edges {
        assert!(
            sharp_chain(out, &next, a, b),
            "{name}: sharp edge ({a}, {b}) not kept"
        );
    }
    if let (Some(n), Some(m)) = (&split.normals, &whole.normals) {
        assert_eq!(n.len(), out.vertex_count());
        assert_eq!(n[..m.len()], m[..]);
    }
}

#[test]
fn corpus_models_split_to_a_longest_edge() {
    let Some(dir) = corpus_dir() else { return };
    for name in [
        "four_cone_fine",
        "bug3883_xr2-ct-214_plate_fine",
        "block_fillet3_fine",
    ] {
        let path = dir.join(format!("tess/{name}.obj"));
        let (input, _) = scode::io::read_mesh(&path).unwrap();
        let hints = sidecar_hints(&path, &input)
            .unwrap()
            .map(|(_, h)| h)
            .unwrap_or_default();
        let (bytes, _) = encode_fitted(&input, &hints, &ModelEncodeOptions::default()).unwrap();
        check_max_edge(name, &bytes);
    }
    let step = std::fs::read(dir.join("step/screw.step")).unwrap();
    let encoded =
        scode::encode(scode::Input::Step(&step), &scode::EncodeOptions::default()).unwrap();
    check_max_edge("screw.step", &encoded.bytes);
}

#[test]
fn the_api_splits_to_the_longest_edge_and_refuses_a_non_length() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus/boss_plate.obj");
    let (input, _) = scode::io::read_mesh(&path).unwrap();
    let (bytes, _) = encode_fitted(&input, &[], &ModelEncodeOptions::default()).unwrap();
    let h = input.diagonal() / 20.0;
    let surface = scode::decode(&bytes, &scode::DecodeOptions::default().max_edge(h)).unwrap();
    let p = |v: u32| DVec3::from(surface.mesh.positions[v as usize]);
    for t in &surface.mesh.triangles {
        for k in 0..3 {
            assert!(p(t[k]).distance(p(t[(k + 1) % 3])) <= h);
        }
    }
    assert_eq!(surface.mesh.group_names.len(), input.groups.len());
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let err = scode::decode(&bytes, &scode::DecodeOptions::default().max_edge(bad));
        assert!(
            matches!(err, Err(scode::Error::Parameter(_))),
            "{bad}: {err:?}"
        );
    }
    // A size that would take more triangles than the limits allow is refused, not tried.
    let opts = scode::DecodeOptions {
        limits: Limits {
            max_subdivided_faces: 10_000,
            ..Limits::default()
        },
        ..scode::DecodeOptions::default().max_edge(input.diagonal() * 1e-4)
    };
    let err = scode::decode(&bytes, &opts);
    assert!(
        matches!(err, Err(scode::Error::LimitsExceeded { .. })),
        "{err:?}"
    );
}
