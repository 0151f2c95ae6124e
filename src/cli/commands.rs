//! One function per subcommand: read inputs, call the library, print what happened.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use scode::codec::{self, Content, EncodeOptions, Limits};
use scode::io::{self, ReadReport};
use scode::subdiv::{self, SubdivOptions};
use scode::ControlMesh;

use super::{DecodeArgs, EncodeArgs, InfoArgs, SubdivideArgs};

fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| scode::Error::io(path, e).into())
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).map_err(|e| scode::Error::io(path, e).into())
}

fn is_scode(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("scode"))
}

fn print_read_report(path: &Path, report: &ReadReport) {
    println!(
        "read {}: {} vertices, {} faces ({:?})",
        path.display(),
        report.input_vertices,
        report.input_faces,
        report.format
    );
    if report.welded_vertices > 0 {
        println!(
            "  welded {} exact duplicate vertices (shared between groups)",
            report.welded_vertices
        );
    }
    for note in &report.repairs {
        println!("  repair: {note}");
    }
}

/// Reads a mesh file or decodes a .scode file into a control mesh.
fn load_control_mesh(path: &Path) -> Result<(ControlMesh, Option<Content>)> {
    if is_scode(path) {
        let bytes = read_file(path)?;
        let decoded = codec::decode(&bytes, &Limits::default())
            .with_context(|| format!("cannot decode {}", path.display()))?;
        Ok((decoded.mesh, Some(decoded.header.content)))
    } else {
        let (mesh, report) = io::read_mesh(path)?;
        print_read_report(path, &report);
        Ok((mesh, None))
    }
}

pub fn encode(args: &EncodeArgs) -> Result<()> {
    let output = args.output.path()?;
    if !args.raw {
        bail!(
            "the fitting encoder is not available in this build yet; use --raw to store {} \
             as the control mesh itself",
            args.input.display()
        );
    }
    let t0 = Instant::now();
    let (mesh, report) = io::read_mesh(&args.input)?;
    let t_read = t0.elapsed();
    print_read_report(&args.input, &report);
    let opts = EncodeOptions {
        quantization_bits: args.bits,
        content: Content::RawMesh,
        store_group_names: !args.no_names,
    };
    let t1 = Instant::now();
    let bytes = codec::encode(&mesh, &opts)
        .with_context(|| format!("cannot encode {}", args.input.display()))?;
    let t_encode = t1.elapsed();
    write_file(output, &bytes)?;
    let nv = mesh.vertex_count().max(1);
    println!(
        "wrote {}: {} bytes ({:.2} bits per vertex, {} vertices, {} faces, {} groups)",
        output.display(),
        bytes.len(),
        bytes.len() as f64 * 8.0 / nv as f64,
        mesh.vertex_count(),
        mesh.face_count(),
        mesh.groups.len()
    );
    if args.verbose {
        println!(
            "timings: read {:.1} ms, encode {:.1} ms",
            t_read.as_secs_f64() * 1e3,
            t_encode.as_secs_f64() * 1e3
        );
    }
    Ok(())
}

pub fn decode(args: &DecodeArgs) -> Result<()> {
    let output = args.output.path()?;
    let bytes = read_file(&args.input)?;
    let mut limits = Limits::default();
    if let Some(max) = args.max_bytes {
        limits.max_input_bytes = max;
    }
    let t0 = Instant::now();
    let decoded = codec::decode(&bytes, &limits)
        .with_context(|| format!("cannot decode {}", args.input.display()))?;
    let t_decode = t0.elapsed();
    let level = match (decoded.header.content, args.level) {
        (_, Some(level)) => level,
        (Content::RawMesh, None) => 0,
        (Content::ControlMesh { default_level }, None) => u32::from(default_level),
    };
    let t1 = Instant::now();
    let (mesh, normals) = if level == 0 && !args.limit {
        (decoded.mesh, None)
    } else {
        let opts = SubdivOptions {
            limit: args.limit,
            ..Default::default()
        };
        subdiv::subdivide(&decoded.mesh, level, &opts)
            .with_context(|| format!("cannot subdivide {}", args.input.display()))?
    };
    let t_subdiv = t1.elapsed();
    io::write_mesh(output, &mesh, normals.as_deref())?;
    println!(
        "wrote {}: {} vertices, {} faces (level {level}; decode {:.1} ms, subdivide {:.1} ms)",
        output.display(),
        mesh.vertex_count(),
        mesh.face_count(),
        t_decode.as_secs_f64() * 1e3,
        t_subdiv.as_secs_f64() * 1e3
    );
    Ok(())
}

pub fn subdivide(args: &SubdivideArgs) -> Result<()> {
    let output = args.output.path()?;
    let (control, _) = load_control_mesh(&args.input)?;
    let opts = SubdivOptions {
        limit: args.limit,
        ..Default::default()
    };
    let t0 = Instant::now();
    let (mesh, normals) = subdiv::subdivide(&control, args.level, &opts)
        .with_context(|| format!("cannot subdivide {}", args.input.display()))?;
    let elapsed = t0.elapsed();
    io::write_mesh(output, &mesh, normals.as_deref())?;
    println!(
        "wrote {}: {} vertices, {} triangles (level {}, {:.1} ms)",
        output.display(),
        mesh.vertex_count(),
        mesh.face_count(),
        args.level,
        elapsed.as_secs_f64() * 1e3
    );
    Ok(())
}

pub fn info(args: &InfoArgs) -> Result<()> {
    if !is_scode(&args.file) {
        let (mesh, report) = io::read_mesh(&args.file)?;
        print_read_report(&args.file, &report);
        print_mesh_summary(&mesh, args.groups);
        return Ok(());
    }
    let bytes = read_file(&args.file)?;
    let info = codec::inspect(&bytes, &Limits::default())
        .with_context(|| format!("cannot read {}", args.file.display()))?;
    let h = &info.header;
    println!("{}: .scode v{}.{}", args.file.display(), h.version_major, h.version_minor);
    match h.content {
        Content::RawMesh => println!("  content: raw mesh (decodes to the stored mesh)"),
        Content::ControlMesh { default_level } => {
            println!("  content: control mesh (default decode level {default_level})")
        }
    }
    println!(
        "  {} vertices, {} faces, {} groups, {} sharp edges, {} corners",
        h.vertex_count,
        h.face_count,
        h.group_count,
        info.sharp_edge_count,
        info.corner_count
    );
    println!(
        "  quantisation: {} bits, bounding box min ({:.6}, {:.6}, {:.6}), extent {:.6}",
        h.quantization_bits, h.bbox_min[0], h.bbox_min[1], h.bbox_min[2], h.bbox_extent
    );
    let nv = (h.vertex_count as f64).max(1.0);
    println!("  {:<14} {:>10} {:>10} {:>12}", "section", "bytes", "raw bytes", "bits/vertex");
    for s in &info.sections {
        println!(
            "  {:<14} {:>10} {:>10} {:>12.3}",
            s.name,
            s.stored_bytes,
            s.raw_bytes,
            s.stored_bytes as f64 * 8.0 / nv
        );
    }
    println!(
        "  {:<14} {:>10} {:>10} {:>12.3}",
        "total",
        info.total_bytes,
        "",
        info.total_bytes as f64 * 8.0 / nv
    );
    if args.groups {
        for (i, name) in info.group_names.iter().enumerate() {
            println!("  group {i}: {name}");
        }
    }
    Ok(())
}

fn print_mesh_summary(mesh: &ControlMesh, list_groups: bool) {
    let mut degrees = std::collections::BTreeMap::new();
    for f in mesh.faces() {
        *degrees.entry(f.len()).or_insert(0usize) += 1;
    }
    let degrees: Vec<String> = degrees.iter().map(|(d, n)| format!("{n} of degree {d}")).collect();
    println!(
        "  {} vertices, {} faces ({}), {} groups, {} sharp edges, {} corners",
        mesh.vertex_count(),
        mesh.face_count(),
        degrees.join(", "),
        mesh.groups.len(),
        mesh.sharp_edges.len(),
        mesh.corners.len()
    );
    if let Some((lo, hi)) = mesh.bounding_box() {
        println!(
            "  bounding box ({:.6}, {:.6}, {:.6}) .. ({:.6}, {:.6}, {:.6}), diagonal {:.6}",
            lo.x,
            lo.y,
            lo.z,
            hi.x,
            hi.y,
            hi.z,
            (hi - lo).length()
        );
    }
    if list_groups {
        let mut counts = vec![0usize; mesh.groups.len()];
        for &g in &mesh.face_groups {
            counts[g as usize] += 1;
        }
        for (i, g) in mesh.groups.iter().enumerate() {
            println!("  group {i} {:?}: {} faces, {:?}", g.name, counts[i], g.patch);
        }
    }
}
