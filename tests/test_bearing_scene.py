"""The bearing's 3D view: geometry from paper 000 (eq. 10, Appendix) and the
mapping of the simulated state onto the scene, on a recording stand-in for
viser's SceneApi."""

import numpy as np
import pytest

from lab_modules.exercises import registry
from lab_modules.plants.radial_bearing import RIG
from lab_modules.scenes import bearing as bs


class Handle:
    """A scene node: keeps its creation arguments and every property set later."""

    def __init__(self, kind, name, args, kwargs):
        self.kind, self.name, self.args = kind, name, args
        self.__dict__.update(kwargs)


class RecordingScene:
    def __init__(self):
        self.nodes: dict[str, Handle] = {}

    def set_up_direction(self, direction):
        self.up = direction

    def __getattr__(self, method):
        if not method.startswith("add_"):
            raise AttributeError(method)

        def add(name, *args, **kwargs):
            self.nodes[name] = Handle(method, name, args, kwargs)
            return self.nodes[name]
        return add


def attached(exercise_name="kalman_noise"):
    exercise = registry()[exercise_name]
    view, scene = exercise.scene(exercise.resolve({})), RecordingScene()
    view.attach(scene)
    return view, scene


def test_poles_sit_at_the_pole_angle_either_side_of_each_magnet_on_the_bore():
    _, scene = attached()
    poles = [node for name, node in scene.nodes.items() if "/stator/pole_" in name]
    assert len(poles) == 8
    angles = sorted(np.degrees(np.arctan2(p.position[1], p.position[2])) % 360 for p in poles)
    np.testing.assert_allclose(angles, 22.5 + 45 * np.arange(8), atol=1e-9)   # alpha = pi/8 about 0, 90, ...
    face_radius = [np.hypot(p.position[1], p.position[2]) - p.args[1][2] / 2 for p in poles]
    np.testing.assert_allclose(face_radius, 0.136 + RIG.delta0_m, atol=1e-9)  # 272 mm rotor + gap


def test_animate_moves_rotor_and_markers_by_the_stated_exaggeration():
    view, scene = attached()
    assert f"×{view.exaggeration:g}" in scene.nodes[f"{bs.ROOT}/labels/title"].args[0]
    view.animate(1.0, {"time_s": 0.01, "x_true_m": 2e-6, "x_measured_m": -3e-6, "x_estimated_m": 1e-6,
                       "current_a": 0.5})
    assert scene.nodes[f"{bs.ROOT}/rotor"].position == pytest.approx((0.0, 0.0, view.exaggeration * 2e-6))
    assert scene.nodes[f"{bs.ROOT}/ghost_0"].position == pytest.approx((0.0, 0.0, view.exaggeration * -3e-6))
    assert scene.nodes[f"{bs.ROOT}/ghost_1"].position == pytest.approx((0.0, 0.0, view.exaggeration * 1e-6))
    # a rotor beyond the drawing's range is clamped and says so
    view.animate(2.0, {"time_s": 0.02, "x_true_m": 1e-3, "x_measured_m": 0.0, "x_estimated_m": 0.0,
                       "current_a": 0.0})
    assert scene.nodes[f"{bs.ROOT}/rotor"].position[2] == pytest.approx(bs.MAX_DRAWN_OFFSET_M)
    assert "off scale" in scene.nodes[f"{bs.ROOT}/labels/legend"].text


def test_upper_coils_carry_i0_plus_i_and_the_force_arrow_follows_eq_10():
    view, scene = attached()
    view.animate(1.0, {"time_s": 0.0, "x_true_m": 0.0, "x_measured_m": 0.0, "x_estimated_m": np.nan,
                       "current_a": 2.0})
    upper, lower = scene.nodes[f"{bs.ROOT}/coils/upper_0"], scene.nodes[f"{bs.ROOT}/coils/lower_1"]
    assert upper.color == bs.coil_color(RIG.i0_a + 2.0) and lower.color == bs.coil_color(RIG.i0_a - 2.0)
    assert upper.color[0] > lower.color[0]                    # redder: more current
    arrow = scene.nodes[f"{bs.ROOT}/arrows/bearing"].points[0]
    length = arrow[1, 2] - arrow[0, 2]
    assert length == pytest.approx(min(RIG.magnetic_force(0.0, 2.0) * view.force_scale_m_per_n,
                                       bs.LONGEST_ARROW_M), rel=1e-6)
    assert length > 0                                         # pulls towards the upper magnet
    assert scene.nodes[f"{bs.ROOT}/ghost_1"].visible is False  # no estimate (NaN): marker hidden


@pytest.mark.parametrize("name", ["kalman_noise", "ekf_parameters", "ekf_disturbance", "lqg_vs_pid"])
def test_each_rigid_axis_exercise_drives_the_view_from_its_own_trace(name):
    exercise = registry()[name]
    values = exercise.resolve({})
    simulation = exercise.simulation(values)
    row = simulation.advance(20)[-1]
    latest = {"time_s": row[0], **dict(zip(simulation.columns, row[1:]))}
    view, scene = attached(name)
    view.animate(0.0, latest)
    x = latest[view.true_column]
    assert scene.nodes[f"{bs.ROOT}/rotor"].position[2] == pytest.approx(view.drawn_offset_m(x))
    assert all(ghost.column in latest for ghost in view.ghosts)
