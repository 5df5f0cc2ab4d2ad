"""The spinning flexible rotor in the lab's 3D view: one whirl mode at the set speed.

The shaft bends in both planes as the chosen closed-loop mode whirls: r(z, t) =
phi(z) e^{i theta(t)} with the mode's complex shape phi (``rotor_at_speed.whirl_shape``,
r = x + i y), theta turning forward (with the spin) or backward.  Each of a few stations
draws its orbit, a circle of radius |phi(z)| (the rotor is isotropic).  A stripe on the
lamination stack turns with the spin.  Both motions are slowed and exaggerated (a
300 Hz whirl cannot be watched): one eighth of a turn per drawn frame, the whirl's sense
kept.  Model axes as in ``scenes.rotor``: x along the shaft, z up = the x-z plane's
deflection, y = the y-z plane's.
"""

from __future__ import annotations

import numpy as np

from lab_modules.plants.flexible_rotor import FlexibleRotor
from lab_modules.scenes.rotor import (
    CAPACITIVE,
    EDDY_CURRENT,
    LAMINATION,
    RING_SEGMENTS,
    STATOR,
    STEEL,
    VIEW_SCALE,
    shaft_mesh,
    tube,
)

ROOT = "/whirl_view"
AMPLITUDE_M = 0.05                  # drawn largest whirl radius
TURN_PER_FRAME_RAD = np.pi / 4      # slowed whirl and spin: an eighth of a turn per drawn frame
ORBIT_STATIONS_M = (0.30, 0.60, 0.80, 0.91)   # where orbits are drawn: along the shaft, stack, free end
ORBIT_POINTS = 48
FORWARD, BACKWARD = (30, 120, 200), (200, 60, 160)


def _colours(rgb: tuple[int, int, int]) -> np.ndarray:
    """One colour for every orbit segment's two ends (viser's line segments take (N, 2, 3) uint8)."""
    return np.broadcast_to(np.array(rgb, dtype=np.uint8), (ORBIT_POINTS, 2, 3)).copy()


def _about_x(angle_rad: float) -> tuple[float, float, float, float]:
    """Quaternion (w, x, y, z) of a rotation about the shaft's axis x."""
    return (float(np.cos(angle_rad / 2)), float(np.sin(angle_rad / 2)), 0.0, 0.0)


class WhirlScene:
    """``SceneView`` of the spinning rotor; ``shape_of(values)`` gives the shown mode's complex
    shape at ``STATIONS`` stations and its signed frequency [Hz] (+ forward)."""

    STATIONS = 92

    def __init__(self, rotor: FlexibleRotor, values: dict, integrated, shape_of) -> None:
        self.rotor, self.geometry = rotor, rotor.geometry
        self.integrated, self.shape_of = integrated, shape_of
        self.values = dict(values)
        self.stations_m = np.linspace(0.0, self.geometry.length_m, self.STATIONS)
        self.handles: dict = {}
        self.frame = 0
        self._shape()

    def _shape(self) -> None:
        shape, self.frequency_hz = self.shape_of(self.values)
        self.shape = AMPLITUDE_M * shape
        at = [int(np.argmin(np.abs(self.stations_m - z))) for z in ORBIT_STATIONS_M]
        self.orbit_radius = np.abs(self.shape[at])
        self.orbit_at = self.stations_m[at]
        bearing = int(np.argmin(np.abs(self.stations_m - self.geometry.bearing_m)))
        self.bearing_index = bearing

    def _x(self, z_m):
        return np.asarray(z_m) - self.geometry.length_m / 2

    @staticmethod
    def _at(x_m, y_m, z_m) -> tuple[float, float, float]:
        return (VIEW_SCALE * float(x_m), VIEW_SCALE * float(y_m), VIEW_SCALE * float(z_m))

    def _orbit_segments(self, radius: float) -> np.ndarray:
        angle = np.linspace(0.0, 2 * np.pi, ORBIT_POINTS + 1)
        ring = np.column_stack([np.zeros_like(angle), radius * np.cos(angle), radius * np.sin(angle)])
        return np.stack([ring[:-1], ring[1:]], axis=1).astype(np.float32)

    # -- SceneView -----------------------------------------------------------------------
    def attach(self, scene) -> None:
        g, h = self.geometry, self.handles
        scene.set_up_direction("+z")
        turn = 3 * np.pi / 4
        self.root = scene.add_frame(ROOT, show_axes=False,
                                    wxyz=(float(np.cos(turn / 2)), 0.0, 0.0, float(np.sin(turn / 2))))
        radius = g.shaft_diameter_m / 2
        self.rest, faces = shaft_mesh(self._x(self.stations_m), radius)
        h["shaft"] = scene.add_mesh_simple(f"{ROOT}/rotor/shaft", self.rest, faces, color=STEEL, scale=VIEW_SCALE)
        vertices, faces = tube(g.stack_length_m, radius, g.stack_diameter_m / 2, 48)
        h["stack"] = scene.add_mesh_simple(f"{ROOT}/rotor/stack", vertices, faces, color=LAMINATION, opacity=0.6,
                                           scale=VIEW_SCALE, position=self._at(self._x(g.bearing_m), 0.0, 0.0))
        h["stripe"] = scene.add_box(f"{ROOT}/rotor/stripe", (250, 250, 250),
                                    (VIEW_SCALE * (g.stack_length_m + 0.004), VIEW_SCALE * 0.012,
                                     VIEW_SCALE * 0.012))
        vertices, faces = tube(g.stack_length_m + 0.03, g.stack_diameter_m / 2 + 0.012,
                               g.stack_diameter_m / 2 + 0.06, 48)
        scene.add_mesh_simple(f"{ROOT}/stator", vertices, faces, color=STATOR, opacity=0.3, scale=VIEW_SCALE,
                              position=self._at(self._x(g.bearing_m), 0.0, 0.0))
        vertices, faces = tube(0.025, radius + 0.004, radius + 0.03)
        scene.add_mesh_simple(f"{ROOT}/ball_bearing", vertices, faces, color=STATOR, scale=VIEW_SCALE,
                              position=self._at(self._x(g.pivot_m), 0.0, 0.0))
        vertices, faces = tube(0.012, radius + 0.006, radius + 0.022)
        h["sensor"] = scene.add_mesh_simple(f"{ROOT}/sensor", vertices, faces, color=EDDY_CURRENT, scale=VIEW_SCALE)
        h["orbits"] = [scene.add_line_segments(f"{ROOT}/orbits/{k}", self._orbit_segments(0.01), _colours(FORWARD),
                                               thickness=0.006, position=self._at(self._x(z), 0.0, 0.0))
                       for k, z in enumerate(ORBIT_STATIONS_M)]
        h["markers"] = [scene.add_icosphere(f"{ROOT}/orbits/{k}/marker", VIEW_SCALE * 0.012, FORWARD)
                        for k in range(len(ORBIT_STATIONS_M))]
        scene.add_label(f"{ROOT}/labels/pivot", "ball bearing (pivot)", position=self._at(self._x(g.pivot_m), 0.0, 0.06))
        h["mode_label"] = scene.add_label(f"{ROOT}/labels/mode", "", anchor="bottom-center",
                                          position=self._at(self._x(g.length_m / 2), 0.0, 0.34))
        self.update(self.values)

    def update(self, values: dict) -> None:
        keys = ("shown_mode", "shown_whirl", "speed_rpm", "sensor_offset_mm", "modes", "beam_theory",
                "gain_factor", "pid_gain", "integral_time_ms", "derivative_time_ms", "derivative_filter_us",
                "feedback", "sensor_lag_us", "modal_damping_percent")
        changed = any(values.get(k) != self.values.get(k) for k in keys)
        self.values = dict(values)
        if changed:
            self._shape()
        h, g = self.handles, self.geometry
        offset = values["sensor_offset_mm"]
        h["sensor"].position = self._at(self._x(g.bearing_m + offset * 1e-3), 0.0, 0.0)
        h["sensor"].color = CAPACITIVE if self.integrated(offset) else EDDY_CURRENT
        colour = FORWARD if self.frequency_hz >= 0 else BACKWARD
        for line, marker, radius in zip(h["orbits"], h["markers"], self.orbit_radius):
            line.points = self._orbit_segments(float(radius))
            line.colors = _colours(colour)
            marker.color = colour
        direction = "forward" if self.frequency_hz >= 0 else "backward"
        h["mode_label"].text = (f"mode {int(values['shown_mode'])}, {direction} whirl: {abs(self.frequency_hz):.0f} Hz "
                                f"at {values['speed_rpm']:.0f} rpm\n(slowed, exaggerated; stripe: spin)")

    def animate(self, wall_time_s: float, latest: dict[str, float]) -> None:
        h = self.handles
        if not h:
            return
        self.frame += 1
        whirl = np.sign(self.frequency_hz or 1.0) * TURN_PER_FRAME_RAD * self.frame
        r = self.shape * np.exp(1j * whirl)                  # r = x + i y: x up (z), y sideways
        vertices = self.rest.copy()
        vertices[:, 2] += np.repeat(r.real, RING_SEGMENTS).astype(np.float32)
        vertices[:, 1] += np.repeat(r.imag, RING_SEGMENTS).astype(np.float32)
        h["shaft"].vertices = vertices
        b = self.bearing_index
        h["stack"].position = self._at(self._x(self.geometry.bearing_m), r[b].imag, r[b].real)
        spin = TURN_PER_FRAME_RAD * self.frame
        rim = self.geometry.stack_diameter_m / 2
        h["stripe"].position = self._at(self._x(self.geometry.bearing_m), r[b].imag + rim * np.sin(spin),
                                        r[b].real + rim * np.cos(spin))
        h["stripe"].wxyz = _about_x(-spin)
        at = [int(np.argmin(np.abs(self.stations_m - z))) for z in self.orbit_at]
        for marker, k in zip(h["markers"], at):                    # a child of its orbit: relative to it
            marker.position = self._at(0.0, r[k].imag, r[k].real)
