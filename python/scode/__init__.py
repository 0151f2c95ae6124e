"""scode: a subdivision-surface codec for CAD models.

Compress a triangle mesh whose triangles are grouped by CAD face (or a STEP file, or an
OBJ/PLY/STL/OFF/glb file) to ``.scode`` bytes, and decode them to a triangle surface that
keeps each triangle's CAD face, the face names and the sharp edges::

    import scode
    data = scode.encode(vertices, faces, groups=groups, names=names, tolerance=1e-3)
    mesh = scode.decode(data)
    print(mesh.vertices.shape, mesh.triangles.shape, mesh.names[mesh.groups[0]])

Encoding and decoding release the GIL. Errors are :class:`ScodeError` subclasses named by
kind: :class:`FormatError`, :class:`LimitsError`, :class:`InputError`,
:class:`ParameterError`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional, Sequence, Union

import numpy as np

from . import _scode
from ._scode import (
    FormatError,
    InputError,
    LimitsError,
    ParameterError,
    ScodeError,
)

__version__ = _scode.__version__

__all__ = [
    "Encoded",
    "FormatError",
    "InputError",
    "LimitsError",
    "Mesh",
    "ParameterError",
    "ScodeError",
    "decode",
    "encode",
    "encode_file",
    "encode_mesh",
    "encode_step",
    "info",
    "sidecar_path",
]


@dataclass
class Mesh:
    """A decoded surface.

    ``vertices`` (n, 3) float64; ``triangles`` (m, 3) uint32; ``groups`` (m,) uint32, the CAD
    face of each triangle, indexing ``names``; ``sharp_edges`` (k, 2) uint32 vertex pairs
    (the CAD-face boundaries among them); ``normals`` (n, 3) float64 unit normals of the limit
    surface, or None; ``level`` the finest subdivision level in the output. The arrays are
    read-only views of the decoder's output (``.copy()`` one to modify it).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    groups: np.ndarray
    sharp_edges: np.ndarray
    names: List[str]
    normals: Optional[np.ndarray] = None
    level: int = 0


@dataclass
class Encoded:
    """What :func:`encode_file` produced: the ``.scode`` bytes and the encoder's report.

    ``tolerance`` and ``max_error`` (the largest distance between the decoded surface and
    the input) are in model units, None in raw mode; ``skipped_faces`` counts the B-rep faces
    of a STEP file that could not be read.
    """

    data: bytes
    input_vertices: int
    input_triangles: int
    input_groups: int
    tolerance: Optional[float]
    max_error: Optional[float]
    within_tolerance: bool
    skipped_faces: int
    # What max_error and the tolerance were measured against (fitted files).
    reference: Optional[str] = None
    notes: List[str] = field(default_factory=list)


def _array(values, dtype, columns: int, what: str) -> np.ndarray:
    """``values`` as a C-contiguous native-endian array of ``columns`` columns (0: 1-D)."""
    try:
        a = np.asarray(values)
    except (TypeError, ValueError) as e:
        raise ParameterError(f"{what}: not an array ({e})") from None
    if columns and (a.ndim != 2 or a.shape[1] != columns):
        raise ParameterError(f"{what}: expected shape (n, {columns}), got {a.shape}")
    if not columns and a.ndim != 1:
        raise ParameterError(f"{what}: expected shape (n,), got {a.shape}")
    if np.dtype(dtype).kind == "u":
        if a.size and a.dtype.kind not in "iu":
            raise ParameterError(f"{what}: expected integers, got {a.dtype}")
        if a.size and (a.min() < 0 or a.max() > np.iinfo(np.uint32).max):
            raise ParameterError(f"{what}: indices must be in 0..2**32")
    return np.ascontiguousarray(a, dtype=dtype)


def _encoded(d: dict) -> Encoded:
    return Encoded(**d)


def encode(
    vertices,
    faces,
    groups=None,
    names: Optional[Sequence[str]] = None,
    tolerance: float = 1e-3,
    relative: bool = True,
    *,
    sharp_edges=None,
    effort: str = "default",
    raw_bits: Optional[int] = None,
    store_names: bool = True,
    chord_allowance: bool = False,
) -> bytes:
    """Encodes a triangle mesh to ``.scode`` bytes.

    ``vertices``: (n, 3) floats; ``faces``: (m, 3) vertex indices, counter-clockwise seen from
    outside; ``groups``: (m,) CAD face of each triangle (None: the encoder segments the mesh
    itself); ``names``: one name per group. ``tolerance``: the largest distance the decoded
    surface may be from the input, a fraction of the bounding-box diagonal when ``relative``
    (default 1e-3) or model units. ``sharp_edges``: (k, 2) vertex pairs that are creases
    besides the group boundaries. ``effort``: "fast", "default" or "max". ``raw_bits``:
    store the mesh itself (no fit), positions quantised to that many bits.
    ``chord_allowance``: hold the tolerance beyond the input's own chord error (each facet's
    estimated distance from the CAD surface it tessellates) instead of to the mesh itself,
    for coarse tessellations of smooth parts; ``Encoded.reference`` says which was measured.
    """
    return encode_mesh(
        vertices,
        faces,
        groups,
        names,
        tolerance,
        relative,
        sharp_edges=sharp_edges,
        effort=effort,
        raw_bits=raw_bits,
        store_names=store_names,
        chord_allowance=chord_allowance,
    ).data


def encode_mesh(
    vertices,
    faces,
    groups=None,
    names: Optional[Sequence[str]] = None,
    tolerance: float = 1e-3,
    relative: bool = True,
    *,
    sharp_edges=None,
    effort: str = "default",
    raw_bits: Optional[int] = None,
    store_names: bool = True,
    chord_allowance: bool = False,
) -> Encoded:
    """:func:`encode` returning the encoder's report (:class:`Encoded`) with the bytes."""
    v = _array(vertices, np.float64, 3, "vertices")
    f = _array(faces, np.uint32, 3, "faces")
    g = None if groups is None else _array(groups, np.uint32, 0, "groups").tobytes()
    s = None if sharp_edges is None else _array(sharp_edges, np.uint32, 2, "sharp_edges").tobytes()
    return _encoded(
        _scode.encode_mesh(
            v.tobytes(),
            f.tobytes(),
            g,
            None if names is None else [str(n) for n in names],
            s,
            float(tolerance),
            bool(relative),
            effort,
            raw_bits,
            bool(store_names),
            bool(chord_allowance),
        )
    )


def encode_file(
    data: bytes,
    format: str,
    tolerance: float = 1e-3,
    relative: bool = True,
    *,
    effort: str = "default",
    raw_bits: Optional[int] = None,
    store_names: bool = True,
    chord_allowance: bool = False,
    faces_json: Optional[bytes] = None,
) -> Encoded:
    """Encodes a model file held in memory.

    ``format``: "step" (or "stp"), "obj", "ply", "stl", "off" or "glb". A STEP file's B-rep
    faces are tessellated and fitted with their surface types (lengths in millimetres); a
    mesh file's groups (OBJ ``g``, glTF primitives or ``_FEATURE_ID_0``) are its CAD faces.
    ``faces_json``: the bytes of a mesh's face sidecar (``<name>.faces.json``, each face's
    surface type; see :func:`sidecar_path`), so that its plane, cylinder and cone faces are
    fitted as such. Other arguments as for :func:`encode`.
    """
    return _encoded(
        _scode.encode_file(
            bytes(data),
            format,
            float(tolerance),
            bool(relative),
            effort,
            raw_bits,
            bool(store_names),
            bool(chord_allowance),
            None if faces_json is None else bytes(faces_json),
        )
    )


def sidecar_path(mesh_path: Union[str, "os.PathLike[str]"]) -> Optional[Path]:
    """The face sidecar of a mesh file, if it exists, by the rule the ``scode`` command
    uses: ``X_coarse.obj`` and ``X_fine.obj`` -> ``X.faces.json`` beside them, else
    ``X.faces.json`` for ``X.obj``."""
    mesh_path = Path(mesh_path)
    stem = mesh_path.stem
    bases = [stem[: -len(s)] for s in ("_coarse", "_fine") if stem.endswith(s)][:1] + [stem]
    for base in bases:
        candidate = mesh_path.with_name(f"{base}.faces.json")
        if candidate.is_file():
            return candidate
    return None


def encode_step(
    data: bytes,
    tolerance: float = 1e-3,
    relative: bool = True,
    *,
    effort: str = "default",
    store_names: bool = True,
) -> bytes:
    """Encodes a STEP file (its bytes) to ``.scode`` bytes; see :func:`encode_file`."""
    return encode_file(
        data, "step", tolerance, relative, effort=effort, store_names=store_names
    ).data


def decode(
    data: bytes,
    level: Optional[int] = None,
    tolerance: Optional[float] = None,
    relative: bool = True,
) -> Mesh:
    """Decodes ``.scode`` bytes to a :class:`Mesh`.

    By default every part of the surface is subdivided to the coarsest level within the
    tolerance the file was encoded for. ``level``: one uniform subdivision level instead;
    ``tolerance``: the coarsest levels within this distance of the limit surface (a fraction
    of the diagonal when ``relative``). Raises :class:`FormatError` for data that is not a
    valid file and :class:`LimitsError` when decoding would exceed the resource limits.
    """
    d = _scode.decode(
        bytes(data),
        None if level is None else int(level),
        None if tolerance is None else float(tolerance),
        bool(relative),
    )
    normals = d["normals"]
    return Mesh(
        vertices=np.frombuffer(d["vertices"], dtype=np.float64).reshape(-1, 3),
        triangles=np.frombuffer(d["triangles"], dtype=np.uint32).reshape(-1, 3),
        groups=np.frombuffer(d["groups"], dtype=np.uint32),
        sharp_edges=np.frombuffer(d["sharp_edges"], dtype=np.uint32).reshape(-1, 2),
        names=list(d["names"]),
        normals=None
        if normals is None
        else np.frombuffer(normals, dtype=np.float64).reshape(-1, 3),
        level=d["level"],
    )


def info(data: bytes) -> dict:
    """The header and section sizes of ``.scode`` bytes, without subdividing: version,
    default_level (None for a raw-mode file), vertices, faces, groups, names, sharp_edges,
    quantization_bits, bbox_min, bbox_extent, bytes, sections (name to bytes)."""
    return _scode.info(bytes(data))
