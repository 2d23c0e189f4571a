"""Raw 2-D roof topology from facet labels, and its simplification.

Facet labels of the points are put on a grid inside the footprint (majority
per cell, empty cells from their nearest labelled cell, small regions merged).
The boundaries between cells of different labels form a planar graph: its
vertices are where three or more regions meet (the outside counts as a region)
and where boundaries reach the footprint; its edges are the chains of cell
edges between two regions. Chains are simplified by Douglas-Peucker with their
end vertices kept, so the topology stays planar and consistent; the footprint
outline (when given) is the outer boundary.

References
----------
Main seed framework, steps 3-4 (raw topology by boundary tracking on the label
grid; Douglas-Peucker simplification keeping junctions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["LabelGrid", "label_grid", "boundary_chains", "RoofPartition", "roof_partition",
           "partition_faces"]


@dataclass(frozen=True, eq=False)
class LabelGrid:
    """Facet labels on a grid: ``labels[i, j]`` covers x0 + j*cell .. and y0 + i*cell ..

    -1 marks cells outside the footprint.
    """

    labels: np.ndarray
    x0: float
    y0: float
    cell: float

    def centers(self) -> np.ndarray:
        h, w = self.labels.shape
        jj, ii = np.meshgrid(np.arange(w), np.arange(h))
        return np.stack([self.x0 + (jj + 0.5) * self.cell, self.y0 + (ii + 0.5) * self.cell], axis=-1)


def label_grid(footprint, xy, labels, *, cell=0.5, min_cells=4) -> LabelGrid:
    """Rasterise point facet labels inside a footprint.

    Parameters
    ----------
    footprint : shapely Polygon or MultiPolygon
    xy : ndarray, shape (N, 2)
    labels : ndarray of int, shape (N,)
        Facet label per point, -1 for none.
    cell : float
        Grid cell size (m), about twice the point spacing.
    min_cells : int
        Connected regions smaller than this join their most common neighbour.
    """
    import shapely
    from scipy import ndimage

    xy = np.asarray(xy, dtype=np.float64)
    labels = np.asarray(labels)
    if len(xy) != len(labels):
        raise InputError(f"{len(xy)} points but {len(labels)} labels")
    xmin, ymin, xmax, ymax = footprint.bounds
    x0, y0 = xmin - cell, ymin - cell
    w = int(np.ceil((xmax - x0) / cell)) + 1
    h = int(np.ceil((ymax - y0) / cell)) + 1
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    inside = shapely.contains_xy(footprint, x0 + (jj + 0.5) * cell, y0 + (ii + 0.5) * cell)
    if not inside.any():
        # a footprint narrower than a cell: take the cell under its representative point
        rp = footprint.representative_point()
        inside[int((rp.y - y0) // cell), int((rp.x - x0) // cell)] = True
    grid = np.full((h, w), -1, dtype=np.int64)
    ok = labels >= 0
    if ok.any():
        n_lab = int(labels[ok].max()) + 1
        cj = np.clip(((xy[ok, 0] - x0) // cell).astype(np.int64), 0, w - 1)
        ci = np.clip(((xy[ok, 1] - y0) // cell).astype(np.int64), 0, h - 1)
        # the most common label of each cell (ties: the smallest), from the (cell, label)
        # pairs present: memory grows with the points, not with cells x labels
        pair, count = np.unique((ci * w + cj) * n_lab + labels[ok], return_counts=True)
        cell_of, lab = np.divmod(pair, n_lab)
        order = np.lexsort((lab, -count, cell_of))
        first = order[np.r_[True, cell_of[order][1:] != cell_of[order][:-1]]]
        flat = np.full(h * w, -1, dtype=np.int64)
        flat[cell_of[first]] = lab[first]
        grid = flat.reshape(h, w)
    grid[~inside] = -1
    known = grid >= 0
    if not known.any():
        grid[inside] = 0
        return LabelGrid(grid, x0, y0, cell)
    # empty cells inside take the label of the nearest labelled cell
    # (the feature transform only: its distances are not needed)
    ni, nj = ndimage.distance_transform_edt(~known, return_distances=False, return_indices=True)
    grid = np.where(inside, grid[ni, nj], -1)
    grid = _merge_small_regions(grid, inside, min_cells)
    return LabelGrid(grid, x0, y0, cell)


def _same_label_components(grid):
    """``(components, n)``: the 4-connected regions of equal labels >= 0 of ``grid``
    numbered 1..n (0 elsewhere), as ``ndimage.label(grid == lab)`` finds them label by
    label, in one call: cells sit on the even rows and columns of a lattice twice the
    size, and the lattice point between two 4-neighbours is set when they carry the
    same label, so lattice components are exactly the regions."""
    from scipy import ndimage

    h, w = grid.shape
    valid = grid >= 0
    lattice = np.zeros((2 * h - 1, 2 * w - 1), dtype=bool)
    lattice[::2, ::2] = valid
    lattice[::2, 1::2] = valid[:, 1:] & (grid[:, 1:] == grid[:, :-1])
    lattice[1::2, ::2] = valid[1:] & (grid[1:] == grid[:-1])
    comp, n = ndimage.label(lattice)
    return comp[::2, ::2], n


def _merge_small_regions(grid, inside, min_cells):
    """Regions (4-connected, one label) of fewer than ``min_cells`` cells take the most
    common label (the smallest on ties) of the cells around them inside the footprint, up
    to 4 passes, each region reading the grid as the pass found it.

    Every small region of a pass at once: the (region, ring cell) pairs of the small
    regions' cells' 4-neighbours (each ring cell once per region), then the label counts
    per region, in a fixed number of array calls however many regions there are (a
    Delft roof has ~10 of them per pass: a loop over them cost ~30 us each).
    """
    h, w = grid.shape
    inside_flat = np.asarray(inside, dtype=bool).ravel()
    for _ in range(4):
        comp, n = _same_label_components(grid)
        if n == 0:
            break
        flat_comp = comp.ravel()
        small = np.bincount(flat_comp, minlength=n + 1) < min_cells
        small[0] = False
        cells = np.flatnonzero(small[flat_comp])
        if not len(cells):
            break
        flat = grid.ravel()
        r, c = np.divmod(cells, w)
        src, nbr = [], []
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            rr, cc = r + dr, c + dc
            ok = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
            src.append(cells[ok])
            nbr.append(rr[ok] * w + cc[ok])
        src, nbr = np.concatenate(src), np.concatenate(nbr)
        # a 4-neighbour of another label is off the region (the region holds all the
        # 4-connected cells of its label)
        keep = inside_flat[nbr] & (flat[nbr] != flat[src])
        reg = flat_comp[src[keep]]
        ring = np.unique(reg * (h * w) + nbr[keep])  # each ring cell once per region
        reg, lab = ring // (h * w), flat[ring % (h * w)]
        if not len(reg):
            break
        n_lab = int(lab.max()) + 1
        key, count = np.unique(reg * n_lab + lab, return_counts=True)
        reg, lab = np.divmod(key, n_lab)
        # per region the most common label, the smallest on ties
        order = np.lexsort((lab, -count, reg))
        first = order[np.r_[True, reg[order][1:] != reg[order][:-1]]]
        new = np.full(n + 1, -1, dtype=np.int64)
        new[reg[first]] = lab[first]
        out = grid.copy()
        to = new[flat_comp[cells]]
        got = to >= 0
        out.ravel()[cells[got]] = to[got]
        grid = out
    return grid


def _boundary_graph(grid: LabelGrid):
    """The unit cell edges between different labels as a graph on the grid's corners:
    ``(u, v, pairs, deg, starts, nbr_edge, junction)`` (edge ends as corner indices, the
    sorted label pair of each edge, corner degrees, each corner's edges as
    ``nbr_edge[starts[c]:starts[c + 1]]``, junction corners), or None without such edges."""
    L = grid.labels
    h, w = L.shape
    pad = np.full((h + 2, w + 2), -1, dtype=np.int64)
    pad[1:-1, 1:-1] = L
    segs, pairs = [], []
    # vertical unit edges: between cells (i, j-1) and (i, j) of the padded grid
    a, b = pad[:, :-1], pad[:, 1:]
    ii, jj = np.nonzero(a != b)
    # corner indices in the unpadded corner lattice: node (r, c) at x0 + c*cell, y0 + r*cell
    r0 = ii - 1
    c0 = jj
    segs.append(np.column_stack([r0, c0, r0 + 1, c0]))
    pairs.append(np.sort(np.column_stack([a[ii, jj], b[ii, jj]]), axis=1))
    a, b = pad[:-1, :], pad[1:, :]
    ii, jj = np.nonzero(a != b)
    r0 = ii
    c0 = jj - 1
    segs.append(np.column_stack([r0, c0, r0, c0 + 1]))
    pairs.append(np.sort(np.column_stack([a[ii, jj], b[ii, jj]]), axis=1))
    segs = np.concatenate(segs)
    pairs = np.concatenate(pairs)
    keep = ~((pairs[:, 0] == -1) & (pairs[:, 1] == -1))
    segs, pairs = segs[keep], pairs[keep]
    if not len(segs):
        return None
    W = w + 1
    u = segs[:, 0] * W + segs[:, 1]
    v = segs[:, 2] * W + segs[:, 3]
    n_nodes = (h + 1) * W
    deg = np.bincount(u, minlength=n_nodes) + np.bincount(v, minlength=n_nodes)
    # adjacency lists
    order_u = np.concatenate([u, v])
    eid = np.concatenate([np.arange(len(u)), np.arange(len(u))])
    srt = np.argsort(order_u, kind="stable")
    starts = np.searchsorted(order_u[srt], np.arange(n_nodes + 1))
    nbr_edge = eid[srt]
    pair_key = pairs[:, 0] * 1_000_003 + pairs[:, 1]
    # a node is a junction when its degree is not 2, or its two edges separate different pairs
    junction = deg != 2
    two = np.flatnonzero(deg == 2)
    e1 = nbr_edge[starts[two]]
    e2 = nbr_edge[starts[two] + 1]
    junction[two[pair_key[e1] != pair_key[e2]]] = True
    return u, v, pairs, deg, starts, nbr_edge, junction


def boundary_chains(grid: LabelGrid):
    """Chains of cell edges between different labels, split at junctions.

    Returns
    -------
    chains : list of ndarray, shape (m, 2)
        Polyline vertices (grid corner coordinates, metres); closed loops start
        and end at the same vertex.
    pairs : list of (int, int)
        The two labels on either side of each chain (-1 for outside), sorted.
    """
    graph = _boundary_graph(grid)
    if graph is None:
        return [], []
    u, v, pairs, deg, starts, nbr_edge, junction = graph
    W = grid.labels.shape[1] + 1
    # the walk in Python lists (numpy scalars made per step cost more than the walk)
    used = [False] * len(u)
    ul, vl, jl = u.tolist(), v.tolist(), junction.tolist()
    sl, nl = starts.tolist(), nbr_edge.tolist()
    chains, chain_edges = [], []

    def walk(node, edge):
        path = [node]
        while True:
            used[edge] = True
            nxt = vl[edge] if ul[edge] == node else ul[edge]
            path.append(nxt)
            if jl[nxt]:
                return path
            s = sl[nxt]
            edge_next = nl[s] if nl[s] != edge else nl[s + 1]
            if used[edge_next]:
                return path
            node, edge = nxt, edge_next

    for node in np.flatnonzero(junction & (deg > 0)).tolist():
        for k in range(sl[node], sl[node + 1]):
            e = nl[k]
            if used[e]:
                continue
            chains.append(walk(node, e))
            chain_edges.append(e)
    # closed loops without junctions
    for e in range(len(ul)):
        if used[e]:
            continue
        chains.append(walk(ul[e], e))
        chain_edges.append(e)
    if not chains:
        return [], []
    # every chain's corners to metres in one pass
    r, c = np.divmod(np.array([x for path in chains for x in path], dtype=np.int64), W)
    xy = np.column_stack([grid.x0 + c * grid.cell, grid.y0 + r * grid.cell])
    out = np.split(xy, np.cumsum([len(path) for path in chains])[:-1])
    return out, [tuple(p) for p in pairs[np.array(chain_edges, dtype=np.int64)].tolist()]


@dataclass(eq=False)
class RoofPartition:
    """A planar partition of a footprint into roof faces.

    ``faces`` are shapely Polygons covering the footprint without overlap
    (shared edges have identical vertices); ``face_labels`` index ``planes``
    (K, 3); ``chains`` and ``chain_pairs`` are the simplified inner boundaries
    with the two labels they separate.
    """

    footprint: object
    faces: list
    face_labels: np.ndarray
    planes: np.ndarray
    chains: list
    chain_pairs: list
    raw_chains: list = None


def _extend_to_boundary(chain, boundary, max_ext):
    """Extend an open chain end lying off the footprint boundary onto it (ray, else nearest)."""
    import shapely
    from shapely.geometry import LineString, Point

    pts = [np.asarray(chain, dtype=float)]
    for end in (0, -1):
        p = pts[0][end]
        q = pts[0][1 if end == 0 else -2] if len(pts[0]) > 1 else p
        d = boundary.distance(Point(p))
        if d > max_ext or d < 1e-9:
            continue
        direction = p - q
        norm = np.hypot(*direction)
        target = None
        if norm > 1e-9:
            ray = LineString([p, p + direction / norm * (2.5 * max_ext)])
            hit = ray.intersection(boundary)
            if not hit.is_empty:
                cand = np.asarray(shapely.get_coordinates(hit))
                dist = np.hypot(*(cand - p).T)
                k = int(dist.argmin())
                if dist[k] <= 2.5 * max_ext:
                    target = cand[k] + (cand[k] - p) / max(dist[k], 1e-9) * 1e-4
        if target is None:
            near = np.asarray(boundary.interpolate(boundary.project(Point(p))).coords[0])
            v = near - p
            target = near + v / max(np.hypot(*v), 1e-9) * 1e-4
        if end == 0:
            pts[0] = np.vstack([target, pts[0]])
        else:
            pts[0] = np.vstack([pts[0], target])
    return pts[0]


def partition_faces(footprint, chains, grid: LabelGrid, *, min_area=0.5):
    """Split a footprint by chains into faces and label each face from the grid.

    Returns ``(faces, labels)``; adjacent faces with the same label are merged
    and faces smaller than ``min_area`` join their longest-shared neighbour.
    """
    import shapely
    from shapely.geometry import LineString, MultiLineString

    rings = list(shapely.get_rings(footprint))
    lines = [LineString(r.coords) for r in rings] + [LineString(c) for c in chains if len(c) >= 2]
    noded = shapely.node(MultiLineString([np.asarray(g.coords) for g in lines]))
    polys = [p for p in shapely.get_parts(shapely.polygonize(shapely.get_parts(noded)))]
    polys = [p for p in polys if p.area > 1e-9 and footprint.covers(p.representative_point())]
    centers = grid.centers()
    inside = grid.labels >= 0
    cx, cy, cl = centers[inside, 0], centers[inside, 1], grid.labels[inside]
    labels = []
    for p in polys:
        m = shapely.contains_xy(p, cx, cy)
        if m.any():
            labels.append(int(np.bincount(cl[m]).argmax()))
        else:
            rp = np.asarray(p.representative_point().coords[0])
            labels.append(int(cl[np.argmin(np.hypot(cx - rp[0], cy - rp[1]))]))
    return _merge_faces(polys, np.array(labels, dtype=np.int64), min_area)


def _merge_faces(polys, labels, min_area):
    import shapely

    polys = list(polys)
    labels = list(labels)
    # areas and boxes kept beside the faces (a face's change only when it absorbs another)
    areas = [p.area for p in polys]
    boxes = [p.bounds for p in polys]

    def apart(a, b):  # boxes disjoint: no shared boundary
        return a[2] < b[0] or b[2] < a[0] or a[3] < b[1] or b[3] < a[1]

    changed = True
    while changed and len(polys) > 1:
        changed = False
        # the pairs (i < j, in that order) that are not apart and of one label or with a
        # small face, found at once (boxes that touch or overlap: an STRtree of the faces)
        arr = np.asarray(polys, dtype=object)
        ii, jj = shapely.STRtree(arr).query(arr)
        lab, area = np.asarray(labels), np.asarray(areas)
        ok = (ii < jj) & ((lab[ii] == lab[jj]) | (np.minimum(area[ii], area[jj]) < min_area))
        ii, jj = ii[ok], jj[ok]
        order = np.lexsort((jj, ii))
        for i, j in zip(ii[order].tolist(), jj[order].tolist(), strict=True):
            same = labels[i] == labels[j]
            small = min(areas[i], areas[j]) < min_area
            shared = polys[i].boundary.intersection(polys[j].boundary).length
            if shared <= 1e-9:
                continue
            if small and not same:
                # the small face joins the neighbour it shares most boundary with
                k = i if areas[i] < areas[j] else j
                best = max((m for m in range(len(polys)) if m != k),
                           key=lambda m: 0.0 if apart(boxes[k], boxes[m]) else
                           polys[k].boundary.intersection(polys[m].boundary).length)
                if best not in (i, j):
                    continue
                keep_label = labels[j] if k == i else labels[i]
            else:
                keep_label = labels[i]
            merged = shapely.union(polys[i], polys[j])
            if merged.geom_type != "Polygon":
                continue
            polys[i] = shapely.normalize(merged)
            areas[i], boxes[i] = polys[i].area, polys[i].bounds
            labels[i] = keep_label
            del polys[j], labels[j], areas[j], boxes[j]
            changed = True
            break
    return polys, np.array(labels, dtype=np.int64)


def roof_partition(footprint, xy, labels, planes, *, cell=0.5, simplify=None, min_cells=4,
                   min_face_area=None) -> RoofPartition:
    """Raw topology, simplified, as a partition of the footprint into roof faces.

    Parameters
    ----------
    footprint : shapely Polygon or MultiPolygon (local metres)
    xy, labels : point positions (N, 2) and facet labels (N,), -1 for none
    planes : ndarray (K, 3)
    cell : float
        Label grid cell (m).
    simplify : float, optional
        Douglas-Peucker tolerance (m); default ``cell``.
    min_face_area : float, optional
        Faces smaller than this (m2) join a neighbour; default 4 cells.
    """
    import shapely
    from shapely.geometry import LineString

    simplify = cell if simplify is None else simplify
    min_face_area = 4 * cell * cell if min_face_area is None else min_face_area
    grid = label_grid(footprint, xy, labels, cell=cell, min_cells=min_cells)
    raw, pairs = boundary_chains(grid)
    boundary = footprint.boundary
    chains, chain_pairs, raw_inner = [], [], []
    for c, p in zip(raw, pairs, strict=True):
        if -1 in p:
            continue  # the footprint itself is the outer boundary
        raw_inner.append(c)
        closed = len(c) > 3 and np.allclose(c[0], c[-1])
        if closed:
            s = shapely.Polygon(c).simplify(simplify, preserve_topology=True)
            if s.is_empty or s.area < min_face_area:
                continue
            chains.append(np.asarray(s.exterior.coords))
        else:
            s = np.asarray(LineString(c).simplify(simplify, preserve_topology=False).coords)
            s = _extend_to_boundary(s, boundary, max_ext=1.5 * cell)
            chains.append(s)
        chain_pairs.append(p)
    faces, face_labels = partition_faces(footprint, chains, grid, min_area=min_face_area)
    return RoofPartition(footprint, faces, face_labels, np.asarray(planes, dtype=float), chains,
                         chain_pairs, raw_inner)
