"""The maglev ball's 3D view: geometry from paper 004 (§3.3, Table 3.1,
eq. 2.7 and 2.10) and the mapping of the trace onto the scene, on a recording
stand-in for viser's SceneApi."""

import numpy as np
import pytest
import viser.transforms as tf
from test_bearing_scene import Handle, RecordingScene

from lab_modules.exercises import registry
from lab_modules.plants.maglev_ball import TABLE_3_1
from lab_modules.scenes import maglev as ms
from lab_modules.scenes.bearing import CAMERA_POSITION

ROOT, FRONT = ms.ROOT, ms.FRONT


class RemovableHandle(Handle):
    def remove(self):
        self.removed = True


class Scene(RecordingScene):
    """The bearing tests' recording scene whose nodes can also be removed (the ruler is redrawn)."""

    def __getattr__(self, method):
        if not method.startswith("add_"):
            raise AttributeError(method)

        def add(name, *args, **kwargs):
            self.nodes[name] = RemovableHandle(method, name, args, kwargs)
            return self.nodes[name]
        return add


def attached(exercise_name="maglev_tracking", overrides=None):
    exercise = registry()[exercise_name]
    view, scene = exercise.scene(exercise.resolve(overrides or {})), Scene()
    view.attach(scene)
    return view, scene


def ball_top_gap_m(scene) -> float:
    """Drawn gap between the magnet's face (z = 0) and the top of the drawn ball."""
    ball = scene.nodes[f"{ROOT}/ball"]
    return -(ball.position[2] + ball.args[0])


def latest(**columns):
    row = {"time_s": 1.0, "reference_m": 0.0148, "x_true_m": 0.0148, "x_measured_m": 0.0148,
           "x_estimated_m": 0.0148, "current_true_a": 0.894, "current_estimated_a": 0.894, "guarded": 0.0,
           "velocity_true_m_per_s": 0.0}
    return row | columns


def test_ball_is_the_papers_19_05_mm_ball_hanging_x1_below_the_coil_face_at_life_size():
    view, scene = attached()
    assert scene.nodes[f"{ROOT}/ball"].args[0] == pytest.approx(0.01905 / 2)   # §3.3
    assert "life size" in scene.nodes[f"{ROOT}/labels/title"].text
    view.animate(1.0, latest(x_true_m=0.0168))
    assert ball_top_gap_m(scene) == pytest.approx(0.0168)
    coil = scene.nodes[f"{ROOT}/magnet/coil"]
    vertices = coil.args[0] + np.asarray(coil.position)
    assert vertices[:, 2].min() == pytest.approx(0.0, abs=1e-9)               # the coil's bottom is x1 = 0
    assert np.hypot(vertices[:, 0], vertices[:, 1]).max() > 2 * ms.BALL_RADIUS_M


def test_force_arrows_are_the_two_terms_of_eq_2_10_and_balance_at_the_operating_point():
    view, scene = attached()
    gap, current = 0.0148, TABLE_3_1.equilibrium_current_a(0.0148)            # eq. 2.14: 0.894 A
    view.animate(1.0, latest(x_true_m=gap, current_true_a=current))
    lengths = {name: float(np.diff(scene.nodes[f"{FRONT}/arrows/{name}"].points[0, :, 2])[0])
               for name in ("magnetic", "gravity")}
    weight = 0.05506 * 9.81
    assert lengths["gravity"] == pytest.approx(-weight * ms.FORCE_SCALE_M_PER_N, rel=1e-6)
    assert lengths["magnetic"] == pytest.approx(weight * ms.FORCE_SCALE_M_PER_N, rel=1e-4)
    # half the current: a quarter of the force (eq. 2.7)
    view.animate(2.0, latest(x_true_m=gap, current_true_a=current / 2))
    magnetic = scene.nodes[f"{FRONT}/arrows/magnetic"].points[0, :, 2]
    assert magnetic[1] - magnetic[0] == pytest.approx(weight / 4 * ms.FORCE_SCALE_M_PER_N, rel=1e-4)


def test_estimate_ghost_and_measurement_follow_their_columns_and_nan_hides_them():
    view, scene = attached()
    view.animate(1.0, latest(x_true_m=0.0150, x_estimated_m=0.0140, x_measured_m=0.0165))
    ghost, measured = scene.nodes[f"{FRONT}/ghost"], scene.nodes[f"{FRONT}/measured"]
    assert ghost.visible and measured.visible
    assert ghost.position[2] == pytest.approx(-0.0140 - ms.BALL_RADIUS_M)   # outline centred on the estimate
    assert measured.position[2] == pytest.approx(-0.0165)                    # dot where the ball's top would be
    view.animate(2.0, latest(x_estimated_m=np.nan, x_measured_m=np.nan))
    assert ghost.visible is False and measured.visible is False
    legend = scene.nodes[f"{ROOT}/labels/legend"].text
    assert "estimate" not in legend and "measured" not in legend


def test_warning_colour_near_the_guarded_region_and_when_the_ball_struck():
    view, scene = attached()
    view.animate(1.0, latest())
    ball = scene.nodes[f"{ROOT}/ball"]
    assert ball.color == ms.BALL_STEEL and "⚠" not in scene.nodes[f"{ROOT}/labels/legend"].text
    view.animate(2.0, latest(current_estimated_a=0.05))                    # x̂3 -> 0
    assert ball.color == ms.WARNING_AMBER and "x̂₃" in scene.nodes[f"{ROOT}/labels/legend"].text
    view.animate(3.0, latest(guarded=1.0))
    assert ball.color == ms.WARNING_AMBER
    view.animate(4.0, latest(x_true_m=0.0029, velocity_true_m_per_s=-5.0))  # 2.9 mm, 5 mm per step upwards
    assert ball.color == ms.STOPPED_RED and "struck" in scene.nodes[f"{ROOT}/labels/legend"].text


def test_small_references_are_drawn_exaggerated_with_a_true_ruler():
    view, scene = attached(overrides={"reference": "square_0.05mm"})
    scale = view.scale
    assert scale.exaggeration == 20 and f"×{scale.exaggeration:g}" in scene.nodes[f"{ROOT}/labels/title"].text
    view.animate(1.0, latest(x_true_m=0.0148 + 0.05e-3))
    assert ball_top_gap_m(scene) == pytest.approx(0.0148 + 20 * 0.05e-3)
    labels = {float(n.args[0]): n.position[2] for name, n in scene.nodes.items()
              if name.startswith(f"{FRONT}/ruler/label_")}
    for gap_mm, z in labels.items():                                         # each label sits at its true gap
        assert -z == pytest.approx(scale.drawn_gap_m(gap_mm * 1e-3))
    # back to the 2 mm step: life size again, the old ruler removed
    old = scene.nodes[f"{FRONT}/ruler/label_0"]
    view.update(registry()["maglev_tracking"].resolve({}))
    assert view.scale.exaggeration == 1 and old.removed
    view.animate(2.0, latest(x_true_m=0.0148 + 0.05e-3))
    assert ball_top_gap_m(scene) == pytest.approx(0.0148 + 0.05e-3)


def test_tuning_view_draws_the_recording_estimate_and_measurement():
    exercise = registry()["maglev_tuning"]
    values = exercise.resolve({})
    replay = exercise.simulation(values)
    row = replay.advance(2000)[-1]
    columns = {"time_s": row[0], **dict(zip(replay.columns, row[1:]))}
    view, scene = attached("maglev_tuning")
    scale = view.scale
    assert scale.exaggeration == 100                   # the recording wanders by micrometres (worksheet: ×100)
    view.animate(0.0, columns)
    assert ball_top_gap_m(scene) == pytest.approx(scale.drawn_gap_m(columns["x_estimated_m"]))
    assert scene.nodes[f"{FRONT}/measured"].position[2] == pytest.approx(-scale.drawn_gap_m(columns["x_measured_m"]))
    assert f"{FRONT}/ghost" not in scene.nodes
    coil = scene.nodes[f"{ROOT}/magnet/coil"].color
    assert coil == ms.coil_color(columns["current_estimated_a"], ms.BIAS_CURRENT_A)


def test_markers_in_front_of_the_ball_project_onto_the_pixels_of_the_balls_mid_plane():
    _, scene = attached()
    root, front = scene.nodes[ROOT], scene.nodes[FRONT]
    rotation = tf.SO3(np.asarray(root.wxyz)).as_matrix()
    for local in ((0.0, ms.RULER_Y_M, -0.0148), (0.0, 0.0, -0.030), (0.0, 0.02, 0.0)):
        on_mid_plane = root.position + rotation @ np.array(local)
        in_front = root.position + rotation @ (np.asarray(front.position) + front.scale * np.array(local))
        assert (rotation.T @ (in_front - root.position))[0] == pytest.approx(ms.FRONT_M)   # before the ball
        to_mid, to_front = on_mid_plane - CAMERA_POSITION, in_front - CAMERA_POSITION
        assert np.linalg.norm(np.cross(to_mid, to_front)) / np.linalg.norm(to_mid) ** 2 < 1e-9   # same ray


def test_coil_faces_point_outwards_so_the_near_side_is_drawn():
    _, scene = attached()
    coil = scene.nodes[f"{ROOT}/magnet/coil"]
    vertices, faces = coil.args
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    centre = (a + b + c) / 3
    side = np.abs(normal[:, 2]) < 1e-12 * np.linalg.norm(normal, axis=1).max()
    outer = side & (np.hypot(centre[:, 0], centre[:, 1]) > ms.COIL_INNER_RADIUS_M + 0.005)
    assert np.all(np.sum(normal[outer, :2] * centre[outer, :2], axis=1) > 0)


def test_legend_numbers_refresh_a_few_times_a_second_but_a_warning_at_once():
    view, scene = attached()
    legend = scene.nodes[f"{ROOT}/labels/legend"]
    view.animate(10.0, latest(x_true_m=0.0150))
    assert "15.00 mm" in legend.text
    view.animate(10.04, latest(x_true_m=0.0151))
    assert "15.00 mm" in legend.text                                   # next frame: text kept
    assert ball_top_gap_m(scene) == pytest.approx(0.0151)                # the ball moved all the same
    view.animate(10.08, latest(x_true_m=0.0151, current_estimated_a=0.05))
    assert "⚠" in legend.text                                           # a warning is shown at once
    view.animate(10.08 + ms.LEGEND_INTERVAL_S, latest(x_true_m=0.0152))
    assert "15.20 mm" in legend.text and "⚠" not in legend.text


def test_drawn_coil_can_hold_a_winding_of_table_3_1s_resistance_at_a_usual_current_density():
    """The magnet's size is not in the paper: a copper winding filling 60 % of the drawn window
    with R_c = 25 ohm must carry the operating current (eq. 2.14) at 2-6 A/mm² (small coils)."""
    copper_ohm_m, fill = 1.72e-8, 0.6
    window_m2 = (ms.COIL_OUTER_RADIUS_M - ms.COIL_INNER_RADIUS_M) * ms.COIL_HEIGHT_M
    turn_m = np.pi * (ms.COIL_OUTER_RADIUS_M + ms.COIL_INNER_RADIUS_M)
    turns = np.sqrt(TABLE_3_1.coil_resistance_ohm * fill * window_m2 / (copper_ohm_m * turn_m))
    wire_m2 = fill * window_m2 / turns
    assert turns == pytest.approx(2300, rel=0.05)                                     # as the docstring says
    assert 2e6 < ms.BIAS_CURRENT_A / wire_m2 < 6e6
    assert np.sqrt(4 * wire_m2 / np.pi) == pytest.approx(0.48e-3, rel=0.05)
