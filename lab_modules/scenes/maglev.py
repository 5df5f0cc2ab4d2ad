"""The maglev ball in the lab's 3D view (viser scene).

Paper 004 (Henley): a steel ball under an electromagnet (§2.1, Fig. 2.1,
2.3).  x1 is the air gap between the bottom of the coil and the ball (§3.3:
"the sensor measures the air gap between the levitated object and the
bottom of the electromagnet coil"), so the ball's top sits x1 below the
magnet's face and x1 -> 0 is the ball touching the coil (§2.4.2).

To scale (life size): the ball's measured diameter 19.05 mm (§3.3), the gap
x1 and the ruler beside it.  The arrows are the two forces of eq. 2.10,
f = C (x3/x1)^2 (eq. 2.7, C = L0 x0 / 2 from Table 3.1) up and m g down, at
``FORCE_SCALE_M_PER_N``.  Where the motion is too small to see at life size
(the 0.05 mm hardware references, a recording wandering by tens of
micrometres) the gap's deviation from a centre gap is drawn ``exaggeration``
times larger; the title states it and the ruler's labels stay true gaps.

Not in the paper, chosen to look like the rig of Fig. 2.1: the magnet's core
(20 mm diameter, ``CORE_RADIUS_M``) and coil (50 mm outer diameter, 50 mm
high).  The winding window (14 mm x 50 mm, 60 % copper, mean turn 0.113 m)
fits Table 3.1's R_c = 25 ohm with about 2300 turns of 0.48 mm wire, which
carry the operating 0.894 A (eq. 2.14) at 4.9 A/mm^2, a usual density for a
small coil (the paper gives no winding data).  The paper's ball is
inconsistent in itself: a solid steel ball of 19.05 mm weighs 28 g, not the
55.06 g of §3.3; the view draws the stated diameter and the gravity arrow
uses the stated mass.

Warning colour: the ball turns amber when the state nears the region the
controller guards (x1 -> 0, x3 -> 0; ``feedback_linearisation.GUARD_GAP_M``,
``GUARD_CURRENT_A``), i.e. gap below ``WARN_GAP_M``, current below
``WARN_CURRENT_A``, or a guarded controller step, and dark red once the ball has
struck the magnet or dropped out of reach (the simulation's touchdown limits).

Framing as the bearing's (``scenes.bearing.view_pose``): the lab's camera,
the magnet's face centred on ``FACE_CENTRE_PX`` in the 3D canvas between the
docked panels, ``PX_PER_MM`` pixels per millimetre.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import viser.transforms as tf

from lab_modules.controllers.feedback_linearisation import GUARD_CURRENT_A, GUARD_GAP_M
from lab_modules.loops.maglev_loop import MAX_GAP_M, MIN_GAP_M
from lab_modules.plants.maglev_ball import TABLE_3_1
from lab_modules.scenes.bearing import (
    BEARING_FORCE_GREEN,
    CAMERA_POSITION,
    DISTURBANCE_PURPLE,
    ESTIMATE_RED,
    MEASURED_GREY,
    NO_SHADOWS,
    circle,
    coil_color,
    set_if_changed,
    view_pose,
)
from lab_modules.scenes.rotor import tube

ROOT = "/maglev_view"
FRONT = f"{ROOT}/front"                  # markers, ruler and arrows, in front of the ball
BALL_RADIUS_M = 0.01905 / 2              # §3.3: measured diameter 1.905 cm
# Not in the paper (see module docstring):
CORE_RADIUS_M = 0.010
COIL_INNER_RADIUS_M, COIL_OUTER_RADIUS_M, COIL_HEIGHT_M = 0.011, 0.025, 0.050
CORE_HEIGHT_M = 0.056
DRAWN_GAP_MAX_M = MAX_GAP_M              # the ruler spans 0 ... 30 mm drawn
RULER_Y_M = -BALL_RADIUS_M - 0.008       # left of the ball
FRONT_M = BALL_RADIUS_M + 0.001
FORCE_SCALE_M_PER_N = 0.04               # 40 mm per newton: m g = 0.54 N -> 22 mm
LONGEST_ARROW_M = 0.03
WARN_GAP_M = 5 * GUARD_GAP_M             # 5 mm: 3 mm above touchdown (2 mm)
WARN_CURRENT_A = 10 * GUARD_CURRENT_A    # 0.1 A: 11 % of the operating current
BIAS_CURRENT_A = TABLE_3_1.equilibrium_current_a(TABLE_3_1.operating_gap_m)   # eq. 2.14: 0.894 A
CORE_IRON, REFERENCE_BLACK = (110, 110, 115), (0, 0, 0)
BALL_STEEL = (135, 140, 150)             # darker than the bearing's steel: the ball's lit top stays visible
WARNING_AMBER = (245, 160, 0)
STOPPED_RED = (110, 15, 15)              # darker than the estimate's red outline drawn over the ball
GRAVITY_VIOLET = DISTURBANCE_PURPLE
FACE_CENTRE_PX = (193, 320)
LEGEND_INTERVAL_S = 0.25
PX_PER_MM = 3.0


def nice_at_least(value: float) -> float:
    """The smallest of 1, 2, 5 x 10^k that is >= ``value``."""
    decade = 10.0 ** np.floor(np.log10(value))
    return float(next(m * decade for m in (1, 2, 5, 10) if m * decade >= value * (1 - 1e-9)))


def nice_at_most(value: float) -> float:
    """The largest of 1, 2, 5 x 10^k that is <= ``value``."""
    decade = 10.0 ** np.floor(np.log10(value))
    return float(next(m * decade for m in (5, 2, 1) if m * decade <= value * (1 + 1e-9)))


def exaggeration_for(deviation_m: float, room_m: float) -> float:
    """Life size (1) unless ``deviation_m`` drawn that way is under ``room_m``; then a 1-2-5
    factor that draws it at most ``room_m``."""
    if not deviation_m > 0:
        return 1.0
    return max(1.0, nice_at_most(room_m / deviation_m))


@dataclass(frozen=True)
class DrawingScale:
    """Drawn gap = centre + exaggeration (x1 - centre), clipped to 0 ... ``DRAWN_GAP_MAX_M``."""

    exaggeration: float = 1.0
    centre_m: float = TABLE_3_1.operating_gap_m

    def drawn_gap_m(self, gap_m: float) -> float:
        return float(np.clip(self.centre_m + self.exaggeration * (gap_m - self.centre_m), 0.0, DRAWN_GAP_MAX_M))

    def off_scale(self, gap_m: float) -> bool:
        return not 0.0 <= self.centre_m + self.exaggeration * (gap_m - self.centre_m) <= DRAWN_GAP_MAX_M

    def true_gap_m(self, drawn_m: float) -> float:
        return self.centre_m + (drawn_m - self.centre_m) / self.exaggeration

    def title(self) -> str:
        if self.exaggeration == 1.0:
            return "Maglev ball, life size"
        return f"Maglev ball, gap ×{self.exaggeration:g} about {self.centre_m * 1e3:g} mm"

    def ticks(self) -> tuple[list[float], list[float]]:
        """True gaps [m] of the ruler's ticks (>= 1 mm apart drawn) and labelled ticks (>= 5 mm)."""
        low, high = self.true_gap_m(0.0), self.true_gap_m(DRAWN_GAP_MAX_M)
        out = []
        for spacing_m in (1e-3, 5e-3):
            step = nice_at_least(spacing_m / self.exaggeration)
            first = np.ceil(low / step - 1e-9)
            # "+ 0.0" turns a tick at -0.0 into 0.0 (no "-0" label)
            out.append([float(k * step) + 0.0 for k in np.arange(first, np.floor(high / step + 1e-9) + 1)])
        return out[0], out[1]


@dataclass(frozen=True)
class Columns:
    """Trace columns the view reads; None: the exercise has no such column.

    ``ball``: the drawn ball's gap x1 [m]; ``ghost``: a second position drawn
    as the ball's outline (the filter's estimate); ``measured``: the sensor's
    gap y [m]; ``current``: the coil current [A] of the coil colour and the
    magnetic force; ``estimate``/``estimated_current``: the filter's x1, x3
    checked against the guarded region; ``guarded``: 1 when the controller
    clamped its input; ``velocity``: the ball's x2 [m/s], to see it strike."""

    ball: str
    ball_label: str
    current: str
    current_label: str = "coil x₃"
    measured: str = "x_measured_m"
    reference: str = "reference_m"
    ghost: str | None = None
    estimate: str = "x_estimated_m"
    estimated_current: str = "current_estimated_a"
    guarded: str | None = None
    velocity: str | None = None


class MaglevScene:
    """``SceneView`` of the maglev ball; ``drawing_scale(values)`` says how the gap is drawn."""

    def __init__(self, values: dict, columns: Columns, drawing_scale: Callable[[dict], DrawingScale]) -> None:
        self.columns = columns
        self.drawing_scale = drawing_scale
        self.scale = drawing_scale(values)
        self.handles: dict = {}
        self.shown: dict = {}
        self.legend_time_s = -np.inf           # wall time of the last legend text sent
        self.legend_warning = ""
        self.ruler: list = []
        self.scene = None

    # -- SceneView -----------------------------------------------------------------------
    def attach(self, scene) -> None:
        self.scene = scene
        h = self.handles
        scene.set_up_direction("+z")
        wxyz, position = view_pose(FACE_CENTRE_PX, 1e-3 / PX_PER_MM)
        self.root = scene.add_frame(ROOT, show_axes=False, wxyz=wxyz, position=position)
        # Markers drawn in front of the ball, yet where the ball's mid plane would show them: the
        # plane x = 0 scaled towards the camera (c, in the view's frame) onto x = FRONT_M.
        camera = tf.SO3(np.asarray(wxyz)).as_matrix().T @ (CAMERA_POSITION - position)
        shrink = (camera[0] - FRONT_M) / camera[0]
        scene.add_frame(FRONT, show_axes=False, position=tuple((1 - shrink) * camera), scale=shrink)
        vertices, faces = _upright(*tube(CORE_HEIGHT_M, 0.0, CORE_RADIUS_M, 48))
        scene.add_mesh_simple(f"{ROOT}/magnet/core", vertices, faces, color=CORE_IRON,
                              position=(0.0, 0.0, CORE_HEIGHT_M / 2), **NO_SHADOWS)
        vertices, faces = _upright(*tube(COIL_HEIGHT_M, COIL_INNER_RADIUS_M, COIL_OUTER_RADIUS_M, 64))
        h["coil"] = scene.add_mesh_simple(f"{ROOT}/magnet/coil", vertices, faces, color=coil_color(0.0, BIAS_CURRENT_A),
                                          position=(0.0, 0.0, COIL_HEIGHT_M / 2), **NO_SHADOWS)
        h["ball"] = scene.add_icosphere(f"{ROOT}/ball", BALL_RADIUS_M, BALL_STEEL, **NO_SHADOWS)
        if self.columns.ghost is not None:
            h["ghost"] = scene.add_frame(f"{FRONT}/ghost", show_axes=False, visible=False)
            scene.add_line_segments(f"{FRONT}/ghost/outline", circle(BALL_RADIUS_M, 0.0), ESTIMATE_RED,
                                    thickness=2.0, thickness_units="screen")
        h["measured"] = scene.add_icosphere(f"{FRONT}/measured", 0.0015, MEASURED_GREY, visible=False,
                                            **NO_SHADOWS)
        reference = np.array([[[0.0, RULER_Y_M, 0.0], [0.0, BALL_RADIUS_M + 0.004, 0.0]]], dtype=np.float32)
        h["reference"] = scene.add_line_segments(f"{FRONT}/reference", reference, REFERENCE_BLACK, thickness=1.5,
                                                 thickness_units="screen", visible=False)
        h["arrows"] = {name: scene.add_arrows(f"{FRONT}/arrows/{name}", np.zeros((1, 2, 3), np.float32), color,
                                              shaft_radius=0.0008, head_radius=0.0018, head_length=0.003,
                                              visible=False)
                       for name, color in (("magnetic", BEARING_FORCE_GREEN), ("gravity", GRAVITY_VIOLET))}
        h["title"] = scene.add_label(f"{ROOT}/labels/title", "", font_screen_scale=0.85, anchor="bottom-center",
                                     position=(0.0, 0.0, CORE_HEIGHT_M + 0.004))
        h["legend"] = scene.add_label(f"{ROOT}/labels/legend", "", font_screen_scale=0.9, anchor="top-center",
                                      position=(0.0, 0.0, -DRAWN_GAP_MAX_M - 2 * BALL_RADIUS_M - 0.004))
        self._draw_ruler()
        self.animate(0.0, {})

    def update(self, values: dict) -> None:
        scale = self.drawing_scale(values)
        if scale != self.scale:
            self.scale = scale
            if self.scene is not None:
                self._draw_ruler()
                self.shown.clear()          # every position depends on the scale: send them again
                self.legend_time_s = -np.inf

    def animate(self, wall_time_s: float, latest: dict[str, float]) -> None:
        h, c, scale = self.handles, self.columns, self.scale
        if not h:
            return
        gap = latest.get(c.ball, scale.centre_m)
        if not np.isfinite(gap):
            return
        current = latest.get(c.current, BIAS_CURRENT_A)
        current = current if np.isfinite(current) else 0.0
        self._set(h["title"], "text", scale.title())
        ball_centre = -scale.drawn_gap_m(gap) - BALL_RADIUS_M
        self._set(h["ball"], "position", (0.0, 0.0, ball_centre))
        self._set(h["coil"], "color", coil_color(current, BIAS_CURRENT_A))
        lines = [f"{c.ball_label} x₁ = {gap * 1e3:.2f} mm" + (" (off scale)" if scale.off_scale(gap) else "")]
        if c.ghost is not None:
            estimate = latest.get(c.ghost, float("nan"))
            self._marker(h["ghost"], estimate, (0.0, 0.0, -BALL_RADIUS_M))
            if np.isfinite(estimate):
                lines.append(f"○ estimate x̂₁ = {estimate * 1e3:.2f} mm")
        measured = latest.get(c.measured, float("nan"))
        self._marker(h["measured"], measured, (0.0, 0.0, 0.0))
        if np.isfinite(measured):
            lines.append(f"• measured y = {measured * 1e3:.2f} mm")
        reference = latest.get(c.reference, float("nan"))
        self._marker(h["reference"], reference, (0.0, 0.0, 0.0))
        if np.isfinite(reference):
            lines.append(f"— reference y_R = {reference * 1e3:.2f} mm")
        magnetic = TABLE_3_1.force_constant_n_m2_per_a2 * (current / gap) ** 2 if gap > 0 else float("inf")
        weight = TABLE_3_1.mass_kg * TABLE_3_1.gravity_m_per_s2
        self._arrow("magnetic", magnetic, -0.002, ball_centre)
        self._arrow("gravity", -weight, 0.002, ball_centre)
        lines += [f"{c.current_label} = {current:.3f} A", f"↑ C(x₃/x₁)² = {magnetic:.2f} N", f"↓ m g = {weight:.2f} N"]
        warning, color = self.warning(latest)
        self._set(h["ball"], "color", color)
        if warning:
            lines.append(f"⚠ {warning}")
        # The numbers change every frame; rewriting the label's text that often costs a third of the
        # frame rate in a software-rendered browser, so it is refreshed a few times a second (at once
        # when the warning changes).
        if wall_time_s - self.legend_time_s >= LEGEND_INTERVAL_S or warning != self.legend_warning:
            self.legend_time_s, self.legend_warning = wall_time_s, warning
            self._set(h["legend"], "text", "\n".join(lines))

    def warning(self, latest: dict[str, float]) -> tuple[str, tuple[int, int, int]]:
        """('' or what is wrong, ball colour): near the guarded region x1 -> 0, x3 -> 0 or stopped."""
        c = self.columns
        gap = latest.get(c.ball, float("nan"))
        velocity = latest.get(c.velocity, 0.0) if c.velocity else 0.0
        next_gap = gap + velocity * TABLE_3_1.sample_time_s      # the row holds the state before its step
        if next_gap < MIN_GAP_M:
            return "the ball struck the magnet", STOPPED_RED
        if next_gap > MAX_GAP_M:
            return "the ball fell out of reach", STOPPED_RED
        estimate = latest.get(c.estimate, float("nan"))
        estimated_current = latest.get(c.estimated_current, float("nan"))
        if c.guarded and latest.get(c.guarded, 0.0) > 0:
            return "controller guard active (x̂ clamped)", WARNING_AMBER
        for name, value, limit, unit, scale in (("x₁", gap, WARN_GAP_M, "mm", 1e3),
                                               ("x̂₁", estimate, WARN_GAP_M, "mm", 1e3),
                                               ("x̂₃", estimated_current, WARN_CURRENT_A, "A", 1.0)):
            if value < limit:
                return f"{name} = {value * scale:.2f} {unit}: near x → 0", WARNING_AMBER
        if gap > MAX_GAP_M - WARN_GAP_M:
            return "the ball is leaving the field", WARNING_AMBER
        return "", BALL_STEEL

    # -- helpers ---------------------------------------------------------------------------
    def _set(self, handle, attribute: str, value) -> None:
        set_if_changed(self.shown, handle, attribute, value)

    def _marker(self, handle, gap_m: float, offset: tuple[float, float, float]) -> None:
        """Show ``handle`` at the drawn gap ``gap_m`` below the face (plus ``offset``); NaN hides it."""
        visible = bool(np.isfinite(gap_m))
        self._set(handle, "visible", visible)
        if visible:
            self._set(handle, "position", (offset[0], offset[1], offset[2] - self.scale.drawn_gap_m(gap_m)))

    def _arrow(self, name: str, force_n: float, across_m: float, centre_m: float) -> None:
        """A force arrow from the ball's centre, ``across_m`` right of its axis."""
        length = float(np.clip(force_n * FORCE_SCALE_M_PER_N, -LONGEST_ARROW_M, LONGEST_ARROW_M))
        handle = self.handles["arrows"][name]
        self._set(handle, "visible", abs(length) > 0.001)
        if abs(length) > 0.001:
            start = (0.001, across_m, centre_m)
            self._set(handle, "points", np.array([[start, (start[0], across_m, centre_m + length)]], np.float32))

    def _draw_ruler(self) -> None:
        """The ruler beside the gap: ticks every >= 1 mm drawn, true gaps [mm] every >= 5 mm drawn."""
        for handle in self.ruler:
            handle.remove()
        scene, scale = self.scene, self.scale
        ticks, labelled = scale.ticks()
        x = 0.0
        segments = [[[x, RULER_Y_M, 0.0], [x, RULER_Y_M, -DRAWN_GAP_MAX_M]]]
        for gap in ticks:
            length = 0.004 if any(abs(gap - m) < 1e-12 for m in labelled) else 0.002
            z = -scale.drawn_gap_m(gap)
            segments.append([[x, RULER_Y_M - length, z], [x, RULER_Y_M, z]])
        self.ruler = [scene.add_line_segments(f"{FRONT}/ruler/ticks", np.array(segments, np.float32), (60, 60, 60),
                                              thickness=1.0, thickness_units="screen")]
        decimals = max(0, -int(np.floor(np.log10(labelled[1] - labelled[0]) + 3 + 1e-9))) if len(labelled) > 1 else 0
        for k, gap in enumerate(labelled):
            self.ruler.append(scene.add_label(
                f"{FRONT}/ruler/label_{k}", f"{gap * 1e3:.{decimals}f}", font_screen_scale=0.7,
                anchor="center-right", position=(x, RULER_Y_M - 0.005, -scale.drawn_gap_m(gap))))
        self.ruler.append(scene.add_label(f"{FRONT}/ruler/unit", "x₁ [mm]", font_screen_scale=0.7,
                                          anchor="bottom-right", position=(x, RULER_Y_M, 0.001)))


def _upright(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A ``tube`` (made along x) turned to stand along z: a cyclic axis swap, which keeps the winding."""
    return np.ascontiguousarray(vertices[:, [1, 2, 0]]), faces
