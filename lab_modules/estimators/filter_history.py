"""A Kalman filter's history, replayed from a bounded record of its inputs, and its branches.

The compiled loops run their filters thousands of times a second and keep nothing of them.  A
simulation that offers a filter debugger records, per ``advance``, only what the filter read: the
prior (x̂⁻, P⁻) of the first sample of the chunk, and per sample the input u, the measurement y
and the plant's true state.  ``FilterTape`` keeps the newest ``capacity`` samples of that (whole
chunks: at most ``capacity`` + one chunk).  ``FilterTape.history`` replays the filter over them
in numpy (the batch correction ``kalman.correction``), giving every sample's

    x̂⁻ = Φ x̂⁺ + Γ u,            P⁻ = Φ P⁺ Φᵀ + Q                       (eq. 2, prediction)
    S = H P⁻ Hᵀ + R,             K = P⁻ Hᵀ S⁻¹,       ν = y − H x̂⁻
    x̂⁺ = x̂⁻ + K ν,               P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ   (eq. 2, correction; Joseph form)

A filter whose prediction is not one fixed (Φ, Γ) - an extended Kalman filter linearised about
its own estimate, a filter whose matrices are scheduled on its operating point, a
continuous-discrete filter that integrates P between samples - hands the model its own
prediction (``FilterModel.propagation``, the filter's compiled kernel): the replay calls it on
each replayed x̂⁺ and u, so the history keeps every sample's Φ_k and Q_k (the Jacobian or the
scheduled matrices, NaN for an integrated P) and a branch re-linearises (re-schedules) about its
own estimates.  The measurement is linear (H constant) in every filter of the lab.

Why the tape holds no Φ_k: Φ_k is a function of what the tape holds (x̂⁺_k is replayed from the
recorded prior, u_k and y_k), so recording it would add n² numbers per sample (200 B at five
states) and say nothing new.  The tape is u, y and the true state per sample, (p + m + n) · 8 B
plus the time, and a prior per chunk: 64 B per sample for the bearing axis's four states and two
measurements, 72 B for the EKFs' five, 48 B for the maglev ball; at most 4000 + one chunk of
samples, under 400 kB per tab (``tests/test_filter_history_exercises.py`` measures it).  Per
sample that is less than one row of the same exercise's scope (72 - 330 B: time and every column),
but the tape keeps 4000 samples where the scope keeps its window.

The replay equals the compiled loop's filter up to rounding (the loop corrects one scalar
measurement at a time, which is the same correction).  ``branch`` reruns the filter from one
sample with another Q or R on the same recorded inputs and measurements: the controller's
inputs and the plant stay as recorded (it asks "what would this filter have estimated?"); with
the same Q and R it reproduces the history bit for bit.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from lab_modules.estimators.kalman import KalmanFilter, correction

#: Samples a tape keeps by default (0.2 s of the bearing axis at 50 µs).
CAPACITY = 4000

#: A filter's own prediction: (x̂⁺ (n,), P⁺ (n, n), u (p,), q_scale, dt [s]) -> (x̂⁻, P⁻, Φ_k, Q_k)
#: with Q_k already scaled; Φ_k and Q_k None when P⁻ is integrated (no one transition matrix).
Propagation = Callable[[np.ndarray, np.ndarray, np.ndarray, float, float], tuple]
LINEAR_PREDICTION = (r"\Phi\hat{x}^+_{k-1} + \Gamma u_{k-1}", r"\Phi P^+_{k-1}\Phi^T + Q")


@dataclass(frozen=True)
class FilterModel:
    """What a Kalman filter knows (eq. 1, 2), in the model's SI units.

    ``Phi`` (n, n) and ``Gamma`` (n, p) the discrete model, ``H`` (m, n) the measurement matrix,
    ``Q`` (n, n) the process-noise covariance per sample, ``R`` (m, m) the measurement-noise
    covariance; ``states`` and ``measurements`` are (label, SI unit) per row.  With a
    ``propagation`` (the module's docstring) the prediction is the filter's own: ``Phi`` and
    ``Gamma`` are then NaN, ``Q`` is the filter's nominal one (for the printout) and
    ``q_scale`` the factor a branch puts on it; ``prediction`` is the LaTeX of x̂⁻ and P⁻."""

    title: str
    sample_time_s: float
    Phi: np.ndarray
    Gamma: np.ndarray
    H: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    states: tuple[tuple[str, str], ...]
    measurements: tuple[tuple[str, str], ...]
    propagation: Propagation | None = None
    q_scale: float = 1.0
    prediction: tuple[str, str] = LINEAR_PREDICTION

    @classmethod
    def of(cls, title, sample_time_s, Phi, Gamma, H, Q, R, states, measurements) -> FilterModel:
        """A model from array-likes (Γ a column for one input, R a diagonal as a vector allowed)."""
        Phi = np.atleast_2d(np.asarray(Phi, dtype=float))
        n = Phi.shape[0]
        Gamma = np.asarray(Gamma, dtype=float).reshape(n, -1)
        R = np.asarray(R, dtype=float)
        R = np.diag(R) if R.ndim == 1 else np.atleast_2d(R)
        return cls(title, float(sample_time_s), Phi, Gamma, np.atleast_2d(np.asarray(H, dtype=float)),
                   np.atleast_2d(np.asarray(Q, dtype=float)), R, tuple(states), tuple(measurements))

    @classmethod
    def of_filter(cls, kalman_filter: KalmanFilter, title, sample_time_s, states, measurements) -> FilterModel:
        """The model of a ``kalman.KalmanFilter`` (its padded arrays cut to its states)."""
        n = kalman_filter.dim_x
        return cls.of(title, sample_time_s, kalman_filter.A[:n, :n], kalman_filter.B[:n], kalman_filter.C[:, :n],
                      kalman_filter.Q[:n, :n], kalman_filter.R_diag, states, measurements)

    @classmethod
    def propagated(cls, title, sample_time_s, inputs: int, H, Q, R, states, measurements,
                   propagation: Propagation, prediction: tuple[str, str]) -> FilterModel:
        """A model that predicts with the filter's own ``propagation`` (``inputs``: p)."""
        n = len(states)
        model = cls.of(title, sample_time_s, np.full((n, n), np.nan), np.full((n, inputs), np.nan), H, Q, R,
                       states, measurements)
        return replace(model, propagation=propagation, prediction=prediction)

    def scaled(self, q_scale: float = 1.0, r_scale: float = 1.0) -> FilterModel:
        """The model with Q and R multiplied by these factors (the branch's tuning)."""
        return replace(self, Q=self.Q * q_scale, R=self.R * r_scale, q_scale=self.q_scale * q_scale)


def predict(model: FilterModel, x_post, P_post, u, dt: float | None = None) -> tuple:
    """Eq. 2, prediction: x̂⁻ = Φ x̂⁺ + Γ u, P⁻ = Φ P⁺ Φᵀ + Q, or the model's own ``propagation``
    over ``dt`` [s] (None: the sample time); P⁻ made exactly symmetric.  Returns (x̂⁻, P⁻, Φ_k, Q_k)."""
    if model.propagation is not None:
        x, P, Phi, Q = model.propagation(np.array(x_post, dtype=float), np.array(P_post, dtype=float),
                                         np.asarray(u, dtype=float), model.q_scale,
                                         model.sample_time_s if dt is None else float(dt))
        return x, 0.5 * (P + P.T), Phi, Q
    P = model.Phi @ P_post @ model.Phi.T + model.Q           # P⁻ = Φ P⁺ Φᵀ + Q
    return model.Phi @ x_post + model.Gamma @ u, 0.5 * (P + P.T), model.Phi, model.Q


@dataclass(frozen=True)
class FilterHistory:
    """Every sample of a replayed filter, oldest first (N samples, n states, m measurements, p inputs).

    ``first_sample`` is the simulation's sample number of row 0; ``truth`` has NaN for states the
    simulation does not know (a sensor's internal state)."""

    model: FilterModel
    first_sample: int
    time_s: np.ndarray        # (N,) [s]
    u: np.ndarray             # (N, p) input applied after the sample's correction
    y: np.ndarray             # (N, m) measurement
    truth: np.ndarray         # (N, n) the plant's true state
    x_prior: np.ndarray       # (N, n) x̂⁻
    P_prior: np.ndarray       # (N, n, n) P⁻
    K: np.ndarray             # (N, n, m) K = P⁻ Hᵀ S⁻¹
    innovation: np.ndarray    # (N, m) ν = y − H x̂⁻
    S: np.ndarray             # (N, m, m) S = H P⁻ Hᵀ + R
    x_post: np.ndarray        # (N, n) x̂⁺
    P_post: np.ndarray        # (N, n, n) P⁺
    Phi: np.ndarray           # (N, n, n) Φ_k that predicts the next sample's prior from x̂⁺ (NaN: integrated)
    Q: np.ndarray             # (N, n, n) Q_k of that prediction (NaN: integrated)

    def __len__(self) -> int:
        return len(self.time_s)

    def rows(self, first: int, last: int) -> FilterHistory:
        """Rows ``first`` ≤ k < ``last`` (indices into this history)."""
        arrays = {name: getattr(self, name)[first:last] for name in ARRAY_FIELDS}
        return replace(self, first_sample=self.first_sample + first, **arrays)

    def index_of(self, sample: int) -> int:
        """Row of the simulation's sample number ``sample`` (ValueError if it is not kept)."""
        row = sample - self.first_sample
        if not 0 <= row < len(self):
            raise ValueError(f"sample {sample} is not in the history (samples {self.first_sample} ... "
                             f"{self.first_sample + len(self) - 1} are kept)")
        return row

    def sample(self, row: int) -> dict:
        """One sample as plain arrays (the inspector's and the command line's view)."""
        return {"sample": self.first_sample + row, **{name: getattr(self, name)[row] for name in ARRAY_FIELDS}}


ARRAY_FIELDS = ("time_s", "u", "y", "truth", "x_prior", "P_prior", "K", "innovation", "S", "x_post", "P_post",
                "Phi", "Q")


def replay(model: FilterModel, x_prior, P_prior, u, y, time_s=None) -> dict[str, np.ndarray]:
    """Eq. 2 over the samples of ``u`` (N, p) and ``y`` (N, m), starting from the first sample's
    prior ``x_prior``, ``P_prior``: the arrays of ``FilterHistory`` that the filter computes.
    ``time_s`` (N,) [s] gives a propagation its intervals (None: the sample time)."""
    count, n, m = len(y), model.Phi.shape[0], model.H.shape[0]
    out = {"x_prior": np.empty((count, n)), "P_prior": np.empty((count, n, n)), "K": np.empty((count, n, m)),
           "innovation": np.empty((count, m)), "S": np.empty((count, m, m)), "x_post": np.empty((count, n)),
           "P_post": np.empty((count, n, n)), "Phi": np.empty((count, n, n)), "Q": np.empty((count, n, n))}
    x, P = np.asarray(x_prior, dtype=float), np.asarray(P_prior, dtype=float)
    R_diag = np.diag(model.R)
    for k in range(count):
        step = correction(x, P, model.H, R_diag, y[k])
        out["x_prior"][k], out["P_prior"][k] = x, P
        out["K"][k], out["innovation"][k], out["S"][k] = step["K"], step["innovation"], step["S"]
        out["x_post"][k], out["P_post"][k] = step["x"], step["P"]
        dt = None if time_s is None or k + 1 == count else time_s[k + 1] - time_s[k]
        x, P, Phi, Q = predict(model, step["x"], step["P"], u[k], dt)
        out["Phi"][k] = np.nan if Phi is None else Phi
        out["Q"][k] = np.nan if Q is None else Q
    return out


class FilterTape:
    """The bounded record of what a filter read (see the module's docstring): chunks of
    (first sample's prior, then per sample time, u, y, true state), newest last."""

    def __init__(self, model: FilterModel, capacity: int = CAPACITY):
        if model.R.shape != (len(model.measurements),) * 2 or np.any(model.R != np.diag(np.diag(model.R))):
            raise ValueError("the tape's filter corrects with a diagonal R, one entry per measurement")
        self.model = model
        self.capacity = capacity
        self.chunks: deque = deque()       # (first sample, x̂⁻, P⁻, time, u, y, truth)
        self.count = 0                     # samples in ``chunks``

    def record(self, first_sample: int, x_prior, P_prior, time_s, u, y, truth) -> None:
        """One ``advance``: the prior of its first sample (before the run) and its samples'
        time (N,), u (N, p), y (N, m) and true state (N, n; NaN where unknown)."""
        if len(time_s) == 0:
            return
        if self.chunks:
            last = self.chunks[-1]
            if last[0] + len(last[3]) != first_sample:          # not contiguous: the old record is stale
                self.chunks.clear()
                self.count = 0
        n = self.model.Phi.shape[0]
        P_prior = np.asarray(P_prior, dtype=float)[:n, :n]
        self.chunks.append((first_sample, np.array(x_prior[:n], dtype=float), 0.5 * (P_prior + P_prior.T),
                            np.array(time_s, dtype=float), np.array(u, dtype=float).reshape(len(time_s), -1),
                            np.array(y, dtype=float).reshape(len(time_s), -1), np.array(truth, dtype=float)))
        self.count += len(time_s)
        while self.count - len(self.chunks[0][3]) >= self.capacity:
            self.count -= len(self.chunks.popleft()[3])

    def history(self) -> FilterHistory | None:
        """The filter replayed over every kept sample (None before the first ``advance``)."""
        if not self.chunks:
            return None
        first_sample, x_prior, P_prior = self.chunks[0][:3]
        time_s, u, y, truth = (np.concatenate([chunk[j] for chunk in self.chunks]) for j in range(3, 7))
        return FilterHistory(self.model, first_sample, time_s, u, y, truth,
                             **replay(self.model, x_prior, P_prior, u, y, time_s))

    @property
    def nbytes(self) -> int:
        """Bytes the kept record holds (its arrays)."""
        return sum(array.nbytes for chunk in self.chunks for array in chunk[1:])


def branch(history: FilterHistory, row: int, model: FilterModel, horizon: int | None = None) -> FilterHistory:
    """The filter rerun with ``model`` (another Q or R) from row ``row`` of ``history`` for
    ``horizon`` samples (None: to the end), on the same recorded inputs and measurements.

    Row ``row``'s prior is predicted with the new model from the row before (the history's
    first row keeps its recorded prior), so a branch with the history's model reproduces it
    bit for bit."""
    if not 0 <= row < len(history):
        raise ValueError(f"branch: row {row} is outside the history's {len(history)} samples")
    last = len(history) if horizon is None else min(len(history), row + max(int(horizon), 1))
    if row == 0:
        x_prior, P_prior = history.x_prior[0], history.P_prior[0]
    else:
        x_prior, P_prior = predict(model, history.x_post[row - 1], history.P_post[row - 1], history.u[row - 1],
                                   history.time_s[row] - history.time_s[row - 1])[:2]
    kept = history.rows(row, last)
    return replace(kept, model=model, **replay(model, x_prior, P_prior, kept.u, kept.y, kept.time_s))
