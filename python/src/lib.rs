//! `scode._scode`: the extension module under the Python package `scode` (python/scode).
//!
//! Thin wrappers of the library's documented API (`scode::encode`, `scode::decode`,
//! `scode::inspect`). Arrays cross the boundary as native-endian bytes that the Python side
//! makes from and into numpy arrays, so this module needs no numpy headers. Every call that
//! encodes or decodes releases the GIL: other Python threads run meanwhile, and several
//! threads can decode at once.
#![forbid(unsafe_code)]

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyOSError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

create_exception!(
    _scode,
    ScodeError,
    PyException,
    "Base class of the errors scode raises."
);
create_exception!(
    _scode,
    FormatError,
    ScodeError,
    "The data is not a valid .scode file (the message names the section and field)."
);
create_exception!(
    _scode,
    LimitsError,
    ScodeError,
    "Decoding would exceed a resource limit (vertices, faces, memory, work)."
);
create_exception!(
    _scode,
    InputError,
    ScodeError,
    "An input model (mesh, mesh file, STEP file) is malformed or unsupported."
);
create_exception!(
    _scode,
    ParameterError,
    ScodeError,
    "An argument is out of range or inconsistent (tolerance, level, indices, array shapes)."
);

/// The Python exception of each kind of library error.
fn to_py(e: scode::Error) -> PyErr {
    let msg = e.to_string();
    match e {
        scode::Error::Format { .. } => FormatError::new_err(msg),
        scode::Error::LimitsExceeded { .. } => LimitsError::new_err(msg),
        scode::Error::Input { .. } | scode::Error::Mesh(_) => InputError::new_err(msg),
        scode::Error::Parameter(_) => ParameterError::new_err(msg),
        scode::Error::Io { .. } => PyOSError::new_err(msg),
    }
}

fn parameter(msg: String) -> PyErr {
    ParameterError::new_err(msg)
}

/// Native-endian `N`-tuples of 8-byte (`f64`) or 4-byte (`u32`) values from `bytes`.
fn tuples<T: Copy + Default, const N: usize, const W: usize>(
    bytes: &[u8],
    what: &str,
    from: fn([u8; W]) -> T,
) -> PyResult<Vec<[T; N]>> {
    if bytes.len() % (N * W) != 0 {
        return Err(parameter(format!(
            "{what}: {} bytes is not a whole number of {N}-tuples",
            bytes.len()
        )));
    }
    Ok(bytes
        .chunks_exact(N * W)
        .map(|c| {
            let mut t = [T::default(); N];
            for (k, v) in c.chunks_exact(W).enumerate() {
                t[k] = from(v.try_into().expect("chunks of W bytes"));
            }
            t
        })
        .collect())
}

fn f64x3(bytes: &[u8], what: &str) -> PyResult<Vec<[f64; 3]>> {
    tuples::<f64, 3, 8>(bytes, what, f64::from_ne_bytes)
}

fn u32s<const N: usize>(bytes: &[u8], what: &str) -> PyResult<Vec<[u32; N]>> {
    tuples::<u32, N, 4>(bytes, what, u32::from_ne_bytes)
}

fn effort(name: &str) -> PyResult<scode::Effort> {
    scode::Effort::ALL
        .into_iter()
        .find(|e| e.name() == name)
        .ok_or_else(|| {
            parameter(format!(
                "effort must be \"fast\", \"default\" or \"max\", not {name:?}"
            ))
        })
}

fn encode_options(
    tolerance: f64,
    relative: bool,
    effort_name: &str,
    raw_bits: Option<u8>,
    store_names: bool,
    chord_allowance: bool,
) -> PyResult<scode::EncodeOptions> {
    Ok(scode::EncodeOptions {
        tolerance: scode::Tolerance::new(tolerance, relative),
        chord_allowance,
        effort: effort(effort_name)?,
        store_group_names: store_names,
        raw_bits,
        ..Default::default()
    })
}

/// The encoded file and what the encoder reported, as a dict.
fn encoded<'py>(py: Python<'py>, e: scode::Encoded) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("data", PyBytes::new(py, &e.bytes))?;
    d.set_item("input_vertices", e.input_vertices)?;
    d.set_item("input_triangles", e.input_triangles)?;
    d.set_item("input_groups", e.input_groups)?;
    d.set_item("tolerance", e.tolerance)?;
    d.set_item("max_error", e.max_error)?;
    d.set_item("reference", e.reference.map(|r| r.describe()))?;
    d.set_item("within_tolerance", e.within_tolerance)?;
    d.set_item("skipped_faces", e.skipped_faces)?;
    d.set_item("notes", PyList::new(py, e.notes)?)?;
    Ok(d)
}

/// Encodes a triangle mesh given as native-endian arrays (see `scode.encode`).
#[pyfunction]
#[pyo3(signature = (positions, triangles, groups, names, sharp_edges, tolerance, relative, effort, raw_bits, store_names, chord_allowance=false))]
#[allow(clippy::too_many_arguments)]
fn encode_mesh<'py>(
    py: Python<'py>,
    positions: &[u8],
    triangles: &[u8],
    groups: Option<&[u8]>,
    names: Option<Vec<String>>,
    sharp_edges: Option<&[u8]>,
    tolerance: f64,
    relative: bool,
    effort: &str,
    raw_bits: Option<u8>,
    store_names: bool,
    chord_allowance: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let mesh = scode::Mesh {
        positions: f64x3(positions, "vertices")?,
        triangles: u32s::<3>(triangles, "faces")?,
        groups: match groups {
            Some(g) => u32s::<1>(g, "groups")?.into_iter().map(|[g]| g).collect(),
            None => Vec::new(),
        },
        group_names: names.unwrap_or_default(),
        sharp_edges: match sharp_edges {
            Some(s) => u32s::<2>(s, "sharp_edges")?,
            None => Vec::new(),
        },
    };
    let opts = encode_options(
        tolerance,
        relative,
        effort,
        raw_bits,
        store_names,
        chord_allowance,
    )?;
    let e = py
        .detach(|| scode::encode(scode::Input::Mesh(&mesh), &opts))
        .map_err(to_py)?;
    encoded(py, e)
}

/// Encodes a file in memory: `format` is "step" (or "stp") or a mesh format ("obj", "ply",
/// "stl", "off", "glb").
#[pyfunction]
#[pyo3(signature = (data, format, tolerance, relative, effort, raw_bits, store_names, chord_allowance=false, faces_json=None))]
#[allow(clippy::too_many_arguments)]
fn encode_file<'py>(
    py: Python<'py>,
    data: &[u8],
    format: &str,
    tolerance: f64,
    relative: bool,
    effort: &str,
    raw_bits: Option<u8>,
    store_names: bool,
    chord_allowance: bool,
    faces_json: Option<Vec<u8>>,
) -> PyResult<Bound<'py, PyDict>> {
    let mut opts = encode_options(
        tolerance,
        relative,
        effort,
        raw_bits,
        store_names,
        chord_allowance,
    )?;
    opts.faces_json = faces_json;
    let format = format.to_ascii_lowercase();
    let input = if format == "step" || format == "stp" {
        scode::Input::Step(data)
    } else {
        let name = std::path::PathBuf::from(format!("input.{format}"));
        let format = scode::MeshFormat::from_path(&name).map_err(to_py)?;
        scode::Input::MeshFile {
            bytes: data,
            format,
        }
    };
    let e = py.detach(|| scode::encode(input, &opts)).map_err(to_py)?;
    encoded(py, e)
}

/// Decodes a `.scode` file: (vertices, triangles, groups, sharp edges as native-endian
/// bytes, group names, normals or None, level).
#[pyfunction]
#[pyo3(signature = (data, level=None, tolerance=None, relative=true))]
fn decode<'py>(
    py: Python<'py>,
    data: &[u8],
    level: Option<u32>,
    tolerance: Option<f64>,
    relative: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let opts = match (level, tolerance) {
        (Some(_), Some(_)) => {
            return Err(parameter(
                "give a level or a tolerance, not both".to_string(),
            ))
        }
        (Some(l), None) => scode::DecodeOptions::level(l),
        (None, Some(t)) => scode::DecodeOptions::tolerance(scode::Tolerance::new(t, relative)),
        (None, None) => scode::DecodeOptions::default(),
    };
    let s = py.detach(|| scode::decode(data, &opts)).map_err(to_py)?;
    let bytes = |v: Vec<u8>| PyBytes::new(py, &v);
    let m = s.mesh;
    let d = PyDict::new(py);
    d.set_item(
        "vertices",
        bytes(
            m.positions
                .iter()
                .flatten()
                .flat_map(|c| c.to_ne_bytes())
                .collect(),
        ),
    )?;
    d.set_item(
        "triangles",
        bytes(
            m.triangles
                .iter()
                .flatten()
                .flat_map(|c| c.to_ne_bytes())
                .collect(),
        ),
    )?;
    d.set_item(
        "groups",
        bytes(m.groups.iter().flat_map(|c| c.to_ne_bytes()).collect()),
    )?;
    d.set_item(
        "sharp_edges",
        bytes(
            m.sharp_edges
                .iter()
                .flatten()
                .flat_map(|c| c.to_ne_bytes())
                .collect(),
        ),
    )?;
    d.set_item("names", PyList::new(py, m.group_names)?)?;
    d.set_item(
        "normals",
        s.normals
            .map(|n| bytes(n.iter().flatten().flat_map(|c| c.to_ne_bytes()).collect())),
    )?;
    d.set_item("level", s.level)?;
    d.set_item("limit", s.limit)?;
    Ok(d)
}

/// Header and section sizes of a `.scode` file, as a dict.
#[pyfunction]
fn info<'py>(py: Python<'py>, data: &[u8]) -> PyResult<Bound<'py, PyDict>> {
    let i = py.detach(|| scode::inspect(data)).map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("version", i.version)?;
    d.set_item("default_level", i.default_level)?;
    d.set_item("vertices", i.vertices)?;
    d.set_item("faces", i.faces)?;
    d.set_item("groups", i.groups)?;
    d.set_item("names", PyList::new(py, i.group_names)?)?;
    d.set_item("sharp_edges", i.sharp_edges)?;
    d.set_item("quantization_bits", i.quantization_bits)?;
    d.set_item("bbox_min", i.bbox_min)?;
    d.set_item("bbox_extent", i.bbox_extent)?;
    d.set_item("bytes", i.bytes)?;
    let sections = PyDict::new(py);
    for (name, size) in i.sections {
        sections.set_item(name, size)?;
    }
    d.set_item("sections", sections)?;
    Ok(d)
}

#[pymodule]
fn _scode(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("ScodeError", py.get_type::<ScodeError>())?;
    m.add("FormatError", py.get_type::<FormatError>())?;
    m.add("LimitsError", py.get_type::<LimitsError>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("ParameterError", py.get_type::<ParameterError>())?;
    m.add_function(wrap_pyfunction!(encode_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(encode_file, m)?)?;
    m.add_function(wrap_pyfunction!(decode, m)?)?;
    m.add_function(wrap_pyfunction!(info, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
