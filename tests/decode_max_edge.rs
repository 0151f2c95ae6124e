//! Decoding with a longest edge (`scode decode --max-edge H`, `DecodeOptions::max_edge`),
//! and with a smallest angle in plane patches (`--min-angle`): on corpus models, one of them
//! read from STEP, the output has no edge longer than H, is as watertight as the decode
//! without it, covers the same surface, and keeps every group, sharp edge and corner; with
//! `--min-angle 25` the plane patches' triangles are refined to it except next to outlines
//! that do not allow it.

mod common;
mod decode_support;
use common::corpus_dir;
use decode_support::open_and_overused_edges;

use std::collections::{BTreeMap, BTreeSet};

use glam::DVec3;
use scode::codec::Limits;
use scode::pipeline::{
    decode_surface, encode_fitted, sidecar_hints, DecodedSurface, ModelEncodeOptions,
    SurfaceOptions,
};
use scode::ControlMesh;

/// Per group: the vector area (the sum of the triangles' area vectors, which depends only on
/// the group's outline) and the area.
fn group_areas(mesh: &ControlMesh) -> Vec<(DVec3, f64)> {
    let mut out = vec![(DVec3::ZERO, 0.0); mesh.groups.len()];
    let p = |v: u32| mesh.positions[v as usize];
    for (f, t) in mesh.faces().enumerate() {
        for k in 1..t.len() - 1 {
            let a = 0.5 * (p(t[k]) - p(t[0])).cross(p(t[k + 1]) - p(t[0]));
            let g = &mut out[mesh.face_groups[f] as usize];
            g.0 += a;
            g.1 += a.length();
        }
    }
    out
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

/// Whether every vertex of group `g`'s triangles lies in one plane.
fn planar_groups(mesh: &ControlMesh) -> Vec<bool> {
    let mut normal = vec![DVec3::ZERO; mesh.groups.len()];
    let mut origin = vec![None; mesh.groups.len()];
    for (f, t) in mesh.faces().enumerate() {
        let p = |k: usize| mesh.positions[t[k] as usize];
        let g = mesh.face_groups[f] as usize;
        normal[g] += (p(1) - p(0)).cross(p(2) - p(0));
        origin[g].get_or_insert(p(0));
    }
    let mut planar: Vec<bool> = normal.iter().map(|n| *n != DVec3::ZERO).collect();
    let tolerance = 1e-9 * mesh.diagonal();
    for (f, t) in mesh.faces().enumerate() {
        let g = mesh.face_groups[f] as usize;
        let (n, o) = (normal[g].normalize_or_zero(), origin[g].unwrap_or_default());
        if t.iter()
            .any(|&v| (mesh.positions[v as usize] - o).dot(n).abs() > tolerance)
        {
            planar[g] = false;
        }
    }
    planar
}

/// Of the triangles in plane patches: how many, and how many have an angle under `limit`
/// degrees.
fn plane_triangles_under(mesh: &ControlMesh, limit: f64) -> (usize, usize) {
    let planar = planar_groups(mesh);
    let (mut all, mut under) = (0, 0);
    for (f, t) in mesh.faces().enumerate() {
        if !planar[mesh.face_groups[f] as usize] {
            continue;
        }
        let q = [0, 1, 2].map(|k| mesh.positions[t[k] as usize]);
        let smallest = (0..3)
            .map(|k| {
                let (a, b, c) = (q[k], q[(k + 1) % 3], q[(k + 2) % 3]);
                (b - a).angle_between(c - a).to_degrees()
            })
            .fold(180.0, f64::min);
        all += 1;
        under += usize::from(smallest < limit);
    }
    (all, under)
}

/// Decodes `bytes` as `scode decode` does by default, and with a longest edge of 1/40 of
/// the diagonal (and a smallest angle, if given), and checks the result against the
/// decode without them.
fn check_max_edge(name: &str, bytes: &[u8], min_angle: Option<f64>) {
    let limits = Limits::default();
    let decode = |max_edge, min_angle| -> DecodedSurface {
        let opts = SurfaceOptions {
            max_edge,
            min_angle,
            ..Default::default()
        };
        decode_surface(bytes, &limits, &opts).unwrap()
    };
    let whole = decode(None, None);
    let h = whole.mesh.diagonal() / 40.0;
    let split = decode(Some(h), min_angle);
    let (mesh, out) = (&whole.mesh, &split.mesh);
    let (longest, smallest) = longest_edge_and_smallest_angle(out);
    let (planes, planes_under) = plane_triangles_under(out, 25.0);
    println!(
        "{name}: {} triangles, with --max-edge {h:.4e} --min-angle {min_angle:?}: {} \
         (longest edge {longest:.4e}, smallest angle {smallest:.1} degrees; in planes \
         {planes_under} of {planes} triangles under 25 degrees, before {:?})",
        mesh.face_count(),
        out.face_count(),
        plane_triangles_under(mesh, 25.0),
    );
    assert!(longest <= h, "{name}: edge of {longest:.4e} over {h:.4e}");
    assert!(
        out.face_count() > mesh.face_count(),
        "{name}: nothing split"
    );
    if min_angle.is_some() {
        // Only triangles pinned by the outline (segments meeting at small angles or too
        // close to each other, which refinement may not split) stay under the angle.
        assert!(
            planes_under * 10 <= planes,
            "{name}: {planes_under} of {planes} plane triangles under 25 degrees"
        );
    }
    // Watertight where the decode is: no edge opened, none shared by three faces.
    let (open, overused) = open_and_overused_edges(out);
    assert_eq!(overused, 0, "{name}: edges with more than two faces");
    assert_eq!(open, open_and_overused_edges(mesh).0, "{name}: open edges");
    // The same surface: new vertices lie on the edges they split, and plane patches are
    // triangulated inside their outlines, so each group's vector area stays. (Its area can
    // shrink: a plane refined anew has no folded triangles.)
    for (g, (before, after)) in group_areas(mesh).iter().zip(group_areas(out)).enumerate() {
        assert!(
            before.0.distance(after.0) <= 1e-9 * before.1,
            "{name}: group {g}'s vector area {} became {}",
            before.0,
            after.0
        );
        assert!(after.1 <= before.1 * (1.0 + 1e-9), "{name}: group {g} grew");
    }
    // Groups: the same ones have faces.
    let used = |m: &ControlMesh| m.face_groups.iter().copied().collect::<BTreeSet<u32>>();
    assert_eq!(used(out), used(mesh), "{name}: groups");
    assert_eq!(out.groups, mesh.groups, "{name}: group names and patches");
    // Vertices of the decode that the output has (all but those inside refined planes)
    // keep their positions exactly: find them by position.
    let key = |p: DVec3| p.to_array().map(f64::to_bits);
    let index: BTreeMap<[u64; 3], u32> = out
        .positions
        .iter()
        .enumerate()
        .map(|(i, &p)| (key(p), i as u32))
        .collect();
    let at = |v: u32| index.get(&key(mesh.positions[v as usize])).copied();
    // Corners: the same points, corners still.
    let corners: BTreeSet<u32> = mesh.corners.iter().filter_map(|&c| at(c)).collect();
    assert_eq!(corners.len(), mesh.corners.len(), "{name}: corners lost");
    assert_eq!(corners, out.corners, "{name}: corners");
    // Every sharp edge runs on as a chain of sharp edges between the same two points.
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
        let (Some(oa), Some(ob)) = (at(a), at(b)) else {
            panic!("{name}: an end of sharp edge ({a}, {b}) is gone");
        };
        assert!(
            sharp_chain(out, &next, oa, ob),
            "{name}: sharp edge ({a}, {b}) not kept"
        );
    }
    if let Some(n) = &split.normals {
        assert_eq!(n.len(), out.vertex_count());
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
        check_max_edge(name, &bytes, None);
        check_max_edge(name, &bytes, Some(25.0));
    }
    let step = std::fs::read(dir.join("step/screw.step")).unwrap();
    let encoded =
        scode::encode(scode::Input::Step(&step), &scode::EncodeOptions::default()).unwrap();
    check_max_edge("screw.step", &encoded.bytes, None);
    check_max_edge("screw.step", &encoded.bytes, Some(25.0));
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
