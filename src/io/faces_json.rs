//! Reader for the corpus face sidecars `<name>.faces.json` (see the corpus `MANIFEST.md`,
//! "Formats"): the surface type of every CAD face, and for ABC models its analytic
//! parameters.
//!
//! Two layouts exist, both with a top-level `faces` array whose entries have a `tag` (the
//! mesh group is `face_<tag>`) and a `type`:
//! * gmsh tessellations (`tess/*.faces.json`): `type` from gmsh, `occ_type` from Open CASCADE
//!   (a second opinion used when gmsh says `Unknown`), `curves` (bounding curve tags);
//! * ABC models (`abc/*.faces.json`): `abc_type`, and analytic parameters `location`,
//!   `z_axis`, `x_axis`, `radius`, `angle` (cone half-angle, radians) where the surface has
//!   them. A cone's apex is computed as `location - radius / tan(angle) * z_axis` (Open
//!   CASCADE `gp_Cone` convention: `radius` is the radius at `location`, growing along
//!   `z_axis`).

use std::path::Path;
#[cfg(feature = "internals")]
use std::path::PathBuf;

use glam::DVec3;
use serde::Deserialize;

use crate::error::{Error, Result};
use crate::mesh::{AnalyticSurface, Axis, ControlMesh};

/// Surface type of a CAD face, from the sidecar's type names.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum SurfaceType {
    Plane,
    Cylinder,
    Cone,
    Sphere,
    Torus,
    BSplineSurface,
    BezierSurface,
    SurfaceOfRevolution,
    SurfaceOfExtrusion,
    OffsetSurface,
    /// A type name this reader does not know, kept verbatim.
    Other(String),
    Unknown,
}

impl SurfaceType {
    /// Maps a gmsh / Open CASCADE / ABC type name (case-insensitive).
    pub fn from_name(name: &str) -> SurfaceType {
        let n = name.trim().to_ascii_lowercase();
        match n.as_str() {
            "plane" => SurfaceType::Plane,
            "cylinder" => SurfaceType::Cylinder,
            "cone" => SurfaceType::Cone,
            "sphere" => SurfaceType::Sphere,
            "torus" => SurfaceType::Torus,
            "bspline surface" | "bspline" | "b-spline surface" | "bsplinesurface" => {
                SurfaceType::BSplineSurface
            }
            "bezier surface" | "bezier" | "beziersurface" => SurfaceType::BezierSurface,
            "surface of revolution" | "revolution" | "surfaceofrevolution" => {
                SurfaceType::SurfaceOfRevolution
            }
            "surface of extrusion"
            | "surface of linear extrusion"
            | "extrusion"
            | "surfaceofextrusion" => SurfaceType::SurfaceOfExtrusion,
            "offset surface" | "offset" | "offsetsurface" => SurfaceType::OffsetSurface,
            "unknown" | "" => SurfaceType::Unknown,
            _ => SurfaceType::Other(name.trim().to_string()),
        }
    }

    /// The display name (as in the manifest's histograms).
    #[cfg(feature = "internals")]
    pub fn name(&self) -> &str {
        match self {
            SurfaceType::Plane => "Plane",
            SurfaceType::Cylinder => "Cylinder",
            SurfaceType::Cone => "Cone",
            SurfaceType::Sphere => "Sphere",
            SurfaceType::Torus => "Torus",
            SurfaceType::BSplineSurface => "BSpline surface",
            SurfaceType::BezierSurface => "Bezier surface",
            SurfaceType::SurfaceOfRevolution => "Surface of Revolution",
            SurfaceType::SurfaceOfExtrusion => "Surface of Extrusion",
            SurfaceType::OffsetSurface => "Offset surface",
            SurfaceType::Other(name) => name,
            SurfaceType::Unknown => "Unknown",
        }
    }

    /// Planes, cylinders, cones, spheres and tori: surfaces with coordinates in which a
    /// face is spanned by its boundary curves (boundary patches; a sphere or torus face only
    /// when it is narrow enough, see `fit::classify`).
    #[cfg(test)]
    pub fn is_boundary_patch_type(&self) -> bool {
        matches!(
            self,
            SurfaceType::Plane
                | SurfaceType::Cylinder
                | SurfaceType::Cone
                | SurfaceType::Sphere
                | SurfaceType::Torus
        )
    }
}

/// One CAD face of a sidecar.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceInfo {
    /// The face tag; the mesh group is [`FaceInfo::group_name`].
    pub tag: i64,
    /// `face_<tag>`, the group name used by the corpus meshes.
    pub group_name: String,
    /// Surface type: `type` (or `abc_type`), replaced by `occ_type` when that is `Unknown`.
    pub surface: SurfaceType,
    /// The gmsh/ABC type string as stored.
    pub source_type: Option<String>,
    /// Open CASCADE's type string as stored (gmsh sidecars; `None` when unmatched).
    pub occ_type: Option<String>,
    /// Tags of bounding curves (gmsh sidecars; empty otherwise).
    pub curves: Vec<i64>,
    /// The exact plane, cylinder or cone where the sidecar gives its parameters (ABC
    /// sidecars: location and axis, plus the radius of a cylinder and the radius and half
    /// angle of a cone); `None` otherwise.
    pub analytic: Option<AnalyticSurface>,
}

/// JSON shape of a sidecar (only the fields used; others are ignored).
#[derive(Deserialize)]
struct SidecarFile {
    faces: Vec<SidecarFace>,
}

#[derive(Deserialize)]
struct SidecarFace {
    tag: i64,
    #[serde(rename = "type")]
    type_name: Option<String>,
    abc_type: Option<String>,
    occ_type: Option<String>,
    #[serde(default)]
    curves: Vec<i64>,
    location: Option<[f64; 3]>,
    z_axis: Option<[f64; 3]>,
    x_axis: Option<[f64; 3]>,
    radius: Option<f64>,
    angle: Option<f64>,
}

/// Reads a `<name>.faces.json` sidecar. Faces come in file order.
#[cfg(feature = "internals")]
pub fn read_faces_json(path: &Path) -> Result<Vec<FaceInfo>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_faces_json(&bytes, path)
}

/// Parses sidecar JSON; `path` names it in errors.
pub fn parse_faces_json(bytes: &[u8], path: &Path) -> Result<Vec<FaceInfo>> {
    let file: SidecarFile = serde_json::from_slice(bytes)
        .map_err(|e| Error::input(path, format!("invalid faces.json: {e}")))?;
    let mut faces = Vec::with_capacity(file.faces.len());
    for f in file.faces {
        let source_type = f.type_name.or(f.abc_type);
        let mut surface = source_type
            .as_deref()
            .map(SurfaceType::from_name)
            .unwrap_or(SurfaceType::Unknown);
        if surface == SurfaceType::Unknown {
            if let Some(occ) = &f.occ_type {
                surface = SurfaceType::from_name(occ);
            }
        }
        let vec = |v: Option<[f64; 3]>, what: &str| -> Result<Option<DVec3>> {
            match v.map(DVec3::from) {
                Some(p) if !p.is_finite() => Err(Error::input(
                    path,
                    format!("face {}: `{what}` is not finite", f.tag),
                )),
                other => Ok(other),
            }
        };
        let unit = |v: Option<DVec3>, what: &str| -> Result<Option<DVec3>> {
            match v {
                Some(d) => d.try_normalize().map(Some).ok_or_else(|| {
                    Error::input(path, format!("face {}: `{what}` has zero length", f.tag))
                }),
                None => Ok(None),
            }
        };
        let location = vec(f.location, "location")?;
        let axis = unit(vec(f.z_axis, "z_axis")?, "z_axis")?;
        // The frame's x axis is checked but not kept: no surface here needs its seam.
        unit(vec(f.x_axis, "x_axis")?, "x_axis")?;
        let analytic = match (&surface, location, axis, f.radius, f.angle) {
            (SurfaceType::Plane, Some(point), Some(normal), _, _) => {
                Some(AnalyticSurface::Plane { point, normal })
            }
            (SurfaceType::Cylinder, Some(origin), Some(direction), Some(radius), _) => {
                Some(AnalyticSurface::Cylinder {
                    axis: Axis { origin, direction },
                    radius,
                })
            }
            // `radius` is the cone's at `location`; its apex is back along the axis.
            (SurfaceType::Cone, Some(loc), Some(direction), Some(r), Some(angle))
                if angle.tan().abs() > 1e-12 =>
            {
                Some(AnalyticSurface::Cone {
                    axis: Axis {
                        origin: loc - direction * (r / angle.tan()),
                        direction,
                    },
                    half_angle: angle,
                })
            }
            _ => None,
        };
        faces.push(FaceInfo {
            tag: f.tag,
            group_name: format!("face_{}", f.tag),
            surface,
            source_type,
            occ_type: f.occ_type,
            curves: f.curves,
            analytic,
        });
    }
    Ok(faces)
}

/// The sidecar of a corpus mesh, if it exists: `tess/X_coarse.obj` and `tess/X_fine.obj` ->
/// `tess/X.faces.json`; otherwise (`abc/X.obj`, `tess/X_cadexport.obj`) `X.faces.json` next
/// to the mesh.
#[cfg(feature = "internals")]
pub fn sidecar_path_for(mesh_path: &Path) -> Option<PathBuf> {
    let stem = mesh_path.file_stem()?.to_str()?;
    let dir = mesh_path.parent().unwrap_or_else(|| Path::new(""));
    let base = stem
        .strip_suffix("_coarse")
        .or_else(|| stem.strip_suffix("_fine"));
    base.into_iter()
        .chain(std::iter::once(stem))
        .map(|s| dir.join(format!("{s}.faces.json")))
        .find(|p| p.is_file())
}

/// For each group of `mesh`, the sidecar face with the same name (`face_<tag>`), if any.
pub fn face_info_for_groups<'a>(
    mesh: &ControlMesh,
    faces: &'a [FaceInfo],
) -> Vec<Option<&'a FaceInfo>> {
    let by_name: std::collections::HashMap<&str, &FaceInfo> =
        faces.iter().map(|f| (f.group_name.as_str(), f)).collect();
    mesh.groups
        .iter()
        .map(|g| by_name.get(g.name.as_str()).copied())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::read_mesh;
    use crate::io::test_support::corpus_dir;

    #[test]
    fn type_names() {
        assert_eq!(
            SurfaceType::from_name("BSpline surface"),
            SurfaceType::BSplineSurface
        );
        assert_eq!(
            SurfaceType::from_name("Surface of Extrusion"),
            SurfaceType::SurfaceOfExtrusion
        );
        assert_eq!(
            SurfaceType::from_name("Weird"),
            SurfaceType::Other("Weird".into())
        );
        assert!(SurfaceType::Cone.is_boundary_patch_type());
        assert!(SurfaceType::Torus.is_boundary_patch_type());
        assert!(!SurfaceType::BSplineSurface.is_boundary_patch_type());
    }

    #[test]
    fn occ_type_overrides_unknown_and_cone_apex() {
        let json = br#"{"faces":[
            {"tag":3,"type":"Unknown","occ_type":"Surface of Extrusion","curves":[1,2]},
            {"tag":4,"type":"Cylinder","occ_type":null},
            {"tag":5,"abc_type":"Cone","type":"Cone","location":[0,0,1.5875],
             "z_axis":[0,-0.0,-1],"radius":2.38125,"angle":0.7853981633974483},
            {"tag":6,"type":"Unknown"}]}"#;
        let faces = parse_faces_json(json, Path::new("x.faces.json")).unwrap();
        assert_eq!(faces[0].surface, SurfaceType::SurfaceOfExtrusion);
        assert_eq!(faces[0].curves, vec![1, 2]);
        assert_eq!(faces[0].group_name, "face_3");
        assert_eq!(faces[1].surface, SurfaceType::Cylinder);
        assert!(faces[1].analytic.is_none());
        match faces[2].analytic {
            Some(AnalyticSurface::Cone { axis, half_angle }) => {
                let apex = DVec3::new(0.0, 0.0, 1.5875 + 2.38125);
                assert!((axis.origin - apex).length() < 1e-12);
                assert_eq!(axis.direction, -DVec3::Z);
                assert_eq!(half_angle, std::f64::consts::FRAC_PI_4);
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(faces[3].surface, SurfaceType::Unknown);
        assert!(parse_faces_json(b"{}", Path::new("x")).is_err());
        assert!(parse_faces_json(
            b"{\"faces\":[{\"tag\":1,\"z_axis\":[0,0,0]}]}",
            Path::new("x")
        )
        .is_err());
    }

    #[test]
    fn corpus_sidecars_match_their_meshes() {
        let Some(dir) = corpus_dir() else { return };
        // (mesh, expected histogram entries) from MANIFEST.md; OCC types where gmsh says Unknown.
        let cases: &[(&str, &[(&str, usize)])] = &[
            (
                "tess/screw_coarse.obj",
                &[("Plane", 4), ("Torus", 3), ("Cone", 2), ("Cylinder", 1)],
            ),
            (
                "tess/Ventilator_fine.obj",
                &[("BSpline surface", 189), ("Surface of Extrusion", 26)],
            ),
            (
                "tess/abc_00000050_coarse.obj",
                &[("Cylinder", 23), ("Plane", 20)],
            ),
            (
                "tess/nist_ftc_08_asme1_ap242-2_cadexport.obj",
                &[("Cylinder", 159), ("Plane", 81)],
            ),
            (
                "abc/abc_00000006.obj",
                &[("Plane", 8), ("Cone", 6), ("Cylinder", 1)],
            ),
            ("abc/abc_00007974_5.obj", &[("Plane", 14), ("Cylinder", 10)]),
        ];
        for &(mesh_file, histogram) in cases {
            let mesh_path = dir.join(mesh_file);
            let sidecar = sidecar_path_for(&mesh_path).unwrap();
            let faces = read_faces_json(&sidecar).unwrap();
            for &(name, count) in histogram {
                let n = faces.iter().filter(|f| f.surface.name() == name).count();
                assert_eq!(n, count, "{mesh_file}: {name}");
            }
            let (mesh, _) = read_mesh(&mesh_path).unwrap();
            let matched = face_info_for_groups(&mesh, &faces);
            assert!(
                matched.iter().all(Option::is_some),
                "{mesh_file}: unmatched group"
            );
            assert_eq!(mesh.groups.len(), faces.len(), "{mesh_file}");
            if mesh_file.starts_with("abc/") {
                for f in &faces {
                    let a = f.analytic;
                    assert!(a.is_some(), "{mesh_file} face {}: {:?}", f.tag, f.surface);
                }
            }
        }
        assert!(sidecar_path_for(&dir.join("meshes/fandisk.obj")).is_none());
    }
}
