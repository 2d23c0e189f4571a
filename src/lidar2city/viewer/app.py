"""The viewer: a viser server showing a model and its points, with semi-automatic editing.

:class:`Viewer` owns the server, the scene and the GUI. Every edit goes through
:class:`lidar2city.tools.edit.EditSession` — the same refit as ``lidar2city
edit`` and ``reconstruct --edits`` — and a refit is only a candidate until it is
accepted (saved atomically, edit appended to EDITS.json) or undone. The actions
are methods (:meth:`Viewer.select`, :meth:`Viewer.refit_primitive`,
:meth:`Viewer.rebuild_from_outline`, :meth:`Viewer.accept`, :meth:`Viewer.undo`)
that the GUI's callbacks call and tests can call directly.
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from pathlib import Path

import numpy as np

from ..errors import DependencyError, InputError, Lidar2CityError, NotEditableError
from . import scene

logger = logging.getLogger(__name__)

__all__ = ["Viewer", "require_viser"]

_SELECTED = (255, 225, 0)
#: above this many points in the tiles the viewer holds only the points it shows (an even
#: sample read tile by tile) and reads a building's points when it needs them (its RMSE, a
#: refit), as ``lidar2city edit`` does: all 17 M points of a 144-tile area held at once
#: would take ~2 GB and a minute to start
LOAD_ALL_POINTS = 5_000_000


def _lod_node(lod) -> str:
    """The scene node prefix of a LoD's meshes: ``"1.2"`` -> ``"lod12"``, ``1`` -> ``"lod1"``."""
    return "lod" + "".join(c for c in str(lod) if c.isalnum())


def _lod_key(lod):
    try:
        return (float(lod), str(lod))
    except ValueError:
        return (math.inf, str(lod))


def require_viser():
    """Import viser, or raise :class:`DependencyError` naming the extra to install."""
    try:
        import viser
    except ImportError:
        raise DependencyError("the viewer needs viser: pip install lidar2city[view]") from None
    return viser


def _model_from_doc(doc):
    from ..io.cityjson import CityModel, _apply_transform

    return CityModel(str(doc.get("version", "")), _apply_transform(doc.get("vertices") or [],
                                                                   doc.get("transform")),
                     doc["CityObjects"], doc.get("metadata") or {},
                     (doc.get("metadata") or {}).get("referenceSystem"), {}, doc.get("transform"))


def _plain_lighting(scene_api):
    """Directional lights without shadows and an ambient light, no environment map.

    viser's default environment map (an HDR image prefiltered in the browser) keeps
    the canvas nearly transparent until it is ready: seconds with software WebGL.
    Flat-shaded buildings read well under plain lights, which cost nothing to set up.
    """
    scene_api.configure_environment_map(None)
    scene_api.configure_default_lights(True, cast_shadow=False)
    scene_api.add_light_ambient("/light/ambient", intensity=2.4)


def _rmse_child(viewer, conn):
    """The forked child of :meth:`Viewer._start_rmse`: compute, send, exit."""
    try:
        os.nice(19)
    except OSError:
        pass
    try:
        conn.send(viewer._rmse_values())
    finally:
        conn.close()


class Viewer:
    """A local web viewer (and editor) of a lidar2city CityJSON model.

    Parameters
    ----------
    model : path
        ``.city.json`` (or ``.city.jsonl``, view only).
    points : sequence of paths
        The LAS/LAZ tiles: shown (subsampled) and needed for editing.
    footprints : path, optional
        The footprint file given to ``reconstruct`` (original outlines for edits).
    edits : path, optional
        EDITS.json accepted edits are appended to (default ``<model>.edits.json``).
    output : path, optional
        Where accepted edits write the model (default: the model, atomically).
    host, port
        Where to listen; 127.0.0.1 by default (loopback only).
    max_points : int
        Points shown at most (evenly subsampled).
    crs, id_field
        As for ``lidar2city edit``.
    """

    def __init__(self, model, *, points=(), footprints=None, edits=None, output=None,
                 host="127.0.0.1", port=8080, max_points=200_000, crs=None, id_field=None):
        self.viser = require_viser()
        from ..io.cityjson import read_cityjson

        self.path = Path(model)
        self.session = None
        #: why edits cannot apply (None: they can)
        self.read_only = None if points else "View only: start with --points to edit."
        if points:
            from ..tools.edit import EditSession

            try:
                self.session = EditSession(model, list(points), footprints=footprints,
                                           crs=crs, id_field=id_field)
                self.model = _model_from_doc(self.session.doc)
            except NotEditableError as exc:  # another tool's model: shown with its points
                self.read_only = f"View only: {exc}."
                logger.warning("%s", self.read_only)
        if self.session is None:
            self.model = read_cityjson(model)
        name = self.path.name
        for end in (".city.json", ".city.jsonl", ".json"):
            if name.endswith(end):
                name = name[: -len(end)]
                break
        self.edits_path = Path(edits) if edits else self.path.with_name(f"{name}.edits.json")
        self.output = output
        self.host, self.port = host, int(port)
        if self.host not in ("127.0.0.1", "localhost", "::1"):
            logger.warning("the viewer will listen on %s: anyone who can reach this machine "
                           "can see and edit the model", self.host)
        self.max_points = int(max_points)
        self.server = None
        #: LoD -> {colour: (ids, mesh handle)}: the buildings drawn, one mesh per colour
        self.groups: dict[str, dict] = {}
        self._meshes: dict[str, dict] = {}   # LoD -> {id: (vertices, triangles) or None}
        self._pickable: dict[str, tuple] = {}  # LoD -> (vertices, triangles, owner, ids)
        self._dirty: dict[str, set] = {}     # LoD -> ids whose mesh changed since drawn
        self.attrs = {bid: dict(self.model.objects[bid].get("attributes") or {})
                      for bid in self.model.buildings()}
        # CityJSON 1.0 (3dfier) writes "lod": 1
        self.lods = sorted({str(g.get("lod")) for o in self.model.objects.values()
                            if o.get("type") in ("Building", "BuildingPart")
                            for g in o.get("geometry", []) or [] if g.get("lod") is not None},
                           key=_lod_key)
        v = self.model.vertices
        self.origin = (np.floor(v.min(axis=0)) if len(v) else np.zeros(3))
        self.extent = (v.max(axis=0) - v.min(axis=0)) if len(v) else np.ones(3)
        self._reader = None
        if points:
            self._reader = (self.session.reader if self.session is not None else
                            self._points_reader(list(points), crs))
            self._check_points_cover(v)
        self.selected = None
        self.pending = None          # (edit, result, previous attributes, previous meshes)
        self.outline = None          # (N, 2) world vertices of the outline being edited
        self.vertex = 0
        self.status = ""
        self.lock = threading.RLock()
        self._gizmos = []
        self._placed = None
        self.cloud = self.classes = None
        self._lazy = False           # the tiles' points are read per building (big areas)
        self._rmse_thread = self._rmse_child = None
        self._refitted = set()       # ids whose refit was accepted (their RMSE is their own)
        self._quiet_worst = False
        self._candidate = {}   # LoD -> {id: mesh} of the pending refit

    # ------------------------------------------------------------------ data
    def _points_reader(self, points, crs):
        """The tiles of a model that cannot be edited, read only to be shown."""
        from ..io.las import TileReader, scan_tiles

        if crs is None:
            crs = (self.model.metadata or {}).get("referenceSystem")
        return TileReader(scan_tiles(points, crs=crs), origin=self.origin)

    def _check_points_cover(self, vertices):
        """Refuse tiles that do not meet the model (another area, or another CRS)."""
        if not len(vertices):
            return
        wb = self._reader.world_bounds()
        lo, hi = vertices[:, :2].min(axis=0), vertices[:, :2].max(axis=0)
        if wb[0] > hi[0] or wb[2] < lo[0] or wb[1] > hi[1] or wb[3] < lo[1]:
            model_crs = (self.model.metadata or {}).get("referenceSystem") or "no CRS"
            raise InputError(
                f"the points (--points) do not cover the model: points x {wb[0]:.0f}..{wb[2]:.0f}"
                f" y {wb[1]:.0f}..{wb[3]:.0f}, model x {lo[0]:.0f}..{hi[0]:.0f} y "
                f"{lo[1]:.0f}..{hi[1]:.0f} (model CRS: {model_crs}): tiles of another area "
                "or CRS?")

    def _world_solids(self, bid, lod):
        return self.model.solids(bid, lod=lod, include_children=True)

    def _result_world_solids(self, result, lod):
        from ..datamodel import Solid

        r = self.session.reader
        unit = np.array([r.xy_unit, r.xy_unit, r.z_unit])
        got = result.solids.get(lod)
        solids = [] if got is None else ([got] if isinstance(got, Solid) else list(got))
        solids += list(result.parts.get(lod, []))
        return [Solid(r.origin + np.asarray(s.vertices) / unit, s.surfaces) for s in solids]

    def _building_points(self, bid):
        """World building points inside the building's outline (for its RMSE)."""
        import shapely
        from shapely.geometry import mapping, shape

        if self.classes is None or self.session is None:
            return None
        fp = shape(self.session.footprint(bid))
        if self._lazy:  # read around the building, classified as a refit sees it
            cloud, classes = self.session.points(mapping(fp))
            r = self.session.reader
            xyz = np.column_stack([r.origin[:2] + cloud.xyz[:, :2] / r.xy_unit,
                                   cloud.xyz[:, 2:] / r.z_unit + r.origin[2]])
            keep = np.isin(classes, self.session.context.lod1.building_classes)
            xyz = xyz[keep]
            return xyz[shapely.contains_xy(fp, xyz[:, 0], xyz[:, 1])]
        xyz = self._world_xyz
        x0, y0, x1, y1 = fp.bounds
        # the building points' x strip of the outline, in the cloud's order
        lo = np.searchsorted(self._build_x, x0, side="left")
        hi = np.searchsorted(self._build_x, x1, side="right")
        idx = self._build_idx[lo:hi]
        idx = np.sort(idx[(xyz[idx, 1] >= y0) & (xyz[idx, 1] <= y1)])
        return xyz[idx[shapely.contains_xy(fp, xyz[idx, 0], xyz[idx, 1])]]

    def _rmse_of(self, bid, solids):
        """RMSE in metres of the building's points to ``solids`` (world coordinates)."""
        from ..datamodel import Solid
        from ..metrics.model import model_rmse

        pts = self._building_points(bid)
        if pts is None or not len(pts) or not solids:
            return None
        # in metres about the viewer's origin, as reconstruct's rmse_lod* (a feet CRS)
        r = self._reader
        unit = np.array([r.xy_unit, r.xy_unit, r.z_unit])
        solids = [Solid((np.asarray(s.vertices) - self.origin) * unit, s.surfaces)
                  for s in solids]
        return round(float(model_rmse((pts - self.origin) * unit, solids)), 4)

    def _rmse_values(self) -> dict:
        """``{id: RMSE}`` of each building's points to its model at the top LoD."""
        top = self.lods[-1] if self.lods else None
        out = {}
        for bid in list(self.attrs):
            try:
                value = self._rmse_of(bid, self._world_solids(bid, top))
            except Lidar2CityError:
                continue
            if value is not None:
                out[bid] = value
        return out

    def _compute_all_rmse(self, values=None):
        """Set every building's ``viewer_rmse`` (``values`` when already computed) but
        those refitted meanwhile, and recolour when colouring by RMSE."""
        values = self._rmse_values() if values is None else values
        with self.lock:
            busy = {str(self.pending[1].id)} if self.pending is not None else set()
            for bid, value in values.items():
                if bid not in self._refitted and bid not in busy:
                    self.attrs[bid]["viewer_rmse"] = value
            if self.server is not None and self.colour_by.value == "RMSE":
                self.recolour()

    def _start_rmse(self):
        """Compute the RMSEs in the background: in a forked child at the lowest CPU
        priority where the platform forks and no other thread runs yet (no lock shared
        with the server, so the browser loading the page is not slowed down), else
        in a thread.
        ``self._rmse_thread`` applies the values when they arrive."""
        import multiprocessing as mp

        # forking a process that runs other threads can deadlock the child: a thread then
        if "fork" not in mp.get_all_start_methods() or threading.active_count() > 1:
            self._rmse_thread = threading.Thread(target=self._compute_all_rmse, daemon=True)
            self._rmse_thread.start()
            return
        ctx = mp.get_context("fork")
        recv, send = ctx.Pipe(duplex=False)
        self._rmse_child = ctx.Process(target=_rmse_child, args=(self, send), daemon=True)
        self._rmse_child.start()
        send.close()

        def wait():
            try:
                values = recv.recv()
            except (EOFError, OSError):  # the child died (or the viewer was stopped)
                logger.warning("the viewer's RMSE computation ended without a result")
                return
            finally:
                recv.close()
                self._rmse_child.join()
            self._compute_all_rmse(values)

        self._rmse_thread = threading.Thread(target=wait, daemon=True)
        self._rmse_thread.start()

    # ------------------------------------------------------------------ server
    def start(self, *, compute_rmse: bool = True) -> str:
        """Start the server, build the scene and GUI; returns the URL."""
        viser = self.viser
        if self._reader is not None:
            self._load_points()
        if self.session is not None:
            if compute_rmse:
                self._start_rmse()  # (forks before the server starts its threads)
        # the RMSEs may arrive while the GUI and scene are built: they wait for the lock
        with self.lock:
            self.server = viser.ViserServer(host=self.host, port=self.port, verbose=False)
            srv = self.server
            if srv.get_port() != self.port:  # viser takes the next free port
                logger.warning("port %d is in use: the viewer listens on %d", self.port,
                               srv.get_port())
                self.port = srv.get_port()
            srv.scene.set_up_direction("+z")
            _plain_lighting(srv.scene)
            d = float(max(self.extent[0], self.extent[1], 10.0))
            centre = self.extent / 2
            cam = srv.initial_camera
            cam.position = (centre[0] - 0.3 * d, centre[1] - 1.1 * d, centre[2] + 0.9 * d)
            cam.look_at = (centre[0], centre[1], 0.0)
            # viser's far plane is 1,000 units: a 2 km area was drawn blank from 2.9 km away
            cam.far = max(1000.0, 4.0 * float(np.hypot(d, max(self.extent[2], 1.0))) + 100.0)
            cam.near = max(0.01, d / 4000.0)  # and the depth buffer's precision kept
            self._build_gui()
            self._draw_buildings()
            if self._reader is not None:
                self._draw_points()
        return f"http://{'127.0.0.1' if self.host in ('0.0.0.0', '::') else self.host}:{self.port}"

    def stop(self):
        child = getattr(self, "_rmse_child", None)
        if child is not None and child.is_alive():
            child.terminate()
        if self.server is not None:
            self.server.stop()
            self.server = None

    def _draw_buildings(self, lod=None):
        """Every building at ``lod`` (default: the LoD shown), meshed when first shown and
        drawn as one mesh per colour (a few scene nodes, not one per building)."""
        lod = lod or self.lod_choice.value
        if lod not in self.lods or lod in self._meshes:
            return
        # a building with a refit pending already has its candidate's mesh at every LoD
        have = self._pending_meshes.get(lod, {})
        todo = {bid: self._world_solids(bid, lod) for bid in self.attrs if bid not in have}
        made = scene.building_meshes(todo, self.origin)
        self._meshes[lod] = {**{bid: made.get(bid) for bid in todo}, **have}
        self._sync_groups(lod, self._colours())

    @property
    def _pending_meshes(self):
        return self._candidate if self.pending is not None else {}

    def _colours(self):
        """Each building's colour now (the selected one stands out); updates the legend."""
        colours, legend = scene.colours_for(scene.attribute_values(self.attrs, self.colour_by.value))
        self.legend.content = scene.legend_markdown(self.colour_by.value, legend)
        if self.selected in colours:
            colours[self.selected] = _SELECTED
        return colours

    def _sync_groups(self, lod, colours):
        """Send the meshes of ``lod``'s colour groups that changed (membership or a
        building's mesh) and remove the groups no longer used."""
        meshes = {b: m for b, m in self._meshes[lod].items() if m is not None}
        want = scene.group_by_colour({b: colours.get(b, (170, 170, 170)) for b in meshes})
        have = self.groups.setdefault(lod, {})
        dirty = self._dirty.pop(lod, set())
        visible = lod == self.lod_choice.value
        with self.server.atomic():
            for colour in [c for c in have if c not in want]:
                have.pop(colour)[1].remove()
            for colour, ids in want.items():
                old = have.get(colour)
                if old is not None and old[0] == tuple(ids) and not dirty.intersection(ids):
                    continue
                v, t, _ = scene.merge_meshes(meshes, ids)
                name = "/{}/{:02x}{:02x}{:02x}".format(_lod_node(lod), *colour)
                h = self.server.scene.add_mesh_simple(
                    name, v, t, color=colour, flat_shading=True, cast_shadow=False,
                    receive_shadow=False, visible=visible)
                h.on_click(self._clicked)
                have[colour] = (tuple(ids), h)

    def scene_nodes(self) -> list[str]:
        """Names of the scene nodes that make the scene shown (its building meshes and
        the points when shown): what a page must have drawn to be complete."""
        with self.lock:
            names = [h.name for _, h in self.groups.get(self.lod_choice.value, {}).values()]
            if getattr(self, "points_handle", None) is not None and self.show_points.value:
                names.append(self.points_handle.name)
            return names

    def scene_prefixes(self) -> list[str]:
        """:meth:`scene_nodes` as name prefixes (``"/lod22/"``, ``"/points"``), which stay
        right when a recolour renames the meshes."""
        with self.lock:
            names = [f"/{_lod_node(self.lod_choice.value)}/"] if self.groups else []
            if getattr(self, "points_handle", None) is not None and self.show_points.value:
                names.append(self.points_handle.name)
            return names

    def _clicked(self, event):
        """A click on a building mesh: the building whose triangle the click's ray hits first."""
        bid = self.pick(event.ray_origin, event.ray_direction)
        if bid is not None:
            self.select(bid)

    def pick(self, origin, direction, lod=None):
        """The id of the building of ``lod`` (default: shown) a display-frame ray hits
        first, or None."""
        lod = lod or self.lod_choice.value
        with self.lock:
            if lod not in self._meshes:
                return None
            if lod not in self._pickable:
                ids = sorted(b for b, m in self._meshes[lod].items() if m is not None)
                self._pickable[lod] = (*scene.merge_meshes(self._meshes[lod], ids), ids)
            v, t, owner, ids = self._pickable[lod]
        k = scene.ray_pick(v, t, origin, direction)
        return None if k is None else ids[owner[k]]

    def _sampled_points(self):
        """An even sample of about ``max_points`` of the tiles' points, read tile by tile:
        ``(world xyz, classes from the files)``."""
        from ..io.las import read_tile

        r = self._reader
        total = max(r.count, 1)
        worlds, classes = [np.zeros((0, 3))], [np.zeros(0, np.uint8)]
        for t in r.tiles:
            if not t.count:
                continue
            tile = read_tile(t.path)
            part = tile.take(scene.subsample(len(tile), -(-len(tile) * self.max_points // total)))
            worlds.append(part.world())
            classes.append(part.attrs.get("classification", np.zeros(len(part), np.uint8)))
        return np.concatenate(worlds), np.concatenate(classes).astype(np.uint8)

    def _load_points(self):
        if self.session is None or self._reader.count > LOAD_ALL_POINTS:
            # shown only (the files' classes); a big area's buildings are read when needed
            self._lazy = self.session is not None
            self._world_xyz, self.classes = self._sampled_points()
            return
        world, cloud, classes = self.session.load_area()
        self.cloud, self.classes = cloud, classes
        self._world_xyz = world
        self._building_mask = np.isin(classes, self.session.context.lod1.building_classes)
        # the building points sorted by x: a building's points are a strip, not a scan
        build = np.flatnonzero(self._building_mask)
        self._build_idx = build[np.argsort(world[build, 0], kind="stable")]
        self._build_x = world[self._build_idx, 0]

    def _draw_points(self):
        classes = self.classes
        idx = scene.subsample(len(self._world_xyz), self.max_points)
        if not len(idx):  # --max-points 0: no cloud (an empty one is never "drawn")
            return
        pts = self._world_xyz[idx] - self.origin
        # about the cloud's centre, float16 keeps 6 cm within 128 m (half the bytes)
        mid = np.round((pts.min(axis=0) + pts.max(axis=0)) / 2) if len(pts) else np.zeros(3)
        half = float(np.abs(pts - mid).max()) if len(pts) else 0.0
        self.points_handle = self.server.scene.add_point_cloud(
            "/points", pts - mid, scene.class_colours(classes[idx]),
            point_size=0.25 / self._reader.xy_unit,  # 25 cm in the CRS's unit
            precision="float16" if half <= 128.0 else "float32", position=tuple(mid),
            visible=self.show_points.value)

    # ------------------------------------------------------------------ GUI
    def _build_gui(self):
        gui = self.server.gui
        with gui.add_folder("Display"):
            self.lod_choice = gui.add_dropdown("LoD", [f"{v}" for v in self.lods] or ["-"],
                                               initial_value=self.lods[-1] if self.lods else "-")
            self.colour_by = gui.add_dropdown("Colour by", scene.COLOUR_BY, initial_value="RMSE")
            self.show_points = gui.add_checkbox("Points", self._reader is not None,
                                                disabled=self._reader is None)
            self.legend = gui.add_markdown("")
        with gui.add_folder("Worst buildings"):
            worst = scene.worst_buildings(self.attrs)
            self.worst = gui.add_dropdown("Building", [self._worst_label(b, r) for b, r in worst]
                                          or ["-"])
            self.next_worst = gui.add_button("Next worst")
        with gui.add_folder("Edit", visible=True):
            self.status_md = gui.add_markdown(self.read_only or "Click a building." + (
                "" if self.session is None or self.session._footprints is not None else
                " Without --footprints the outlines are the model's; `reconstruct --edits` "
                "re-applies edits only with the footprint file the model was made from (a "
                "model with traced footprints keeps its edits in this file and EDITS.json)."))
            self.kind = gui.add_dropdown("Primitive", ("auto", "box", "gable", "hip", "shed",
                                                       "prism"), initial_value="auto")
            self.place = gui.add_checkbox("Start from a placed primitive", False)
            self.p_len = gui.add_number("Length (m)", 10.0, min=0.5, step=0.1, visible=False)
            self.p_wid = gui.add_number("Width (m)", 6.0, min=0.5, step=0.1, visible=False)
            self.refit_btn = gui.add_button("Refit as primitive", disabled=self.session is None)
            self.outline_btn = gui.add_button("Edit outline", disabled=self.session is None)
            self.add_v = gui.add_button("Add vertex", visible=False)
            self.del_v = gui.add_button("Delete vertex", visible=False)
            self.rebuild_btn = gui.add_button("Rebuild from outline", visible=False)
            self.accept_btn = gui.add_button("Accept", color="green", disabled=True)
            self.undo_btn = gui.add_button("Undo", color="red", disabled=True)
        with gui.add_folder("Building"):
            self.info = gui.add_markdown("")

        for control, action in ((self.lod_choice, self._show_lod), (self.colour_by, self.recolour),
                                (self.show_points, self._toggle_points),
                                (self.worst, self._select_worst), (self.place, self._toggle_place),
                                (self.p_len, self._draw_placed_box),
                                (self.p_wid, self._draw_placed_box)):
            control.on_update(lambda _, action=action: action())
        for button, action in ((self.next_worst, self._next_worst),
                               (self.refit_btn, lambda: self.refit_primitive(self.kind.value)),
                               (self.outline_btn, self.start_outline),
                               (self.add_v, self.add_vertex), (self.del_v, self.delete_vertex),
                               (self.rebuild_btn, self.rebuild_from_outline),
                               (self.accept_btn, self.accept), (self.undo_btn, self.undo)):
            button.on_click(lambda _, action=action: action())

    def worst_order(self):
        """Every building, worst first: ``[(id, RMSE or None)]``."""
        with self.lock:
            return scene.worst_buildings(self.attrs, n=len(self.attrs))

    @staticmethod
    def _worst_label(bid, rmse):
        return f"{bid} (RMSE {rmse:.2f} m)" if rmse is not None else f"{bid}"

    def _show_lod(self):
        with self.lock:
            self._draw_buildings(self.lod_choice.value)
            for lod, groups in self.groups.items():
                for _, h in groups.values():
                    h.visible = lod == self.lod_choice.value

    def _toggle_points(self):
        if getattr(self, "points_handle", None) is not None:
            self.points_handle.visible = self.show_points.value

    def _select_worst(self):
        if self._quiet_worst:
            return
        bid = self.worst.value.split(" ")[0]
        if bid in self.attrs and bid != self.selected:
            self.select(bid, focus=True)

    def _next_worst(self):
        opts = list(self.worst.options)
        if self.worst.value in opts:
            self.worst.value = opts[(opts.index(self.worst.value) + 1) % len(opts)]

    def recolour(self):
        """Colour every building by the chosen attribute; the selected one stands out."""
        with self.lock:
            colours = self._colours()
            for lod in self._meshes:
                self._sync_groups(lod, colours)
            worst = scene.worst_buildings(self.attrs)
            labels = [self._worst_label(b, r) for b, r in worst] or ["-"]
            if list(self.worst.options) != labels:
                self._quiet_worst = True
                try:
                    self.worst.options = labels
                finally:
                    self._quiet_worst = False

    def _message(self, text, *, error=False):
        self.status = text
        self.status_md.content = (f"<span style='color:#c00'>**Error:** {text}</span>" if error
                                  else text)
        if error and self.server is not None:
            for client in self.server.get_clients().values():
                client.add_notification("Edit refused", text, color="red", auto_close_seconds=8)

    # ------------------------------------------------------------------ actions
    def select(self, bid, *, focus=False):
        """Show a building's attributes (and fly to it with ``focus``)."""
        with self.lock:
            if bid not in self.attrs:
                self._message(f"unknown building id {bid!r}", error=True)
                return
            if self.pending is not None and self.pending[1].id != bid:
                self.undo()
            self._end_outline()
            self.selected = bid
            self.info.content = scene.attributes_markdown(bid, self.attrs[bid])
            if self.session is not None and self.pending is None:
                self._message(f"Building {bid}: refit it as a primitive, or edit its outline.")
            self.recolour()
            if self._placed is not None:
                self._toggle_place()
        if focus and self.server is not None:
            solids = self._world_solids(bid, self.lods[-1]) if self.lods else []
            if solids:
                c = np.concatenate([s.vertices for s in solids]).mean(axis=0) - self.origin
                for client in self.server.get_clients().values():
                    client.camera.look_at = tuple(c)
                    client.camera.position = (c[0] - 25.0, c[1] - 35.0, c[2] + 30.0)

    def _need(self, what="edit"):
        if self.session is None:
            raise InputError(self.read_only)
        if self.selected is None:
            raise InputError(f"click a building to {what} first")

    def _approx(self):
        """The placed primitive's approximate parameters (world x, y; azimuth; sizes)."""
        if not self.place.value or self._placed is None:
            return {}
        p = np.asarray(self._placed.position, dtype=np.float64) + self.origin
        w, x, y, z = self._placed.wxyz
        az = math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
        return {"x": float(p[0]), "y": float(p[1]), "azimuth": round(az, 6),
                "length": float(self.p_len.value), "width": float(self.p_wid.value)}

    def refit_primitive(self, kind):
        """Refit the selected building as ``kind`` (by least squares, or from the placed
        primitive); returns the seconds taken or None on error (the message says why)."""
        try:
            self._need("refit")
            edit = self.session.make_edit(self.selected, primitive=kind, approximate=self._approx())
        except Lidar2CityError as exc:
            self._message(str(exc), error=True)
            return None
        return self._run(edit)

    def _run(self, edit):
        t0 = time.perf_counter()
        with self.lock:
            try:
                result = self.session.refit(edit)
            except Lidar2CityError as exc:
                self._message(str(exc), error=True)
                return None
            if self.pending is not None:
                self.undo()
            bid = str(result.id)
            before = (dict(self.attrs[bid]), {lod: self._world_solids(bid, lod) for lod in self.lods})
            attrs = {k: v for k, v in result.attributes.items()}
            attrs["status"] = result.status
            new = {lod: self._result_world_solids(result, lod) for lod in self.lods}
            rmse = self._rmse_of(bid, new.get(self.lods[-1]) or [])
            if rmse is not None:
                attrs["viewer_rmse"] = rmse
            self.pending = (edit, result, before[0], before[1])
            self._show_solids(bid, new)
            self.attrs[bid] = attrs
            self._end_outline()
            self.info.content = scene.attributes_markdown(bid, attrs)
            self.accept_btn.disabled = False
            self.undo_btn.disabled = False
            dt = time.perf_counter() - t0
            old = scene.attribute_values({bid: before[0]}, "RMSE")[bid]
            self._message(f"{edit.describe()} in {dt:.2f} s: RMSE "
                          f"{'-' if old is None else f'{old:.3f}'} -> "
                          f"{'-' if rmse is None else f'{rmse:.3f}'} m, "
                          f"{'valid' if attrs.get('valid', True) is not False else 'INVALID'}"
                          f"{', LoD2.2 fallback: ' + attrs['lod22_fallback'] if attrs.get('lod22_fallback') else ''}"
                          ". Accept or Undo.")
            self.recolour()
            return dt

    def _show_solids(self, bid, solids_by_lod, *, candidate=True):
        """Show ``bid`` with these solids at each LoD (the candidate of a refit, or with
        ``candidate=False`` the model's again); drawn at the next :meth:`recolour`."""
        meshes = {lod: scene.building_meshes({bid: s}, self.origin).get(bid)
                  for lod, s in solids_by_lod.items()}
        self._candidate = {lod: {bid: m} for lod, m in meshes.items()} if candidate else {}
        for lod, m in meshes.items():
            if lod in self._meshes:
                self._meshes[lod][bid] = m
                self._dirty.setdefault(lod, set()).add(bid)
                self._pickable.pop(lod, None)

    def accept(self):
        """Save the pending refit (model written atomically and validated, edit appended)."""
        with self.lock:
            if self.pending is None:
                self._message("nothing to accept", error=True)
                return None
            edit, result, _, _ = self.pending
            try:
                out = self.session.save(result, edit, output=self.output, edits=self.edits_path)
            except Lidar2CityError as exc:
                self._message(str(exc), error=True)
                return None
            self.model = _model_from_doc(self.session.doc)
            bid = str(result.id)
            self._refitted.add(bid)
            viewer_rmse = self.attrs[bid].get("viewer_rmse")
            self.attrs[bid] = dict(self.model.objects[bid].get("attributes") or {})
            if viewer_rmse is not None:
                self.attrs[bid]["viewer_rmse"] = viewer_rmse
            self.pending = None
            self.accept_btn.disabled = self.undo_btn.disabled = True
            self._message(f"Saved {out.name}; edit appended to {self.edits_path.name}.")
            self.recolour()
            return out

    def undo(self):
        """Discard the pending refit: the building is shown as it is in the model again."""
        with self.lock:
            if self.pending is None:
                return
            edit, result, attrs, solids = self.pending
            self.pending = None
            bid = str(result.id)
            self.attrs[bid] = attrs
            self._show_solids(bid, solids, candidate=False)
            self.info.content = scene.attributes_markdown(bid, attrs)
            self.accept_btn.disabled = self.undo_btn.disabled = True
            self._message("Undone.")
            self.recolour()

    # -- outline editing
    def start_outline(self):
        """Show the selected building's outline with a handle per vertex."""
        from shapely.geometry import shape

        try:
            self._need("edit the outline of")
            geom = shape(self.session.footprint(self.selected))
        except Lidar2CityError as exc:
            self._message(str(exc), error=True)
            return
        if geom.geom_type != "Polygon":
            geom = max(geom.geoms, key=lambda g: g.area)
        self._holes = [list(r.coords) for r in geom.interiors]
        self.outline = np.asarray(geom.exterior.coords, dtype=np.float64)[:-1, :2]
        self.vertex = 0
        for b in (self.add_v, self.del_v, self.rebuild_btn):
            b.visible = True
        self._draw_outline()
        self._message("Drag the handles; Add / Delete vertex act after / on the last one moved; "
                      "then Rebuild from outline.")

    def _outline_z(self):
        a = self.attrs.get(self.selected, {})
        z = a.get("roof_height_max", a.get("roof_height", 0.0))
        return float(z if isinstance(z, (int, float)) else 0.0) + 0.5 - self.origin[2]

    def _draw_outline(self):
        for g in self._gizmos:
            g.remove()
        self._gizmos = []
        if self.outline is None:
            return
        z = self._outline_z()
        local = self.outline - self.origin[:2]
        self._line = self.server.scene.add_line_segments(
            "/outline", self._outline_segments(), (255, 40, 40), thickness=3.0,
            thickness_units="screen")
        self._gizmos.append(self._line)
        for i, (x, y) in enumerate(local):
            g = self.server.scene.add_transform_controls(
                f"/outline_v{i}", scale=1.5, active_axes=(True, True, False),
                disable_rotations=True, position=(float(x), float(y), z))
            g.on_update(lambda _e, i=i, g=g: self._moved(i, g))
            self._gizmos.append(g)

    def _moved(self, i, g):
        with self.lock:
            if self.outline is None or i >= len(self.outline):
                return
            self.outline[i] = np.asarray(g.position[:2], dtype=np.float64) + self.origin[:2]
            self.vertex = i
            self._line.points = self._outline_segments()

    def _outline_segments(self):
        """The outline's edges, (N, 2, 3) float32 in the display frame, above the roof."""
        z = self._outline_z()
        local = self.outline - self.origin[:2]
        ring = np.vstack([local, local[:1]])
        return np.stack([np.column_stack([ring[:-1], np.full(len(ring) - 1, z)]),
                         np.column_stack([ring[1:], np.full(len(ring) - 1, z)])],
                        axis=1).astype(np.float32)

    def move_vertex(self, i, xy):
        """Move outline vertex ``i`` to world ``xy`` (what dragging its handle does)."""
        self.outline[i] = np.asarray(xy, dtype=np.float64)
        self.vertex = i
        self._draw_outline()

    def add_vertex(self):
        """Insert a vertex in the middle of the edge after the last vertex moved."""
        if self.outline is None:
            return
        i = self.vertex
        mid = (self.outline[i] + self.outline[(i + 1) % len(self.outline)]) / 2
        self.outline = np.insert(self.outline, i + 1, mid, axis=0)
        self.vertex = i + 1
        self._draw_outline()

    def delete_vertex(self):
        """Delete the last vertex moved (an outline keeps at least 3)."""
        if self.outline is None:
            return
        if len(self.outline) <= 3:
            self._message("an outline needs at least 3 vertices", error=True)
            return
        self.outline = np.delete(self.outline, self.vertex, axis=0)
        self.vertex = self.vertex % len(self.outline)
        self._draw_outline()

    def rebuild_from_outline(self):
        """Re-run the selected building's reconstruction from the edited outline."""
        if self.outline is None:
            self._message("press Edit outline first", error=True)
            return None
        ring = [[float(x), float(y)] for x, y in self.outline] + \
            [[float(self.outline[0, 0]), float(self.outline[0, 1])]]
        poly = {"type": "Polygon", "coordinates": [ring, *[[list(map(float, c[:2])) for c in h]
                                                           for h in self._holes]]}
        try:
            self._need("rebuild")
            edit = self.session.make_edit(self.selected, footprint=poly)
        except Lidar2CityError as exc:
            self._message(str(exc), error=True)
            return None
        return self._run(edit)

    def _end_outline(self):
        self.outline = None
        for g in self._gizmos:
            g.remove()
        self._gizmos = []
        for b in (self.add_v, self.del_v, self.rebuild_btn):
            b.visible = False

    def _toggle_place(self):
        """Show (or hide) the handle of a user-placed primitive on the selected building."""
        import shapely
        from shapely.geometry import shape

        if self._placed is not None:
            self._placed.remove()
            self._placed = None
        self.p_len.visible = self.p_wid.visible = bool(self.place.value)
        if not self.place.value or self.selected is None or self.session is None:
            return
        try:
            fp = shape(self.session.footprint(self.selected))
        except Lidar2CityError as exc:
            self._message(str(exc), error=True)
            return
        rect = np.asarray(shapely.minimum_rotated_rectangle(fp).exterior.coords)[:4]
        e1, e2 = rect[1] - rect[0], rect[2] - rect[1]
        long_, short = (e1, e2) if np.hypot(*e1) >= np.hypot(*e2) else (e2, e1)
        az = math.atan2(long_[1], long_[0])
        self.p_len.value = round(float(np.hypot(*long_)), 2)
        self.p_wid.value = round(float(np.hypot(*short)), 2)
        c = np.asarray(fp.centroid.coords[0]) - self.origin[:2]
        self._placed = self.server.scene.add_transform_controls(
            "/placed", scale=3.0, active_axes=(True, True, False),
            position=(float(c[0]), float(c[1]), self._outline_z()),
            wxyz=(math.cos(az / 2), 0.0, 0.0, math.sin(az / 2)))
        self._draw_placed_box()

    def _draw_placed_box(self):
        """A translucent box of the placed primitive's length and width under its handle."""
        if self._placed is None:
            return
        self.server.scene.add_box("/placed/box", color=(255, 225, 0),
                                  dimensions=(float(self.p_len.value), float(self.p_wid.value), 1.0),
                                  opacity=0.45, position=(0.0, 0.0, -0.5))
