"""The filter debugger's 3D picture: the 3σ ellipsoids of P⁻ and P⁺ for three states around the
true state (``lab_modules.estimators.covariance_shapes``), drawn in the tab's 3D view in place of
the rig while the student steps through the filter's samples.

The box is ±``HALF_WIDTH`` world units about the origin, where the lab's camera looks; each axis
is one state, labelled with the length (in its unit) that a half-width stands for."""

from __future__ import annotations

import numpy as np

from app.panels.inspector import prefixed, symbol
from lab_modules.estimators.covariance_shapes import SIGMAS, StateBox, state_box
from lab_modules.formatting import number

ROOT = "/covariance_view"
HALF_WIDTH = 0.9                                 # world units per box half-width (fits 386 px of view)
PRIOR, POSTERIOR, TRUTH, AXIS = (31, 119, 180), (214, 39, 40), (44, 160, 44), (90, 90, 90)
MARKER_RADIUS = 0.05
NO_SHADOWS = {"cast_shadow": False, "receive_shadow": False}
LABEL = {"font_screen_scale": 0.8}


def box_edges() -> np.ndarray:
    """The twelve edges of the box, as segments (12, 2, 3)."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float32) * HALF_WIDTH
    pairs = [(a, b) for a in range(8) for b in range(a + 1, 8) if np.count_nonzero(corners[a] != corners[b]) == 1]
    return np.array([(corners[a], corners[b]) for a, b in pairs], np.float32)


def axis_text(box: StateBox, axis: int, states: tuple[tuple[str, str], ...]) -> str:
    """An axis label: the state's symbol and what one half-width stands for (about x̂⁻ where the
    simulation does not know the state's true value)."""
    label, unit = states[box.states[axis]]
    factor, shown_unit = prefixed(box.lengths[axis], unit)
    about = "" if box.known_truth[axis] else " about x̂⁻"
    return f"{symbol(label)} ±{number(box.lengths[axis] / factor, 3)} {shown_unit}{about}"


class CovarianceView:
    """The ellipsoids in ``scene`` (the tab's viser SceneApi) in place of ``rig`` (the exercise's
    attached ``SceneView``, whose root frame is hidden while they show; None without one)."""

    def __init__(self, scene, rig, states: tuple[tuple[str, str], ...]):
        self.scene, self.rig, self.states = scene, rig, states
        self.handles: dict | None = None          # made at the first ``show``
        self.root = None
        self.shown = False

    def _build(self) -> dict:
        scene = self.scene
        self.root = scene.add_frame(ROOT, show_axes=False)
        scene.add_line_segments(f"{ROOT}/box", box_edges(), AXIS, thickness=1.0, thickness_units="screen")
        ends = np.eye(3) * HALF_WIDTH
        scene.add_line_segments(f"{ROOT}/axes", np.stack([-ends, ends], axis=1).astype(np.float32), AXIS,
                                thickness=2.0, thickness_units="screen")
        handles = {"axis": [scene.add_label(f"{ROOT}/axis_{k}", "", position=tuple(ends[k] * 1.08), **LABEL)
                            for k in range(3)],
                   "title": scene.add_label(f"{ROOT}/title", "", position=(0.0, 0.0, HALF_WIDTH * 1.35),
                                            anchor="bottom-center", **LABEL)}
        scene.add_icosphere(f"{ROOT}/truth", MARKER_RADIUS, TRUTH, **NO_SHADOWS)
        for name, colour in (("prior", PRIOR), ("posterior", POSTERIOR)):
            handles[name] = scene.add_icosphere(f"{ROOT}/{name}", 1.0, colour, opacity=0.25, subdivisions=4,
                                                **NO_SHADOWS)
            handles[f"{name}_estimate"] = scene.add_icosphere(f"{ROOT}/{name}_estimate", MARKER_RADIUS, colour,
                                                              **NO_SHADOWS)
        return handles

    def show(self, sample: dict, states: tuple[int, int, int]) -> None:
        """The ellipsoids of ``sample`` (a ``FilterHistory.sample``) for ``states``."""
        if self.handles is None:
            self.handles = self._build()
        if not self.shown:
            self.root.visible, self.shown = True, True
            if self.rig is not None:
                self.rig.root.visible = False
        box = state_box(sample, states)
        for name, x, P in (("prior", sample["x_prior"], sample["P_prior"]),
                           ("posterior", sample["x_post"], sample["P_post"])):
            shape = box.ellipsoid(x, P)
            world = shape.centre * HALF_WIDTH
            self.handles[name].position = tuple(world)
            self.handles[name].wxyz = shape.wxyz()
            self.handles[name].scale = tuple(np.maximum(SIGMAS * shape.semi_axes * HALF_WIDTH, 1e-4))
            self.handles[f"{name}_estimate"].position = tuple(world)
        for k, label in enumerate(self.handles["axis"]):
            label.text = axis_text(box, k, self.states)
        self.handles["title"].text = (f"Sample {sample['sample']}: 3σ of P⁻ (blue), P⁺ (red)\n"
                                      "estimates: dots; true state: green, at the centre")

    def hide(self) -> None:
        """The rig again (after ``show``); the ellipsoids are hidden, kept for the next ``show``."""
        if not self.shown:
            return
        self.root.visible, self.shown = False, False
        if self.rig is not None:
            self.rig.root.visible = True
