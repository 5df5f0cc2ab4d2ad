"""The operating-point maps of paper 002 (axial bearing) as 3D plots in the lab's view.

* ``StiffnessMapScene`` (exercise ``stiffness_map``): one of three surfaces over
  the operating range i ∈ [-1.5, 1.5] A, x ∈ [-0.5, 0.5] mm (the grid of
  Tables 2-3), chosen by the parameter ``view_surface``:
  - ``force``: F(i, x) of eq. 1 (colour: blue pulls down, red up), the 25 nodes,
    and at the chosen node the tangent plane (eq. 3-4, grey) and the plane the
    least squares fits (eq. 26, no constant: through the origin; red);
  - ``k_i`` / ``k_s``: the FBFNN surface (eq. 32-33) while it trains, coloured by
    its error |FBFNN - LSM| against the least-squares map it learns (grey wire),
    the printed Table 4 / 5 values as black points, and the same error over the
    41×41 test grid as a heat map on the floor of the box (RMS = the test RMSE).
* ``OperatingPointScene`` (exercise ``adaptive_filter``): the force surface, the
  nodes and a marker at the loop's present (i, x, F) with its recent path.

The box sits at the origin, where the lab's camera looks (``scenes.bearing.
CAMERA_POSITION``), so dragging the view turns the plot about its centre.
Axes: i along world +y, x along world -x (the camera looks from (+, +, +)),
the plotted quantity along +z.  Every surface is a grid of quads, each face
stored in both windings (``grid_faces``): the viewer culls back faces, and a
surface must show from above and from below.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh

from lab_modules.estimators.fuzzy_basis_network import LiveTraining, test_grid
from lab_modules.plants.axial_bearing import (
    AXIAL,
    GRID_CURRENTS_A,
    GRID_POSITIONS_M,
    N_PER_MM,
    TABLE_4_KI_N_PER_A,
    TABLE_5_KS_N_PER_MM,
)

ROOT = "/force_map_view"
CURRENT_RANGE_A, POSITION_RANGE_M = 1.5, 0.5e-3
HALF_WIDTH = 1.25                    # world units for half the current and half the position range
HEIGHT = 3.0                         # world units for the plotted quantity's range
SURFACE_POINTS = 25                  # live FBFNN surface: 25×25 vertices
FORCE_POINTS = 31
NODE_BLACK, WIRE_GREY, AXIS_GREY = (20, 20, 20), (110, 110, 110), (90, 90, 90)
TANGENT_GREY, LSM_RED, MARKER_GREEN = (185, 185, 185), (235, 60, 60), (44, 160, 44)
LABEL = {"font_screen_scale": 0.75}
NO_SHADOWS = {"cast_shadow": False, "receive_shadow": False}
PATH_POINTS = 12                     # the marker's recent positions (one per 3D update)


@dataclass(frozen=True)
class Axis:
    """The plotted quantity: label, unit, range [lo, hi] and tick values (in the unit)."""

    label: str
    unit: str
    lo: float
    hi: float
    ticks: tuple[float, ...]


FORCE_AXIS = Axis("magnet force F", "N", -30.0, 30.0, (-30.0, -15.0, 0.0, 15.0, 30.0))
KI_AXIS = Axis("k_i", "N/A", 0.0, 15.0, (0.0, 5.0, 10.0, 15.0))
KS_AXIS = Axis("k_s", "N/mm", 0.0, 35.0, (0.0, 10.0, 20.0, 30.0))
AXES = {"force": FORCE_AXIS, "k_i": KI_AXIS, "k_s": KS_AXIS}


def to_world(current_a, position_m, value, axis: Axis) -> np.ndarray:
    """World points (..., 3) of operating points and values (clipped to the box)."""
    i, x, z = np.broadcast_arrays(np.asarray(current_a, float), np.asarray(position_m, float),
                                  np.asarray(value, float))
    z = np.clip((z - axis.lo) / (axis.hi - axis.lo), 0.0, 1.0) * HEIGHT - HEIGHT / 2
    return np.stack([-x / POSITION_RANGE_M * HALF_WIDTH, i / CURRENT_RANGE_A * HALF_WIDTH, z], axis=-1)


def grid_faces(rows: int, columns: int) -> np.ndarray:
    """Triangles of a rows×columns vertex grid (row-major), each in both windings:
    the first half faces +z for a grid whose rows run along -x and columns along +y
    (as ``to_world`` lays out positions and currents), the second half the other way."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(columns - 1), indexing="ij")
    a = (r * columns + c).ravel()
    b, d, e = a + 1, a + columns, a + columns + 1
    up = np.concatenate([np.stack([a, b, e], 1), np.stack([a, e, d], 1)])
    return np.concatenate([up, up[:, ::-1]]).astype(np.uint32)


def surface(currents_a: np.ndarray, positions_m: np.ndarray, values: np.ndarray,
            axis: Axis) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a surface over a grid: rows ``positions_m``, columns ``currents_a``."""
    i, x = np.meshgrid(currents_a, positions_m, indexing="xy")
    vertices = to_world(i, x, values, axis).reshape(-1, 3).astype(np.float32)
    return vertices, grid_faces(len(positions_m), len(currents_a))


def colormap(values: np.ndarray, lo: float, hi: float, anchors: np.ndarray) -> np.ndarray:
    """RGB (uint8) of ``values`` on a piecewise-linear map through ``anchors`` (k×3) from lo to hi."""
    t = np.clip((np.asarray(values, float) - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    stops = np.linspace(0.0, 1.0, len(anchors))
    return np.stack([np.interp(t, stops, anchors[:, k]) for k in range(3)], axis=-1).round().astype(np.uint8)


DIVERGING = np.array([[0, 45, 200], [235, 235, 235], [215, 30, 30]], float)       # −, 0, +
HEAT = np.array([[255, 255, 200], [250, 200, 40], [240, 110, 20], [200, 30, 40], [100, 10, 90]], float)


def coloured_mesh(vertices: np.ndarray, faces: np.ndarray, colors: np.ndarray) -> trimesh.Trimesh:
    """A mesh with one colour per vertex (sent as glTF; ``process=False`` keeps both windings)."""
    rgba = np.column_stack([colors, np.full(len(colors), 255, np.uint8)])
    return trimesh.Trimesh(vertices=vertices, faces=faces, vertex_colors=rgba, process=False)


def error_heat_map(network, target: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """|network − target| on the test grid (41×41, rows x, columns i), in the target's unit × ``scale``."""
    currents, positions = test_grid()
    n = round(np.sqrt(currents.size))
    return (np.abs(network.predict(currents, positions) - target) * scale).reshape(n, n)


def nice_ceiling(value: float) -> float:
    """The next of 1, 1.5, 2, 3, 4, 5, 6, 8 × 10^n at or above ``value`` (a colour scale that does not jitter)."""
    if not np.isfinite(value) or value <= 0:
        return 1.0
    base = 10.0 ** np.floor(np.log10(value))
    return float(next(m * base for m in (1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0) if m * base >= value * (1 - 1e-12)))


def box_lines() -> np.ndarray:
    """The twelve edges of the plot box and a grid on its floor, as segments (n, 2, 3)."""
    h, z0, z1 = HALF_WIDTH, -HEIGHT / 2, HEIGHT / 2
    corners = [(-h, -h), (h, -h), (h, h), (-h, h)]
    segments = []
    for k in range(4):
        (x0, y0), (x1, y1) = corners[k], corners[(k + 1) % 4]
        segments += [((x0, y0, z0), (x1, y1, z0)), ((x0, y0, z1), (x1, y1, z1)), ((x0, y0, z0), (x0, y0, z1))]
    for t in np.linspace(-h, h, 5)[1:-1]:
        segments += [((t, -h, z0), (t, h, z0)), ((-h, t, z0), (h, t, z0))]
    return np.array(segments, np.float32)


class _ForceMapBase:
    """Box, axes, ticks and the title/legend labels shared by both scenes (call under ``self.lock``)."""

    def __init__(self) -> None:
        self.scene = None
        self.handles: dict = {}
        self.lock = threading.Lock()

    def _frame(self, scene) -> None:
        self.scene = scene
        scene.set_up_direction("+z")
        self.root = scene.add_frame(ROOT, show_axes=False)
        scene.add_line_segments(f"{ROOT}/box", box_lines(), AXIS_GREY, thickness=1.0, thickness_units="screen")
        h, z0 = HALF_WIDTH, -HEIGHT / 2
        for i in (-1.5, 0.0, 1.5):
            scene.add_label(f"{ROOT}/ticks/i{i:g}", f"{i:g}", position=to_world(i, -0.5e-3, 0.0, FORCE_AXIS)
                            * (1, 1, 0) + (0.12, 0, z0), anchor="top-right", **LABEL)
        scene.add_label(f"{ROOT}/ticks/i_title", "i [A]", position=(h + 0.35, 0.0, z0), anchor="top-center", **LABEL)
        for x_mm in (-0.5, 0.0, 0.5):
            scene.add_label(f"{ROOT}/ticks/x{x_mm:g}", f"{x_mm:g}",
                            position=to_world(1.5, x_mm * 1e-3, 0.0, FORCE_AXIS) * (1, 1, 0) + (0, 0.12, z0),
                            anchor="top-left", **LABEL)
        scene.add_label(f"{ROOT}/ticks/x_title", "x [mm]", position=(0.0, h + 0.35, z0), anchor="top-center",
                        **LABEL)
        self.handles["title"] = scene.add_label(f"{ROOT}/title", "", position=(0.0, 0.0, HEIGHT / 2 + 0.45),
                                                anchor="bottom-center", **LABEL)
        self.handles["legend"] = scene.add_label(f"{ROOT}/legend", "", position=(HALF_WIDTH, HALF_WIDTH, -HEIGHT / 2 - 0.9),
                                                 anchor="top-center", **LABEL)

    def _z_axis(self, axis: Axis) -> None:
        """Tick labels of the plotted quantity on the vertical edge at (i = −1.5 A, x = −0.5 mm), left on screen."""
        for handle in self.handles.pop("z_ticks", []):
            handle.remove()
        corner = to_world(-1.5, -0.5e-3, 0.0, axis)
        ticks = [self.scene.add_label(f"{ROOT}/z_ticks/{k}", f"{value:g}",
                                      position=(corner[0] + 0.06, corner[1] - 0.06, to_world(0, 0, value, axis)[2]),
                                      anchor="center-right", **LABEL) for k, value in enumerate(axis.ticks)]
        ticks.append(self.scene.add_label(f"{ROOT}/z_ticks/title", f"{axis.label} [{axis.unit}]",
                                          position=(corner[0], corner[1], HEIGHT / 2 + 0.12),
                                          anchor="bottom-center", **LABEL))
        self.handles["z_ticks"] = ticks

    def _replace(self, key: str, add: Callable[[], object]) -> None:
        """Put a node in place of the one stored under ``key`` (re-sent whole)."""
        old = self.handles.pop(key, None)
        if old is not None:
            old.remove()
        self.handles[key] = add()

    def _drop(self, *keys: str) -> None:
        for key in keys:
            handle = self.handles.pop(key, None)
            if handle is not None and hasattr(handle, "remove"):
                handle.remove()

    def _force_surface(self) -> None:
        i = np.linspace(-CURRENT_RANGE_A, CURRENT_RANGE_A, FORCE_POINTS)
        x = np.linspace(-POSITION_RANGE_M, POSITION_RANGE_M, FORCE_POINTS)
        force = AXIAL.force_n(*np.meshgrid(i, x, indexing="xy"))
        vertices, faces = surface(i, x, force, FORCE_AXIS)
        colors = colormap(force.ravel(), FORCE_AXIS.lo, FORCE_AXIS.hi, DIVERGING)
        mesh = coloured_mesh(vertices, faces, colors)
        self._replace("surface", lambda: self.scene.add_mesh_trimesh(f"{ROOT}/surface", mesh, **NO_SHADOWS))
        nodes_i, nodes_x = np.meshgrid(GRID_CURRENTS_A, GRID_POSITIONS_M, indexing="xy")
        points = to_world(nodes_i, nodes_x, AXIAL.force_n(nodes_i, nodes_x), FORCE_AXIS).reshape(-1, 3)
        self._replace("nodes", lambda: self.scene.add_point_cloud(
            f"{ROOT}/nodes", points.astype(np.float32), NODE_BLACK, point_size=0.07, point_shape="circle"))


def plane_patch(i_node: float, x_node: float, plane: Callable[[np.ndarray, np.ndarray], np.ndarray],
                axis: Axis = FORCE_AXIS, through_origin: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A 9×9 patch of a plane F = plane(i, x) one grid step either side of the node (inside the
    range); ``through_origin`` stretches it to the centre (i, x) = (0, 0), where a plane without a
    constant term passes through F = 0."""
    i_lo, i_hi = (min(i_node, 0.0), max(i_node, 0.0)) if through_origin else (i_node, i_node)
    x_lo, x_hi = (min(x_node, 0.0), max(x_node, 0.0)) if through_origin else (x_node, x_node)
    i = np.linspace(max(i_lo - 0.75, -1.5), min(i_hi + 0.75, 1.5), 9)
    x = np.linspace(max(x_lo - 0.25e-3, -0.5e-3), min(x_hi + 0.25e-3, 0.5e-3), 9)
    ii, xx = np.meshgrid(i, x, indexing="xy")
    return surface(i, x, plane(ii, xx), axis)


class StiffnessMapScene(_ForceMapBase):
    """``SceneView`` of ``stiffness_map``.  The exercise passes its own functions:
    ``training(values)`` (a fresh ``LiveTraining``), ``training_key(values)`` (what the
    networks depend on), ``lsm(values, i, x)`` → (k_i [N/A], k_s [N/m]) noise-free,
    ``tables(values)`` → the identified 5×5 tables (k_i [N/A], k_s [N/mm])."""

    def __init__(self, values: dict, *, training: Callable, training_key: Callable, lsm: Callable,
                 tables: Callable) -> None:
        super().__init__()
        self.values = dict(values)
        self.functions = (training, training_key, lsm, tables)
        self.live: LiveTraining | None = None
        self.live_key = None
        self.shown_epoch = -1
        self.shown_key = None

    # -- SceneView ---------------------------------------------------------------------
    def attach(self, scene) -> None:
        with self.lock:
            self._frame(scene)
            self._rebuild()

    def update(self, values: dict) -> None:
        with self.lock:
            self.values = dict(values)
            if self.scene is not None:
                self._rebuild()

    def animate(self, wall_time_s: float, latest: dict[str, float]) -> None:
        with self.lock:
            if self.scene is None or self.values["view_surface"] == "force":
                return
            epoch = latest.get("fbfnn_epoch")
            if epoch is not None and np.isfinite(epoch) and int(epoch) != self.shown_epoch:
                self._networks(int(epoch))

    # -- drawing -------------------------------------------------------------------------
    def _rebuild(self) -> None:
        mode = self.values["view_surface"]
        key = (mode, self.values["node_current_a"], self.values["node_position_mm"], self.values["fit"],
               self.functions[1](self.values))
        if key == self.shown_key:
            return
        self.shown_key = key
        self._z_axis(AXES[mode])
        if mode == "force":
            self._drop("fbfnn", "heat", "lsm_wire", "table")
            self.handles.pop("heat_mode", None)
            self._force_surface()
            self._planes()
        else:
            self._drop("surface", "nodes", "tangent", "fit", "node")
            self._target_wire(mode)
            self.shown_epoch = -1
            self._networks(self.live.epoch if self.live is not None and self.live_key == key[-1] else 0)

    def _planes(self) -> None:
        tables = self.functions[3]
        i_n, x_n = float(self.values["node_current_a"]), float(self.values["node_position_mm"]) * 1e-3
        f_n = float(AXIAL.force_n(i_n, x_n))
        kit, kst = (float(v) for v in AXIAL.tangent_factors(i_n, x_n))
        ki_table, ks_table = tables(self.values)
        row, col = list(GRID_POSITIONS_M).index(x_n), list(GRID_CURRENTS_A).index(i_n)
        ki, ks = float(ki_table[row, col]), float(ks_table[row, col]) * N_PER_MM
        intercept = self.values["fit"] == "with_intercept"
        fitted = (lambda i, x: f_n + ki * (i - i_n) + ks * (x - x_n)) if intercept else (lambda i, x: ki * i + ks * x)
        vertices, faces = plane_patch(i_n, x_n, lambda i, x: f_n + kit * (i - i_n) + kst * (x - x_n))
        self._replace("tangent", lambda: self.scene.add_mesh_simple(
            f"{ROOT}/tangent", vertices, faces, color=TANGENT_GREY, opacity=0.7, **NO_SHADOWS))
        vertices_fit, faces_fit = plane_patch(i_n, x_n, fitted, through_origin=not intercept)
        self._replace("fit", lambda: self.scene.add_mesh_simple(
            f"{ROOT}/fit", vertices_fit, faces_fit, color=LSM_RED, opacity=0.7, **NO_SHADOWS))
        self._replace("node", lambda: self.scene.add_icosphere(
            f"{ROOT}/node", 0.06, (255, 200, 0), position=tuple(to_world(i_n, x_n, f_n, FORCE_AXIS)), **NO_SHADOWS))
        model = ("LSM with a constant: nearly the tangent plane" if intercept else
                 "LSM without constant: through the node and F = 0 at the centre")
        self.handles["title"].text = "Force F(i, x), eq. 1: 25 nodes, tangent (grey) and LSM plane (red)"
        self.handles["legend"].text = "\n".join([
            f"node i = {i_n:g} A, x = {x_n * 1e3:g} mm (yellow): F = {f_n:.2f} N",
            f"tangent: k_i = {kit:.2f} N/A, k_s = {kst / N_PER_MM:.2f} N/mm",
            f"LSM: k_i = {ki:.2f} N/A, k_s = {ks / N_PER_MM:.2f} N/mm", model,
            "colour: blue F < 0, red F > 0 (±30 N)"])

    def _target_wire(self, mode: str) -> None:
        """The LSM map the network learns (grey wire) and the printed table (black points)."""
        _, _, lsm, _ = self.functions
        axis, scale = (KI_AXIS, 1.0) if mode == "k_i" else (KS_AXIS, 1 / N_PER_MM)
        i = np.linspace(-1.5, 1.5, 13)
        x = np.linspace(-0.5e-3, 0.5e-3, 13)
        ii, xx = np.meshgrid(i, x, indexing="xy")
        values = lsm(self.values, ii, xx)[0 if mode == "k_i" else 1] * scale
        points = to_world(ii, xx, values, axis)
        segments = np.concatenate([np.stack([points[:, :-1], points[:, 1:]], -2).reshape(-1, 2, 3),
                                   np.stack([points[:-1], points[1:]], -2).reshape(-1, 2, 3)]).astype(np.float32)
        self._replace("lsm_wire", lambda: self.scene.add_line_segments(
            f"{ROOT}/lsm_wire", segments, WIRE_GREY, thickness=1.0, thickness_units="screen"))
        table = TABLE_4_KI_N_PER_A if mode == "k_i" else TABLE_5_KS_N_PER_MM
        nodes_i, nodes_x = np.meshgrid(GRID_CURRENTS_A, GRID_POSITIONS_M, indexing="xy")
        dots = to_world(nodes_i, nodes_x, table, axis).reshape(-1, 3).astype(np.float32)
        self._replace("table", lambda: self.scene.add_point_cloud(
            f"{ROOT}/table", dots, NODE_BLACK, point_size=0.07, point_shape="circle"))

    def _networks(self, epoch: int) -> None:
        """The FBFNN surface and the error heat map at ``epoch`` (replaying the training)."""
        training, training_key, lsm, _ = self.functions
        key = training_key(self.values)
        if self.live is None or self.live_key != key:
            self.live, self.live_key = training(self.values), key
        self.live.advance_to(epoch)
        self.shown_epoch = epoch
        mode = self.values["view_surface"]
        network, axis, scale = ((self.live.ki, KI_AXIS, 1.0) if mode == "k_i"
                                else (self.live.ks, KS_AXIS, 1 / N_PER_MM))
        currents, positions = test_grid()
        target = lsm(self.values, currents, positions)[0 if mode == "k_i" else 1]
        heat = error_heat_map(network, target, scale)
        top = nice_ceiling(float(np.max(heat)))   # colour scale: the present largest error, rounded up
        i = np.linspace(-1.5, 1.5, SURFACE_POINTS)
        x = np.linspace(-0.5e-3, 0.5e-3, SURFACE_POINTS)
        ii, xx = np.meshgrid(i, x, indexing="xy")
        values = network.predict(ii, xx) * scale
        error = np.abs(values - lsm(self.values, ii, xx)[0 if mode == "k_i" else 1] * scale)
        vertices, faces = surface(i, x, values, axis)
        mesh = coloured_mesh(vertices, faces, colormap(error.ravel(), 0.0, top, HEAT))
        self._replace("fbfnn", lambda: self.scene.add_mesh_trimesh(f"{ROOT}/fbfnn", mesh, **NO_SHADOWS))
        heat_colors = colormap(heat.ravel(), 0.0, top, HEAT)
        if self.handles.get("heat_mode") == mode and "heat" in self.handles:
            self.handles["heat"].colors = heat_colors             # positions stay: send the colours only
        else:
            n = heat.shape[0]
            grid_i, grid_x = np.meshgrid(np.linspace(-1.5, 1.5, n), np.linspace(-0.5e-3, 0.5e-3, n), indexing="xy")
            floor = to_world(grid_i, grid_x, axis.lo, axis).reshape(-1, 3)
            floor[:, 2] -= 0.01                                   # just under the floor grid
            self._replace("heat", lambda: self.scene.add_point_cloud(
                f"{ROOT}/heat", floor.astype(np.float32), heat_colors, point_size=2 * HALF_WIDTH / (n - 1),
                point_shape="square", point_shading="flat"))
            self.handles["heat_mode"] = mode
        rmse = float(np.sqrt(np.mean(heat**2)))
        self.handles["title"].text = (f"{axis.label} map: FBFNN (coloured by its error), LSM map (grey wire), "
                                      f"Table {'4' if mode == 'k_i' else '5'} (dots)")
        self.handles["legend"].text = "\n".join([
            f"FBFNN epoch {epoch}: test RMSE {rmse:.3f} {axis.unit}",
            f"max |FBFNN − LSM| {float(np.max(heat)):.3f} {axis.unit}",
            f"colour and floor: |FBFNN − LSM| 0 (pale) … {top:g} {axis.unit} (purple)",
            "floor: the 41×41 test grid"])


class OperatingPointScene(_ForceMapBase):
    """``SceneView`` of ``adaptive_filter``: the force surface with a marker at the loop's
    (i, x_true, F_Magnet) and its recent path (one point per 3D update)."""

    def __init__(self, values: dict) -> None:
        super().__init__()
        self.values = dict(values)
        self.path: list[np.ndarray] = []

    def attach(self, scene) -> None:
        with self.lock:
            self._frame(scene)
            self._z_axis(FORCE_AXIS)
            self._force_surface()
            self.handles["marker"] = scene.add_icosphere(f"{ROOT}/marker", 0.08, MARKER_GREEN,
                                                         position=tuple(self.marker_world({})), **NO_SHADOWS)
            self.handles["title"].text = "Operating point on F(i, x) (green), 25 nodes (black)"
            self.handles["legend"].text = "waiting for the first samples …"

    def update(self, values: dict) -> None:
        self.values = dict(values)

    @staticmethod
    def operating_point(latest: dict[str, float]) -> tuple[float, float, float]:
        """(i [A], x [m], F [N]) of the newest sample (the centre with the weight before any)."""
        i = float(latest.get("current_a", AXIAL.weight_n / AXIAL.centre_factors()[0]))
        x = float(latest.get("x_true_m", 0.0))
        return i, x, float(latest.get("magnet_force_n", AXIAL.force_n(i, x)))

    def marker_world(self, latest: dict[str, float]) -> np.ndarray:
        i, x, force = self.operating_point(latest)
        return to_world(np.clip(i, -1.5, 1.5), np.clip(x, -0.5e-3, 0.5e-3), force, FORCE_AXIS)

    def animate(self, wall_time_s: float, latest: dict[str, float]) -> None:
        with self.lock:
            if self.scene is None or not latest:
                return
            i, x, force = self.operating_point(latest)
            if not all(np.isfinite((i, x, force))):
                return
            point = self.marker_world(latest)
            self.handles["marker"].position = tuple(float(v) for v in point)
            self.path = [*self.path, point][-PATH_POINTS:]
            if len(self.path) > 1:
                points = np.array(self.path, np.float32)
                segments = np.stack([points[:-1], points[1:]], axis=1)
                if "path" in self.handles:
                    self.handles["path"].points = segments
                else:
                    self.handles["path"] = self.scene.add_line_segments(
                        f"{ROOT}/path", segments, MARKER_GREEN, thickness=2.0, thickness_units="screen")
            self.handles["legend"].text = "\n".join([
                f"i = {i:+.3f} A, x = {x * 1e3:+.3f} mm", f"F_Magnet = {force:+.2f} N",
                f"t = {latest.get('time_s', 0.0) * 1e3:.0f} ms; path: last {PATH_POINTS} updates"])
