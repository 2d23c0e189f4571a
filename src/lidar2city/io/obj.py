"""Wavefront OBJ export of building models.

One ``o`` object per building (``o <building id>``) and, for LoD1.3, one per
part (``o <building id>-part<k>``), with a ``g`` group per semantic surface
type (``g RoofSurface``...). Several LoDs go in one file, one object per
building and LoD, the LoD in its name (``o <building id>_lod12``,
``o <building id>_lod22``, ``o <building id>_lod13-part<k>``). Faces are triangles oriented outward (normals
by the right-hand rule). Vertices are shared within the file.

Coordinates: world coordinates in CRS units (``local=False``, the default,
written with millimetre precision: the same numbers as the CityJSON), or,
with ``local=True``, relative to the origin given in the header comment
``# origin X Y Z`` (convenient for viewers working in single precision).

CRS: OBJ has no field for it, so it goes in the header comment ``# crs EPSG:7415``
(the authority code, else the CRS's name) and, in full, as WKT in a ``.prj``
sidecar beside the file (``buildings.obj`` -> ``buildings.prj``), written
atomically too. Without a CRS neither is written.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..datamodel import Solid
from ..errors import InputError
from ._atomic import atomic_path

__all__ = ["write_obj", "read_obj"]


def _objects(results, lods):
    """``(object name, solids)`` per building and LoD (the LoD named when there are several)."""
    for r in results:
        for lod in lods:
            tag = f"_lod{lod.replace('.', '')}" if len(lods) > 1 else ""
            if lod in r.solids and r.solids[lod] is not None:
                s = r.solids[lod]
                yield f"{r.id}{tag}", [s] if isinstance(s, Solid) else list(s)
            elif lod in r.parts:
                for k, p in enumerate(r.parts[lod]):
                    yield f"{r.id}{tag}-part{k + 1}", [p]


def write_obj(path, results, *, origin, crs=None, xy_unit=1.0, z_unit=1.0, lod="1.2",
              local: bool = False, precision: int = 3) -> None:
    """Write the ``lod`` models of ``results`` to an OBJ file, atomically.

    Parameters
    ----------
    results : sequence of BuildingResult
    origin : array_like, shape (3,)
        World coordinates of the local origin (CRS units).
    crs : pyproj.CRS, optional
        The coordinates' CRS: header comment and ``.prj`` sidecar (see module doc).
    xy_unit, z_unit : float
        Metres per CRS unit.
    lod : str or sequence of str
        ``"1.2"``, ``"2.2"`` (the Building's solid) or ``"1.3"`` (one object per
        part); several LoDs give one object per building and LoD (see module doc).
    local : bool
        Write coordinates relative to ``origin`` (see module doc).
    """
    from ..lod.mesh import triangulate_surfaces

    origin = np.asarray(origin, dtype=np.float64).reshape(3)
    unit = np.array([xy_unit, xy_unit, z_unit])
    step = 10.0 ** (-precision)
    lods = (lod,) if isinstance(lod, str) else tuple(dict.fromkeys(lod))
    if not lods:
        raise InputError("no LoD to write")
    blocks, chunks, count = [], [], 0
    for name, solids in _objects(results, lods):
        groups: dict[str, list] = {}
        for s in solids:
            world = np.asarray(s.vertices) / unit + (0.0 if local else origin)
            q = np.round(world / step).astype(np.int64)
            idx = np.arange(count, count + len(q))
            chunks.append(q)
            count += len(q)
            tris, face = triangulate_surfaces(s.vertices, s.surfaces)
            for t, f in zip(tris, face, strict=True):
                groups.setdefault(s.surfaces[f].semantic or "Surface", []).append(idx[t])
        blocks.append((name, groups))
    if chunks:
        allq = np.concatenate(chunks)
        uniq, inverse = np.unique(allq, axis=0, return_inverse=True)
        inverse = inverse.ravel()
    else:
        uniq, inverse = np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    with atomic_path(path) as tmp, open(tmp, "w", encoding="ascii") as f:
        f.write(f"# lidar2city LoD{'+'.join(lods)} buildings\n")
        if crs is not None:
            auth = crs.to_authority()
            f.write(f"# crs {':'.join(auth) if auth else crs.name}\n")
        if local:
            f.write(f"# origin {origin[0]:.{precision}f} {origin[1]:.{precision}f} "
                    f"{origin[2]:.{precision}f}\n")
        fmt = f"v %.{precision}f %.{precision}f %.{precision}f\n"
        f.write("".join(fmt % tuple(v) for v in uniq * step))
        for name, groups in blocks:
            f.write(f"o {name}\n")
            for sem, tris in groups.items():
                f.write(f"g {sem}\n")
                faces = inverse[np.array(tris)] + 1
                f.write("".join(f"f {a} {b} {c}\n" for a, b, c in faces))
    if crs is not None:
        prj = Path(path).with_suffix(".prj")
        with atomic_path(prj) as tmp, open(tmp, "w", encoding="utf-8") as f:
            f.write(crs.to_wkt())


def read_obj(path):
    """Read an OBJ file's vertices and faces: ``(vertices (N, 3), {object: [faces]})``.

    Faces are lists of 0-based vertex indices; meant for checks and tests.
    """
    from ._atomic import check_input_file

    p = check_input_file(path)
    verts, objects, current = [], {}, None
    with open(p, encoding="utf-8") as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                verts.append([float(x) for x in parts[1:4]])
            elif parts[0] == "o":
                current = " ".join(parts[1:])
                objects.setdefault(current, [])
            elif parts[0] == "f":
                objects.setdefault(current, []).append(
                    [int(tok.split("/")[0]) - 1 for tok in parts[1:]])
    return np.array(verts, dtype=np.float64).reshape(-1, 3), objects
