//! Decoding a `.scode` file to a surface: a uniform subdivision level or the coarsest levels
//! within a tolerance of the limit surface. Decoder side only (`codec`, `subdiv`), so a
//! decoder-only build has it; [`crate::pipeline`] re-exports it for the encoder's users.

use crate::codec::{self, Content, Limits};
use crate::error::{Error, Result};
use crate::mesh::{ControlMesh, Tolerance};

/// A `.scode` file decoded to a surface (see [`SurfaceOptions`]).
#[derive(Clone, Debug)]
pub struct DecodedSurface {
    /// Raw-mode files: the stored mesh; control-mesh files: the subdivided surface.
    pub mesh: ControlMesh,
    /// Limit normals, when the surface was projected to the limit.
    pub normals: Option<Vec<glam::DVec3>>,
    /// Subdivision level applied: the uniform level, or with `accuracy` the finest level a
    /// base triangle is shown at (0 for raw-mode files unless asked otherwise).
    pub level: u32,
    /// Whether positions are limit positions.
    pub limit: bool,
    #[cfg(feature = "internals")]
    pub content: Content,
    /// How a surface decoded to a tolerance came out (`None` for a uniform level and for
    /// raw-mode files, which are the stored surface itself).
    pub accuracy: Option<AccuracyReport>,
}

/// What decoding to a tolerance delivered.
#[derive(Clone, Debug, PartialEq)]
pub struct AccuracyReport {
    /// The tolerance in model units.
    pub tolerance: f64,
    /// The largest estimated distance between the output and the limit surface (see
    /// [`crate::subdiv::subdivide_to_tolerance`]); above `tolerance` only where a base
    /// triangle would need a level beyond `max_level`.
    pub bound: f64,
    /// The finest level a base triangle could be shown at.
    pub max_level: u32,
    /// Base triangles (control faces fan-triangulated) shown at each level `0..=max_level`.
    pub triangles_per_level: Vec<usize>,
    /// Bytes charged against the memory budget at the end (its peak): what the decode held
    /// and what the subdivision charged for its measurement and its output.
    pub memory: u64,
}

/// How much detail a control mesh is decoded to.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Detail {
    /// Every base triangle at the coarsest level within the tolerance the file was encoded
    /// for of the limit surface.
    #[default]
    FileTolerance,
    /// Every base triangle at the coarsest level within this distance of the limit surface
    /// (a relative tolerance is a fraction of the surface's bounding-box diagonal).
    Tolerance(Tolerance),
    /// One uniform level for the whole surface.
    Level(u32),
    /// The file's default level, uniform: the surface the encoder measured against its
    /// input, so what `scode info --against` and `scode report` measure.
    DefaultLevel,
}

/// How to turn a decoded `.scode` file into a surface. A raw-mode file stays as stored
/// (level 0, no limit) unless [`Detail::Level`] asks for a level; a control mesh is decoded
/// to the file's tolerance by default (`detail`) and always to limit positions unless
/// `limit` is `Some(false)`, which needs a uniform level.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfaceOptions {
    pub detail: Detail,
    pub limit: Option<bool>,
    /// How boundary patches are triangulated (sparse, as S-CODE, by default).
    pub boundary_patches: crate::subdiv::BoundaryPatchOutput,
    /// The longest edge allowed, in model units: longer edges of the decoded surface are
    /// split at their midpoints, conforming across faces (see
    /// [`crate::subdiv::split_to_max_edge`]). For solvers that need an element size.
    pub max_edge: Option<f64>,
    /// The smallest angle (degrees, at most 30) of the triangles inside plane patches, with
    /// `max_edge`: planes are triangulated anew by constrained Delaunay refinement inside
    /// their outlines (`crate::subdiv::refine_planes`, feature `remesh`); curved
    /// patches keep the triangles `max_edge` gives.
    pub min_angle: Option<f64>,
}

/// The encoder's default tolerance, relative to the model's diagonal: without a tolerance of
/// its own, a decode to an accuracy uses it (capped by the file's grid, [`file_tolerance`]).
pub const DEFAULT_RELATIVE_TOLERANCE: f64 = 1e-3;

/// How many quantisation steps the tolerance of a fitted file is at most. The encoder picks
/// the fewest bits whose Euclidean quantisation error `sqrt(3)/2 step` is at most a quarter
/// of the tolerance `t` (`pipeline::bits_for_tolerance`): the bit count rounds up, so the nominal
/// step over the model's extent `E` exceeds `t / (4 sqrt(3))`, and the grid's box is at
/// least the input's box widened by 1/32 of its extent on each side, so `step > (17/16) t /
/// (4 sqrt(3))`, i.e. `t < 6.53 step`; fitting may then coarsen the grid, which only makes
/// the step larger. A file whose grid the encoder chose this way was encoded for a
/// tolerance below this many steps.
pub const TOLERANCE_STEPS: f64 = 6.6;

/// The tolerance a decode to an accuracy uses by default: the file does not store the
/// tolerance it was encoded for, so it is [`DEFAULT_RELATIVE_TOLERANCE`] of the decoded
/// surface's diagonal (the encoder's default, relative to the input's diagonal, which the
/// surface matches), but never more than [`TOLERANCE_STEPS`] quantisation steps, a bound
/// the grid gives on the tolerance of a file encoded for a tighter one. Returns the relative
/// tolerance and the cap in model units.
pub fn file_tolerance(header: &codec::Header) -> (Tolerance, f64) {
    let cap = TOLERANCE_STEPS * header.quantization_step();
    let cap = if cap > 0.0 && cap.is_finite() {
        cap
    } else {
        f64::INFINITY
    };
    (Tolerance::Relative(DEFAULT_RELATIVE_TOLERANCE), cap)
}

/// Decodes `bytes` and builds the surface asked for (see [`SurfaceOptions`]). One
/// implementation for `scode decode`, `scode info --against` and `scode report`, so they all
/// measure the surfaces they name.
pub fn decode_surface(
    bytes: &[u8],
    limits: &Limits,
    opts: &SurfaceOptions,
) -> Result<DecodedSurface> {
    let Some(max_edge) = opts.max_edge else {
        if opts.min_angle.is_some() {
            return Err(Error::Parameter(
                "a smallest angle needs a longest edge (max_edge) to size the triangles".into(),
            ));
        }
        return decode_detail(bytes, limits, opts);
    };
    if !(max_edge > 0.0 && max_edge.is_finite()) {
        return Err(Error::Parameter(format!(
            "the longest edge must be a positive length, got {max_edge}"
        )));
    }
    if let Some(a) = opts.min_angle {
        if !(a > 0.0 && a <= 30.0) {
            return Err(Error::Parameter(format!(
                "the smallest angle must be in (0, 30] degrees, got {a}"
            )));
        }
        if cfg!(not(feature = "remesh")) {
            return Err(Error::Parameter(
                "a smallest angle needs the library's `remesh` feature".into(),
            ));
        }
    }
    let mut surface = decode_detail(bytes, limits, opts)?;
    let (mesh, normals) = crate::subdiv::split_to_max_edge(
        &surface.mesh,
        surface.normals.as_deref(),
        max_edge,
        limits.max_subdivided_faces,
    )?;
    surface.mesh = mesh;
    surface.normals = normals;
    #[cfg(feature = "remesh")]
    if let Some(min_angle) = opts.min_angle {
        let (mesh, normals, _) = crate::subdiv::refine_planes(
            &surface.mesh,
            surface.normals.as_deref(),
            max_edge,
            min_angle,
            limits.max_subdivided_faces,
        )?;
        // Refinement keeps the outlines, so a triangle spanning a narrow strip between two
        // of them can keep an edge over the length: split those, conforming as before.
        let (mesh, normals) = crate::subdiv::split_to_max_edge(
            &mesh,
            normals.as_deref(),
            max_edge,
            limits.max_subdivided_faces,
        )?;
        surface.mesh = mesh;
        surface.normals = normals;
    }
    Ok(surface)
}

/// [`decode_surface`] up to the detail asked for, before any edge is split.
fn decode_detail(bytes: &[u8], limits: &Limits, opts: &SurfaceOptions) -> Result<DecodedSurface> {
    let (decoded, usage) = codec::decode_with_usage(bytes, limits);
    let decoded = decoded?;
    let content = decoded.header.content;
    let default_level = match content {
        Content::RawMesh => None,
        Content::ControlMesh { default_level } => Some(u32::from(default_level)),
    };
    let level = match (opts.detail, default_level) {
        (Detail::Level(l), _) => l,
        (_, None) => 0,
        (Detail::DefaultLevel, Some(l)) => l,
        (Detail::FileTolerance | Detail::Tolerance(_), Some(l)) => {
            if opts.limit == Some(false) {
                return Err(Error::Parameter(
                    "a decode to a tolerance measures against the limit surface: without limit \
                     positions, ask for a uniform level"
                        .into(),
                ));
            }
            return decode_to_tolerance(decoded, usage.held, l, limits, opts);
        }
    };
    let limit = opts.limit.unwrap_or(default_level.is_some());
    let (mesh, normals) = if level == 0 && !limit {
        (decoded.mesh, None)
    } else {
        // Before subdividing: the finest level's triangles (fan-triangulated faces times
        // 4^level) against the limits, and the memory they take on top of what the decode
        // still holds (the input and the control mesh) against the budget.
        check_subdivision(
            &decoded.mesh,
            level,
            crate::subdiv::MEMORY_PER_TRIANGLE,
            usage.held,
            limits,
        )?;
        let sopts = crate::subdiv::SubdivOptions {
            limit,
            boundary_patches: opts.boundary_patches,
            max_faces: limits.max_subdivided_faces,
            ..Default::default()
        };
        crate::subdiv::subdivide(&decoded.mesh, level, &sopts)?
    };
    Ok(DecodedSurface {
        mesh,
        normals,
        level,
        limit,
        #[cfg(feature = "internals")]
        content,
        accuracy: None,
    })
}

/// A file's surface at its default level (what [`Detail::DefaultLevel`] decodes), in the
/// shape a measurement against a reference reads it: a control mesh's level-n limit surface
/// handed out group by group, so that no array of its tens of millions of triangles exists
/// (`metrics::hausdorff_by_group`); a raw-mode file's stored mesh as it is.
#[cfg(feature = "internals")]
pub enum DefaultSurface {
    /// A raw-mode file's mesh.
    Stored(ControlMesh),
    /// A control mesh's limit surface at its default `level`, sparse boundary patches.
    ByGroup {
        surface: Box<crate::subdiv::UniformSurface>,
        level: u32,
    },
}

/// Bytes a [`DefaultSurface::ByGroup`] takes per finest-level triangle (fan-triangulated
/// control faces times `4^level`), counted as [`check_subdivision`] counts: the level's
/// limit positions (about half a vertex per triangle) and the coarser level's faces, plus
/// the refinement that makes them, which is dropped once they are evaluated.
#[cfg(feature = "internals")]
pub const MEMORY_PER_GROUPED_TRIANGLE: u64 = 80;

/// Decodes `bytes` to its [`DefaultSurface`], its subdivision checked against `limits`
/// before it is made.
#[cfg(feature = "internals")]
pub fn decode_default_surface(bytes: &[u8], limits: &Limits) -> Result<DefaultSurface> {
    let (decoded, usage) = codec::decode_with_usage(bytes, limits);
    let decoded = decoded?;
    let Content::ControlMesh { default_level } = decoded.header.content else {
        return Ok(DefaultSurface::Stored(decoded.mesh));
    };
    let level = u32::from(default_level);
    check_subdivision(
        &decoded.mesh,
        level,
        MEMORY_PER_GROUPED_TRIANGLE,
        usage.held,
        limits,
    )?;
    let surface =
        crate::subdiv::UniformSurface::new(&decoded.mesh, level, limits.max_subdivided_faces)?;
    Ok(DefaultSurface::ByGroup {
        surface: Box::new(surface),
        level,
    })
}

/// `Error::LimitsExceeded` unless `mesh`'s triangles at `level` (fan-triangulated faces
/// times 4^level) fit `max_subdivided_faces` and, at `per_triangle` bytes each, the memory
/// budget on top of the `held` bytes the decode still holds.
fn check_subdivision(
    mesh: &ControlMesh,
    level: u32,
    per_triangle: u64,
    held: u64,
    limits: &Limits,
) -> Result<()> {
    let triangles = (mesh.face_vertices.len() - 2 * mesh.face_count()) as u64;
    let finest = triangles.saturating_mul(
        1u64.checked_shl(level.saturating_mul(2))
            .unwrap_or(u64::MAX),
    );
    let memory = held.saturating_add(finest.saturating_mul(per_triangle));
    for (what, value, limit) in [
        ("subdivided faces", finest, limits.max_subdivided_faces),
        (
            "decode memory with subdivision (bytes)",
            memory,
            limits.max_memory,
        ),
    ] {
        if value > limit {
            return Err(Error::LimitsExceeded { what, value, limit });
        }
    }
    Ok(())
}

/// The decode to a tolerance of a control mesh whose default level is `default_level`.
///
/// The finest level shown is one beyond the file's default level. The encoder chose the
/// default level as the coarsest whose triangles meet the file's tolerance of its input;
/// this decode is measured against the limit surface instead, which those triangles stand
/// off by their chord error, and one level more leaves a quarter of it. A tighter tolerance
/// gets one more level per factor 4 (a triangle's distance from a smooth surface shrinks
/// with its size squared, 4 times per level), estimated against the control mesh's
/// diagonal; the measurement then picks the levels actually shown.
fn decode_to_tolerance(
    decoded: codec::Decoded,
    held: u64,
    default_level: u32,
    limits: &Limits,
    opts: &SurfaceOptions,
) -> Result<DecodedSurface> {
    let (file_relative, cap) = file_tolerance(&decoded.header);
    let tolerance = match opts.detail {
        Detail::Tolerance(t) => t,
        _ => file_relative,
    };
    let diagonal = decoded.mesh.diagonal();
    let file_t = file_relative.resolve(diagonal).min(cap);
    let asked = tolerance.resolve(diagonal);
    // `subdivide_to_tolerance` shows at most level MAX_LEVEL - 1.
    let deepest = crate::subdiv::MAX_LEVEL - 1;
    let mut max_level = crate::subdiv::default_top_level(default_level);
    if asked > 0.0 && asked < file_t {
        let extra = (file_t / asked).log(4.0).ceil();
        max_level = (f64::from(max_level) + extra).min(f64::from(deepest)) as u32;
    }
    // The triangle count first; the memory as the subdivision allocates it (its measurement,
    // then the output of the levels it chooses), on top of what the decode still holds.
    check_subdivision(&decoded.mesh, max_level, 0, held, limits)?;
    let mut live = held;
    let mut charge = |what: &'static str, bytes: u64| {
        live = live.saturating_add(bytes);
        if live > limits.max_memory {
            return Err(Error::LimitsExceeded {
                what,
                value: live,
                limit: limits.max_memory,
            });
        }
        Ok(())
    };
    let aopts = crate::subdiv::AccuracyOptions {
        tolerance,
        max_tolerance: if matches!(opts.detail, Detail::Tolerance(_)) {
            f64::INFINITY
        } else {
            cap
        },
        max_level,
        normals: true,
        max_faces: limits.max_subdivided_faces,
        boundary_patches: opts.boundary_patches,
    };
    let out = crate::subdiv::subdivide_to_tolerance_within(&decoded.mesh, &aopts, &mut charge)?;
    let mut triangles_per_level = vec![0; max_level as usize + 1];
    for &m in &out.levels {
        triangles_per_level[m as usize] += 1;
    }
    Ok(DecodedSurface {
        mesh: out.mesh,
        normals: out.normals,
        level: out.levels.iter().copied().max().unwrap_or(0).into(),
        limit: true,
        #[cfg(feature = "internals")]
        content: decoded.header.content,
        accuracy: Some(AccuracyReport {
            tolerance: out.tolerance,
            bound: out.bound,
            max_level,
            triangles_per_level,
            memory: live,
        }),
    })
}
