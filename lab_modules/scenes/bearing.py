"""The radial magnetic bearing of the rig in the lab's 3D view (viser scene).

Paper 000 (Schuhmann, Hofmann, Werner), §III-B and Appendix: an eight-pole
heteropolar radial bearing of four magnets, each of two adjacent poles that
sit at the pole angle alpha = pi/8 either side of the magnet's centre (eq. 10);
rotor laminations 272 mm in diameter; nominal air gap delta0 = 0.460 mm
(derived from the Appendix in ``plants.radial_bearing``).  The bearing is seen along the
shaft with the simulated axis x drawn vertical: the upper magnet carries
i0 + i (its gap delta0 - x cos alpha closes as x grows, eq. 10), the lower
one i0 - i.  The horizontal magnets belong to the other axis, which is not
simulated; they are drawn at their bias current i0.

To scale: rotor diameter, bore (rotor + 2 delta0), pole angles.  Not in the
paper, chosen to look like a bearing of this size: pole width and length,
yoke thickness, coil size (``POLE_WIDTH_M`` ...).  The air gap and the rotor's
motion (micrometres) are invisible at this scale, so the rotor and the
markers of the measured and estimated positions are drawn displaced by
``exaggeration`` times their simulated value, stated in the view (the drawn
rotor then overlaps the poles it approaches; the true gaps are in the text).

Framing: the lab's camera (``CAMERA_POSITION``, set by the server, looking at
the origin, 75° vertical field of view) on a 1366 x 768 window, where the 3D
canvas is the gap between the docked controls and charts (``CANVAS_PX``).  The
bearing's face is turned parallel to the image plane and placed life size on
the camera ray through ``BEARING_CENTRE_PX``, as near to the camera as makes
it about ``STATOR_DIAMETER_PX`` wide.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import viser.transforms as tf

from lab_modules.plants.flexible_rotor import RotorGeometry
from lab_modules.plants.radial_bearing import RIG
from lab_modules.scenes.rotor import tube

ROOT = "/bearing_view"

_ROTOR = RotorGeometry()
ROTOR_RADIUS_M = _ROTOR.stack_diameter_m / 2       # Appendix: laminations 272 mm
SHAFT_RADIUS_M = _ROTOR.shaft_diameter_m / 2
STACK_LENGTH_M = _ROTOR.stack_length_m
BORE_RADIUS_M = ROTOR_RADIUS_M + RIG.delta0_m      # pole faces one nominal air gap away
# Not in the paper (see module docstring):
POLE_WIDTH_M = 0.045
POLE_LENGTH_M = 0.050
YOKE_THICKNESS_M = 0.030
COIL_THICKNESS_M = 0.012
COIL_DEPTH_M = 0.030
STATOR_RADIUS_M = BORE_RADIUS_M + POLE_LENGTH_M + YOKE_THICKNESS_M
MAX_DRAWN_OFFSET_M = 0.07           # beyond this the drawn displacement is clamped ("off scale")
LONGEST_ARROW_M = 0.12
NO_SHADOWS = {"cast_shadow": False, "receive_shadow": False}   # shadows cost frames, show nothing here

#: Magnet centres, clockwise from the top of the view; the upper and lower
#: magnets act on the simulated axis x.
MAGNETS = {"upper": 0.0, "right": np.pi / 2, "lower": np.pi, "left": 3 * np.pi / 2}

STEEL, LAMINATION, STATOR = (175, 180, 190), (70, 90, 140), (150, 150, 150)
COIL_IDLE, COPPER, COIL_HOT = (205, 205, 215), (200, 120, 50), (230, 20, 20)
TRUE_BLUE = (31, 119, 180)          # the scope's colours: true, measured, estimated
MEASURED_GREY, ESTIMATE_RED = (120, 120, 120), (214, 39, 40)
BEARING_FORCE_GREEN, DISTURBANCE_PURPLE = (44, 160, 44), (148, 103, 189)

# The lab's camera in world coordinates (scene up +z), looking at the origin; the
# server sets it (app/server.py), the views are framed for it.
CAMERA_POSITION = np.array([4.0, 4.0, 4.0])
CAMERA_FOV_RAD = np.deg2rad(75.0)
CANVAS_PX = (1366 - 380 - 600, 768)  # 1366x768 less the docked controls and charts (app/tab/session.py)
BEARING_CENTRE_PX = (193, 300)
STATOR_DIAMETER_PX = 300



def view_pose(centre_px: tuple[float, float] = BEARING_CENTRE_PX,
              metres_per_px: float = 2 * STATOR_RADIUS_M / STATOR_DIAMETER_PX) -> tuple[np.ndarray, np.ndarray]:
    """(wxyz, position) of a view frame: its x axis (the bearing's shaft) towards the
    camera, y to the right, z up on the screen, its origin on pixel ``centre_px``
    (default: ``BEARING_CENTRE_PX``), drawn at ``metres_per_px`` life-size metres per pixel."""
    forward = -CAMERA_POSITION / np.linalg.norm(CAMERA_POSITION)
    right = np.cross(forward, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    focal_px = CANVAS_PX[1] / 2 / np.tan(CAMERA_FOV_RAD / 2)
    across = (centre_px[0] - CANVAS_PX[0] / 2) / focal_px
    down = (centre_px[1] - CANVAS_PX[1] / 2) / focal_px
    depth = focal_px * metres_per_px     # life size, near the camera
    position = CAMERA_POSITION + depth * (forward + across * right - down * up)
    rotation = tf.SO3.from_matrix(np.column_stack([-forward, right, up]))
    return rotation.wxyz, position


def _about_shaft(angle_rad: float) -> tuple[float, float, float, float]:
    """Quaternion turning the frame's +z (up) clockwise by ``angle_rad`` as seen from the camera."""
    return (float(np.cos(-angle_rad / 2)), float(np.sin(-angle_rad / 2)), 0.0, 0.0)


def _radial(angle_rad: float, radius_m: float, axial_m: float = 0.0) -> tuple[float, float, float]:
    """Point at ``radius_m`` in the direction ``angle_rad`` clockwise from the top."""
    return (axial_m, radius_m * float(np.sin(angle_rad)), radius_m * float(np.cos(angle_rad)))


def pole_angles_rad() -> dict[str, tuple[float, float]]:
    """The two pole angles of each magnet: its centre -/+ alpha (eq. 10)."""
    alpha = RIG.pole_angle_rad
    return {name: (centre - alpha, centre + alpha) for name, centre in MAGNETS.items()}


def coil_color(current_a: float, bias_a: float = RIG.i0_a) -> tuple[int, int, int]:
    """Pale at no current, copper at the bias ``bias_a`` (default the bearing's i0), red at twice it and beyond."""
    level = min(abs(current_a) / bias_a, 2.0)
    low, high, t = (COIL_IDLE, COPPER, level) if level <= 1.0 else (COPPER, COIL_HOT, level - 1.0)
    return tuple(round(a + (b - a) * t) for a, b in zip(low, high))


def circle(radius_m: float, axial_m: float, segments: int = 96) -> np.ndarray:
    """Line segments (segments, 2, 3) of a circle about the shaft axis."""
    angle = np.linspace(0.0, 2 * np.pi, segments + 1)
    points = np.column_stack([np.full(segments + 1, axial_m), radius_m * np.sin(angle), radius_m * np.cos(angle)])
    return np.stack([points[:-1], points[1:]], axis=1).astype(np.float32)


@dataclass(frozen=True)
class Ghost:
    """A position drawn as an outline of the rotor with a dot at its centre."""

    label: str
    column: str
    color: tuple[int, int, int]


class BearingScene:
    """``SceneView`` of the radial bearing driven by one axis's trace.

    ``true_column`` and ``current_column`` name the rotor's true displacement
    x [m] and control current i [A] (``rotor_label`` names it when there are
    two loops); ``ghosts`` are further positions (sensor,
    filter, another loop); ``disturbance_n(latest, values)`` gives f_z [N]
    (None: the exercise has none).  ``exaggeration`` scales displacements,
    ``force_scale_m_per_n`` the force arrows (drawn metres per newton).
    """

    def __init__(self, values: dict, *, exaggeration: float, force_scale_m_per_n: float,
                 true_column: str, current_column: str, ghosts: tuple[Ghost, ...] = (),
                 disturbance_n: Callable[[dict, dict], float] | None = None, rotor_label: str = "") -> None:
        self.values = dict(values)
        self.exaggeration = exaggeration
        self.force_scale_m_per_n = force_scale_m_per_n
        self.true_column, self.current_column = true_column, current_column
        self.ghosts = ghosts
        self.disturbance_n = disturbance_n
        self.rotor_label = rotor_label
        self.handles: dict = {}
        self.shown: dict = {}                     # last values sent, to send only changes

    def drawn_offset_m(self, x_m: float) -> float:
        """Drawn displacement [m, life size] of a simulated one, clamped to ``MAX_DRAWN_OFFSET_M``."""
        return float(np.clip(self.exaggeration * x_m, -MAX_DRAWN_OFFSET_M, MAX_DRAWN_OFFSET_M))

    # -- SceneView -----------------------------------------------------------------------
    def attach(self, scene) -> None:
        h = self.handles
        scene.set_up_direction("+z")
        wxyz, position = view_pose()
        self.root = scene.add_frame(ROOT, show_axes=False, wxyz=wxyz, position=position)
        vertices, faces = tube(STACK_LENGTH_M, BORE_RADIUS_M + POLE_LENGTH_M - 0.002, STATOR_RADIUS_M, 96)
        scene.add_mesh_simple(f"{ROOT}/stator/yoke", vertices, faces, color=STATOR, **NO_SHADOWS)
        h["coils"] = {}
        for magnet, angles in pole_angles_rad().items():
            for k, angle in enumerate(angles):
                scene.add_box(f"{ROOT}/stator/pole_{magnet}_{k}", STATOR,
                              (STACK_LENGTH_M, POLE_WIDTH_M, POLE_LENGTH_M), wxyz=_about_shaft(angle),
                              position=_radial(angle, BORE_RADIUS_M + POLE_LENGTH_M / 2), **NO_SHADOWS)
                h["coils"][magnet, k] = scene.add_box(
                    f"{ROOT}/coils/{magnet}_{k}", coil_color(RIG.i0_a),
                    (STACK_LENGTH_M + 2 * COIL_THICKNESS_M, POLE_WIDTH_M + 2 * COIL_THICKNESS_M, COIL_DEPTH_M),
                    wxyz=_about_shaft(angle), position=_radial(angle, BORE_RADIUS_M + 0.012 + COIL_DEPTH_M / 2),
                    **NO_SHADOWS)
        front = STACK_LENGTH_M / 2 + COIL_THICKNESS_M + 0.002
        centre_mark = np.array([[[front, -0.012, 0.0], [front, 0.012, 0.0]],
                                [[front, 0.0, -0.012], [front, 0.0, 0.012]]], dtype=np.float32)
        scene.add_line_segments(f"{ROOT}/stator/centre", centre_mark, (0, 0, 0), thickness=1.5,
                                thickness_units="screen")
        h["rotor"] = scene.add_frame(f"{ROOT}/rotor", show_axes=False)
        vertices, faces = tube(STACK_LENGTH_M, SHAFT_RADIUS_M, ROTOR_RADIUS_M, 96)
        scene.add_mesh_simple(f"{ROOT}/rotor/laminations", vertices, faces, color=LAMINATION, **NO_SHADOWS)
        vertices, faces = tube(0.16, 0.0, SHAFT_RADIUS_M, 32)
        scene.add_mesh_simple(f"{ROOT}/rotor/shaft", vertices, faces, color=STEEL, position=(-0.05, 0.0, 0.0),
                              **NO_SHADOWS)
        scene.add_icosphere(f"{ROOT}/rotor/centre", 0.006, TRUE_BLUE, position=(0.035, 0.0, 0.0), **NO_SHADOWS)
        h["ghosts"] = []
        for k, ghost in enumerate(self.ghosts):
            frame = scene.add_frame(f"{ROOT}/ghost_{k}", show_axes=False, visible=False)
            scene.add_line_segments(f"{ROOT}/ghost_{k}/outline", circle(ROTOR_RADIUS_M, front), ghost.color,
                                    thickness=2.0, thickness_units="screen")
            scene.add_icosphere(f"{ROOT}/ghost_{k}/centre", 0.005, ghost.color, position=(front + 0.02, 0.0, 0.0),
                                  **NO_SHADOWS)
            h["ghosts"].append(frame)
        h["arrows"] = {name: scene.add_arrows(f"{ROOT}/arrows/{name}", np.zeros((1, 2, 3), np.float32), color,
                                              shaft_radius=0.005, head_radius=0.011, head_length=0.02,
                                              visible=False)
                       for name, color in (("bearing", BEARING_FORCE_GREEN), ("disturbance", DISTURBANCE_PURPLE))
                       if name == "bearing" or self.disturbance_n is not None}
        h["currents"] = {magnet: scene.add_label(f"{ROOT}/labels/{magnet}", "", font_screen_scale=0.8,
                                                 anchor="center-center",
                                                 position=_radial(MAGNETS[magnet], 0.1, front + 0.02))
                         for magnet in ("upper", "lower")}
        scene.add_label(f"{ROOT}/labels/title", f"Radial bearing, ×{self.exaggeration:g} motion",
                        font_screen_scale=0.85, anchor="bottom-center",
                        position=(0.0, 0.0, STATOR_RADIUS_M + 0.01))
        h["legend"] = scene.add_label(f"{ROOT}/labels/legend", "", font_screen_scale=0.9, anchor="top-center",
                                      position=(0.0, 0.0, -STATOR_RADIUS_M - 0.01))
        self.front_m = front
        self.animate(0.0, {})

    def update(self, values: dict) -> None:
        self.values = dict(values)

    def animate(self, wall_time_s: float, latest: dict[str, float]) -> None:
        h = self.handles
        if not h:
            return
        x = latest.get(self.true_column, 0.0)
        i = latest.get(self.current_column, 0.0)
        if not (np.isfinite(x) and np.isfinite(i)):
            return
        lift = self.drawn_offset_m(x)
        self._set(h["rotor"], "position", (0.0, 0.0, lift))
        for ghost, frame in zip(self.ghosts, h["ghosts"]):
            value = latest.get(ghost.column, float("nan"))
            self._set(frame, "visible", bool(np.isfinite(value)))
            if np.isfinite(value):
                self._set(frame, "position", (0.0, 0.0, self.drawn_offset_m(value)))
        i0 = RIG.i0_a
        for magnet, current in (("upper", i0 + i), ("lower", i0 - i)):
            for k in (0, 1):
                self._set(h["coils"][magnet, k], "color", coil_color(current))
            self._set(h["currents"][magnet], "text", f"i₀{'+' if magnet == 'upper' else '−'}i = {current:.2f} A")
        bearing_force = float(RIG.magnetic_force(x, i))
        self._arrow("bearing", bearing_force, -0.03, lift)
        cos_alpha = np.cos(RIG.pole_angle_rad)
        lines = [f"{self.rotor_label} x = {x * 1e6:+.1f} µm".lstrip() + (" (off scale)" if abs(self.exaggeration * x) > MAX_DRAWN_OFFSET_M
                                              else ""),
                 (f"gap top {(RIG.delta0_m - x * cos_alpha) * 1e3:.3f}, "
                 f"bottom {(RIG.delta0_m + x * cos_alpha) * 1e3:.3f} mm")]
        lines += [f"○ {ghost.label}: {_color_name(ghost.color)}" for ghost in self.ghosts]
        lines.append(f"↑ f_m = {bearing_force:+.0f} N (green)")
        if self.disturbance_n is not None and latest:
            disturbance = float(self.disturbance_n(latest, self.values))
            self._arrow("disturbance", disturbance, 0.03, lift)
            lines.append(f"↑ f_z = {disturbance:+.0f} N (violet)")
        lines += [f"arrows {self.force_scale_m_per_n * 1e3:g} mm/N", "coils: pale 0, copper i₀, red 2i₀"]
        self._set(h["legend"], "text", "\n".join(lines))

    # -- helpers ---------------------------------------------------------------------------
    def _set(self, handle, attribute: str, value) -> None:
        set_if_changed(self.shown, handle, attribute, value)

    def _arrow(self, name: str, force_n: float, across_m: float, lift_m: float) -> None:
        """A force arrow on the rotor's face, ``across_m`` right of its centre."""
        length = float(np.clip(force_n * self.force_scale_m_per_n, -LONGEST_ARROW_M, LONGEST_ARROW_M))
        handle = self.handles["arrows"][name]
        self._set(handle, "visible", abs(length) > 0.004)
        if abs(length) > 0.004:
            start = (self.front_m + 0.01, across_m, lift_m)
            points = np.array([[start, (start[0], across_m, lift_m + length)]], dtype=np.float32)
            self._set(handle, "points", points)


def set_if_changed(shown: dict, handle, attribute: str, value) -> None:
    """Send a node property only when it changed (``shown`` remembers what was sent; scenes update every frame)."""
    key = (id(handle), attribute)
    if key not in shown or not np.array_equal(shown[key], value):
        shown[key] = value
        setattr(handle, attribute, value)


def _color_name(color: tuple[int, int, int]) -> str:
    return {MEASURED_GREY: "grey", ESTIMATE_RED: "red", TRUE_BLUE: "blue"}.get(color, "outline")
