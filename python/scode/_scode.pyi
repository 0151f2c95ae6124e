"""Type stubs of the extension module; the documented API is the package ``scode``."""

from typing import Any, Dict, List, Optional

__version__: str

class ScodeError(Exception): ...
class FormatError(ScodeError): ...
class LimitsError(ScodeError): ...
class InputError(ScodeError): ...
class ParameterError(ScodeError): ...

def encode_mesh(
    positions: bytes,
    triangles: bytes,
    groups: Optional[bytes],
    names: Optional[List[str]],
    sharp_edges: Optional[bytes],
    tolerance: float,
    relative: bool,
    effort: str,
    raw_bits: Optional[int],
    store_names: bool,
    chord_allowance: bool = False,
    faces_json: Optional[bytes] = None,
) -> Dict[str, Any]: ...
def encode_file(
    data: bytes,
    format: str,
    tolerance: float,
    relative: bool,
    effort: str,
    raw_bits: Optional[int],
    store_names: bool,
    chord_allowance: bool = False,
) -> Dict[str, Any]: ...
def decode(
    data: bytes,
    level: Optional[int] = None,
    tolerance: Optional[float] = None,
    relative: bool = True,
) -> Dict[str, Any]: ...
def info(data: bytes) -> Dict[str, Any]: ...
