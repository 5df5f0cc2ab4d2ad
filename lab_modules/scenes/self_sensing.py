"""The self-sensing rig of paper 001 in the lab's 3D view (viser scene).

Fig. 1a of the paper: a ferrite ball under a ferrite core carrying one coil.
The ball hangs at its true gap s below the core's face (life size); the gap
the estimator reads from the current ripple, ŝ, is the red outline.  The
estimation error is micrometres, invisible at life size, so the outline is
drawn at s + ``ERROR_EXAGGERATION`` (ŝ − s), clipped to ±``GHOST_CLIP_M``
(the title says so; the legend gives the true numbers).

Not in the paper, drawn to match the lab's parameter set
(``plants.self_sensing_ball``): a ball of 0.14 kg ferrite (about 4.8 g/cm³)
is 38 mm across; the core's pole is 16 mm across (2.0 cm² core area); the
coil is 40 mm high, 10-25 mm in radius.  The coil's colour follows the mean
current (pale at 0, copper at the paper's ī = 1.5 A, red at twice that).

Framing as the other scenes (``scenes.bearing.view_pose``): the core's face
centred on ``FACE_CENTRE_PX`` of the 3D canvas, ``PX_PER_MM`` pixels per mm.
"""

from __future__ import annotations

import numpy as np

from lab_modules.scenes.bearing import ESTIMATE_RED, NO_SHADOWS, circle, coil_color, set_if_changed, view_pose
from lab_modules.scenes.rotor import tube

ROOT = "/self_sensing_view"
BALL_RADIUS_M = 0.019
CORE_RADIUS_M = 0.008
COIL_INNER_RADIUS_M, COIL_OUTER_RADIUS_M, COIL_HEIGHT_M = 0.010, 0.025, 0.040
CORE_HEIGHT_M = 0.046
MEAN_CURRENT_A = 1.5                     # paper §4.2: ī
ERROR_EXAGGERATION = 100.0
GHOST_CLIP_M = 0.015
FACE_CENTRE_PX = (193, 250)
PX_PER_MM = 3.0
LEGEND_INTERVAL_S = 0.25
FERRITE = (70, 70, 78)
BALL_GREY = (120, 120, 130)


def _upright(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A ``tube`` (made along x) turned to stand along z (cyclic axis swap keeps the winding)."""
    return np.ascontiguousarray(vertices[:, [1, 2, 0]]), faces


class SelfSensingScene:
    """``SceneView``: core, coil, the ball at its true gap and the estimate as an outline."""

    def __init__(self, columns: dict[str, str]) -> None:
        self.columns = columns            # keys: gap, estimate, sigma, current, inductance, estimated_inductance
        self.handles: dict = {}
        self.shown: dict = {}
        self.legend_time_s = -np.inf

    def attach(self, scene) -> None:
        h = self.handles
        scene.set_up_direction("+z")
        wxyz, position = view_pose(FACE_CENTRE_PX, 1e-3 / PX_PER_MM)
        self.root = scene.add_frame(ROOT, show_axes=False, wxyz=wxyz, position=position)
        vertices, faces = _upright(*tube(CORE_HEIGHT_M, 0.0, CORE_RADIUS_M, 48))
        scene.add_mesh_simple(f"{ROOT}/core", vertices, faces, color=FERRITE,
                              position=(0.0, 0.0, CORE_HEIGHT_M / 2), **NO_SHADOWS)
        vertices, faces = _upright(*tube(COIL_HEIGHT_M, COIL_INNER_RADIUS_M, COIL_OUTER_RADIUS_M, 64))
        h["coil"] = scene.add_mesh_simple(f"{ROOT}/coil", vertices, faces, color=coil_color(0.0, MEAN_CURRENT_A),
                                          position=(0.0, 0.0, COIL_HEIGHT_M / 2 + 0.003), **NO_SHADOWS)
        h["ball"] = scene.add_icosphere(f"{ROOT}/ball", BALL_RADIUS_M, BALL_GREY, **NO_SHADOWS)
        h["ghost"] = scene.add_line_segments(f"{ROOT}/ghost", circle(BALL_RADIUS_M, BALL_RADIUS_M + 0.001),
                                             ESTIMATE_RED, thickness=2.0, thickness_units="screen")
        h["title"] = scene.add_label(f"{ROOT}/title", f"Self-sensing ball, life size; estimate error ×"
                                     f"{ERROR_EXAGGERATION:g} (red outline)", font_screen_scale=0.8,
                                     anchor="bottom-center", position=(0.0, 0.0, CORE_HEIGHT_M + 0.004))
        h["legend"] = scene.add_label(f"{ROOT}/legend", "", font_screen_scale=0.85, anchor="top-center",
                                      position=(0.0, 0.0, -0.008 - 2 * BALL_RADIUS_M - 0.012))
        self.animate(0.0, {})

    def update(self, values: dict) -> None:
        """Nothing in the drawing depends on the sliders."""

    def drawn_ghost_gap_m(self, gap_m: float, estimate_m: float) -> float:
        """Where the outline is drawn: the error magnified, clipped."""
        error = float(np.clip(ERROR_EXAGGERATION * (estimate_m - gap_m), -GHOST_CLIP_M, GHOST_CLIP_M))
        return max(gap_m + error, 0.0)

    def animate(self, wall_time_s: float, latest: dict[str, float]) -> None:
        h, c = self.handles, self.columns
        if not h:
            return
        gap = latest.get(c["gap"], 4e-3)
        estimate = latest.get(c["estimate"], gap)
        if not (np.isfinite(gap) and np.isfinite(estimate)):
            return
        current = latest.get(c["current"], 0.0)
        set_if_changed(self.shown, h["ball"], "position", (0.0, 0.0, -gap - BALL_RADIUS_M))
        ghost = self.drawn_ghost_gap_m(gap, estimate)
        set_if_changed(self.shown, h["ghost"], "position", (0.0, 0.0, -ghost - BALL_RADIUS_M))
        set_if_changed(self.shown, h["coil"], "color", coil_color(current, MEAN_CURRENT_A))
        if wall_time_s - self.legend_time_s >= LEGEND_INTERVAL_S and latest:
            self.legend_time_s = wall_time_s
            sigma = latest.get(c["sigma"], float("nan"))
            lines = [f"gap s = {gap * 1e3:.3f} mm (grey ball)",
                     f"estimate ŝ = {estimate * 1e3:.3f} mm (red), ŝ − s = {(estimate - gap) * 1e6:.1f} µm",
                     f"σ̂(ŝ) = {sigma * 1e6:.1f} µm",
                     (f"L = {latest.get(c['inductance'], float('nan')) * 1e3:.3f} mH, "
                     f"L̄ = {latest.get(c['estimated_inductance'], float('nan')) * 1e3:.3f} mH"),
                     f"mean coil current {current:.3f} A"]
            set_if_changed(self.shown, h["legend"], "text", "\n".join(lines))
