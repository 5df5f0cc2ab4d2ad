"""Exercise ``sensor_placement``: collocated against external position sensors
on the flexible rotor.

Paper 000 (Schuhmann, Hofmann, Werner), §I and Fig. 2: with the eddy-current
sensors on their own track beside the bearing, the third natural mode has its
node between sensor and bearing laminations, the position feedback of that
mode turns positive and the rotor oscillates at its natural frequency (high
gains: unstable).  The capacitive sensors integrated into the bearing's pole
gaps measure in the bearing plane; the same gains are then stable and could
be raised by more than 75 %.  The integrated sensor is noisier (eq. 16:
R_x = 7.1e-4 V², i.e. 1.33 µm); the Kalman filter of §II removes that noise.

The loop is the paper's: amplifier eq. 4, PID K = 0.65, T_I = 50 ms,
T_D = 3 ms (§IV), sampling T = 50 µs, optional steady-state Kalman filter
(eq. 2) on the paper's rigid one-axis model; the plant is the beam model of
``lab_modules.plants.flexible_rotor``.  Sensor positions are measured along the
shaft from the bearing plane, positive towards the free (outboard) end.

Values the paper leaves out (also in the worksheet):

* **Sensor type follows the position.**  Within the stack's length (±20 mm)
  the sensor is the integrated capacitive one (1.33 µm, eq. 16); outside it
  an eddy-current sensor on its own track, 0.27 µm: the paper only says the
  external sensor is quieter; 0.27 µm is what remains of 1.33 µm after the
  paper's ~80 % reduction by the filter (§II), so "integrated + filter" and
  "external" end up comparably quiet, as the paper's argument needs.
* **Default external position +60 mm**: half the stack (20 mm) plus room for
  the winding heads and the sensor head (40 mm).
* **Sensor lag T_mx = 50 µs for both sensors** (eq. 12; one sample period,
  3.2 kHz bandwidth).  It must be short for the paper's result: with
  T_mx = 200 µs the collocated loop already sits at its limit at the
  nominal gains (factor 1.02: mode 3 at ~300 Hz gets the lag's negative
  damping), and the paper's +75 % would be impossible.
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import control
import numpy as np
import scipy.signal

from lab_modules import analysis
from lab_modules.claims import Claim
from lab_modules.exercises import ANALYSIS, POLE_MAP, Analysis, Chart, Exercise, Plot, PoleCategory, Series
from lab_modules.exercises._common import AXIS_LAGS, controller_states, nearest_names, pid_from_values
from lab_modules.exercises._flexible_rotor import (
    CAPACITIVE_NOISE,
    CONTROLLER,
    CURRENT_NOISE_A,
    DISTURBANCE_FORCE,
    EDDY_CURRENT_NOISE,
    EXTERNAL_OFFSET_MM,
    GEOMETRY,
    K_MI,
    K_MX,
    MODAL_DAMPING,
    OFFSET_RANGE_MM,
    SENSOR_LAG,
    T,
    filter_for,
    integrated,
    scaled_pid,
    sensor_noise_m,
)
from lab_modules.loops.flexible_rotor_loop import (
    LOOP_OUTPUTS,
    LoopSimulation,
    closed_loop,
    discrete_plant,
    kalman_compensator,
    pid_compensator,
)
from lab_modules.parameters import Parameter, in_si
from lab_modules.plants.flexible_rotor import FlexibleRotor, modal_plant
from lab_modules.plants.radial_bearing import RIG
from lab_modules.scenes.rotor import RotorScene

GAIN_STEP = 0.05
GAIN_SEARCH = np.round(np.arange(GAIN_STEP, 4.0 + 1e-9, GAIN_STEP), 2)   # gain factors tried, bottom up
EDGE_STEP = 1e-4                  # the mode that goes unstable first: the most unstable this far above the edge
PATH_OFFSETS_MM = np.linspace(*OFFSET_RANGE_MM, 43)

P = Parameter
PARAMETERS = (
    P("sensor_offset_mm", "Sensor position from bearing plane", "mm", EXTERNAL_OFFSET_MM, *OFFSET_RANGE_MM,
      "Axial position of the position sensor (+ towards the free end). Within ±20 mm: the integrated "
      "capacitive sensor; outside: an eddy-current sensor on its own track (paper §I).",
      step=1.0, group="Sensor"),
    CAPACITIVE_NOISE,
    EDDY_CURRENT_NOISE,
    SENSOR_LAG,
    *CONTROLLER,
    P("modes", "Modes kept", "", 4, 1, 6, "Modal truncation of the beam model (mode 1: rigid tilting).",
      integer=True, step=1, group="Rotor"),
    MODAL_DAMPING,
    P("shown_mode", "Mode shown in 3D", "", 3, 1, 6, "Mode shape animated in the 3D view.", integer=True,
      step=1, group="Sensor"),
    P("reference_step_um", "Reference step", "µm", 50.0, -100.0, 100.0,
      "Square-wave reference position (paper Fig. 8: 50 µm).", step=1.0, group="Excitation"),
    P("step_period_ms", "Step period", "ms", 100.0, 10.0, 1000.0, "Period of the reference square wave.",
      step=10.0, group="Excitation"),
    DISTURBANCE_FORCE,
    P("seed", "Random seed", "", 0, 0, 2**31 - 1, "Seed of this lab's noise.", integer=True, step=1,
      group="Run"),
    P("time_scale", "Time scale", "×", 0.02, 0.001, 1.0,
      "Simulated seconds per wall-clock second in the browser (1 = real time).", log=True, group="Run"),
)


# -- the set-up ------------------------------------------------------------------------
@lru_cache(maxsize=8)
def rotor(modal_damping: float) -> FlexibleRotor:
    return FlexibleRotor(replace(GEOMETRY, modal_damping=modal_damping))


@lru_cache(maxsize=256)
def _plant(modal_damping: float, sensor_offset_mm: float, modes: int, sensor_lag_s: float):
    return discrete_plant(rotor(modal_damping), GEOMETRY.bearing_m + sensor_offset_mm * 1e-3, modes,
                          sensor_lag_s)


def compensator(values: dict, gain_factor: float | None = None,
                sensor_offset_mm: float | None = None) -> control.StateSpace:
    """PID (scaled by the gain factor) on the measurement or on the filter's estimate."""
    controller = scaled_pid(values, gain_factor)
    if values["feedback"] == "measured":
        return pid_compensator(controller)
    model, gain, _, _ = filter_for(values, sensor_offset_mm)
    return kalman_compensator(controller, model, gain)


def plant(values: dict, sensor_offset_mm: float | None = None) -> control.StateSpace:
    offset = values["sensor_offset_mm"] if sensor_offset_mm is None else sensor_offset_mm
    return _plant(values["modal_damping_percent"] / 100, float(offset), int(values["modes"]),
                  in_si(PARAMETERS, values)["sensor_lag_us"])


def loop_at_plant_input(values: dict) -> control.StateSpace:
    """Open loop L broken at the amplifier input i_ref (S = 1 / (1 + L)): every mode the
    plant keeps, the sensor at its position, the compensator reading position and current."""
    system = plant(values)
    A, B, C, D = (np.asarray(M) for M in (system.A, system.B, system.C, system.D))
    measured = control.ss(A, B[:, :1], C[[0, 3]], D[[0, 3], :1], system.dt)   # (K_mx x_d, K_mi i) [V]
    return analysis.loop_at_plant_input(measured, compensator(values)[:, :2])


def loop(values: dict, gain_factor: float | None = None, sensor_offset_mm: float | None = None):
    """The closed loop at the given gain factor and sensor position (defaults: the values')."""
    return closed_loop(plant(values, sensor_offset_mm), compensator(values, gain_factor, sensor_offset_mm))


# -- linear analysis ---------------------------------------------------------------------
def continuous_poles(system: control.StateSpace) -> np.ndarray:
    return analysis.z_to_s(system.poles(), T)


def mode_poles(system: control.StateSpace, n_modes: int) -> np.ndarray:
    """The closed-loop pole (s-plane, upper half or real) that belongs to each rotor mode.

    Each eigenvector's modal energy |eta_j|^2 (omega_j^2 + |s|^2) is split over the
    modes; mode j gets the pole in which its share is largest (modal states come
    first in the closed loop's state vector).
    """
    A = np.asarray(system.A)
    z, vectors = np.linalg.eig(A)
    s = analysis.z_to_s(z, T)
    omega = 2 * np.pi * rotor(GEOMETRY.modal_damping).natural_frequencies_hz(n_modes)   # damping-free
    energy = np.abs(vectors[:n_modes]) ** 2 * (omega[:, None] ** 2 + np.abs(s)[None, :] ** 2)
    share = energy / np.maximum(energy.sum(axis=0), 1e-300)
    share[:, np.abs(s.imag) < 1e-6] -= 2.0      # a real pole only when no oscillating one is left
    share[:, s.imag < -1e-9] = -10.0
    chosen, taken = np.empty(n_modes, dtype=complex), set()
    for j in np.argsort(-share.max(axis=1)):
        order = [k for k in np.argsort(-share[j]) if k not in taken]
        taken.add(order[0])
        chosen[j] = s[order[0]]
    return chosen


def mode_name(j: int) -> str:
    """The physical name of rotor mode ``j`` (0-based): mode 1 is the rigid tilting about the
    ball bearing, the others bend the shaft."""
    if j == 0:
        return "rotor mode 1 (rigid tilting)"
    ordinal = {1: "1st", 2: "2nd", 3: "3rd"}.get(j, f"{j}th")
    return f"rotor mode {j + 1} ({ordinal} bending)"


def plant_mode_names(values: dict, poles_s: np.ndarray) -> list[str | None]:
    """Names of the open-loop plant's poles: the mechanical block (modal states) is coupled by
    the magnet's negative stiffness k_x, so each of its eigenvalues is named after the mode that
    holds most of its modal energy |η_j|² (ω_j² + |s|²); the amplifier and the sensor lag add
    one real pole each (the plant is block triangular)."""
    n = int(values["modes"])
    r = rotor(values["modal_damping_percent"] / 100)
    si = in_si(PARAMETERS, values)
    lag = si["sensor_lag_us"]
    A = np.asarray(modal_plant(r, GEOMETRY.bearing_m + si["sensor_offset_mm"], n, lag).A)
    s, vectors = np.linalg.eig(A[:2 * n, :2 * n])
    omega = 2 * np.pi * r.natural_frequencies_hz(n)
    energy = np.abs(vectors[:n]) ** 2 * (omega[:, None] ** 2 + np.abs(s)[None, :] ** 2)
    named = [(complex(p), mode_name(int(j))) for p, j in zip(s, np.argmax(energy, axis=0))]
    named.append((complex(-1.0 / RIG.amplifier_lag_s), AXIS_LAGS[0]))
    if lag > 0:
        named.append((complex(-1.0 / lag), AXIS_LAGS[1]))
    return nearest_names(poles_s, named)


def damping(poles_s: np.ndarray) -> np.ndarray:
    return -poles_s.real / np.maximum(np.abs(poles_s), 1e-12)


def unstable_mode_sentence(modes_s: np.ndarray) -> str:
    """'mode j grows at f Hz' for the most unstable mode (or: diverges without oscillating)."""
    j = int(np.argmax(modes_s.real))
    if abs(modes_s[j].imag) < 2 * np.pi:
        return f"mode {j + 1} diverges without oscillating (too little stiffness against k_x)"
    return f"mode {j + 1} grows at {abs(modes_s[j].imag) / (2 * np.pi):.0f} Hz"


def stable(system: control.StateSpace) -> bool:
    return bool(np.max(np.abs(system.poles())) < 1.0)


def largest_stable_gain(values: dict, sensor_offset_mm: float | None = None) -> tuple[float, int | None]:
    """Largest gain factor (on the PID gain K) reached by raising the gain from the
    smallest one that levitates the rotor, with every closed-loop pole stable; and
    the mode that goes unstable just above it (1-based; None if the loop is still
    stable at the top of the range).

    The closed loop's state matrix is affine in the factor (it scales the PID's output), so
    the loops at both ends of ``GAIN_SEARCH`` give every factor's poles: the first stable
    factor of ``GAIN_SEARCH``, then the stability edge above it (``analysis.first_instability``:
    the bracketing grid step, then Brent's method on the spectral radius).  With no stable
    gain at all it returns 0.0 and the mode most unstable at the set gains.
    """
    key = (tuple(sorted((k, v) for k, v in values.items() if k not in ("shown_mode", "seed", "time_scale"))),
           sensor_offset_mm)
    return _largest_stable_gain(key)


@lru_cache(maxsize=256)
def _largest_stable_gain(key) -> tuple[float, int | None]:
    values, offset = dict(key[0]), key[1]
    low, high = float(GAIN_SEARCH[0]), float(GAIN_SEARCH[-1])
    A_low, A_high = (np.asarray(loop(values, g, offset).A) for g in (low, high))

    def most_unstable_mode(g: float) -> int:
        return int(np.argmax(mode_poles(loop(values, g, offset), int(values["modes"])).real)) + 1

    stable = np.flatnonzero(analysis.stability_margins(A_low, A_high, low, high, GAIN_SEARCH) < 0.0)
    if stable.size == 0:
        return 0.0, most_unstable_mode(values["gain_factor"])
    start = float(GAIN_SEARCH[stable[0]])
    A_start = A_low + (start - low) / (high - low) * (A_high - A_low)
    edge = analysis.first_instability(A_start, A_high, start, high, factors=GAIN_SEARCH[stable[0]:])
    if edge >= high:
        return high, None
    return edge, most_unstable_mode(edge * (1.0 + EDGE_STEP))


def residue_signs(values: dict, sensor_offset_mm: float | None = None) -> np.ndarray:
    """sign(phi_j(bearing) phi_j(sensor)) per mode: + collocated-like, - positive feedback."""
    offset = values["sensor_offset_mm"] if sensor_offset_mm is None else sensor_offset_mm
    r = rotor(values["modal_damping_percent"] / 100)
    n = int(values["modes"])
    phi_b = r.displacement(GEOMETRY.bearing_m, n)[0]
    phi_s = r.displacement(GEOMETRY.bearing_m + offset * 1e-3, n)[0]
    return np.sign(phi_b * phi_s)


@lru_cache(maxsize=32)
def _pole_paths(key) -> np.ndarray:
    """Mode poles (rows: offsets ``PATH_OFFSETS_MM``, columns: modes) over the offset range."""
    values = dict(key)
    return np.array([mode_poles(loop(values, None, float(d)), int(values["modes"])) for d in PATH_OFFSETS_MM])


def pole_paths(values: dict) -> np.ndarray:
    return _pole_paths(tuple(sorted((k, v) for k, v in values.items()
                                    if k not in ("sensor_offset_mm", "shown_mode", "seed", "time_scale"))))


def step_response(values: dict, duration_s: float = 0.03):
    """Reference step (``reference_step_um``, or 50 µm if zero) of the noise-free loop:
    time [s], rotor at the bearing [m], sensor reading [m]; cut at touchdown."""
    step_m = in_si(PARAMETERS, values)["reference_step_um"] or 50.0 * 1e-6
    response = control.step_response(loop(values), T=np.arange(0.0, duration_s, T), input=0)
    outputs = np.asarray(response.outputs).reshape(len(LOOP_OUTPUTS), -1) * step_m
    bearing = outputs[LOOP_OUTPUTS.index("x_bearing_m")]
    reading = outputs[LOOP_OUTPUTS.index("sensor_reading_m")]
    beyond = np.flatnonzero(np.abs(bearing) >= RIG.touchdown_m)
    if beyond.size:
        bearing, reading = bearing.copy(), reading.copy()
        bearing[beyond[0] + 1:] = np.nan
        reading[beyond[0] + 1:] = np.nan
    return np.asarray(response.time), bearing, reading


def simulation_inputs(values: dict):
    """Square-wave reference (first half of each period zero); no deterministic force."""
    si = in_si(PARAMETERS, values)
    step_m, period_s = si["reference_step_um"], si["step_period_ms"]

    def inputs(first_step: int, n_steps: int):
        t = (first_step + np.arange(n_steps)) * T
        on = (np.mod(t, period_s) >= 0.5 * period_s).astype(float)
        return step_m * on, np.zeros(n_steps)
    return inputs


def oscillation_frequency_hz(x_m: np.ndarray, window_s: float = 0.02) -> float:
    """Dominant frequency [Hz] at the end of a trace: periodogram peak of its last
    ``window_s`` after removing a linear trend (a growing mode dominates there)."""
    tail = scipy.signal.detrend(x_m[-round(window_s / T):])
    f, power = scipy.signal.periodogram(tail, fs=1 / T, nfft=16384)
    return float(f[np.argmax(power)])


CLAIMS = (
    Claim("paper 000 §I, Fig. 2", "external sensor (+60 mm): largest stable gain factor",
          "unstable at the nominal gains", "max_gain_factor_external", (None, 1.0), "×"),
    Claim("paper 000 §I, Fig. 2", "external sensor: the mode that turns unstable first",
          "a bending mode whose node lies between bearing and sensor", "first_unstable_mode_external", (3, 3), "",
          note="mode 1 is the rigid mode; mode 3's node lies between the bearing and the +60 mm sensor"),
    Claim("paper 000 §I-II", "integrated (collocated) sensor: largest stable gain factor", "more than +75 %",
          "max_gain_factor_collocated", (1.75, None), "×"),
    Claim("paper 000 §II", "coil-current noise reduction by the filter, integrated sensor", "about 80 %",
          "current_noise_reduction_collocated_percent", (75, None), "%"),
)


class SensorPlacement(Exercise):
    name = "sensor_placement"
    title = "Sensor placement on the flexible rotor"
    worksheet = "sensor_placement.md"
    parameters = PARAMETERS
    default_duration_s = 0.3
    claims = CLAIMS
    locus = ("gain_factor", "closed loop")
    key_readouts = ("Largest stable gain factor here", "Mode that goes unstable first",
                    "RMS rotor motion at the bearing", "RMS sensor reading")
    charts = (
        Chart("Rotor position", "µm", (
            Series("reference", "reference_m", 1e6, "#7f7f7f"),
            Series("sensor reading", "sensor_reading_m", 1e6, "#b0b0b0"),
            Series("rotor at the sensor", "x_sensor_m", 1e6, "#ff7f0e"),
            Series("rotor at the bearing", "x_bearing_m", 1e6, "#1f77b4"))),
        Chart("Control current", "A", (Series("coil current i", "current_a", 1.0, "#2ca02c"),)),
    )

    def locus_matrices(self, values: dict, factors: tuple[float, ...]) -> tuple[list[np.ndarray], float]:
        """The closed loop's state matrices at these gain factors."""
        return [np.asarray(loop(values, factor).A) for factor in factors], T

    def mode_matrices(self, values: dict) -> dict[str, tuple]:
        """The closed loop by its states: the rotor's modal coordinates η_j, η̇_j (each pair one
        rotor mode; paper 005's beam model, ``plants.flexible_rotor``), the coil current and the
        sensor lag (paper 000 eq. 4, 12), with the estimated feedback the filter's prediction of
        the rigid model (x, v, i, x_d: it is not an error coordinate, the filter's model differs
        from the plant), and the PID in its modal states (integrator, derivative filter)."""
        n = int(values["modes"])
        system = loop(values)
        A = np.asarray(system.A)
        comp = compensator(values)
        controller = pid_from_values(values)
        nc, npid = comp.nstates, controller.nstates
        n_plant = A.shape[0] - nc
        lags = [("i [A]", "coil current"), ("x_d [m]", "position sensor lag")]
        states = ([(f"η_{j + 1} [m kg^½]", mode_name(j)) for j in range(n)]
                  + [(f"η̇_{j + 1} [m kg^½/s]", mode_name(j)) for j in range(n)] + lags[:n_plant - 2 * n])
        basis = np.eye(A.shape[0])
        V = analysis.modal_basis(controller.A)
        pid_at = n_plant + nc - npid                     # the PID's states come last in the compensator
        basis[pid_at:, pid_at:] = V
        estimate = [(label, "filter's estimate (rigid model)") for label in
                    ("x̂ [m]", "v̂ [m/s]", "î [A]", "x̂_d [m]")[:nc - npid]]
        states += estimate + controller_states(controller, V)
        return {"closed loop": (analysis.change_basis(A, basis), states, T)}

    def pole_categories(self, values: dict) -> dict[str, PoleCategory]:
        return {"open-loop plant": PoleCategory.PLANT, "closed loop": PoleCategory.CLOSED_LOOP}

    def mode_names(self, values: dict, poles: dict[str, np.ndarray]) -> dict[str, list[str | None]]:
        """The rotor's modes by name in the plant and the closed loop (``mode_poles``: by modal
        energy), the amplifier and sensor lag in the plant; the controller's and the filter's
        poles keep their generic kind."""
        chosen = mode_poles(loop(values), int(values["modes"]))
        return {"open-loop plant": plant_mode_names(values, poles["open-loop plant"]),
                "closed loop": nearest_names(poles["closed loop"],
                                              [(complex(p), mode_name(j)) for j, p in enumerate(chosen)])}

    def model(self, values: dict) -> dict:
        r = rotor(values["modal_damping_percent"] / 100)
        n = int(values["modes"])
        si = in_si(PARAMETERS, values)
        z_s = GEOMETRY.bearing_m + si["sensor_offset_mm"]
        continuous = modal_plant(r, z_s, n, si["sensor_lag_us"])
        discrete = plant(values)
        return {
            "states": [f"eta_{j + 1} [m·kg^0.5]" for j in range(n)] + [f"eta_{j + 1}' [m·kg^0.5/s]" for j in range(n)]
                      + ["i [A]"] + (["x_d [m]"] if values["sensor_lag_us"] > 0 else []),
            "inputs": ["i_ref [V]", "f_z [N]"], "outputs": ["K_mx x_d [V]", "x_b [m]", "x_s [m]", "K_mi i [V]"],
            "sample_time_s": T,
            "A_continuous": np.asarray(continuous.A).tolist(),
            "A": np.asarray(discrete.A).tolist(), "B": np.asarray(discrete.B).tolist(),
            "C": np.asarray(discrete.C).tolist(),
            "geometry": {"length_m": GEOMETRY.length_m, "shaft_diameter_m": GEOMETRY.shaft_diameter_m,
                         "pivot_m": GEOMETRY.pivot_m, "bearing_m": GEOMETRY.bearing_m,
                         "sensor_m": z_s, "stack_length_m": GEOMETRY.stack_length_m,
                         "stack_diameter_m": GEOMETRY.stack_diameter_m, "stack_mass_kg": GEOMETRY.stack_mass_kg,
                         "hub_position_m": GEOMETRY.hub_position_m, "hub_mass_kg": GEOMETRY.hub_mass_kg,
                         "total_mass_kg": r.total_mass_kg},
            "sensor": "integrated capacitive" if integrated(values["sensor_offset_mm"]) else "external eddy-current",
        }

    def open_loops(self, values: dict) -> dict:
        return {f"bearing PID, {values['feedback']} x": loop_at_plant_input(values)}

    def analyse_panel(self, values: dict, panel: str) -> Analysis:
        """The Scope: the modes, the largest stable gain and the closed loop's damping; the Pole map:
        the open and closed loop's poles; the Analysis tab: the step response, the poles' paths over
        the sensor positions and the damping along them."""
        if panel == ANALYSIS:
            return Analysis([], {}, [], self._plots(values))
        if panel == POLE_MAP:
            si = in_si(PARAMETERS, values)
            r = rotor(values["modal_damping_percent"] / 100)
            return Analysis([], {"open-loop plant": np.linalg.eigvals(np.asarray(
                                    modal_plant(r, GEOMETRY.bearing_m + si["sensor_offset_mm"], int(values["modes"]),
                                                si["sensor_lag_us"]).A)),
                                 "closed loop": continuous_poles(loop(values))}, [])
        return self._readouts(values)

    @staticmethod
    def _readouts(values: dict) -> Analysis:
        n = int(values["modes"])
        r = rotor(values["modal_damping_percent"] / 100)
        frequencies = r.natural_frequencies_hz(n)
        closed = loop(values)
        modes_s = mode_poles(closed, n)
        signs = residue_signs(values)
        max_gain, first_mode = largest_stable_gain(values)
        sensor = "integrated capacitive" if integrated(values["sensor_offset_mm"]) else "eddy-current track"
        readouts = [(f"Natural frequency, mode {j + 1}", f, "Hz") for j, f in enumerate(frequencies)]
        readouts += [("Largest stable gain factor here", max_gain, "×"),
                     ("Mode that goes unstable first", f"mode {first_mode}" if first_mode else "none", ""),
                     ("Sensor noise σ (" + sensor + ")", sensor_noise_m(values) * 1e6, "µm")]
        for j in range(n):
            readouts += [(f"Mode {j + 1}: residue sign φ(actuator)·φ(sensor)", float(signs[j]), ""),
                         (f"Mode {j + 1}: closed-loop damping", 100 * damping(modes_s[j:j + 1])[0], "%")]
        nodes = [", ".join(f"{(z - GEOMETRY.bearing_m) * 1e3:+.0f}" for z in r.nodal_points_m(j)) or "none"
                 for j in range(n)]
        notes = [f"Sensor: {sensor} at {values['sensor_offset_mm']:+.0f} mm from the bearing plane.",
                 "Nodes (mm from the bearing plane): " + "; ".join(f"mode {j + 1}: {s}" for j, s in enumerate(nodes)),
                 ("A mode with residue sign −1 is fed back with the wrong sign: the PID's damping "
                  "becomes negative damping for it."),
                 ("Natural frequencies: the rotor on its ball bearing with the magnetic bearing switched off "
                  "(mode 1 is the rigid tilting about the ball bearing).")]
        if not stable(closed):
            notes.insert(0, f"Unstable: {unstable_mode_sentence(modes_s)}.")
        return Analysis(readouts, {}, notes=notes)

    @staticmethod
    def _plots(values: dict) -> list:
        n = int(values["modes"])
        paths = pole_paths(values)
        colours = ("#1f77b4", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2")
        # pole paths in the s-plane: one shared, increasing x (Re s), NaN elsewhere
        real = paths.real.ravel()
        order = np.argsort(real, kind="stable")
        x = real[order]
        series = []
        for j in range(n):
            y = np.full(x.size, np.nan)
            mine = order % n == j
            y[mine] = np.abs(paths.imag.ravel()[order][mine]) / (2 * np.pi)
            series.append((f"mode {j + 1}", y, colours[j]))
        path_plot = Plot(f"Closed-loop poles for sensor positions {OFFSET_RANGE_MM[0]:.0f} … "
                         f"{OFFSET_RANGE_MM[1]:.0f} mm", "Re s [1/s]", "Im s / 2π [Hz]", x, tuple(series),
                         points=True)
        damping_plot = Plot("Closed-loop damping of each mode vs sensor position", "sensor position [mm]",
                            "damping ζ [%]", PATH_OFFSETS_MM,
                            tuple((f"mode {j + 1}", 100 * damping(paths[:, j]), colours[j]) for j in range(n)))
        t, bearing, reading = step_response(values)
        step_plot = Plot("Reference step response (linear, noise-free)", "time [ms]", "position [µm]", t * 1e3,
                         (("rotor at the bearing", bearing * 1e6, "#1f77b4"),
                          ("sensor reading", reading * 1e6, "#ff7f0e")))
        return [step_plot, path_plot, damping_plot]

    def simulation(self, values: dict) -> LoopSimulation:
        closed = loop(values)

        def explain() -> str:
            modes_s = mode_poles(closed, int(values["modes"]))
            if stable(closed):
                return ("The linear loop is stable: the reference step (the PID's derivative kick on the "
                        "step) or the noise was too large. Set the reference step to 0 to see the loop's own "
                        "stability.")
            return (f"The loop is unstable: {unstable_mode_sentence(modes_s)}. "
                    "Move the sensor or change the gain, then reset.")
        return LoopSimulation(closed, simulation_inputs(values), values["disturbance_force_n"],
                              (K_MX * sensor_noise_m(values), K_MI * CURRENT_NOISE_A),
                              seed=int(values["seed"]), explain=explain)

    def retune(self, simulation: LoopSimulation, values: dict) -> LoopSimulation:
        return self.simulation(values).carry_on_from(simulation)

    def report_figures(self, values: dict) -> list:
        """Fig. 2's point: each mode's closed-loop damping against the sensor's position."""
        from lab_modules.exercises._figures import plot_figure
        return [plot_figure(plot) for plot in self._plots(values) if plot.title.startswith("Closed-loop damping")]

    def live_readouts(self, trace: dict[str, np.ndarray]) -> list[tuple[str, float, str]]:
        def rms(x):
            return float(np.sqrt(np.mean((x - np.mean(x)) ** 2)))
        return [("RMS rotor motion at the bearing", rms(trace["x_bearing_m"]) * 1e6, "µm"),
                ("RMS sensor reading", rms(trace["sensor_reading_m"]) * 1e6, "µm"),
                ("RMS coil current", rms(trace["current_a"]), "A")]

    def scene(self, values: dict) -> RotorScene:
        return RotorScene(rotor(values["modal_damping_percent"] / 100), values, integrated)

    def metrics(self, values: dict, duration_s: float) -> dict:
        n = int(values["modes"])
        r = rotor(values["modal_damping_percent"] / 100)
        at = {"collocated": 0.0, "external": EXTERNAL_OFFSET_MM}
        gains = {name: largest_stable_gain(values, offset) for name, offset in at.items()}
        nominal = {name: mode_poles(loop(values, 1.0, offset), n) for name, offset in at.items()}
        n_steps = round(duration_s / T)
        runs = {}
        for name, offset in at.items():
            sim = self.simulation({**values, "sensor_offset_mm": offset, "gain_factor": 1.0})
            trace = sim.advance(n_steps)
            x_b = trace[:, 1 + LOOP_OUTPUTS.index("x_bearing_m")]
            runs[name] = {"status": sim.status_message() or "ok",
                          "oscillation_hz": oscillation_frequency_hz(x_b) if x_b.size > 64 else float("nan"),
                          "peak_um": float(np.max(np.abs(x_b))) * 1e6 if x_b.size else float("nan")}
        noise = {}
        for source in ("measured", "estimated"):
            quiet = {**values, "sensor_offset_mm": 0.0, "gain_factor": 1.0, "feedback": source,
                     "reference_step_um": 0.0}
            trace = self.simulation(quiet).advance(n_steps)[n_steps // 4:]
            noise[source] = {column: float(np.std(trace[:, 1 + LOOP_OUTPUTS.index(column)])) if len(trace)
                             else float("nan") for column in ("x_bearing_m", "current_a")}
        current = mode_poles(loop(values), n)
        return {
            "natural_frequencies_hz": r.natural_frequencies_hz(n).tolist(),
            "max_gain_factor_collocated": gains["collocated"][0],
            "max_gain_factor_external": gains["external"][0],
            "first_unstable_mode_collocated": gains["collocated"][1],
            "first_unstable_mode_external": gains["external"][1],
            "external_offset_mm": EXTERNAL_OFFSET_MM,
            "mode_nodes_from_bearing_mm": [((r.nodal_points_m(j) - GEOMETRY.bearing_m) * 1e3).tolist()
                                           for j in range(n)],
            "residue_signs_collocated": residue_signs(values, 0.0).tolist(),
            "residue_signs_external": residue_signs(values, EXTERNAL_OFFSET_MM).tolist(),
            "mode_damping_nominal_collocated": damping(nominal["collocated"]).tolist(),
            "mode_damping_nominal_external": damping(nominal["external"]).tolist(),
            "mode_frequency_nominal_external_hz": (np.abs(nominal["external"].imag) / (2 * np.pi)).tolist(),
            "oscillation_frequency_external_hz": runs["external"]["oscillation_hz"],
            "status_external": runs["external"]["status"],
            "status_collocated": runs["collocated"]["status"],
            "peak_bearing_displacement_collocated_um": runs["collocated"]["peak_um"],
            "rms_displacement_collocated_measured_feedback_um": noise["measured"]["x_bearing_m"] * 1e6,
            "rms_displacement_collocated_estimated_feedback_um": noise["estimated"]["x_bearing_m"] * 1e6,
            "rms_current_collocated_measured_feedback_a": noise["measured"]["current_a"],
            "rms_current_collocated_estimated_feedback_a": noise["estimated"]["current_a"],
            "current_noise_reduction_collocated_percent":
                100.0 * (1.0 - noise["estimated"]["current_a"] / noise["measured"]["current_a"]),
            "max_gain_factor_collocated_estimated_feedback":
                largest_stable_gain({**values, "feedback": "estimated"}, 0.0)[0],
            "max_gain_factor_external_estimated_feedback":
                largest_stable_gain({**values, "feedback": "estimated"}, EXTERNAL_OFFSET_MM)[0],
            "sensor_offset_mm": values["sensor_offset_mm"],
            "mode_damping_current": damping(current).tolist(),
            "largest_stable_gain_factor_current": largest_stable_gain(values)[0],
            "total_mass_kg": r.total_mass_kg,
            "equivalent_mass_at_bearing_kg": float(1 / r.displacement(GEOMETRY.bearing_m, 1)[0, 0] ** 2),
            "duration_s": n_steps * T,
        }


EXERCISE = SensorPlacement()
