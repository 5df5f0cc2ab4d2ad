"""thrust_liftoff's honest labels: why the two noise-free lift-offs differ (paper 003 §3.2,
"basically the same"), and how well a median over seeds is known.

Without noise the filter's estimate would equal the state (separation principle) but for two
things the filter does not know: its Taylor model (eq. 9-11) against the plant's exact ZOH
matrices, and the touchdown bearing's stop, which holds the collar at X0 = −0.75 mm while the
current builds up and the filter's model lets it move.  Each is switched off in turn: the
filter on the exact matrices, and the stop moved out of reach (the collar starts free at X0).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lab_modules.loops.thrust_liftoff_loop import ThrustSetup, ThrustSimulation

FAR_CLEARANCE_M = 1.0      # a touchdown bearing the collar never reaches: "off the stop"


def liftoff_difference_m(setup: ThrustSetup, duration_s: float) -> float:
    """Largest |x_measured-feedback − x_estimated-feedback| [m] of the two noise-free lift-offs."""
    runs = [ThrustSimulation(replace(setup, use_estimate=estimate, noise_on=False)).run(duration_s)["x_true_m"]
            for estimate in (False, True)]
    n = min(len(r) for r in runs)
    return float(np.max(np.abs(runs[0][:n] - runs[1][:n]))) if n else float("nan")


def liftoff_gap_evidence(setup: ThrustSetup, duration_s: float) -> dict:
    """The gap between the two noise-free lift-offs [µm] with the Taylor or the exact filter
    model, on the touchdown stop (as the paper starts) and off it."""
    off_stop = replace(setup.bearing, touchdown_clearance_m=FAR_CLEARANCE_M)
    result = {}
    for model, exact in (("taylor", False), ("exact", True)):
        for place, bearing in (("on_stop", setup.bearing), ("off_stop", off_stop)):
            changed = replace(setup, filter_exact_model=exact, bearing=bearing)
            result[f"{model}_filter_{place}_um"] = liftoff_difference_m(changed, duration_s) * 1e6
    return result


def median_standard_error(samples) -> float:
    """Standard error of the median of ``samples`` for a near-normal spread: √(π/2) s/√n
    (1.25 times the mean's; s the sample standard deviation).  NaN below two samples."""
    samples = np.asarray(samples, dtype=float)
    if samples.size < 2:
        return float("nan")
    return float(np.sqrt(np.pi / 2) * np.std(samples, ddof=1) / np.sqrt(samples.size))
