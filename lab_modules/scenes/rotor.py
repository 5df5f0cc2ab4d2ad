"""The flexible rotor in the lab's 3D view (viser scene).

Shaft, lamination stack, bearing stator, ball bearing and the position
sensor's ring at its current axial position; the selected mode shape is
animated at an exaggerated amplitude and slowed down (a 300 Hz mode cannot
be watched), with its nodes marked by red spheres.  The shaft is one tube
mesh whose vertices are rewritten every frame; the stack moves as a rigid
body with the shaft's displacement and slope at the bearing plane.

Model axes: x along the shaft (drive end at negative x), z up = the bearing
axis whose deflection is shown.  Everything hangs under one frame that turns
the shaft 135° about z; every node is drawn ``VIEW_SCALE`` times life size, so the viewer's default camera (which
looks at the origin along the space diagonal) sees the rotor side-on.
"""

from __future__ import annotations

import numpy as np

from lab_modules.plants.flexible_rotor import FlexibleRotor

AMPLITUDE_M = 0.05              # drawn peak deflection of the shown mode
VIEW_SCALE = 4.0                # the rotor is drawn four times life size
ROOT = "/rotor_view"
SHOWN_FREQUENCY_HZ = 0.125      # the animation's (slowed) oscillation: eight drawn frames a swing at the
                                # 3D view's default once-a-second refresh (app/tab/session.py SCENE_REFRESH)
RING_SEGMENTS = 20
SHAFT_STATIONS = 92
STEEL, LAMINATION, STATOR = (175, 180, 190), (70, 90, 140), (150, 150, 150)
CAPACITIVE, EDDY_CURRENT, NODE = (40, 170, 80), (240, 140, 30), (220, 30, 30)


def tube(length_m: float, inner_radius_m: float, outer_radius_m: float, segments: int = RING_SEGMENTS):
    """Vertices and faces of a hollow cylinder (or a solid one with inner radius 0) along x, centred;
    faces wound counter-clockwise seen from outside (normals outwards, so back-face culling hides the far side)."""
    angle = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    vertices = []
    for x in (-length_m / 2, length_m / 2):
        for r in (outer_radius_m, max(inner_radius_m, 1e-6)):
            vertices.append(np.column_stack([np.full(segments, x), r * ring]))
    vertices = np.concatenate(vertices)
    outer_a, inner_a, outer_b, inner_b = (np.arange(segments) + k * segments for k in range(4))
    faces = []
    for a, b, flip in ((outer_a, outer_b, True), (inner_a, inner_b, False), (outer_a, inner_a, False),
                       (outer_b, inner_b, True)):         # counter-clockwise seen from outside
        a1, b1 = np.roll(a, -1), np.roll(b, -1)
        quads = np.concatenate([np.stack([a, b, b1], 1), np.stack([a, b1, a1], 1)])
        faces.append(quads[:, ::-1] if flip else quads)
    return vertices.astype(np.float32), np.concatenate(faces).astype(np.uint32)


def shaft_mesh(station_x: np.ndarray, radius_m: float, segments: int = RING_SEGMENTS):
    """Tube skin through the stations (closed by the stack and hub, so no end caps)."""
    angle = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    offsets = radius_m * np.stack([np.zeros(segments), np.cos(angle), np.sin(angle)], axis=1)
    vertices = (np.column_stack([station_x, np.zeros((len(station_x), 2))])[:, None, :] + offsets[None]).reshape(-1, 3)
    faces = []
    for i in range(len(station_x) - 1):
        a = i * segments + np.arange(segments)
        b, a1 = a + segments, np.roll(a, -1)
        b1 = a1 + segments
        faces += [np.stack([a, a1, b], 1), np.stack([a1, b1, b], 1)]
    return vertices.astype(np.float32), np.concatenate(faces).astype(np.uint32)


def _about_y(angle_rad: float) -> tuple[float, float, float, float]:
    """Quaternion (w, x, y, z) of a rotation about the scene's y axis."""
    return (float(np.cos(angle_rad / 2)), 0.0, float(np.sin(angle_rad / 2)), 0.0)


class RotorScene:
    """``SceneView`` of the flexible rotor; ``sensor_offset_mm``, ``shown_mode`` and
    whether the sensor is the integrated one come from the exercise's values."""

    def __init__(self, rotor: FlexibleRotor, values: dict, integrated) -> None:
        self.rotor = rotor
        self.geometry = rotor.geometry
        self.integrated = integrated
        self.values = dict(values)
        self.stations_m = np.linspace(0.0, self.geometry.length_m, SHAFT_STATIONS)
        self.handles: dict = {}
        self._shape()

    def _x(self, z_m):
        """Model x [m] of an axial position (shaft centred on the origin)."""
        return np.asarray(z_m) - self.geometry.length_m / 2

    @staticmethod
    def _at(x_m, y_m, z_m) -> tuple[float, float, float]:
        """Scene position of a model point [m] (drawn ``VIEW_SCALE`` times life size)."""
        return (VIEW_SCALE * float(x_m), VIEW_SCALE * float(y_m), VIEW_SCALE * float(z_m))

    def _shape(self) -> None:
        mode = int(self.values["shown_mode"]) - 1
        g = self.geometry
        shape = self.rotor.displacement(self.stations_m, mode + 1)[:, mode]
        scale = AMPLITUDE_M / np.max(np.abs(shape))
        self.shape = shape * scale
        dz = 1e-3
        at = self.rotor.displacement([g.bearing_m - dz, g.bearing_m, g.bearing_m + dz], mode + 1)[:, mode] * scale
        self.bearing_shape, self.bearing_slope = at[1], (at[2] - at[0]) / (2 * dz)
        self.nodes_m = self.rotor.nodal_points_m(mode)
        self.frequency_hz = self.rotor.natural_frequencies_hz(mode + 1)[mode]

    # -- SceneView -----------------------------------------------------------------------
    def attach(self, scene) -> None:
        g, h = self.geometry, self.handles
        scene.set_up_direction("+z")
        turn = 3 * np.pi / 4              # model x -> the camera's left-to-right
        self.root = scene.add_frame(ROOT, show_axes=False,
                                    wxyz=(float(np.cos(turn / 2)), 0.0, 0.0, float(np.sin(turn / 2))))
        radius = g.shaft_diameter_m / 2
        self.rest, faces = shaft_mesh(self._x(self.stations_m), radius)
        h["shaft"] = scene.add_mesh_simple(f"{ROOT}/rotor/shaft", self.rest, faces, color=STEEL, scale=VIEW_SCALE)
        vertices, faces = tube(g.stack_length_m, radius, g.stack_diameter_m / 2, 48)
        h["stack"] = scene.add_mesh_simple(f"{ROOT}/rotor/stack", vertices, faces, color=LAMINATION, opacity=0.6,
                                           scale=VIEW_SCALE,
                                           position=self._at(self._x(g.bearing_m), 0.0, 0.0))
        vertices, faces = tube(g.stack_length_m + 0.03, g.stack_diameter_m / 2 + 0.012,
                               g.stack_diameter_m / 2 + 0.06, 48)
        scene.add_mesh_simple(f"{ROOT}/stator", vertices, faces, color=STATOR, opacity=0.35, scale=VIEW_SCALE,
                              position=self._at(self._x(g.bearing_m), 0.0, 0.0))
        vertices, faces = tube(0.025, radius + 0.004, radius + 0.03)
        scene.add_mesh_simple(f"{ROOT}/ball_bearing", vertices, faces, color=STATOR, scale=VIEW_SCALE,
                              position=self._at(self._x(g.pivot_m), 0.0, 0.0))
        vertices, faces = tube(0.03, 0.0, g.hub_diameter_m / 2)
        h["hub"] = scene.add_mesh_simple(f"{ROOT}/rotor/hub", vertices, faces, color=STEEL, scale=VIEW_SCALE,
                                         position=self._at(self._x(g.hub_position_m), 0.0, 0.0))
        vertices, faces = tube(0.012, radius + 0.006, radius + 0.022)
        h["sensor"] = scene.add_mesh_simple(f"{ROOT}/sensor", vertices, faces, color=EDDY_CURRENT, scale=VIEW_SCALE)
        # a node: a red sphere on the axis and a red post through it (visible inside the stack too)
        h["nodes"] = [(scene.add_icosphere(f"{ROOT}/nodes/{k}/ball", VIEW_SCALE * 0.026, NODE),
                       scene.add_box(f"{ROOT}/nodes/{k}/post", NODE, (0.004 * VIEW_SCALE, 0.004 * VIEW_SCALE,
                                                                        0.36 * VIEW_SCALE)))
                      for k in range(6)]
        # labels near the bearing end (the right edge of the narrow 3D view) extend to the left
        scene.add_label(f"{ROOT}/labels/bearing", "magnetic bearing", anchor="bottom-right",
                        position=self._at(self._x(g.bearing_m), 0.0, g.stack_diameter_m / 2 + 0.08))
        scene.add_label(f"{ROOT}/labels/pivot", "ball bearing (pivot)",
                        position=self._at(self._x(g.pivot_m), 0.0, 0.06))
        h["sensor_label"] = scene.add_label(f"{ROOT}/labels/sensor", "sensor", anchor="top-right",
                                            position=(0.0, 0.0, 0.0))
        h["mode_label"] = scene.add_label(f"{ROOT}/labels/mode", "", anchor="bottom-center",
                                          position=self._at(self._x(g.length_m / 2), 0.0, 0.34))
        self.update(self.values)

    def update(self, values: dict) -> None:
        if int(values["shown_mode"]) != int(self.values["shown_mode"]):
            self.values = dict(values)
            self._shape()
        self.values = dict(values)
        h, g = self.handles, self.geometry
        offset = values["sensor_offset_mm"]
        z_s = g.bearing_m + offset * 1e-3
        integrated = self.integrated(offset)
        h["sensor"].position = self._at(self._x(z_s), 0.0, 0.0)
        h["sensor"].color = CAPACITIVE if integrated else EDDY_CURRENT
        kind = "integrated capacitive sensor" if integrated else "eddy-current sensor"
        h["sensor_label"].text = f"{kind} ({offset:+.0f} mm)"
        h["sensor_label"].position = self._at(self._x(z_s), 0.0, -0.06 - 0.05 * integrated)
        for k, (ball, post) in enumerate(h["nodes"]):
            ball.visible = post.visible = k < len(self.nodes_m)
            if ball.visible:
                ball.position = post.position = self._at(self._x(self.nodes_m[k]), 0.0, 0.0)
        mode = int(values["shown_mode"])
        h["mode_label"].text = f"mode {mode}: {self.frequency_hz:.0f} Hz\n(slowed, exaggerated; red: nodes)"

    def animate(self, wall_time_s: float, latest: dict[str, float]) -> None:
        h = self.handles
        if not h:
            return
        phase = np.sin(2 * np.pi * SHOWN_FREQUENCY_HZ * wall_time_s)
        deflection = np.repeat(phase * self.shape, RING_SEGMENTS).astype(np.float32)
        vertices = self.rest.copy()
        vertices[:, 2] += deflection
        h["shaft"].vertices = vertices
        h["stack"].position = self._at(self._x(self.geometry.bearing_m), 0.0, phase * self.bearing_shape)
        h["stack"].wxyz = _about_y(-float(np.arctan(phase * self.bearing_slope)))
