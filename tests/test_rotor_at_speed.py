"""The flexible rotor at speed (plants/spinning_rotor.py, loops/spinning_rotor_loop.py, the
rotor_at_speed exercise): Timoshenko elements against closed form, the complex one-plane
form against the two real planes, the modal reduction against the full finite-element
model, the loop at standstill against sensor_placement's, the unbalance response against
the time simulation, and the natural frequencies against ROSS (skipped only where ROSS
cannot be imported)."""

import numpy as np
import pytest
import scipy.linalg

from lab_modules.exercises import rotor_at_speed as ras
from lab_modules.exercises import sensor_placement as sp
from lab_modules.loops.spinning_rotor_loop import (
    RunUpSimulation,
    critical_speeds_rpm,
    sweep,
    unbalance_response,
)
from lab_modules.plants.flexible_rotor import (
    STEEL_DENSITY_KG_M3,
    STEEL_POISSON,
    STEEL_YOUNGS_PA,
    THEORIES,
    FlexibleRotor,
    assemble_beam,
    beam_element,
    cowper_shear_factor,
    solve_modes,
)
from lab_modules.plants.spinning_rotor import (
    SpinningRotor,
    iso_14839_2_zone,
    permissible_unbalance_kg_m,
    two_plane_matrices,
    whirl_frequencies_hz,
)
from lab_modules.scenes.rotor import VIEW_SCALE

SPEEDS_CHECKED_RPM = (0.0, 3000.0, 6000.0)


# -- elements --------------------------------------------------------------------------

def test_timoshenko_cantilever_tip_deflection_is_exact():
    """A cantilever under a tip force P: w = P L^3 / (3 EI) + P L / (kappa G A), which the
    Timoshenko element reproduces exactly on any mesh; with phi = 0 the bending part alone."""
    d, length, force = 0.038, 0.5, 100.0
    area, second_moment = np.pi / 4 * d**2, np.pi * d**4 / 64
    ei = STEEL_YOUNGS_PA * second_moment
    shear = cowper_shear_factor() * STEEL_YOUNGS_PA / (2 * (1 + STEEL_POISSON)) * area
    z = np.linspace(0.0, length, 4)
    for phi_of in (lambda l: 12 * ei / (shear * l**2), lambda l: 0.0 * l):
        K, _ = assemble_beam(z, ei, 1.0, phi_of(np.diff(z)))
        f = np.zeros(K.shape[0])
        f[-2] = force
        w = np.linalg.solve(K[2:, 2:], f[2:])[-2]
        exact = force * length**3 / (3 * ei) + (force * length / shear if phi_of(1.0) else 0.0)
        assert w == pytest.approx(exact, rel=1e-10)


def test_timoshenko_mass_with_phi_zero_is_the_euler_bernoulli_element():
    K0, M0 = beam_element(0.02, 2.0e4, 8.0)
    l = 0.02
    np.testing.assert_allclose(M0, 8.0 * l / 420 * np.array([[156, 22 * l, 54, -13 * l], [22 * l, 4 * l * l, 13 * l, -3 * l * l],
                                                               [54, 13 * l, 156, -22 * l], [-13 * l, -3 * l * l, -22 * l, 4 * l * l]]))
    assert np.allclose(K0, K0.T)


def test_timoshenko_lowers_the_frequencies_most_for_the_higher_modes():
    """Shear and rotary inertia soften a beam, the more the shorter the wavelength."""
    eb, tim = (FlexibleRotor(theory=t).natural_frequencies_hz(5)[1:] for t in THEORIES)
    ratio = tim / eb
    assert np.all(ratio < 1.0) and np.all(np.diff(ratio) < 0)


# -- two planes, complex form, modal reduction -----------------------------------------

def test_complex_form_has_the_two_real_planes_eigenvalues():
    """Eq. 1 (real, both planes) and eq. 2 (complex r = x + i y): the real system's eigenvalues
    are the complex one's and their conjugates."""
    rotor = FlexibleRotor(theory="timoshenko", elements=20)
    M2, G2, K2 = two_plane_matrices(rotor)
    n = rotor.K.shape[0]
    free = np.setdiff1d(np.arange(2 * n), [rotor.constrained_dofs[0], n + rotor.constrained_dofs[0]])
    M2, G2, K2 = (X[np.ix_(free, free)] for X in (M2, G2, K2))
    omega = 6000 * np.pi / 30
    m = len(free)
    real = np.linalg.eigvals(np.block([[np.zeros((m, m)), np.eye(m)],
                                       [-np.linalg.solve(M2, K2), -omega * np.linalg.solve(M2, G2)]]))
    bending = np.sort(np.abs(real.imag[np.abs(real.imag) > 2 * np.pi * 20]))[::2][:6] / (2 * np.pi)
    backward, forward = whirl_frequencies_hz(rotor, 6000.0)
    np.testing.assert_allclose(bending, np.sort(np.concatenate([backward, forward])), rtol=1e-8)


@pytest.mark.parametrize("theory", THEORIES)
def test_six_modes_hold_the_whirl_frequencies_of_the_full_model(theory):
    rotor = FlexibleRotor(theory=theory)
    reduced = SpinningRotor(rotor).free_whirl_hz([0.0, 6000.0, 12000.0], 6)
    for k, rpm in enumerate((0.0, 6000.0, 12000.0)):
        backward, forward = whirl_frequencies_hz(rotor, rpm)
        np.testing.assert_allclose(-reduced[k, 1:4, 0], backward, rtol=5e-4)
        np.testing.assert_allclose(reduced[k, 1:4, 1], forward, rtol=5e-4)


def test_spin_splits_each_bending_mode_forward_up_backward_down():
    rotor = FlexibleRotor(theory="timoshenko")
    still = rotor.natural_frequencies_hz(4)[1:]
    backward, forward = whirl_frequencies_hz(rotor, 6000.0)
    assert np.all(forward > still) and np.all(backward < still)
    assert forward[1] - backward[1] > 80.0                         # mode 3: the stack's I_p / I_d ~ 1.9


# -- the loop --------------------------------------------------------------------------

@pytest.mark.parametrize("feedback", ["measured", "estimated"])
@pytest.mark.parametrize("offset", [0.0, 60.0])
def test_loop_at_standstill_is_sensor_placements(feedback, offset):
    """Euler-Bernoulli, four modes, 0 rpm: every pole of sensor_placement's loop is a pole of this
    one (with measured feedback this one also runs the filter as a watcher, whose poles are its own)."""
    common = {"feedback": feedback, "sensor_offset_mm": offset}
    theirs = sp.loop(sp.EXERCISE.resolve(common)).poles()
    ours = np.linalg.eigvals(ras.loop(ras.EXERCISE.resolve({**common, "beam_theory": "euler-bernoulli",
                                                            "modes": 4}), [0.0]).A[0])
    for pole in theirs:
        assert np.min(np.abs(ours - pole)) < 1e-9


def test_unbalance_response_is_what_the_simulation_settles_to():
    """Noise-free run held at 4000 rpm: after the transient the orbit at the bearing is a circle
    of the radius ``unbalance_response`` predicts (within 1 %)."""
    values = ras.EXERCISE.resolve({"speed_rpm": 4000.0, "balance_grade": "G 16", "disturbance_force_n": 0.0,
                                   "capacitive_noise_um": 0.0})
    sim = ras.EXERCISE.simulation(values)
    sim.sigma[:] = 0.0                                             # no sensor noise on the current either
    trace = sim.advance(round(0.6 / sim.sample_time_s))[-round(0.05 / sim.sample_time_s):]
    radius = np.hypot(trace[:, 1], trace[:, 2])
    predicted = abs(unbalance_response(ras.loop(values, [4000.0]), ras.unbalance_kg_m(values))[0, 1])
    assert radius.max() == pytest.approx(predicted, rel=0.01)
    assert radius.min() == pytest.approx(predicted, rel=0.01)


def test_run_up_passes_the_critical_speed_and_carries_on_after_a_retune():
    values = ras.EXERCISE.resolve({"speed_rpm": 6000.0, "run_up_rpm_per_s": 10000.0})
    sim = ras.EXERCISE.simulation(values)
    speed = 1 + RunUpSimulation.columns.index("speed_rpm")
    first = sim.advance(2000)
    assert first[0, speed] == 0.0 and first[-1, speed] == pytest.approx(1000.0, abs=1.0)
    retuned = ras.EXERCISE.retune(sim, {**values, "gain_factor": 1.2})
    assert isinstance(retuned, RunUpSimulation)
    second = retuned.advance(2000)
    assert second[0, 0] == pytest.approx(first[-1, 0] + sim.sample_time_s)
    assert second[0, speed] == pytest.approx(first[-1, speed] + 0.5, abs=1.0)


def test_critical_speed_interpolates_the_crossing_of_the_1x_line():
    speeds = np.array([0.0, 1000.0, 2000.0])
    assert critical_speeds_rpm(speeds, np.array([20.0, 20.0, 20.0])) == [pytest.approx(1200.0)]
    assert critical_speeds_rpm(speeds, np.array([100.0, 100.0, 100.0])) == []


def test_external_sensor_mode_3_backward_whirl_stays_unstable_at_speed():
    """The wrong-signed residue of mode 3 (node between bearing and +60 mm sensor) keeps its
    backward whirl negatively damped at every speed; its forward whirl regains damping."""
    values = ras.EXERCISE.resolve({"sensor_offset_mm": 60.0})
    swept = sweep(ras.loop(values))
    assert np.all(swept.damping[:, 2, 0] < 0)
    assert swept.damping[0, 2, 1] < 0 < swept.damping[-1, 2, 1]


def test_every_whirl_stays_a_whirl_over_speed():
    """External sensor: the compensator's real pole, which the gyroscopic coupling moves off the
    real axis by half a hertz above 6000 rpm, is never taken for mode 1's forward whirl (it was,
    and drew a jump to 100 % damping and a false critical speed near 6100 rpm)."""
    values = ras.EXERCISE.resolve({"sensor_offset_mm": 60.0})
    swept = sweep(ras.loop(values))
    assert np.all(swept.damping[:, 0, :] < 0.5) and np.all(swept.whirl_hz[:, 0, 1] > 200.0)
    criticals = [c for j in range(swept.whirl_hz.shape[1])
                 for c in critical_speeds_rpm(ras.CAMPBELL_SPEEDS_RPM, swept.whirl_hz[:, j, 1])]
    assert len(criticals) == 1 and 7000.0 < criticals[0] < 9000.0


def test_external_sensor_is_stabilisable_at_a_lower_gain_up_to_a_speed():
    """Some gain factor keeps the external sensor's loop stable at low speed, none above the
    bisected speed (checked on both sides of it)."""
    values = ras.EXERCISE.resolve({"sensor_offset_mm": 60.0})
    limits = ras.largest_stable_gain(values, 60.0)
    up_to = ras.stabilisable_up_to_rpm(values, 60.0, limits)
    assert limits[0] > 0 and 1000.0 < up_to < 12000.0
    assert ras.largest_stable_gain(values, 60.0, [up_to - 10.0])[0] > 0
    assert ras.largest_stable_gain(values, 60.0, [up_to + 10.0])[0] == 0


def test_iso_figures():
    """ISO 21940-11: 25 kg at G 2.5 and 3000 rpm: U = 25 * 2.5e-3 / 314.16 = 199 g mm; ISO 14839-2
    zones as fractions 0.3 / 0.4 / 0.5 of C_min."""
    assert permissible_unbalance_kg_m(25.0, 2.5, 3000.0) == pytest.approx(1.989e-4, rel=1e-3)
    assert [iso_14839_2_zone(f * 100e-6, 100e-6) for f in (0.29, 0.35, 0.45, 0.55)] == ["A", "B", "C", "D"]


def test_whirl_shape_turns_with_the_chosen_direction():
    values = ras.EXERCISE.resolve({"speed_rpm": 6000.0, "shown_mode": 3})
    _, forward = ras.whirl_shape({**values, "shown_whirl": "forward"})
    _, backward = ras.whirl_shape({**values, "shown_whirl": "backward"})
    assert forward > 300.0 and -300.0 < backward < -200.0


# -- against ROSS ------------------------------------------------------------------------

def _ross_rotor(rotor: FlexibleRotor):
    """ROSS's model of the same rotor: one shaft element per lab element (same theory: shear and
    rotary inertia on or off, gyroscopic always), the stack and hub as the same lumped discs, the
    ball bearing as a 1e12 N/m bearing (moment-free), the magnetic bearing off."""
    rs = pytest.importorskip("ross")
    g = rotor.geometry
    steel = rs.Material(name="lab_steel", rho=STEEL_DENSITY_KG_M3, E=STEEL_YOUNGS_PA, Poisson=STEEL_POISSON)
    timoshenko = rotor.theory == "timoshenko"
    shaft = [rs.ShaftElement(L=float(length), idl=0.0, odl=g.shaft_diameter_m, material=steel,
                             shear_effects=timoshenko, rotary_inertia=timoshenko, gyroscopic=True)
             for length in np.diff(rotor.node_z_m)]
    low, high = g.stack_ends_m
    disks = [rs.DiskElement(n=rotor.node(z), m=share * g.stack_mass_kg, Id=0.0, Ip=0.0)
             for z, share in ((low, 1 / 6), (high, 1 / 6))]
    disks += [rs.DiskElement(n=rotor.node(g.bearing_m), m=2 / 3 * g.stack_mass_kg, Id=g.stack_inertia_kg_m2,
                             Ip=g.stack_polar_inertia_kg_m2),
              rs.DiskElement(n=rotor.node(g.hub_position_m), m=g.hub_mass_kg,
                             Id=g.hub_mass_kg * g.hub_diameter_m**2 / 16, Ip=g.hub_mass_kg * g.hub_diameter_m**2 / 8)]
    bearing = rs.BearingElement(n=rotor.node(g.pivot_m), kxx=1e12, kyy=1e12, cxx=0.0)
    return rs.Rotor(shaft, disks, [bearing])


def _ross_whirl_hz(ross_rotor, speed_rpm: float):
    """ROSS's first three bending modes (backward, forward) [Hz]: lateral modes above 20 Hz by
    ROSS's own whirl direction (at standstill each frequency appears twice)."""
    modal = ross_rotor.run_modal(speed=speed_rpm * np.pi / 30, num_modes=30, sparse=False)
    frequencies = modal.wd / (2 * np.pi)
    directions = np.array([w[0] for w in modal.whirl_direction()])
    lateral = (frequencies > 20.0) & np.isin(directions, ("F", "B"))
    if speed_rpm == 0:
        pairs = np.sort(frequencies[lateral])[::2][:3]
        return pairs, pairs
    return (np.sort(frequencies[lateral & (directions == "B")])[:3],
            np.sort(frequencies[lateral & (directions == "F")])[:3])


@pytest.mark.parametrize("theory", THEORIES)
def test_natural_frequencies_agree_with_ross(theory):
    """At 0, 3000 and 6000 rpm, first three bending modes, backward and forward: the lab's full
    model within 0.5 % of ROSS's on the same mesh (30 elements: ROSS's dense eigensolver takes
    minutes on 60), and that mesh within 0.1 % of the lab's default 60 elements."""
    rotor = FlexibleRotor(theory=theory, elements=30)
    ross_rotor = _ross_rotor(rotor)
    default = FlexibleRotor(theory=theory)
    for rpm in SPEEDS_CHECKED_RPM:
        ours = whirl_frequencies_hz(rotor, rpm)
        theirs = _ross_whirl_hz(ross_rotor, rpm)
        for lab, ross in zip(ours, theirs):
            np.testing.assert_allclose(lab, ross, rtol=5e-3)
        np.testing.assert_allclose(np.concatenate(ours), np.concatenate(whirl_frequencies_hz(default, rpm)),
                                   rtol=1e-3)


def test_standstill_modes_agree_with_scipy_on_the_assembled_matrices():
    """solve_modes (with the exact rigid tilting) against scipy's generalized eigensolver."""
    rotor = FlexibleRotor(theory="timoshenko")
    free = np.setdiff1d(np.arange(rotor.K.shape[0]), rotor.constrained_dofs)
    omega_sq = scipy.linalg.eigvalsh(rotor.K[np.ix_(free, free)], rotor.M[np.ix_(free, free)])
    np.testing.assert_allclose(rotor.natural_frequencies_hz(5)[1:], np.sqrt(omega_sq[1:5]) / (2 * np.pi), rtol=1e-9)
    assert solve_modes(rotor.K, rotor.M, rotor.constrained_dofs)[0][0] < 1.0     # round-off, not zero


def test_whirl_scene_attaches_updates_and_animates_in_a_real_viser_scene():
    """viser casts every property on assignment: the scene must pass its checks (colours as
    uint8 arrays, segments (N, 2, 3)); the shaft's vertices move in both planes."""
    import viser
    server = viser.ViserServer(host="127.0.0.1", port=8463, verbose=False)
    try:
        values = ras.EXERCISE.resolve({"speed_rpm": 6000.0})
        view = ras.EXERCISE.scene(values)
        view.attach(server.scene)
        view.update({**values, "shown_whirl": "backward", "sensor_offset_mm": 60.0})
        view.animate(0.0, {})                                                   # 45° of whirl
        moved = view.handles["shaft"].vertices - view.rest
        assert np.ptp(moved[:, 1]) > 0.01 and np.ptp(moved[:, 2]) > 0.01      # both planes
        assert view.frequency_hz < 0                                           # backward
        for marker, radius in zip(view.handles["markers"], view.orbit_radius):  # on its orbit (its parent)
            x, y, z = marker.position
            assert x == 0.0 and np.hypot(y, z) == pytest.approx(VIEW_SCALE * radius, rel=1e-5)
    finally:
        server.stop()


def test_a_run_up_shows_the_critical_speed_at_mid_span():
    """Run-up 0 -> 12,000 rpm at 6000 rpm/s: the mid-span deflection (scope column x_watched_m) peaks
    just past the Campbell diagram's first critical speed (the mode lags a fast run-up) and stands
    well above its level at 5000 rpm."""
    values = ras.EXERCISE.resolve({"speed_rpm": 12000.0, "run_up_rpm_per_s": 6000.0, "balance_grade": "G 6.3"})
    critical = ras.EXERCISE.metrics(values, 0.01)["first_critical_speed_rpm"]
    trace = ras.EXERCISE.simulation(values).advance(round(2.0 / 50e-6))
    columns = ("t",) + RunUpSimulation.columns
    speed, midspan = trace[:, columns.index("speed_rpm")], np.abs(trace[:, columns.index("x_watched_m")])
    peak_speed = speed[np.argmax(midspan)]
    assert critical < peak_speed < critical + 1500.0
    assert midspan.max() > 3 * midspan[(speed > 4500) & (speed < 5500)].max()
