//! Encodes a small grouped mesh and decodes it through the documented API alone.

fn main() -> scode::Result<()> {
    let mesh = scode::Mesh {
        positions: vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
        triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        groups: vec![0, 1, 2, 3],
        group_names: ["bottom", "front", "side", "slope"]
            .map(String::from)
            .to_vec(),
        sharp_edges: Vec::new(),
    };
    let options = scode::EncodeOptions {
        tolerance: scode::Tolerance::Relative(1e-3),
        ..Default::default()
    };
    let encoded = scode::encode(scode::Input::Mesh(&mesh), &options)?;
    let info = scode::inspect(&encoded.bytes)?;
    let surface = scode::decode(&encoded.bytes, &scode::DecodeOptions::default())?;
    println!(
        "{} bytes, {} groups; decoded {} triangles at level {}",
        encoded.bytes.len(),
        info.groups,
        surface.mesh.triangles.len(),
        surface.level
    );
    assert_eq!(surface.mesh.group_names, mesh.group_names);
    Ok(())
}
