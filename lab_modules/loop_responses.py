"""Step and frequency responses of the closed bearing-axis loop (``analysis.closed_loop``): the
compiled step recursions, one channel's frequency gain and its peak over frequency (the trade-off
sweeps and the stiffness figures of ``loops.radial_axis_step_tests`` need hundreds of them)."""

from __future__ import annotations

import numba
import numpy as np
import scipy.optimize

from lab_modules.analysis import LOOP_INPUTS, LOOP_OUTPUTS, Loop


@numba.njit(cache=True, nogil=True)
def _unit_step_outputs(A, b, C, d, n_samples):
    """Outputs y_k = C x_k + d of x_{k+1} = A x_k + b, x_0 = 0 (a unit step at k = 0)."""
    n, n_out = A.shape[0], C.shape[0]
    x, work = np.zeros(n), np.zeros(n)
    y = np.empty((n_samples, n_out))
    for k in range(n_samples):
        for r in range(n_out):
            acc = d[r]
            for c in range(n):
                acc += C[r, c] * x[c]
            y[k, r] = acc
        for r in range(n):
            acc = b[r]
            for c in range(n):
                acc += A[r, c] * x[c]
            work[r] = acc
        x[:] = work
    return y


@numba.njit(cache=True, nogil=True)
def _unit_step_outputs_of_two(A, B, C, D, n_samples):
    """``_unit_step_outputs`` for the two columns of B (n, 2) and D (n_out, 2) at once, each
    sum in the same order, so each response is the same to the last bit: rows (k) of
    y[j, k] = C x_jk + D[:, j].  Two rows of A times two state vectors per pass over the
    columns: four independent sums side by side, where one after another waits on each addition."""
    n, n_out = A.shape[0], C.shape[0]
    x, work = np.zeros((2, n)), np.zeros((2, n))
    y = np.empty((2, n_samples, n_out))
    for k in range(n_samples):
        for r in range(n_out):
            first, second = D[r, 0], D[r, 1]
            for c in range(n):
                first += C[r, c] * x[0, c]
                second += C[r, c] * x[1, c]
            y[0, k, r], y[1, k, r] = first, second
        r = 0
        while r < n:
            if r + 1 < n:                       # rows r and r + 1
                first_r, first_next, second_r, second_next = B[r, 0], B[r + 1, 0], B[r, 1], B[r + 1, 1]
                for c in range(n):
                    first_r += A[r, c] * x[0, c]
                    first_next += A[r + 1, c] * x[0, c]
                    second_r += A[r, c] * x[1, c]
                    second_next += A[r + 1, c] * x[1, c]
                work[0, r], work[0, r + 1], work[1, r], work[1, r + 1] = first_r, first_next, second_r, second_next
                r += 2
            else:                               # the last row of an odd n
                first_r, second_r = B[r, 0], B[r, 1]
                for c in range(n):
                    first_r += A[r, c] * x[0, c]
                    second_r += A[r, c] * x[1, c]
                work[0, r], work[1, r] = first_r, second_r
                r += 1
        x[:, :] = work
    return y


def step_response(loop: Loop, input_name: str, n_samples: int) -> np.ndarray:
    """Response of every loop output (``LOOP_OUTPUTS``, columns) to a unit step
    on one input at sample 0, from rest: rows k = 0 ... n_samples - 1 (what
    python-control's ``step_response`` returns, compiled: the trade-off sweeps
    need hundreds of them)."""
    sys = loop.system
    j = LOOP_INPUTS.index(input_name)
    A, B, C, D = (np.ascontiguousarray(np.asarray(M, dtype=float)) for M in (sys.A, sys.B, sys.C, sys.D))
    return _unit_step_outputs(A, np.ascontiguousarray(B[:, j]), C, np.ascontiguousarray(D[:, j]), n_samples)


def step_responses(loop: Loop, input_names: tuple[str, str], n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """``step_response`` to each of two inputs, the same to the last bit, in one compiled pass
    (two thirds of the time of two: ``linear_figures`` wants the force and the reference step)."""
    sys = loop.system
    columns = [LOOP_INPUTS.index(name) for name in input_names]
    A, B, C, D = (np.ascontiguousarray(np.asarray(M, dtype=float)) for M in (sys.A, sys.B, sys.C, sys.D))
    y = _unit_step_outputs_of_two(A, np.ascontiguousarray(B[:, columns]), C, np.ascontiguousarray(D[:, columns]),
                                  n_samples)
    return y[0], y[1]


def frequency_gain(loop: Loop, input_name: str, output_name: str, frequencies_hz) -> np.ndarray:
    """|G(exp(j 2 pi f T))| of one input-output channel (as python-control's
    ``frequency_response``, by one batched solve of (zI - A) x = b)."""
    return _channel_gain(loop, input_name, output_name)(frequencies_hz)


def _channel_gain(loop: Loop, input_name: str, output_name: str):
    """``frequency_gain`` of one channel as a function of the frequencies [Hz]: the matrices are
    read once for the many single-frequency calls of ``peak_gain``'s search."""
    sys = loop.system
    j, i = LOOP_INPUTS.index(input_name), LOOP_OUTPUTS.index(output_name)
    A, B, C, D = (np.asarray(M, dtype=float) for M in (sys.A, sys.B, sys.C, sys.D))
    n = A.shape[0]
    identity, b, c, d = np.eye(n), B[:, j], C[i], D[i, j]

    def gain(frequencies_hz) -> np.ndarray:
        z = np.exp(2j * np.pi * np.asarray(frequencies_hz, dtype=float) * sys.dt)
        x = np.linalg.solve(z[:, None, None] * identity - A, np.broadcast_to(b, (z.size, n))[..., None])
        return np.abs(x[..., 0] @ c + d)
    return gain


def peak_gain(loop: Loop, input_name: str, output_name: str, lowest_hz: float = 0.5,
              points: int = 200) -> tuple[float, float]:
    """Largest |G| of one channel between ``lowest_hz`` and the Nyquist
    frequency, and where it occurs [Hz]: a log-spaced grid, then a bounded
    search between the grid neighbours of the largest value."""
    channel_gain = _channel_gain(loop, input_name, output_name)
    f = np.geomspace(lowest_hz, 0.5 / loop.system.dt, points)
    gain = channel_gain(f)
    k = int(np.argmax(gain))
    bounds = np.log(f[max(k - 1, 0)]), np.log(f[min(k + 1, f.size - 1)])
    found = scipy.optimize.minimize_scalar(
        lambda log_f: -channel_gain([np.exp(log_f)])[0],
        bounds=bounds, method="bounded", options={"xatol": 1e-5})
    if -found.fun > gain[k]:
        return float(-found.fun), float(np.exp(found.x))
    return float(gain[k]), float(f[k])
