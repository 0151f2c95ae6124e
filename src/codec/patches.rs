//! The `patches` section (`spec/format.md` §9, *Patches*): each group's patch kind and, for
//! cylinders, cones, spheres and tori, the axis (and a torus's major radius). Writer and
//! readers side by side.
//!
//! Version 3 range-codes the section: kinds with the previous kind as context; axis
//! directions by reference into a short move-to-front list (CAD parts repeat a few
//! directions); cylinder origins moved along the axis to the point whose dominant coordinate
//! is 0 on the grid, so only two coordinates are stored, and a "same line" bit for coaxial
//! cylinders. Version 4 adds two kinds to the alphabet, spheres and tori, stored like cones
//! (the whole origin), a torus with its major radius in grid units. Versions 1 and 2 store
//! bytes (kind, three zigzag varints, three i16) and zlib.

use glam::DVec3;

use super::bytes::Reader;
use super::geometry::{GridAxis, Quantizer};
use super::rangecoder::{BitModel, FreqModel, IntModel, RangeDecoder};
use super::unzigzag64;
#[cfg(any(feature = "encoder", feature = "internals"))]
use super::{rangecoder::RangeEncoder, zigzag64};
use crate::error::{Error, Result};
use crate::mesh::topology::NONE;
#[cfg(any(feature = "encoder", feature = "internals"))]
use crate::mesh::Group;
use crate::mesh::{Axis, BoundarySurface, PatchKind};

const PATCH_CLOSED: u8 = 0;
const PATCH_PLANE: u8 = 1;
const PATCH_CYLINDER: u8 = 2;
const PATCH_CONE: u8 = 3;
const PATCH_SPHERE: u8 = 4;
const PATCH_TORUS: u8 = 5;
/// Size of the kind alphabet: version 4 adds spheres and tori to version 3's four kinds.
pub const KINDS: usize = 6;
pub const KINDS_V3: usize = 4;
/// Axis directions are stored as three i16 components scaled by this.
#[cfg(any(feature = "encoder", feature = "internals"))]
const DIRECTION_SCALE: f64 = 32767.0;
/// Length of the move-to-front list of axis directions (version 3).
const RECENT_DIRECTIONS: usize = 8;
/// Largest origin coordinate magnitude, in grid units.
const MAX_ORIGIN: u64 = 1 << 52;
/// Integer-model value that announces a coordinate too large for the model (version 3): the
/// zigzagged value follows as 64 direct bits.
const ESCAPE: u32 = u32::MAX - 1;

/// The section (`None` when every group is closed) and the grid axes the decoder will see.
#[cfg(any(feature = "encoder", feature = "internals"))]
pub type EncodedPatches = (Option<Vec<u8>>, Vec<Option<GridAxis>>);

/// Patch kinds per group, and the grid axes of cylinders and cones (for §8.2's arcs).
pub type DecodedPatches = (Vec<PatchKind>, Vec<Option<GridAxis>>);

#[cfg(any(feature = "encoder", feature = "internals"))]
fn kind_of(patch: &PatchKind) -> (u8, Option<Axis>) {
    match *patch {
        PatchKind::Closed => (PATCH_CLOSED, None),
        PatchKind::Boundary(BoundarySurface::Plane) => (PATCH_PLANE, None),
        PatchKind::Boundary(BoundarySurface::Cylinder { axis }) => (PATCH_CYLINDER, Some(axis)),
        PatchKind::Boundary(BoundarySurface::Cone { axis }) => (PATCH_CONE, Some(axis)),
        PatchKind::Boundary(BoundarySurface::Sphere { axis }) => (PATCH_SPHERE, Some(axis)),
        PatchKind::Boundary(BoundarySurface::Torus { axis, .. }) => (PATCH_TORUS, Some(axis)),
    }
}

/// A torus's major radius in grid units (version 4).
#[cfg(any(feature = "encoder", feature = "internals"))]
fn quantize_major_radius(patch: &PatchKind, quant: &Quantizer, name: &str) -> Result<i64> {
    let PatchKind::Boundary(BoundarySurface::Torus { major_radius, .. }) = *patch else {
        return Ok(0);
    };
    let step = quant.step();
    let q = if step > 0.0 {
        (major_radius / step).round()
    } else {
        0.0
    };
    if !(q.is_finite() && q >= 0.0 && q <= MAX_ORIGIN as f64) {
        return Err(Error::Mesh(format!(
            "group `{name}`: torus major radius {major_radius} cannot be quantised"
        )));
    }
    Ok(q as i64)
}

/// The axis as version 3 stores it: direction as i16 components; the origin in grid units,
/// for a cylinder moved along the (stored) direction to the point whose dominant coordinate
/// (largest |component|, lowest index on ties) is the middle of the grid, `2^(bits-1)`.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn quantize_axis(kind: u8, axis: &Axis, quant: &Quantizer, name: &str) -> Result<GridAxisBits> {
    let d = axis.direction;
    let len = d.length();
    if !len.is_finite() || len == 0.0 {
        return Err(Error::Mesh(format!(
            "group `{name}`: axis direction must be a finite non-zero vector"
        )));
    }
    // Normalised, so the largest component rounds to at least 18918: never all zero.
    let dir = [0, 1, 2].map(|i| (d[i] / len * DIRECTION_SCALE).round() as i16);
    let step = quant.step();
    let mut g = [0, 1, 2].map(|i| {
        if step > 0.0 {
            (axis.origin[i] - quant.min[i]) / step
        } else {
            0.0
        }
    });
    if kind == PATCH_CYLINDER {
        let unit = GridAxis::new([0; 3], dir).dir;
        let k = dominant(dir);
        let mid = grid_middle(quant);
        let t = (mid as f64 - g[k]) / unit[k];
        g = [0, 1, 2].map(|i| {
            if i == k {
                mid as f64
            } else {
                g[i] + t * unit[i]
            }
        });
    }
    let mut origin = [0i64; 3];
    for i in 0..3 {
        let q = g[i].round();
        if !q.is_finite() || q.abs() > MAX_ORIGIN as f64 {
            return Err(Error::Mesh(format!(
                "group `{name}`: axis origin is too far from the mesh to quantise"
            )));
        }
        origin[i] = q as i64;
    }
    Ok(GridAxisBits { origin, dir })
}

/// The implied dominant coordinate of a cylinder origin (version 3).
fn grid_middle(quant: &Quantizer) -> i64 {
    1i64 << (quant.bits - 1)
}

/// An axis exactly as stored: grid origin and i16 direction.
#[derive(Clone, Copy, Debug, PartialEq)]
struct GridAxisBits {
    origin: [i64; 3],
    dir: [i16; 3],
}

/// Index of the largest |component| (lowest index on ties).
fn dominant(d: [i16; 3]) -> usize {
    let a = d.map(|c| i32::from(c).abs());
    if a[0] >= a[1] && a[0] >= a[2] {
        0
    } else if a[1] >= a[2] {
        1
    } else {
        2
    }
}

fn negate(d: [i16; 3]) -> Option<[i16; 3]> {
    Some([
        d[0].checked_neg()?,
        d[1].checked_neg()?,
        d[2].checked_neg()?,
    ])
}

/// Move-to-front list of directions, each with the last cylinder origin coded on it.
#[derive(Default)]
struct RecentDirections(Vec<([i16; 3], Option<[i64; 3]>)>);

impl RecentDirections {
    /// Moves entry `i` to the front.
    fn touch(&mut self, i: usize) {
        let e = self.0.remove(i);
        self.0.insert(0, e);
    }

    fn push(&mut self, d: [i16; 3]) {
        self.0.insert(0, (d, None));
        self.0.truncate(RECENT_DIRECTIONS);
    }
}

/// Adaptive models of the version-3 section.
struct Models {
    kinds: Vec<FreqModel>,
    direction: FreqModel,
    negated: BitModel,
    component: IntModel,
    same_line: BitModel,
    origin: IntModel,
    apex: IntModel,
    major_radius: IntModel,
}

impl Models {
    /// The models of a section whose kind alphabet has `kinds` symbols ([`KINDS`] or
    /// [`KINDS_V3`]).
    fn new(kinds: usize) -> Self {
        Models {
            kinds: vec![FreqModel::new(kinds); kinds + 1],
            direction: FreqModel::new(RECENT_DIRECTIONS + 1),
            negated: BitModel::default(),
            component: IntModel::default(),
            same_line: BitModel::default(),
            origin: IntModel::default(),
            apex: IntModel::default(),
            major_radius: IntModel::default(),
        }
    }
}

#[cfg(any(feature = "encoder", feature = "internals"))]
fn encode_coord(enc: &mut RangeEncoder, model: &mut IntModel, v: i64) {
    let z = zigzag64(v);
    if z < u64::from(ESCAPE) {
        model.encode(enc, z as u32);
    } else {
        model.encode(enc, ESCAPE);
        for shift in [48, 32, 16, 0] {
            enc.encode_direct(((z >> shift) & 0xFFFF) as u32, 16);
        }
    }
}

fn decode_coord(dec: &mut RangeDecoder, model: &mut IntModel, field: &'static str) -> Result<i64> {
    let mut z = u64::from(model.decode(dec, ESCAPE, field)?);
    if z == u64::from(ESCAPE) {
        z = 0;
        for _ in 0..4 {
            z = (z << 16) | u64::from(dec.decode_direct(16)?);
        }
        if z < u64::from(ESCAPE) {
            return Err(Error::format(
                "patches",
                field,
                "escaped value fits the model",
            ));
        }
    }
    let v = unzigzag64(z);
    if v.unsigned_abs() > MAX_ORIGIN {
        return Err(Error::format("patches", field, "out of range"));
    }
    Ok(v)
}

/// Writes the version-4 section (`None` when every group is closed) and returns the grid
/// axes the decoder will see, per group.
#[cfg(any(feature = "encoder", feature = "internals"))]
pub fn encode(groups: &[Group], quant: &Quantizer) -> Result<EncodedPatches> {
    let mut axes = Vec::with_capacity(groups.len());
    if groups.iter().all(|g| g.patch == PatchKind::Closed) {
        return Ok((None, vec![None; groups.len()]));
    }
    let mut enc = RangeEncoder::new();
    let mut m = Models::new(KINDS);
    let mut recent = RecentDirections::default();
    let mut prev_kind = KINDS;
    for g in groups {
        let (kind, axis) = kind_of(&g.patch);
        m.kinds[prev_kind].encode(&mut enc, usize::from(kind));
        prev_kind = usize::from(kind);
        let Some(axis) = axis else {
            axes.push(None);
            continue;
        };
        let a = quantize_axis(kind, &axis, quant, &g.name)?;
        let hit = recent.0.iter().enumerate().find_map(|(i, e)| {
            if e.0 == a.dir {
                Some((i, false))
            } else if negate(e.0) == Some(a.dir) {
                Some((i, true))
            } else {
                None
            }
        });
        let line = match hit {
            Some((i, neg)) => {
                m.direction.encode(&mut enc, i);
                enc.encode_bit(&mut m.negated, neg);
                recent.touch(i);
                recent.0[0].1
            }
            None => {
                m.direction.encode(&mut enc, RECENT_DIRECTIONS);
                for c in a.dir {
                    m.component
                        .encode(&mut enc, super::rangecoder::zigzag(i32::from(c)));
                }
                recent.push(a.dir);
                None
            }
        };
        if kind == PATCH_CYLINDER {
            let k = dominant(a.dir);
            let same = line == Some(a.origin);
            if line.is_some() {
                enc.encode_bit(&mut m.same_line, same);
            }
            if !same {
                for i in (0..3).filter(|&i| i != k) {
                    encode_coord(&mut enc, &mut m.origin, a.origin[i]);
                }
            }
            recent.0[0].1 = Some(a.origin);
        } else {
            for o in a.origin {
                encode_coord(&mut enc, &mut m.apex, o);
            }
        }
        if kind == PATCH_TORUS {
            let r = quantize_major_radius(&g.patch, quant, &g.name)?;
            encode_coord(&mut enc, &mut m.major_radius, r);
        }
        axes.push(Some(GridAxis::new(a.origin, a.dir)));
    }
    Ok((Some(enc.finish()), axes))
}

/// The patch of a stored axis kind; `major_radius` in grid units (tori only).
fn patch_of(kind: u8, a: GridAxisBits, major_radius: i64, quant: &Quantizer) -> PatchKind {
    let axis = Axis {
        origin: DVec3::from([0, 1, 2].map(|i| quant.min[i] + a.origin[i] as f64 * quant.step())),
        direction: DVec3::from(a.dir.map(f64::from)).normalize(),
    };
    PatchKind::Boundary(match kind {
        PATCH_CYLINDER => BoundarySurface::Cylinder { axis },
        PATCH_SPHERE => BoundarySurface::Sphere { axis },
        PATCH_TORUS => BoundarySurface::Torus {
            axis,
            major_radius: major_radius as f64 * quant.step(),
        },
        _ => BoundarySurface::Cone { axis },
    })
}

/// Reads the version-3 (`kinds` = [`KINDS_V3`]) or version-4 (`kinds` = [`KINDS`]) section.
pub fn decode(
    payload: &[u8],
    group_count: usize,
    quant: &Quantizer,
    kinds: usize,
) -> Result<DecodedPatches> {
    let mut dec = RangeDecoder::new(payload, "patches")?;
    let mut m = Models::new(kinds);
    let mut recent = RecentDirections::default();
    let mut prev_kind = kinds;
    // A capacity hint only (the vectors grow if a file really holds more groups per byte);
    // `group_count` itself is already within the limits.
    let cap = group_count.min(payload.len().saturating_mul(64));
    let (mut out, mut grid) = (Vec::with_capacity(cap), Vec::with_capacity(cap));
    for _ in 0..group_count {
        let kind = m.kinds[prev_kind].decode(&mut dec)? as u8;
        prev_kind = usize::from(kind);
        if kind == PATCH_CLOSED || kind == PATCH_PLANE {
            out.push(if kind == PATCH_CLOSED {
                PatchKind::Closed
            } else {
                PatchKind::Boundary(BoundarySurface::Plane)
            });
            grid.push(None);
            continue;
        }
        let s = m.direction.decode(&mut dec)?;
        let (dir, line) = if s < RECENT_DIRECTIONS {
            if s >= recent.0.len() {
                return Err(Error::format(
                    "patches",
                    "axis_direction",
                    format!("reference {s} to a list of {} directions", recent.0.len()),
                ));
            }
            let neg = dec.decode_bit(&mut m.negated)?;
            recent.touch(s);
            let (d, line) = recent.0[0];
            let d = if neg {
                negate(d).ok_or_else(|| {
                    Error::format("patches", "axis_direction", "component -32768 negated")
                })?
            } else {
                d
            };
            (d, line)
        } else {
            let mut d = [0i16; 3];
            for c in &mut d {
                let z = m.component.decode(&mut dec, 65535, "axis_direction")?;
                *c = super::rangecoder::unzigzag(z) as i16;
            }
            if d == [0; 3] {
                return Err(Error::format("patches", "axis_direction", "zero direction"));
            }
            recent.push(d);
            (d, None)
        };
        let mut origin = [0i64; 3];
        if kind == PATCH_CYLINDER {
            let same = line.is_some() && dec.decode_bit(&mut m.same_line)?;
            match line {
                Some(o) if same => origin = o,
                _ => {
                    let k = dominant(dir);
                    for (i, o) in origin.iter_mut().enumerate() {
                        *o = if i == k {
                            grid_middle(quant)
                        } else {
                            decode_coord(&mut dec, &mut m.origin, "axis_origin")?
                        };
                    }
                }
            }
            recent.0[0].1 = Some(origin);
        } else {
            for o in &mut origin {
                *o = decode_coord(&mut dec, &mut m.apex, "axis_origin")?;
            }
        }
        let major_radius = if kind == PATCH_TORUS {
            let r = decode_coord(&mut dec, &mut m.major_radius, "major_radius")?;
            if r < 0 {
                return Err(Error::format("patches", "major_radius", "negative"));
            }
            r
        } else {
            0
        };
        let a = GridAxisBits { origin, dir };
        out.push(patch_of(kind, a, major_radius, quant));
        grid.push(Some(GridAxis::new(origin, dir)));
    }
    dec.finish()?;
    Ok((out, grid))
}

/// Reads the version 1-2 section.
pub fn decode_v1(payload: &[u8], group_count: usize, quant: &Quantizer) -> Result<DecodedPatches> {
    let mut r = Reader::new(payload, "patches");
    let mut out = Vec::with_capacity(group_count.min(payload.len()));
    let mut grid = Vec::with_capacity(group_count.min(payload.len()));
    for _ in 0..group_count {
        let kind = r.u8("kind")?;
        match kind {
            PATCH_CLOSED => {
                out.push(PatchKind::Closed);
                grid.push(None);
            }
            PATCH_PLANE => {
                out.push(PatchKind::Boundary(BoundarySurface::Plane));
                grid.push(None);
            }
            PATCH_CYLINDER | PATCH_CONE => {
                let mut origin = [0i64; 3];
                for o in &mut origin {
                    *o = unzigzag64(r.varint("axis_origin")?);
                    if o.unsigned_abs() > MAX_ORIGIN {
                        return Err(r.err("axis_origin", "out of range"));
                    }
                }
                let mut dir = [0i16; 3];
                for c in &mut dir {
                    *c = r.i16("axis_direction")?;
                }
                if dir == [0; 3] {
                    return Err(r.err("axis_direction", "zero direction"));
                }
                out.push(patch_of(kind, GridAxisBits { origin, dir }, 0, quant));
                grid.push(Some(GridAxis::new(origin, dir)));
            }
            k => return Err(r.err("kind", format!("unknown patch kind {k}"))),
        }
    }
    r.expect_end()?;
    Ok((out, grid))
}

/// Grid axes of the cylinder and cone groups (in group order) and, per face, the index of its
/// group's axis or `NONE` (the arc candidates of §8.2).
pub fn face_axes(face_group: &[u32], group_axes: &[Option<GridAxis>]) -> (Vec<u32>, Vec<GridAxis>) {
    let mut index = vec![NONE; group_axes.len()];
    let mut axes = Vec::new();
    for (g, a) in group_axes.iter().enumerate() {
        if let Some(a) = a {
            index[g] = axes.len() as u32;
            axes.push(*a);
        }
    }
    let per_face = face_group
        .iter()
        .map(|&g| index.get(g as usize).copied().unwrap_or(NONE))
        .collect();
    (per_face, axes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quant() -> Quantizer {
        Quantizer {
            min: [-1.0, -2.0, -3.0],
            extent: 8.0,
            bits: 12,
            as_f32: true,
        }
    }

    fn cyl(o: [f64; 3], d: [f64; 3]) -> PatchKind {
        PatchKind::Boundary(BoundarySurface::Cylinder {
            axis: Axis {
                origin: DVec3::from(o),
                direction: DVec3::from(d),
            },
        })
    }

    fn cone(o: [f64; 3], d: [f64; 3]) -> PatchKind {
        PatchKind::Boundary(BoundarySurface::Cone {
            axis: Axis {
                origin: DVec3::from(o),
                direction: DVec3::from(d),
            },
        })
    }

    fn groups(kinds: &[PatchKind]) -> Vec<Group> {
        kinds
            .iter()
            .map(|&patch| Group {
                name: String::new(),
                patch,
            })
            .collect()
    }

    /// Distance from `p` to the line through `o` along unit `d`.
    fn off_line(p: DVec3, o: DVec3, d: DVec3) -> f64 {
        let v = p - o;
        (v - d * v.dot(d)).length()
    }

    #[test]
    fn every_branch_round_trips() {
        let q = quant();
        let kinds = [
            PatchKind::Closed,
            PatchKind::Boundary(BoundarySurface::Plane),
            cyl([1.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
            cyl([1.0, 1.0, 4.0], [0.0, 0.0, -3.0]), // coaxial, reversed: same line
            cyl([2.0, 1.0, 0.0], [0.0, 0.0, 1.0]),  // parallel, another line
            cone([0.5, 0.5, 0.5], [1.0, 1.0, 0.0]), // new direction
            cone([0.0, 0.0, 1e9], [0.0, 0.0, 1.0]), // apex needs the escape code
            cyl([0.3, -1.0, 2.0], [0.2, 1.0, 0.1]), // oblique, dominant y
            PatchKind::Boundary(BoundarySurface::Sphere {
                axis: Axis {
                    origin: DVec3::new(0.25, 1.5, -0.5),
                    direction: DVec3::new(0.0, 1.0, 1.0),
                },
            }),
            PatchKind::Boundary(BoundarySurface::Torus {
                axis: Axis {
                    origin: DVec3::new(1.0, 1.0, 0.0),
                    direction: DVec3::new(0.0, 0.0, 1.0), // a known direction, new kind
                },
                major_radius: 2.345,
            }),
        ];
        let g = groups(&kinds);
        let (bytes, grid) = encode(&g, &q).unwrap();
        let bytes = bytes.unwrap();
        let (back, grid2) = decode(&bytes, g.len(), &q, KINDS).unwrap();
        assert_eq!(grid, grid2);
        assert_eq!(back.len(), kinds.len());
        for (a, b) in kinds.iter().zip(&back) {
            match (a, b) {
                (
                    PatchKind::Boundary(BoundarySurface::Cylinder { axis: a }),
                    PatchKind::Boundary(BoundarySurface::Cylinder { axis: b }),
                ) => {
                    let d = a.direction.normalize();
                    assert!((b.direction - d).length() < 1e-4);
                    assert!(off_line(b.origin, a.origin, d) < q.step(), "{a:?} {b:?}");
                }
                (
                    PatchKind::Boundary(BoundarySurface::Cone { axis: a }),
                    PatchKind::Boundary(BoundarySurface::Cone { axis: b }),
                ) => {
                    assert!((b.direction - a.direction.normalize()).length() < 1e-4);
                    assert!((b.origin - a.origin).abs().max_element() <= q.step() / 2.0 + 1e-6);
                }
                (
                    PatchKind::Boundary(BoundarySurface::Sphere { axis: a }),
                    PatchKind::Boundary(BoundarySurface::Sphere { axis: b }),
                ) => {
                    assert!((b.direction - a.direction.normalize()).length() < 1e-4);
                    assert!((b.origin - a.origin).abs().max_element() <= q.step() / 2.0 + 1e-6);
                }
                (
                    PatchKind::Boundary(BoundarySurface::Torus {
                        axis: a,
                        major_radius: ra,
                    }),
                    PatchKind::Boundary(BoundarySurface::Torus {
                        axis: b,
                        major_radius: rb,
                    }),
                ) => {
                    assert!((b.direction - a.direction.normalize()).length() < 1e-4);
                    assert!((b.origin - a.origin).abs().max_element() <= q.step() / 2.0 + 1e-6);
                    assert!((ra - rb).abs() <= q.step() / 2.0 + 1e-9, "{ra} {rb}");
                }
                (a, b) => assert_eq!(a, b),
            }
        }
        // The coaxial cylinder shares the line origin exactly (one bit in the file).
        let (o2, o3) = (grid2[2].unwrap().origin, grid2[3].unwrap().origin);
        assert_eq!(o2, o3);
        // Cylinder origins sit in the middle of the grid on their dominant axis.
        assert_eq!(grid2[2].unwrap().origin[2], 2048.0);
        assert_eq!(grid2[7].unwrap().origin[1], 2048.0);
    }

    #[test]
    fn all_closed_has_no_section() {
        let (bytes, grid) = encode(&groups(&[PatchKind::Closed; 3]), &quant()).unwrap();
        assert!(bytes.is_none());
        assert_eq!(grid, vec![None; 3]);
    }

    #[test]
    fn malformed_sections_are_errors() {
        let q = quant();
        // A cylinder that references the (empty) direction list.
        let mut enc = RangeEncoder::new();
        let mut m = Models::new(KINDS);
        m.kinds[KINDS].encode(&mut enc, usize::from(PATCH_CYLINDER));
        m.direction.encode(&mut enc, 0);
        let e = decode(&enc.finish(), 1, &q, KINDS).unwrap_err().to_string();
        assert!(e.contains("axis_direction"), "{e}");
        // A zero direction.
        let mut enc = RangeEncoder::new();
        let mut m = Models::new(KINDS);
        m.kinds[KINDS].encode(&mut enc, usize::from(PATCH_CONE));
        m.direction.encode(&mut enc, RECENT_DIRECTIONS);
        for _ in 0..3 {
            m.component.encode(&mut enc, 0);
        }
        let e = decode(&enc.finish(), 1, &q, KINDS).unwrap_err().to_string();
        assert!(e.contains("zero direction"), "{e}");
        // An escaped coordinate that would have fitted the model.
        let mut enc = RangeEncoder::new();
        let mut m = Models::new(KINDS);
        m.kinds[KINDS].encode(&mut enc, usize::from(PATCH_CONE));
        m.direction.encode(&mut enc, RECENT_DIRECTIONS);
        for c in [0, 0, 2] {
            m.component.encode(&mut enc, c);
        }
        m.apex.encode(&mut enc, ESCAPE);
        for _ in 0..4 {
            enc.encode_direct(0, 16);
        }
        let e = decode(&enc.finish(), 1, &q, KINDS).unwrap_err().to_string();
        assert!(e.contains("escaped"), "{e}");
        // A negative torus major radius.
        let mut enc = RangeEncoder::new();
        let mut m = Models::new(KINDS);
        m.kinds[KINDS].encode(&mut enc, usize::from(PATCH_TORUS));
        m.direction.encode(&mut enc, RECENT_DIRECTIONS);
        for c in [0, 0, 2] {
            m.component.encode(&mut enc, c);
        }
        for _ in 0..3 {
            m.apex.encode(&mut enc, 0);
        }
        m.major_radius.encode(&mut enc, zigzag64(-3) as u32);
        let e = decode(&enc.finish(), 1, &q, KINDS).unwrap_err().to_string();
        assert!(e.contains("major_radius"), "{e}");
        // A version-3 section has no sphere or torus kind: the same bytes read with version
        // 3's alphabet are another file (and here an error or other kinds, never a torus).
        let torus = groups(&[PatchKind::Boundary(BoundarySurface::Torus {
            axis: Axis {
                origin: DVec3::ZERO,
                direction: DVec3::Z,
            },
            major_radius: 1.0,
        })]);
        let (bytes, _) = encode(&torus, &q).unwrap();
        if let Ok((kinds, _)) = decode(&bytes.unwrap(), 1, &q, KINDS_V3) {
            assert!(!matches!(
                kinds[0],
                PatchKind::Boundary(BoundarySurface::Torus { .. })
            ));
        }
        // Truncated: more groups than the data holds.
        let (bytes, _) = encode(&groups(&[cyl([0.0; 3], [1.0, 0.0, 0.0])]), &q).unwrap();
        assert!(decode(&bytes.unwrap(), 50, &q, KINDS).is_err());
    }
}
