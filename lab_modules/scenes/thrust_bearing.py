"""The thrust bearing of paper 003 in the lab's 3D view (viser scene), as a section.

Fig. 2 of the paper: a thrust collar on the rotor between two stator halves
(upper and lower magnet, differential drive), and the touchdown bearing that
stops the collar at ±0.75 mm (the lab's choice, see ``plants.thrust_bearing``).
The view is a side section through the shaft with the bearing's axis drawn
vertical.  Not to scale and not in the paper: the stator, collar and shaft
proportions (chosen to read as a thrust bearing).  The gaps (0.75 mm) are
drawn ``EXAGGERATION`` times larger, and so is the collar's motion; the
estimate is a thin red bar at its drawn position, the coil colours follow the
two magnets' currents i0 ± i.
"""

from __future__ import annotations

import numpy as np

from lab_modules.plants.thrust_bearing import TABLE_1
from lab_modules.scenes.bearing import view_pose

ROOT = "/thrust_view"
EXAGGERATION = 40.0                      # drawn gap 30 mm for 0.75 mm
GAP_DRAWN_M = TABLE_1.gap_m * EXAGGERATION
SHAFT_WIDTH_M = 0.10
COLLAR_WIDTH_M, COLLAR_HEIGHT_M = 0.46, 0.05
STATOR_WIDTH_M, STATOR_HEIGHT_M = 0.17, 0.09
STATOR_INNER_M = 0.07                    # bore clearance between shaft and stator
SHAFT_HEIGHT_M = 0.56
CENTRE_PX = (193, 330)
METRES_PER_PX = 0.6 / 300                # the section about 300 px wide
IRON = (120, 124, 130)
COLLAR_STEEL = (70, 110, 170)
TOUCHDOWN = (30, 30, 30)
ESTIMATE_RED = (214, 39, 40)
NO_SHADOWS = {"cast_shadow": False, "receive_shadow": False}


def coil_color(current_a: float, limit_a: float) -> tuple[int, int, int]:
    """Copper that glows red with the coil's current (0 ... limit)."""
    share = float(np.clip(current_a / max(limit_a, 1e-9), 0.0, 1.0))
    return (int(184 + 71 * share), int(115 * (1 - share) + 40 * share), int(51 * (1 - share)))


class ThrustBearingScene:
    """``SceneView`` of ``thrust_liftoff``: collar, stator halves, coils, touchdown bearing, estimate."""

    def __init__(self, values: dict):
        self.values = dict(values)
        self.handles: dict = {}

    def attach(self, scene) -> None:
        h = self.handles
        scene.set_up_direction("+z")
        wxyz, position = view_pose(CENTRE_PX, METRES_PER_PX)
        self.root = scene.add_frame(ROOT, show_axes=False, wxyz=wxyz, position=position)
        depth = 0.05
        scene.add_box(f"{ROOT}/shaft", IRON, (depth, SHAFT_WIDTH_M, SHAFT_HEIGHT_M), **NO_SHADOWS)
        offset = GAP_DRAWN_M + COLLAR_HEIGHT_M / 2 + STATOR_HEIGHT_M / 2
        side = SHAFT_WIDTH_M / 2 + STATOR_INNER_M + STATOR_WIDTH_M / 2
        for half, z in (("upper", offset), ("lower", -offset)):
            for y in (-side, side):
                scene.add_box(f"{ROOT}/stator/{half}_{y > 0}", IRON, (depth, STATOR_WIDTH_M, STATOR_HEIGHT_M),
                              position=(0.0, y, z), **NO_SHADOWS)
            h[f"coil_{half}"] = [scene.add_box(
                f"{ROOT}/coil/{half}_{y > 0}", coil_color(TABLE_1.bias_current_a, 10.0),
                (depth * 1.1, STATOR_WIDTH_M * 0.45, STATOR_HEIGHT_M * 0.5), position=(0.0, y, z), **NO_SHADOWS)
                for y in (-side, side)]
        # touchdown bearing: rings on the shaft that stop the collar at ±clearance (drawn exaggerated)
        clearance = TABLE_1.touchdown_clearance_m * EXAGGERATION
        for half, z in (("upper", clearance + COLLAR_HEIGHT_M / 2 + 0.01), ("lower", -clearance - COLLAR_HEIGHT_M / 2 - 0.01)):
            for y in (-1, 1):
                scene.add_box(f"{ROOT}/touchdown/{half}_{y}", TOUCHDOWN, (depth * 1.2, 0.035, 0.02),
                              position=(0.0, y * (SHAFT_WIDTH_M / 2 + 0.0175), z), **NO_SHADOWS)
        h["collar"] = scene.add_box(f"{ROOT}/collar", COLLAR_STEEL, (depth * 0.9, COLLAR_WIDTH_M, COLLAR_HEIGHT_M),
                                    **NO_SHADOWS)
        h["estimate"] = scene.add_box(f"{ROOT}/estimate", ESTIMATE_RED, (depth * 1.3, COLLAR_WIDTH_M * 1.05, 0.004),
                                      **NO_SHADOWS)
        h["label"] = scene.add_label(f"{ROOT}/label", "", position=(0.0, 0.0, -SHAFT_HEIGHT_M / 2 - 0.02),
                                     font_screen_scale=0.8, anchor="top-center")
        scene.add_label(f"{ROOT}/title", f"Thrust collar between the stator halves (gaps and motion ×{EXAGGERATION:g})",
                        position=(0.0, 0.0, SHAFT_HEIGHT_M / 2 + 0.02), font_screen_scale=0.8,
                        anchor="bottom-center")
        self.animate(0.0, {})

    def update(self, values: dict) -> None:
        self.values = dict(values)

    def animate(self, wall_time_s: float, latest: dict[str, float]) -> None:
        h = self.handles
        if not h:
            return
        x = float(latest.get("x_true_m", self.values.get("start_position_mm", -0.75) * 1e-3))
        x_hat = float(latest.get("x_estimated_m", x))
        i = float(latest.get("current_a", 0.0))
        limit = float(self.values.get("current_limit_a", 10.0))
        h["collar"].position = (0.0, 0.0, x * EXAGGERATION)
        h["estimate"].position = (0.0, 0.0, x_hat * EXAGGERATION)
        i0 = TABLE_1.bias_current_a
        for half, current in (("upper", i0 + i), ("lower", i0 - i)):
            for coil in h[f"coil_{half}"]:
                coil.color = coil_color(max(current, 0.0), limit + i0)
        h["label"].text = f"collar x = {x * 1e6:.0f} µm, estimate {x_hat * 1e6:.0f} µm, coil current i = {i:.2f} A"
