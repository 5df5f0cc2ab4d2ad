"""Several loops of the bearing axis on one scope: simulations that run in lockstep on the same noise.

Two ``AxisSimulation`` seeded alike draw identical noise while they advance alike, so the
loops differ only by their controllers (paper 000, §IV: the LQG against the PID, Figs. 8-9).
"""

from __future__ import annotations

import numpy as np

from lab_modules.loops.radial_axis_experiment import AxisSetup, AxisSimulation
from lab_modules.loops.radial_axis_loop import OK, TRACE_COLUMNS

#: The columns of each loop on the scope (suffixed ``_<loop name in lower case>``).
SCOPE_COLUMNS = ("x_true_m", "x_estimated_m", "current_a")


class SideBySide:
    """The loops' simulations advanced together: rows (t [s], reference [m], disturbance [N],
    then ``SCOPE_COLUMNS`` of each loop in order).  The filter inspector shows the first
    loop's Kalman filter."""

    def __init__(self, simulations: dict[str, AxisSimulation]):
        self.simulations = simulations
        first = next(iter(simulations.values()))
        self.sample_time_s = first.setup.rig.sample_time_s
        self.columns = ("reference_m", "disturbance_n") + tuple(
            f"{c}_{name.lower()}" for name in simulations for c in SCOPE_COLUMNS)

    @classmethod
    def seeded(cls, loops: dict[str, AxisSetup], seed: int) -> SideBySide:
        """One simulation per loop, all with the same seed (identical noise)."""
        return cls({name: AxisSimulation(axis, seed=seed) for name, axis in loops.items()})

    def advance(self, n_steps: int) -> np.ndarray:
        first = next(iter(self.simulations.values()))
        reference, disturbance = first.inputs(max(n_steps, 0))
        traces = [sim.advance(n_steps) for sim in self.simulations.values()]
        rows = min(len(trace) for trace in traces)
        parts = [traces[0][:rows, :1], reference[:rows, None], disturbance[:rows, None]]
        parts += [trace[:rows, [1 + TRACE_COLUMNS.index(c) for c in SCOPE_COLUMNS]] for trace in traces]
        return np.hstack(parts)

    def filter_state(self) -> dict | None:
        """The first loop's Kalman filter, titled with the loop's name."""
        name, simulation = next(iter(self.simulations.items()))
        state = simulation.filter_state()
        return state and {**state, "title": f"{name} loop: {state['title']}"}

    def filter_tape(self):
        """The first loop's filter record (the one the inspector shows)."""
        return next(iter(self.simulations.values())).filter_tape()

    def status_message(self) -> str:
        return " ".join(f"{name} loop: {sim.status_message()}"
                        for name, sim in self.simulations.items() if sim.status != OK)

    def retuned(self, loops: dict[str, AxisSetup]) -> SideBySide:
        return SideBySide({name: sim.retuned(loops[name]) for name, sim in self.simulations.items()})
