"""PLY point clouds (ASCII and binary, vertex element only), as City3D ships them."""

from __future__ import annotations

import numpy as np

from ..datamodel import PointCloud
from ..errors import FileFormatError
from ._atomic import check_input_file

__all__ = ["read_ply"]

_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
          "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
          "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def read_ply(path, *, crs=None) -> PointCloud:
    """Read the vertices of a PLY file as a :class:`PointCloud` (x, y, z; colours if present).

    Other elements (faces) are ignored. PLY has no CRS: pass ``crs`` when known.

    Raises
    ------
    FileFormatError
        Missing file, not a PLY, no vertex element or no x, y, z properties.
    """
    from ..crs import parse_crs, unit_factors

    p = check_input_file(path)
    with open(p, "rb") as f:
        if f.readline().strip() != b"ply":
            raise FileFormatError(f"{str(p)!r} is not a PLY file")
        fmt, n, props, in_vertex, order = None, 0, [], False, []
        while True:
            line = f.readline()
            if not line:
                raise FileFormatError(f"{str(p)!r}: PLY header has no end_header")
            words = line.decode("ascii", "replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                in_vertex = words[1] == "vertex"
                order.append(words[1])
                if in_vertex:
                    n = int(words[2])
            elif words[0] == "property" and in_vertex:
                if words[1] == "list":
                    raise FileFormatError(f"{str(p)!r}: list properties on vertices are not supported")
                props.append((words[2], _TYPES[words[1]]))
            elif words[0] == "end_header":
                break
        names = [name for name, _ in props]
        if not n or not {"x", "y", "z"} <= set(names):
            raise FileFormatError(f"{str(p)!r}: no vertex element with x, y, z")
        if order[0] != "vertex":
            raise FileFormatError(f"{str(p)!r}: the vertex element must come first")
        if fmt == "ascii":
            data = np.loadtxt(f, max_rows=n, ndmin=2)
            rec = {name: data[:, i] for i, name in enumerate(names)}
        elif fmt in ("binary_little_endian", "binary_big_endian"):
            end = "<" if fmt == "binary_little_endian" else ">"
            dtype = np.dtype([(name, end + t) for name, t in props])
            arr = np.frombuffer(f.read(dtype.itemsize * n), dtype=dtype, count=n)
            rec = {name: arr[name] for name in names}
        else:
            raise FileFormatError(f"{str(p)!r}: unknown PLY format {fmt!r}")
    xyz = np.column_stack([rec["x"], rec["y"], rec["z"]]).astype(np.float64)
    attrs = {c: np.asarray(rec[c]).astype(np.uint16) for c in ("red", "green", "blue") if c in rec}
    resolved = parse_crs(crs)
    xy_unit, z_unit = unit_factors(resolved)
    return PointCloud.from_world(xyz, crs=resolved, xy_unit=xy_unit, z_unit=z_unit, attributes=attrs)
