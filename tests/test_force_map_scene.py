"""The 3D maps of paper 002 (``scenes.force_map``): mesh geometry and winding, the
planes at the node, the FBFNN surface and its error heat map against the network's
own error, the replayed training, and the operating-point marker of
``adaptive_filter`` — on a recording stand-in for viser's SceneApi."""

import numpy as np
import pytest

from lab_modules.estimators.fuzzy_basis_network import test_grid as grid_41
from lab_modules.exercises.adaptive_filter import EXERCISE as ADAPTIVE
from lab_modules.exercises.stiffness_map import EXERCISE as MAP
from lab_modules.exercises.stiffness_map import (
    StiffnessMapSimulation,
    error_maps,
    live_training,
    lsm_map,
    networks,
)
from lab_modules.exercises.stiffness_map import (
    test_rmse as network_rmse,
)
from lab_modules.plants.axial_bearing import AXIAL, N_PER_MM
from lab_modules.scenes import force_map as fm
from tests.test_bearing_scene import RecordingScene as BearingRecordingScene


class RecordingScene(BearingRecordingScene):
    """The bearing tests' stand-in for viser's SceneApi, whose nodes can also be removed."""

    def __getattr__(self, method):
        add = super().__getattr__(method)

        def add_removable(name, *args, **kwargs):
            handle = add(name, *args, **kwargs)
            handle.removed = False

            def remove():
                handle.removed = True
                if self.nodes.get(name) is handle:
                    del self.nodes[name]
            handle.remove = remove
            return handle
        return add_removable


def normals(vertices, faces):
    a, b, c = (np.asarray(vertices, float)[faces[:, k]] for k in range(3))
    return np.cross(b - a, c - a)


# -- mesh geometry ---------------------------------------------------------------------------------

def test_grid_faces_cover_every_quad_in_both_windings():
    rows, columns = 4, 6
    faces = fm.grid_faces(rows, columns)
    half = len(faces) // 2
    assert half == 2 * (rows - 1) * (columns - 1)
    assert np.array_equal(faces[half:], faces[:half, ::-1])
    assert faces.max() == rows * columns - 1


@pytest.mark.parametrize("axis", [fm.FORCE_AXIS, fm.KI_AXIS, fm.KS_AXIS])
def test_surfaces_face_up_then_down_whatever_their_slope(axis):
    """A graph z = f(i, x): the first half of the faces must point up (+z), the second down,
    so the surface shows from above and below although the viewer culls back faces."""
    i, x = np.linspace(-1.5, 1.5, 13), np.linspace(-0.5e-3, 0.5e-3, 11)
    ii, xx = np.meshgrid(i, x, indexing="xy")
    values = AXIAL.force_n(ii, xx) if axis is fm.FORCE_AXIS else 1e-3 * AXIAL.tangent_factors(ii, xx)[1]
    vertices, faces = fm.surface(i, x, values, axis)
    n = normals(vertices, faces)
    half = len(faces) // 2
    assert np.all(n[:half, 2] > 0) and np.all(n[half:, 2] < 0)
    # no degenerate triangle
    assert np.all(np.linalg.norm(n, axis=1) > 1e-9)


def test_force_surface_vertices_are_eq_1_in_the_plot_box():
    i, x = np.array([-1.5, 0.0, 1.5]), np.array([-0.5e-3, 0.5e-3])
    ii, xx = np.meshgrid(i, x, indexing="xy")
    force = AXIAL.force_n(ii, xx)
    vertices, _ = fm.surface(i, x, force, fm.FORCE_AXIS)
    corner = vertices[-1]                                     # i = 1.5 A, x = 0.5 mm: F = 26.8 N
    assert float(force[-1, -1]) == pytest.approx(26.8, abs=1e-9)
    assert corner == pytest.approx((-fm.HALF_WIDTH, fm.HALF_WIDTH, (26.8 + 30) / 60 * fm.HEIGHT - fm.HEIGHT / 2),
                                   abs=1e-6)
    assert np.all(np.abs(vertices[:, :2]) <= fm.HALF_WIDTH + 1e-6)
    assert np.all(np.abs(vertices[:, 2]) <= fm.HEIGHT / 2 + 1e-6)


def test_coloured_mesh_keeps_both_windings_and_one_colour_per_vertex():
    vertices, faces = fm.surface(np.linspace(-1.5, 1.5, 5), np.linspace(-0.5e-3, 0.5e-3, 4),
                                 np.zeros((4, 5)), fm.FORCE_AXIS)
    colors = fm.colormap(np.linspace(-30, 30, len(vertices)), -30, 30, fm.DIVERGING)
    mesh = fm.coloured_mesh(vertices, faces, colors)
    assert len(mesh.faces) == len(faces) and len(mesh.vertices) == len(vertices)
    assert np.array_equal(mesh.visual.vertex_colors[:, :3], colors)
    assert tuple(colors[0]) == tuple(fm.DIVERGING[0].astype(int)) and tuple(colors[-1]) == tuple(fm.DIVERGING[-1])


def test_nice_ceiling():
    assert [fm.nice_ceiling(v) for v in (0.037, 0.1, 0.3751, 1.59, 7.0, 2.354, 0.0)] == [0.04, 0.1, 0.4, 2.0, 8.0, 3.0, 1.0]


# -- the stiffness map's view ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def values():
    return MAP.resolve({})


def attached(values, **overrides):
    view, scene = MAP.scene({**values, **overrides}), RecordingScene()
    view.attach(scene)
    return view, scene


def test_planes_at_the_node_tangent_and_no_constant_least_squares(values):
    view, scene = attached(values, node_current_a="-1.5", node_position_mm="-0.5")
    i_n, x_n = -1.5, -0.5e-3
    f_n = float(AXIAL.force_n(i_n, x_n))
    kit, kst = AXIAL.tangent_factors(i_n, x_n)
    tangent = scene.nodes[f"{fm.ROOT}/tangent"]
    vertices = np.asarray(tangent.args[0], float)
    node = fm.to_world(i_n, x_n, f_n, fm.FORCE_AXIS)
    assert np.min(np.linalg.norm(vertices - node, axis=1)) < 1e-6          # the tangent touches F at the node
    fit = np.asarray(scene.nodes[f"{fm.ROOT}/fit"].args[0], float)
    assert fm.to_world(0.0, 0.0, 0.0, fm.FORCE_AXIS) == pytest.approx((0.0, 0.0, 0.0))
    plane, *_ = np.linalg.lstsq(np.column_stack([fit[:, :2], np.ones(len(fit))]), fit[:, 2], rcond=None)
    assert abs(plane[2]) < 1e-6                                             # no constant: F = 0 at the centre
    assert np.min(np.linalg.norm(fit[:, :2] - node[:2], axis=1)) < 1e-6     # and it reaches the node
    legend = scene.nodes[f"{fm.ROOT}/legend"].text
    assert f"k_i = {float(kit):.2f} N/A" in legend and f"k_s = {float(kst) / N_PER_MM:.2f} N/mm" in legend
    assert "k_i = 7.15 N/A, k_s = 32.16 N/mm" in legend                     # Tables 4-5 at the corner
    assert len(scene.nodes[f"{fm.ROOT}/nodes"].args[0]) == 25
    assert {"surface", "tangent", "fit"} <= set(view.handles)


def test_switching_to_k_i_shows_the_network_and_its_error_heat_map(values):
    view, scene = attached(values)
    surface = scene.nodes[f"{fm.ROOT}/surface"]
    view.update({**values, "view_surface": "k_i"})
    assert surface.removed and f"{fm.ROOT}/tangent" not in scene.nodes
    assert f"{fm.ROOT}/fbfnn" in scene.nodes and f"{fm.ROOT}/heat" in scene.nodes
    assert len(scene.nodes[f"{fm.ROOT}/table"].args[0]) == 25
    assert "k_i [N/A]" in scene.nodes[f"{fm.ROOT}/z_ticks/title"].args[0]
    view.update({**values, "view_surface": "k_s"})
    assert "k_s [N/mm]" in scene.nodes[f"{fm.ROOT}/z_ticks/title"].args[0]
    assert "Table 5" in scene.nodes[f"{fm.ROOT}/title"].text


def test_heat_map_values_are_the_networks_error_and_their_rms_the_test_rmse(values):
    pair = networks(values)
    heat_ki, heat_ks = error_maps(values, pair.ki, pair.ks)
    assert heat_ki.shape == heat_ks.shape == (41, 41)
    rmse_ki, rmse_ks = network_rmse(values, pair.ki, pair.ks)
    assert float(np.sqrt(np.mean(heat_ki**2))) == pytest.approx(rmse_ki, rel=1e-12)
    assert float(np.sqrt(np.mean(heat_ks**2))) == pytest.approx(rmse_ks, rel=1e-12)
    # one cell by hand: row 7 (x), column 30 (i) of the 41×41 grid
    currents, positions = grid_41()
    i, x = np.linspace(-1.5, 1.5, 41)[30], np.linspace(-0.5e-3, 0.5e-3, 41)[7]
    k_i, _ = lsm_map(values, i, x)
    assert heat_ki[7, 30] == pytest.approx(abs(float(pair.ki.predict(i, x)) - float(k_i)), abs=1e-12)
    assert currents.reshape(41, 41)[7, 30] == i and positions.reshape(41, 41)[7, 30] == x


def test_view_replays_the_simulations_training_and_draws_its_error(values):
    simulation = StiffnessMapSimulation(values)
    simulation.advance(round(0.04 / simulation.sample_time_s))                 # 40 ms: 20 epochs
    epoch = simulation.epoch
    assert epoch == 20
    view, scene = attached(values, view_surface="k_i")
    view.animate(1.0, {"fbfnn_epoch": float(epoch)})
    assert view.live.epoch == epoch
    assert np.array_equal(view.live.ki.widths, simulation.ki.widths)
    assert np.array_equal(view.live.ks.widths, simulation.ks.widths)
    legend = scene.nodes[f"{fm.ROOT}/legend"].text
    assert f"epoch {epoch}: test RMSE {simulation.rmse[0]:.3f} N/A" in legend
    heat = scene.nodes[f"{fm.ROOT}/heat"]                                     # 41×41 coloured squares
    assert len(heat.args[0]) == 41 * 41
    # the heat map's colours follow |FBFNN − LSM|: the darkest square sits at the largest error
    error = error_maps(values, simulation.ki, simulation.ks)[0].ravel()
    brightness = np.asarray(getattr(heat, "colors", heat.args[1])).astype(int).sum(axis=1)
    assert brightness[np.argmax(error)] == brightness.min()
    # a later epoch sends the colours only
    view.animate(1.5, {"fbfnn_epoch": float(epoch + 5)})
    assert scene.nodes[f"{fm.ROOT}/heat"] is heat and len(heat.colors) == 41 * 41
    # a restart (fewer epochs than shown) trains again from the start
    view.animate(2.0, {"fbfnn_epoch": 3.0})
    fresh = live_training(values)
    fresh.advance_to(3)
    assert np.array_equal(view.live.ki.widths, fresh.ki.widths)


# -- adaptive_filter's marker -------------------------------------------------------------------------

def test_operating_point_marker_follows_the_loop():
    view, scene = ADAPTIVE.scene(ADAPTIVE.resolve({})), RecordingScene()
    view.attach(scene)
    marker = scene.nodes[f"{fm.ROOT}/marker"]
    latest = {"current_a": 1.19, "x_true_m": 0.4e-3, "magnet_force_n": 15.08, "time_s": 0.25}
    view.animate(1.0, latest)
    assert marker.position == pytest.approx(tuple(fm.to_world(1.19, 0.4e-3, 15.08, fm.FORCE_AXIS)))
    assert "i = +1.190 A, x = +0.400 mm" in scene.nodes[f"{fm.ROOT}/legend"].text
    for k in range(20):
        view.animate(2.0 + k, {**latest, "x_true_m": -0.4e-3 * k / 19})
    assert len(view.path) == fm.PATH_POINTS
    assert len(scene.nodes[f"{fm.ROOT}/path"].points) == fm.PATH_POINTS - 1
    # out of range: drawn on the box's edge
    view.animate(30.0, {"current_a": 1.5, "x_true_m": 0.9e-3, "magnet_force_n": 40.0})
    assert marker.position[0] == pytest.approx(-fm.HALF_WIDTH) and marker.position[2] == pytest.approx(fm.HEIGHT / 2)
