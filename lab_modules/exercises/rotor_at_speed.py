"""Exercise ``rotor_at_speed``: the flexible rotor spinning, its Campbell diagram, the
sensor placement verdict against speed and the unbalance response.

Paper 000 (Schuhmann, Hofmann, Werner), §I, Fig. 2 motivates collocated sensing with
this rotor at standstill (``sensor_placement``); a magnetic bearing exists to carry a
*spinning* rotor.  The lamination stack's polar inertia is about twice its diametral
inertia, so spun up each bending mode splits into a backward and a forward whirl
(``plants.spinning_rotor``), the frequency at which an external sensor's wrong-signed
residue acts moves with speed, and the unbalance's synchronous force excites the
forward whirls at the critical speeds.  Nothing here is in the paper: the claims are
lab targets, the natural frequencies checked against ROSS (the field's open
rotordynamics library) built with the same geometry and element theory.

A separate exercise rather than a speed slider on ``sensor_placement``: that one keeps
the paper's standstill figures (its claims, its nine tasks, its step response), and the
questions at speed (Campbell diagram, critical speeds, balance grades, ISO zones) need
their own plots, controls and worksheet.  Both share the controls of
``exercises._flexible_rotor`` (sensor noise and lag, the paper's PID, the rigid-model
Kalman filter); at 0 rpm with the same modes and Euler-Bernoulli elements this loop
has ``sensor_placement``'s poles (tested).

Values not in any paper (also in the worksheet): Timoshenko elements by default; six
modes kept; the unbalance at the stack, its grade's permissible residual unbalance at
the top of the range (12,000 rpm); the touchdown bearing's minimum clearance C_min =
230 µm (half the 460 µm air gap); the speed range 0 ... 12,000 rpm.
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import control
import numpy as np

from lab_modules.analysis import loop_at_plant_input, participation, z_to_s
from lab_modules.claims import Claim
from lab_modules.exercises import POLE_MAP, SCOPE, Analysis, Chart, Exercise, Plot, PoleCategory, Series
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
    filter_for,
    integrated,
    scaled_pid,
    sensor_noise_m,
)
from lab_modules.loops.spinning_rotor_loop import (
    LOOP_OUTPUTS,
    RunUpSimulation,
    closed_loop_at_speed,
    critical_speeds_rpm,
    discretised,
    observed_compensator,
    stable,
    sweep,
    unbalance_response,
    unbalance_states,
)
from lab_modules.parameters import Parameter, in_si
from lab_modules.plants.flexible_rotor import THEORIES, FlexibleRotor
from lab_modules.plants.radial_bearing import RIG
from lab_modules.plants.spinning_rotor import (
    BALANCE_GRADES_MM_S,
    ISO_14839_2_LIMITS,
    SPEED_RANGE_RPM,
    SpinningRotor,
    iso_14839_2_zone,
    permissible_unbalance_kg_m,
    whirl_by_mode,
    whirl_frequencies_hz,
)
from lab_modules.scenes.spinning_rotor import WhirlScene

#: The Campbell diagram's speeds [rpm]: 61 from 0 to 12,000 (200 rpm apart).
CAMPBELL_SPEEDS_RPM = np.linspace(*SPEED_RANGE_RPM, 61)
#: Speeds [rpm] of the stability-limit curve (largest stable gain factor): every 1,000 rpm.
LIMIT_SPEEDS_RPM = np.linspace(*SPEED_RANGE_RPM, 13)
#: The plots' speed axis, in thousands of rpm (a last tick label "12,000" would not fit the chart).
SPEED_AXIS = "speed n [1000 rpm]"
GAIN_GRID = np.round(np.arange(0.1, 4.0 + 1e-9, 0.1), 2)   # gain factors tried before bisecting
#: Where the first bending mode (mode 2) moves most, between the ball bearing and the stack: its
#: critical speed shows there, while the bearing plane sits near that mode's node.
MIDSPAN_M = 0.45
CLEARANCE_UM = 1e6 * RIG.delta0_m / 2                      # touchdown bearing: half the air gap (230 µm)
SENSORS = {"integrated (collocated)": 0.0, f"external (+{EXTERNAL_OFFSET_MM:.0f} mm)": EXTERNAL_OFFSET_MM}
MODE_COLOURS = ("#1f77b4", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22")
SET_SPEED_COLOUR = "#e7298a"
BACKWARD_COLOURS = ("#9ecae1", "#a1d99b", "#fc9272", "#bcbddc", "#c49c94", "#f7b6d2", "#9edae5", "#dbdb8d")

P = Parameter
PARAMETERS = (
    P("speed_rpm", "Rotor speed n", "rpm", 3000.0, *SPEED_RANGE_RPM,
      "Spin speed: the Campbell diagram's cursor, the 3D view's whirl and the simulation's speed "
      "(its end speed in a run-up).", step=50.0, group="Speed"),
    P("run_up_rpm_per_s", "Run-up rate", "rpm/s", 0.0, 0.0, 10000.0,
      "0: the simulation holds the speed. Above 0: it starts at 0 rpm and accelerates at this rate up "
      "to the set speed (through the critical speeds on the way).", step=100.0, group="Speed"),
    P("sensor_offset_mm", "Sensor position from bearing plane", "mm", 0.0, *OFFSET_RANGE_MM,
      "Axial position of the position sensor (+ towards the free end). Within ±20 mm: the integrated "
      "capacitive sensor; outside: an eddy-current sensor on its own track (paper 000 §I).",
      step=1.0, group="Sensor"),
    CAPACITIVE_NOISE,
    EDDY_CURRENT_NOISE,
    SENSOR_LAG,
    *CONTROLLER,
    P("beam_theory", "Beam elements", "", "timoshenko", choices=THEORIES,
      description="Timoshenko (shear deformation and rotary inertia) or Euler-Bernoulli (sensor_placement's).",
      group="Rotor"),
    P("modes", "Modes kept", "", 6, 2, 8, "Modal truncation (mode 1: rigid tilting about the ball bearing).",
      integer=True, step=1, group="Rotor"),
    MODAL_DAMPING,
    P("shown_mode", "Mode shown in 3D", "", 3, 1, 4, "Mode whose whirl the 3D view shows at the set speed.",
      integer=True, step=1, group="Rotor"),
    P("shown_whirl", "Whirl shown in 3D", "", "forward", choices=("forward", "backward"),
      description="Forward whirl: the orbit turns with the spin; backward: against it.", group="Rotor"),
    P("balance_grade", "Balance grade (ISO 21940-11)", "", "G 2.5", choices=tuple(BALANCE_GRADES_MM_S),
      description="Permissible residual unbalance U = m G / Ω_max at the stack (G 2.5: turbines, machine-tool "
                  "drives; G 6.3: electric motors, general machinery).", group="Unbalance"),
    P("max_service_speed_rpm", "Maximum service speed", "rpm", SPEED_RANGE_RPM[1], 1000.0, SPEED_RANGE_RPM[1],
      "Ω_max of the balance grade's e = G / Ω_max (not in the paper: the top of the range).", step=100.0,
      group="Unbalance"),
    P("clearance_um", "Touchdown bearing clearance C_min", "µm", round(CLEARANCE_UM, 1), 50.0, 460.0,
      "Minimum radial clearance of the touchdown bearing (not in the paper: half the 460 µm air gap); "
      "ISO 14839-2's zones are fractions of it.", step=5.0, group="Unbalance"),
    DISTURBANCE_FORCE,
    P("seed", "Random seed", "", 0, 0, 2**31 - 1, "Seed of this lab's noise.", integer=True, step=1, group="Run"),
    P("time_scale", "Time scale", "×", 0.05, 0.001, 1.0,
      "Simulated seconds per wall-clock second in the browser (1 = real time).", log=True, group="Run"),
)


# -- the set-up ------------------------------------------------------------------------
@lru_cache(maxsize=8)
def spinning_rotor(theory: str, modal_damping: float) -> SpinningRotor:
    return SpinningRotor(FlexibleRotor(replace(GEOMETRY, modal_damping=modal_damping), theory=theory))


def rotor_of(values: dict) -> SpinningRotor:
    return spinning_rotor(values["beam_theory"], values["modal_damping_percent"] / 100)


@lru_cache(maxsize=64)
def _plant(theory: str, modal_damping: float, sensor_offset_mm: float, modes: int, sensor_lag_s: float):
    """The plant at this sensor (cached per plant)."""
    return spinning_rotor(theory, modal_damping).plant(GEOMETRY.bearing_m + sensor_offset_mm * 1e-3, modes,
                                                       sensor_lag_s)


@lru_cache(maxsize=64)
def _plant_and_grid(theory: str, modal_damping: float, sensor_offset_mm: float, modes: int, sensor_lag_s: float):
    """The plant at this sensor and its discretisations on the Campbell and stability-limit grids
    (they depend on no controller setting: cached per plant)."""
    plant = _plant(theory, modal_damping, sensor_offset_mm, modes, sensor_lag_s)
    return plant, discretised(plant, CAMPBELL_SPEEDS_RPM), discretised(plant, LIMIT_SPEEDS_RPM)


def _plant_key(values: dict, sensor_offset_mm: float | None) -> tuple:
    offset = values["sensor_offset_mm"] if sensor_offset_mm is None else sensor_offset_mm
    return (values["beam_theory"], values["modal_damping_percent"] / 100, float(offset), int(values["modes"]),
            in_si(PARAMETERS, values)["sensor_lag_us"])


def plant_of(values: dict, sensor_offset_mm: float | None = None):
    """The plant alone: what the loop at a few speeds needs (no grid discretised)."""
    return _plant(*_plant_key(values, sensor_offset_mm))


def plant_and_grid(values: dict, sensor_offset_mm: float | None = None):
    return _plant_and_grid(*_plant_key(values, sensor_offset_mm))


def compensator(values: dict, sensor_offset_mm: float | None = None, gain_factor: float | None = None):
    """The PID (scaled by the gain factor) on the measurement or the rigid-model filter's estimate,
    the filter always running (its innovation is a scope trace)."""
    model, gain, _, _ = filter_for(values, sensor_offset_mm)
    return observed_compensator(scaled_pid(values, gain_factor), model, gain, values["feedback"] == "estimated")


def loop(values: dict, speeds_rpm=None, sensor_offset_mm: float | None = None, gain_factor: float | None = None):
    """The closed loop at the given speeds (default: the Campbell grid)."""
    comp = compensator(values, sensor_offset_mm, gain_factor)
    if speeds_rpm is None:
        plant, grid, _ = plant_and_grid(values, sensor_offset_mm)
        return closed_loop_at_speed(plant, comp, CAMPBELL_SPEEDS_RPM, discrete=grid)
    return closed_loop_at_speed(plant_of(values, sensor_offset_mm), comp, speeds_rpm)


def unbalance_kg_m(values: dict) -> float:
    """ISO 21940-11's permissible residual unbalance U = m G / Omega_max [kg m] of the whole rotor."""
    return permissible_unbalance_kg_m(rotor_of(values).rotor.total_mass_kg,
                                      BALANCE_GRADES_MM_S[values["balance_grade"]], values["max_service_speed_rpm"])


def midspan_orbit_m(values: dict, closed) -> np.ndarray:
    """Unbalance orbit radius [m] at ``MIDSPAN_M`` per speed of ``closed``: r = phi(z) eta."""
    n = int(values["modes"])
    eta = unbalance_states(closed, unbalance_kg_m(values))[:, :n]
    return np.abs(eta @ rotor_of(values).rotor.displacement(MIDSPAN_M, n)[0])


def sensor_name(offset_mm: float) -> str:
    return "integrated capacitive" if integrated(offset_mm) else "external eddy-current"


# -- linear analysis over speed ----------------------------------------------------------
def largest_stable_gain(values: dict, sensor_offset_mm: float, speeds_rpm=LIMIT_SPEEDS_RPM) -> np.ndarray:
    """Per speed: the largest gain factor on K reached from the smallest one that levitates the
    rotor with every closed-loop pole stable (0 when none is, 4 at the top of the range); the
    closed loop's A is affine in the factor (it scales the compensator's output), A(g) =
    A(0) + g (A(1) - A(0)), so each speed's gains are tried in one stacked eigenvalue call,
    then the edge is bisected to 0.005."""
    key = (tuple(sorted((k, v) for k, v in values.items() if k not in NOT_IN_THE_LOOP)), float(sensor_offset_mm),
           tuple(np.asarray(speeds_rpm, dtype=float)))
    return _largest_stable_gain(key)


#: Parameters that change nothing in the linear loop.
NOT_IN_THE_LOOP = ("speed_rpm", "run_up_rpm_per_s", "shown_mode", "shown_whirl", "seed", "time_scale",
                   "balance_grade", "max_service_speed_rpm", "clearance_um", "gain_factor")


@lru_cache(maxsize=64)
def _largest_stable_gain(key) -> np.ndarray:
    values, offset, speeds = {**dict(key[0]), "gain_factor": 1.0}, key[1], np.array(key[2])
    grid = plant_and_grid(values, offset)[2] if np.array_equal(speeds, LIMIT_SPEEDS_RPM) else None
    plant = plant_and_grid(values, offset)[0]
    at = {g: closed_loop_at_speed(plant, compensator(values, offset, g), speeds, discrete=grid).A for g in (0.0, 1.0)}
    slope = at[1.0] - at[0.0]
    limits = np.zeros(len(speeds))
    def is_stable(k: int, gains) -> np.ndarray:
        stack = at[0.0][k][None] + np.asarray(gains)[:, None, None] * slope[k][None]
        return np.max(np.abs(np.linalg.eigvals(stack)), axis=-1) < 1.0

    for k in range(len(speeds)):
        ok = is_stable(k, GAIN_GRID)
        if not ok.any():
            continue
        first = int(np.argmax(ok))
        beyond = np.flatnonzero(~ok[first:])
        if beyond.size == 0:
            limits[k] = GAIN_GRID[-1]
            continue
        low, high = GAIN_GRID[first + beyond[0] - 1], GAIN_GRID[first + beyond[0]]
        while high - low > 0.005:
            mid = 0.5 * (low + high)
            low, high = (mid, high) if is_stable(k, [mid])[0] else (low, mid)
        limits[k] = low
    return limits


def stability_changes_rpm(values: dict, sensor_offset_mm: float, flags: np.ndarray) -> list[tuple[float, str]]:
    """Speeds [rpm] where the loop at the set gains turns unstable or stable again between two
    Campbell speeds, bisected to 5 rpm: (speed, 'loses' or 'regains')."""
    changes = []
    for k in np.flatnonzero(flags[:-1] != flags[1:]):
        low, high = CAMPBELL_SPEEDS_RPM[k], CAMPBELL_SPEEDS_RPM[k + 1]
        while high - low > 5.0:
            mid = 0.5 * (low + high)
            if stable(loop(values, [mid], sensor_offset_mm))[0] == flags[k]:
                low = mid
            else:
                high = mid
        changes.append((0.5 * (low + high), "regains" if flags[k + 1] else "loses"))
    return changes


def stabilisable_up_to_rpm(values: dict, sensor_offset_mm: float, limits: np.ndarray) -> float | None:
    """The speed [rpm] above which no gain factor keeps the loop stable (``limits``: the largest
    stable gain per ``LIMIT_SPEEDS_RPM``), bisected to 10 rpm where the first stable speed's
    limit first drops to 0; None when some gain is stable at every speed or at none."""
    stable_somewhere = np.flatnonzero(limits > 0)
    if stable_somewhere.size == 0:
        return None
    lost = np.flatnonzero(limits[stable_somewhere[0]:] == 0)
    if lost.size == 0:
        return None
    low, high = LIMIT_SPEEDS_RPM[stable_somewhere[0] + lost[0] - 1], LIMIT_SPEEDS_RPM[stable_somewhere[0] + lost[0]]
    while high - low > 10.0:
        mid = 0.5 * (low + high)
        low, high = (mid, high) if largest_stable_gain(values, sensor_offset_mm, [mid])[0] > 0 else (low, mid)
    return 0.5 * (low + high)


def free_whirl(values: dict) -> np.ndarray:
    """The rotor on its ball bearing (magnetic bearing off), reduced model: (speeds, modes, 2) [Hz]."""
    return rotor_of(values).free_whirl_hz(CAMPBELL_SPEEDS_RPM, int(values["modes"]))


def nearest_speed(speed_rpm: float) -> int:
    return int(np.argmin(np.abs(CAMPBELL_SPEEDS_RPM - speed_rpm)))


def whirl_shape(values: dict) -> tuple[np.ndarray, float]:
    """The shown mode's whirl at the set speed in the closed loop: complex displacement at the 3D
    view's stations (1 at its largest) and its signed frequency [Hz] (+ forward)."""
    n = int(values["modes"])
    closed = loop(values, [values["speed_rpm"]])
    z, vectors = np.linalg.eig(closed.A[0])
    _, p = participation(closed.A[0])
    s = z_to_s(z, RIG.sample_time_s)
    index = whirl_by_mode(s, p[:n] + p[n:2 * n])[int(values["shown_mode"]) - 1,
                                                     int(values["shown_whirl"] == "forward")]
    stations = np.linspace(0.0, GEOMETRY.length_m, WhirlScene.STATIONS)
    shape = rotor_of(values).rotor.displacement(stations, n) @ vectors[:n, index]
    largest = shape[np.argmax(np.abs(shape))]
    return shape / largest, float(s[index].imag / (2 * np.pi))      # largest deflection real, 1 (phase 0)


# -- plots -------------------------------------------------------------------------------
def with_marks(x: np.ndarray, series: list, marks: list[tuple[str, float, float, float, str]]):
    """Series on the grid ``x`` plus vertical marks (label, x, y_low, y_high, colour): each mark's x is
    inserted twice into the shared axis (a vertical segment; NaN elsewhere), the other series
    interpolated there.  Returns the new x and the series."""
    points = sorted([(float(v), -1, 0) for v in x] + [(float(m[1]), k, end) for k, m in enumerate(marks)
                                                      for end in (0, 1)])
    xs = np.array([p[0] for p in points])
    out = [(label, np.interp(xs, x, y), colour) for label, y, colour in series]
    marked: dict[str, tuple[np.ndarray, str]] = {}
    for i, (_, k, end) in enumerate(points):
        if k >= 0:
            label, _, low, high, colour = marks[k]
            marked.setdefault(label, (np.full(len(xs), np.nan), colour))[0][i] = (low, high)[end]
    return xs, out + [(label, y, colour) for label, (y, colour) in marked.items()]


CLAIMS = (
    Claim("ROSS 2.3, same geometry and Timoshenko elements (lab target)",
          "rotor on its ball bearing, 6000 rpm: mode 3 (2nd bending) backward whirl", "263.48 Hz",
          "free_rotor_mode3_backward_6000_rpm_hz", (263.48 * 0.995, 263.48 * 1.005), "Hz",
          note="full finite-element model, eq. 2; ROSS run_modal at 628.3 rad/s, pivot as a 1e12 N/m bearing"),
    Claim("ROSS 2.3, same geometry and Timoshenko elements (lab target)",
          "rotor on its ball bearing, 6000 rpm: mode 3 (2nd bending) forward whirl", "355.61 Hz",
          "free_rotor_mode3_forward_6000_rpm_hz", (355.61 * 0.995, 355.61 * 1.005), "Hz",
          note="the stack's I_p / I_d ≈ 1.9 stiffens the forward whirl and softens the backward one"),
    Claim("paper 000 §I, Fig. 2 (at standstill); lab target at speed",
          "external sensor (+60 mm): share of the speeds 0-12,000 rpm with a stable loop at nominal gains",
          "unstable at standstill", "external_stable_fraction", (None, 0.0), "",
          note="measured feedback; the stack's node of mode 3 stays between bearing and sensor at every speed"),
    Claim("lab target", "integrated (collocated) sensor: lowest largest-stable-gain factor over 0-12,000 rpm",
          "at least the paper's +75 % at standstill", "largest_stable_gain_collocated_min", (1.75, None), "×",
          note="13 speeds, gain bisected to 0.005"),
    Claim("lab target (ISO 21940-11 G 2.5, ISO 14839-2)",
          "G 2.5 unbalance: peak orbit at the bearing over 0-12,000 rpm relative to C_min", "zone A (< 0.3 C_min)",
          "peak_unbalance_over_clearance", (None, 0.3), "",
          note="collocated sensor, U = m G / Ω_max at the stack, Ω_max = 12,000 rpm, C_min = 230 µm"),
    Claim("lab target (consistency)", "speed of the peak unbalance orbit at mid-span over the Campbell diagram's "
          "first critical speed", "1 (the forward whirl meets 1×)", "peak_speed_over_critical_speed", (0.98, 1.02), "",
          note="collocated sensor; peak found on an 81-point grid around the sweep's largest orbit"),
)


class RotorAtSpeed(Exercise):
    name = "rotor_at_speed"
    title = "The flexible rotor at speed"
    worksheet = "rotor_at_speed.md"
    parameters = PARAMETERS
    default_duration_s = 0.3
    claims = CLAIMS
    key_readouts = ("Closed loop at this speed", "Critical speed 1 (forward whirl meets 1× spin)",
                    "Unbalance: peak orbit at the bearing, 0-12,000 rpm", "Unbalance: speed of that peak",
                    "Largest orbit radius at the bearing", "Speed now")
    charts = (
        Chart("Rotor position", "µm", (
            Series("bearing x (x-z plane)", "x_bearing_m", 1e6, "#1f77b4"),
            Series("bearing y (y-z plane)", "y_bearing_m", 1e6, "#ff7f0e"),
            Series("sensor reading x", "sensor_reading_m", 1e6, "#b0b0b0"),
            Series(f"x at mid-span ({MIDSPAN_M * 1e3:.0f} mm)", "x_watched_m", 1e6, "#9467bd"))),
        Chart("Coil current", "A", (Series("coil current i_x", "current_a", 1.0, "#2ca02c"),)),
        Chart("Filter innovation", "µm", (Series("innovation ν_x (rigid model)", "innovation_m", 1e6, "#d62728"),)),
        Chart("Speed", "rpm", (Series("speed n", "speed_rpm", 1.0, "#7f7f7f"),)),
    )

    def model(self, values: dict) -> dict:
        plant, _, _ = plant_and_grid(values)
        r = rotor_of(values)
        n = int(values["modes"])
        return {
            "states": [f"eta_{j + 1} [m·kg^0.5]" for j in range(n)] + [f"eta_{j + 1}' [m·kg^0.5/s]" for j in range(n)]
                      + ["i [A]"] + (["x_d [m]"] if values["sensor_lag_us"] > 0 else []),
            "complex_coordinates": "r = x + i y (x-z plane real, y-z plane imaginary)",
            "A0_real": plant.A0.real.tolist(), "A1_imag": plant.A1.imag.tolist(),
            "polar_inertia_modal": r.polar_modal(n).tolist(),
            "beam_theory": values["beam_theory"],
            "natural_frequencies_hz": r.rotor.natural_frequencies_hz(n).tolist(),
            "unbalance_kg_m": unbalance_kg_m(values),
            "stack_polar_over_diametral_inertia": GEOMETRY.stack_polar_inertia_kg_m2
            / (GEOMETRY.stack_inertia_kg_m2 + GEOMETRY.stack_mass_kg * GEOMETRY.stack_length_m**2 / 12),
        }

    def open_loops(self, values: dict) -> dict:
        """The loop broken at the amplifier input at 0 rpm, where the planes decouple and each is real;
        at speed the loop is complex (its L(jω) has no mirror symmetry) and margins of one plane lose
        their meaning."""
        plant = plant_and_grid(values)[0]
        still = control.c2d(control.ss(plant.A0.real, plant.B.real[:, :1], plant.C.real[[0, 3]], np.zeros((2, 1))),
                            RIG.sample_time_s, "zoh")
        c = compensator(values)
        compensator_system = control.ss(c.A, c.B[:, :2], c.C[:1], c.D[:1, :2], RIG.sample_time_s)
        return {f"bearing PID at 0 rpm, {values['feedback']} x": loop_at_plant_input(still, compensator_system)}

    def pole_categories(self, values: dict) -> dict[str, PoleCategory]:
        return {"open-loop plant": PoleCategory.PLANT, "closed loop": PoleCategory.CLOSED_LOOP}

    def analyse_panel(self, values: dict, panel: str):
        """The Scope: the loop, the free rotor and the unbalance at the set speed; the Pole map: the
        plant's and the closed loop's poles at that speed; the Analysis tab: the sweeps over speed
        (Campbell diagram, critical speeds, unbalance response), then each sensor's stability and
        largest stable gain against speed."""
        if panel == SCOPE:
            return at_set_speed(values)
        if panel == POLE_MAP:
            spin_rad_s = float(np.pi * values["speed_rpm"] / 30)     # Ω = 2π n / 60
            return Analysis([], {"open-loop plant": np.linalg.eigvals(plant_of(values).A(spin_rad_s)),
                                 "closed loop": at_speed_poles(values)}, [])
        return over_speed(values)

    def simulation(self, values: dict) -> RunUpSimulation:
        plant, _, _ = plant_and_grid(values)

        def explain() -> str:
            if stable(loop(values, [values["speed_rpm"]]))[0]:
                return ("The linear loop is stable at the set speed: the unbalance or the noise drove the rotor "
                        "this far (a lower balance grade, or less gain on the noise, helps).")
            return "The loop is unstable at this speed: move the sensor, change the gain or the speed, then reset."
        return RunUpSimulation(plant, compensator(values), values["speed_rpm"], values["run_up_rpm_per_s"],
                               unbalance_kg_m(values), values["disturbance_force_n"],
                               (K_MX * sensor_noise_m(values), K_MI * CURRENT_NOISE_A), seed=int(values["seed"]),
                               clearance_m=in_si(PARAMETERS, values)["clearance_um"],
                               watched_row=rotor_of(values).rotor.displacement(MIDSPAN_M, int(values["modes"]))[0],
                               explain=explain)

    def retune(self, simulation: RunUpSimulation, values: dict) -> RunUpSimulation:
        return self.simulation(values).carry_on_from(simulation)

    def live_readouts(self, trace: dict[str, np.ndarray]) -> list[tuple[str, float, str]]:
        radius = np.hypot(trace["x_bearing_m"], trace["y_bearing_m"])
        return [("Largest orbit radius at the bearing", float(np.max(radius)) * 1e6, "µm"),
                ("RMS filter innovation", float(np.sqrt(np.mean(trace["innovation_m"] ** 2))) * 1e6, "µm"),
                ("Speed now", float(trace["speed_rpm"][-1]), "rpm")]

    def scene(self, values: dict) -> WhirlScene:
        return WhirlScene(rotor_of(values).rotor, values, integrated, whirl_shape)

    def report_figures(self, values: dict) -> list:
        """The Campbell diagram, damping against speed for both sensors and the unbalance response."""
        from lab_modules.exercises._figures import plot_figure
        result = None
        for result in self.analyse(values):
            pass
        return [plot_figure(plot) for plot in result.plots]

    def metrics(self, values: dict, duration_s: float) -> dict:
        n = int(values["modes"])
        rotor = rotor_of(values).rotor
        full = {rpm: whirl_frequencies_hz(rotor, rpm) for rpm in (0.0, 3000.0, 6000.0)}
        sensors = {name: sweep(loop(values, sensor_offset_mm=o)) for name, o in SENSORS.items()}
        collocated, external = sensors.values()
        limit_collocated, limit_external = (largest_stable_gain(values, o) for o in SENSORS.values())
        criticals = {name: sorted(c for j in range(n)
                                  for c in critical_speeds_rpm(CAMPBELL_SPEEDS_RPM, sw.whirl_hz[:, j, 1]))
                     for name, sw in sensors.items()}
        closed = loop(values)
        response = unbalance_response(closed, unbalance_kg_m(values))
        bearing = np.abs(response[:, LOOP_OUTPUTS.index("r_bearing_m")])
        peak = int(np.argmax(bearing))
        midspan = midspan_orbit_m(values, closed)
        at = int(np.argmax(midspan))
        fine = np.linspace(CAMPBELL_SPEEDS_RPM[max(at - 1, 0)], CAMPBELL_SPEEDS_RPM[min(at + 1, len(midspan) - 1)], 81)
        fine_peak = int(np.argmax(midspan_orbit_m(values, loop(values, fine))))
        set_criticals = sorted(c for j in range(n) for c in critical_speeds_rpm(
            CAMPBELL_SPEEDS_RPM, sweep(closed).whirl_hz[:, j, 1]))
        sim = self.simulation(values)
        trace = sim.advance(round(duration_s / RIG.sample_time_s))
        clearance = in_si(PARAMETERS, values)["clearance_um"]
        return {
            "speeds_rpm": CAMPBELL_SPEEDS_RPM.tolist(),
            "beam_theory": values["beam_theory"],
            "free_rotor_whirl_hz": {f"{rpm:.0f}": {"backward": b.tolist(), "forward": f.tolist()}
                                    for rpm, (b, f) in full.items()},
            "free_rotor_mode3_backward_6000_rpm_hz": float(full[6000.0][0][1]),
            "free_rotor_mode3_forward_6000_rpm_hz": float(full[6000.0][1][1]),
            "closed_loop_whirl_hz": {name: {"backward": sw.whirl_hz[:, :, 0].tolist(),
                                            "forward": sw.whirl_hz[:, :, 1].tolist()} for name, sw in sensors.items()},
            "closed_loop_damping": {name: {"backward": sw.damping[:, :, 0].tolist(),
                                           "forward": sw.damping[:, :, 1].tolist()} for name, sw in sensors.items()},
            "critical_speeds_rpm": criticals,
            "collocated_stable_fraction": float(np.mean(collocated.stable)),
            "external_stable_fraction": float(np.mean(external.stable)),
            "external_stability_changes_rpm": stability_changes_rpm(values, EXTERNAL_OFFSET_MM, external.stable),
            "stability_limit_speeds_rpm": LIMIT_SPEEDS_RPM.tolist(),
            "largest_stable_gain_collocated": limit_collocated.tolist(),
            "largest_stable_gain_external": limit_external.tolist(),
            "largest_stable_gain_collocated_min": float(np.min(limit_collocated)),
            "largest_stable_gain_external_max": float(np.max(limit_external)),
            "external_stabilisable_up_to_rpm": stabilisable_up_to_rpm(values, EXTERNAL_OFFSET_MM, limit_external),
            "unbalance_kg_m": unbalance_kg_m(values),
            "peak_unbalance_bearing_um": float(bearing[peak] * 1e6),
            "peak_unbalance_sensor_um": float(np.max(np.abs(response[:, LOOP_OUTPUTS.index("r_sensor_m")])) * 1e6),
            "peak_unbalance_current_a": float(np.max(np.abs(response[:, LOOP_OUTPUTS.index("current_a")]))),
            "peak_unbalance_speed_rpm": float(CAMPBELL_SPEEDS_RPM[peak]),
            "peak_unbalance_midspan_um": float(np.max(midspan) * 1e6),
            "peak_unbalance_midspan_speed_rpm": float(fine[fine_peak]),
            "peak_unbalance_zone": iso_14839_2_zone(bearing[peak], clearance),
            "peak_unbalance_over_clearance": float(bearing[peak] / clearance),
            "innovation_at_peak_um": float(np.abs(response[at, LOOP_OUTPUTS.index("innovation_m")]) * 1e6),
            "innovation_at_half_peak_speed_um": float(np.abs(response[at // 2, LOOP_OUTPUTS.index("innovation_m")])
                                                      * 1e6),
            "first_critical_speed_rpm": set_criticals[0] if set_criticals else float("nan"),
            "peak_speed_over_critical_speed": float(fine[fine_peak] / set_criticals[0]) if set_criticals
            else float("nan"),
            "run_status": sim.status_message() or "ok",
            "run_largest_orbit_um": float(np.max(np.hypot(trace[:, 1], trace[:, 2]))) * 1e6 if len(trace)
            else float("nan"),
            "duration_s": len(trace) * RIG.sample_time_s,
        }


def at_set_speed(values: dict) -> Analysis:
    """The readouts at the set speed: the closed loop's whirls, the rotor on its ball bearing at
    the nearest Campbell speed, the unbalance's force, orbits, current and ISO 14839-2 zone."""
    n = int(values["modes"])
    speed = values["speed_rpm"]
    here = nearest_speed(speed)
    at_speed_loop = loop(values, [speed])
    at_speed = sweep(at_speed_loop)
    free = rotor_of(values).free_whirl_hz(CAMPBELL_SPEEDS_RPM[here:here + 1], n)[0]
    response_here = unbalance_response(at_speed_loop, unbalance_kg_m(values))[0]
    bearing_here = abs(response_here[LOOP_OUTPUTS.index("r_bearing_m")])
    offset = values["sensor_offset_mm"]
    readouts = [("Speed n", speed, "rpm"), ("Spin frequency n / 60", speed / 60, "Hz"),
                ("Closed loop at this speed", "stable" if at_speed.stable[0] else "unstable", "")]
    for j in range(min(n, 3)):
        for d, direction in ((0, "backward"), (1, "forward")):
            whirl = f"Closed loop at this speed: mode {j + 1} {direction} whirl"
            readouts += [(f"{whirl}, frequency", at_speed.whirl_hz[0, j, d], "Hz"),
                         (f"{whirl}, damping ratio", 100 * at_speed.damping[0, j, d], "%")]
    for j in range(1, min(n, 3)):
        for d, direction in ((0, "backward"), (1, "forward")):
            label = f"Rotor on its ball bearing at {CAMPBELL_SPEEDS_RPM[here]:.0f} rpm: mode {j + 1} {direction} whirl"
            readouts.append((label, (-1, 1)[d] * free[j, d], "Hz"))
    readouts += [
        (f"Unbalance: U ({values['balance_grade']})", unbalance_kg_m(values) * 1e6, "g·mm"),
        ("Unbalance: force at this speed", unbalance_kg_m(values) * float(np.pi * speed / 30) ** 2, "N"),
        ("Unbalance: orbit at the bearing, this speed", bearing_here * 1e6, "µm"),
        ("Unbalance: orbit at the sensor, this speed", abs(response_here[LOOP_OUTPUTS.index("r_sensor_m")]) * 1e6, "µm"),
        ("Unbalance: control current amplitude, this speed", abs(response_here[LOOP_OUTPUTS.index("current_a")]), "A"),
        ("Unbalance: ISO 14839-2 at this speed",
         f"zone {iso_14839_2_zone(bearing_here, in_si(PARAMETERS, values)['clearance_um'])}", ""),
    ]
    notes = [(f"Sensor: {sensor_name(offset)} at {offset:+.0f} mm from the bearing plane; feedback: "
              f"{values['feedback']} position. Complex coordinates r = x + i y: a pole with Im s > 0 whirls "
              "forward (with the spin), Im s < 0 backward."),
             ("The pole map shows the closed loop at the set speed (one pole per whirl: the two planes "
              "together, not conjugate pairs).")]
    if not at_speed.stable[0]:
        j, d = np.unravel_index(np.argmin(at_speed.damping[0]), at_speed.damping[0].shape)
        notes.insert(0, f"Unstable at {speed:.0f} rpm: mode {j + 1}'s {('backward', 'forward')[d]} whirl "
                        f"grows at {at_speed.whirl_hz[0, j, d]:.0f} Hz.")
    return Analysis(readouts, {}, notes)


def over_speed(values: dict):
    """The Analysis tab: the Campbell diagram, the critical speeds and the unbalance response over
    0-12,000 rpm first, then each sensor's stability at these gains and its largest stable gain
    factor against speed (``largest_stable_gain``: the costly part, cached per loop)."""
    n = int(values["modes"])
    offset = values["sensor_offset_mm"]
    clearance = in_si(PARAMETERS, values)["clearance_um"]
    closed = loop(values)
    swept = sweep(closed)
    free = free_whirl(values)
    criticals = sorted(c for j in range(n) for c in critical_speeds_rpm(CAMPBELL_SPEEDS_RPM, swept.whirl_hz[:, j, 1]))
    response = unbalance_response(closed, unbalance_kg_m(values))
    peak = int(np.argmax(np.abs(response[:, LOOP_OUTPUTS.index("r_bearing_m")])))
    peak_m = abs(response[peak, LOOP_OUTPUTS.index("r_bearing_m")])
    midspan = midspan_orbit_m(values, closed)
    readouts = ([(f"Critical speed {k + 1} (forward whirl meets 1× spin)", c, "rpm") for k, c in enumerate(criticals)]
                or [("Critical speeds below 12,000 rpm", "none", "")])
    readouts += [("Unbalance: peak orbit at the bearing, 0-12,000 rpm", peak_m * 1e6, "µm"),
                 ("Unbalance: speed of that peak", CAMPBELL_SPEEDS_RPM[peak], "rpm"),
                 ("Unbalance: ISO 14839-2 at that peak", f"zone {iso_14839_2_zone(peak_m, clearance)}", ""),
                 (f"Unbalance: peak orbit at mid-span, {MIDSPAN_M * 1e3:.0f} mm along the shaft",
                  np.max(midspan) * 1e6, "µm"),
                 ("Unbalance: speed of the mid-span peak", CAMPBELL_SPEEDS_RPM[np.argmax(midspan)], "rpm")]
    plots = [campbell_plot(values, free, swept, criticals)]
    yield Analysis(readouts + [("Stability limits against speed", "computing …", "")], {}, [],
                   plots + [unbalance_plot(values, response, midspan)])
    sensors = {name: sweep(loop(values, sensor_offset_mm=o)) if o != offset else swept for name, o in SENSORS.items()}
    limits = {name: largest_stable_gain(values, o) for name, o in SENSORS.items()}
    notes = []
    for name, o in SENSORS.items():
        changes = stability_changes_rpm(values, o, sensors[name].stable)
        verdict = ("stable over the whole range" if sensors[name].stable.all() else
                   "unstable over the whole range" if not sensors[name].stable.any() else
                   "; ".join(f"{what} stability at {rpm:.0f} rpm" for rpm, what in changes))
        up_to = stabilisable_up_to_rpm(values, o, limits[name])
        notes.append(f"{name.capitalize()} sensor at these gains: {verdict}." + (
            "" if up_to is None else f" A lower gain keeps it stable up to {up_to:.0f} rpm, none above."))
        readouts.append((f"{name.capitalize()}: largest stable gain factor, lowest over speed",
                         float(np.min(limits[name])), "×"))
    plots += [damping_plot(name, sensors[name]) for name in SENSORS]
    plots += [limit_plot(limits), unbalance_plot(values, response, midspan)]
    yield Analysis(readouts, {}, notes, plots)


def at_speed_poles(values: dict) -> np.ndarray:
    return z_to_s(np.linalg.eigvals(loop(values, [values["speed_rpm"]]).A[0]), RIG.sample_time_s)


def campbell_plot(values: dict, free: np.ndarray, swept, criticals: list[float]) -> Plot:
    """Whirl frequencies against speed: the rotor on its ball bearing (bending modes) and the closed
    loop (every mode), the 1x line, the critical speeds and the set speed as vertical marks."""
    n = int(values["modes"])
    shown = min(n, 4)
    series = [("1× (spin frequency)", CAMPBELL_SPEEDS_RPM / 60, "#000000")]
    for j in range(shown):
        series.append((f"mode {j + 1} forward", swept.whirl_hz[:, j, 1], MODE_COLOURS[j]))
        series.append((f"mode {j + 1} backward", swept.whirl_hz[:, j, 0], BACKWARD_COLOURS[j]))
    for j in range(1, shown):
        series.append((f"mode {j + 1} forward, bearing off", free[:, j, 1], "#7f7f7f"))
        series.append((f"mode {j + 1} backward, bearing off", -free[:, j, 0], "#c7c7c7"))
    top = float(np.nanmax(swept.whirl_hz[:, :shown])) * 1.05
    marks = [("set speed n (cursor)", values["speed_rpm"], 0.0, top, SET_SPEED_COLOUR)]
    marks += [("critical speeds (forward whirl meets 1×)", c, 0.0, top, "#e6550d") for c in criticals]
    x, out = with_marks(CAMPBELL_SPEEDS_RPM, series, marks)
    x = x / 1000
    return Plot(f"Campbell diagram ({values['beam_theory']}; closed loop with the {sensor_name(values['sensor_offset_mm'])}"
                " sensor)", SPEED_AXIS, "whirl frequency [Hz]", x, tuple(out))


def damping_plot(name: str, swept) -> Plot:
    n = swept.poles_s.shape[1]
    shown = min(n, 4)
    series = []
    for j in range(shown):
        series.append((f"mode {j + 1} forward", 100 * swept.damping[:, j, 1], MODE_COLOURS[j]))
        series.append((f"mode {j + 1} backward", 100 * swept.damping[:, j, 0], BACKWARD_COLOURS[j]))
    return Plot(f"Closed-loop damping against speed, {name} sensor", SPEED_AXIS, "damping ζ [%]",
                swept.speeds_rpm / 1000, tuple(series))


def limit_plot(limits: dict) -> Plot:
    colours = ("#1f77b4", "#d62728")
    return Plot("Stability limit against speed: largest stable gain factor", SPEED_AXIS, "gain factor [×]",
                LIMIT_SPEEDS_RPM / 1000, tuple((name, limits[name], colour) for name, colour in zip(SENSORS, colours))
                + (("nominal gains", np.ones(len(LIMIT_SPEEDS_RPM)), "#7f7f7f"),))


def unbalance_plot(values: dict, response: np.ndarray, midspan_m: np.ndarray) -> Plot:
    """Unbalance orbit radius at the bearing, the sensor and mid-span with ISO 14839-2's zone limits."""
    clearance_um = values["clearance_um"]
    series = [(f"rotor at mid-span ({MIDSPAN_M * 1e3:.0f} mm)", midspan_m * 1e6, "#9467bd"), ("rotor at the bearing", np.abs(response[:, LOOP_OUTPUTS.index("r_bearing_m")]) * 1e6, "#1f77b4"),
              ("rotor at the sensor", np.abs(response[:, LOOP_OUTPUTS.index("r_sensor_m")]) * 1e6, "#ff7f0e"),
              ("control current (1 A drawn as 10 µm)", np.abs(response[:, LOOP_OUTPUTS.index("current_a")]) * 10,
               "#2ca02c"),
              ("filter innovation ν", np.abs(response[:, LOOP_OUTPUTS.index("innovation_m")]) * 1e6, "#d62728")]
    colours = {"A": "#31a354", "B": "#fdae6b", "C": "#e6550d"}
    series += [(f"zone {zone}/{chr(ord(zone) + 1)} limit {limit:.1f} C_min", np.full(len(CAMPBELL_SPEEDS_RPM),
                                                                                  limit * clearance_um), colours[zone])
               for zone, limit in ISO_14839_2_LIMITS]
    return Plot(f"Unbalance response ({values['balance_grade']}, U at the stack) and ISO 14839-2 zones",
                SPEED_AXIS, "orbit radius [µm]", CAMPBELL_SPEEDS_RPM / 1000, tuple(series), log_y=True,
                log_decades=4)




EXERCISE = RotorAtSpeed()
