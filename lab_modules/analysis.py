"""Linear analysis of the bearing-axis loop: closed-loop poles, noise-driven
RMS values, where a loop affine in a gain factor loses stability and the largest
tolerable gain factor, the loop broken at the plant input and the modes' names
(step and frequency responses: ``loop_responses``; margins and sensitivity:
``loop_sensitivity``).

The loop is assembled from the discrete plant model (eq. 1, 3-4, 12), a
discrete controller and the *steady-state* Kalman filter of eq. 2, and
returned as a discrete ``control.StateSpace`` so that python-control's
functions (poles, step responses) apply directly.
"""

from __future__ import annotations

import threading
import warnings
from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg
import scipy.optimize

#: Inputs and outputs of the loop returned by ``closed_loop``.
LOOP_INPUTS = ("reference_m", "disturbance_n", "process_v", "process_i", "noise_x_v", "noise_i_v")
LOOP_OUTPUTS = ("x_m", "current_reference_v", "current_a")


def steady_state_kalman(model: control.StateSpace, Q, R):
    """Steady-state gain K and predicted covariance P of eq. 2 (k -> infinity).

    Solves the filter's Riccati equation with python-control's ``dlqe``; the
    returned K is eq. 2's correction gain P C^T (C P C^T + R)^-1, not the
    predictor gain A K that ``dlqe`` itself returns.
    """
    A, C, Q, R = (np.ascontiguousarray(M, dtype=float) for M in (model.A, model.C, Q, R))
    key = tuple((M.shape, M.tobytes()) for M in (A, C, Q, R))
    with _kalman_lock:
        cached = _kalman_cache.get(key)
    if cached is None:
        _, P, _ = control.dlqe(A, np.eye(A.shape[0]), C, Q, R)
        cached = (P @ C.T @ np.linalg.inv(C @ P @ C.T + R), P)
        with _kalman_lock:                        # the analysis threads of all tabs share it
            _kalman_cache[key] = cached
            while len(_kalman_cache) > KALMAN_CACHE:
                _kalman_cache.pop(next(iter(_kalman_cache)))
    return cached[0].copy(), cached[1].copy()


#: Riccati solutions kept (the analysis, the pole map's root locus and the sweeps of one
#: setting ask for the same filter; a solve takes milliseconds)
KALMAN_CACHE = 64
_kalman_cache: dict = {}
_kalman_lock = threading.Lock()


@dataclass(frozen=True)
class Matrices:
    """A discrete system's matrices and sample time [s]: all that the analyses below read of a
    ``control.StateSpace``, without its construction (the trade-off sweeps assemble hundreds)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float


@dataclass(frozen=True)
class Loop:
    """A closed bearing-axis loop and where its parts sit in the state vector."""

    system: control.StateSpace | Matrices   # inputs LOOP_INPUTS, outputs LOOP_OUTPUTS
    loop_states: slice                      # states that take part in the feedback loop


def closed_loop(model: control.StateSpace, controller: control.StateSpace,
                kalman_gain: np.ndarray, use_estimate: bool,
                state_gain: np.ndarray | None = None) -> Loop:
    """``closed_loop_matrices`` as a python-control system (named inputs and outputs)."""
    loop = closed_loop_matrices(model, controller, kalman_gain, use_estimate, state_gain)
    return Loop(_state_space(loop.system), loop.loop_states)


def _state_space(system: Matrices) -> control.StateSpace:
    return control.ss(system.A, system.B, system.C, system.D, system.dt, inputs=LOOP_INPUTS, outputs=LOOP_OUTPUTS)


def closed_loop_matrices(model: control.StateSpace, controller: control.StateSpace | Matrices,
                         kalman_gain: np.ndarray, use_estimate: bool,
                         state_gain: np.ndarray | None = None) -> Loop:
    """Assemble plant, controller and steady-state filter into one discrete system (``Matrices``).

    State z = (plant s, controller x_c, filter prediction x_p).  With
    y = C s + eta and x_hat = x_p + K (y - C x_p), the fed-back position is
    the measurement K_mx x_d + eta_x or the estimate K_mx x_hat[0], and

        u = C_c x_c + D_c e - K_s x_hat,   e = K_mx r - fed-back position.

    With measured feedback and no state gain the filter only watches, so its
    states are excluded from ``loop_states`` (and from the loop's poles).

    Parameters
    ----------
    model : control.StateSpace
        Discrete plant = filter model, inputs (i_ref [V], f_z [N]), outputs (position [V], current [V]).
    controller : control.StateSpace
        Discrete controller, control error [V] -> i_ref [V].
    kalman_gain : ndarray
        Steady-state correction gain K of eq. 2.
    use_estimate : bool
        Feed back the estimated instead of the measured position.
    state_gain : ndarray, optional
        K_s on the filter's state estimate (LQG, paper §IV); None: no state feedback.
    """
    A, B, C = (np.asarray(M) for M in (model.A, model.B, model.C))
    Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(M)) for M in
                      (controller.A, controller.B, controller.C, controller.D))
    n, nc = A.shape[0], Ac.shape[0]
    K = np.asarray(kalman_gain)
    Bu, Bf = B[:, :1], B[:, 1:2]
    k_mx = np.max(np.abs(C[0]))
    I = np.eye(n)
    # fed-back position [V] = Fs s + Fp x_p + Fn eta
    if use_estimate:
        h = np.zeros((1, n))
        h[0, 0] = k_mx
        Fs, Fp, Fn = h @ K @ C, h @ (I - K @ C), h @ K
    else:
        Fs, Fp, Fn = C[:1], np.zeros((1, n)), np.array([[1.0, 0.0]])
    Ks = np.zeros((1, n)) if state_gain is None else np.reshape(state_gain, (1, n))
    # u = Us s + Cc x_c + Up x_p + Un eta + Dc K_mx r
    Us, Up, Un = -Dc @ Fs - Ks @ K @ C, -Dc @ Fp - Ks @ (I - K @ C), -Dc @ Fn - Ks @ K
    G = np.zeros((n, 2))
    G[1, 0], G[2, 1] = 1.0, 1.0      # process noise on v and i (eq. 17's structure)
    Acl = np.block([
        [A + Bu @ Us, Bu @ Cc, Bu @ Up],
        [-Bc @ Fs, Ac, -Bc @ Fp],
        [A @ K @ C + Bu @ Us, Bu @ Cc, A @ (I - K @ C) + Bu @ Up],
    ])
    reference = np.vstack([Bu @ Dc, Bc, Bu @ Dc]) * k_mx          # input in metres
    disturbance = np.vstack([Bf, np.zeros((nc, 1)), np.zeros((n, 1))])
    process = np.vstack([G, np.zeros((nc, 2)), np.zeros((n, 2))])
    sensor = np.vstack([Bu @ Un, -Bc @ Fn, A @ K + Bu @ Un])
    Bcl = np.hstack([reference, disturbance, process, sensor])
    x_row = np.zeros((1, 2 * n + nc))
    x_row[0, 0] = 1.0
    current_row = np.zeros((1, 2 * n + nc))
    current_row[0, 2] = 1.0
    u_row = np.hstack([Us, Cc, Up])
    Ccl = np.vstack([x_row, u_row, current_row])
    Dcl = np.zeros((3, Bcl.shape[1]))
    Dcl[1] = np.hstack([Dc[0] * k_mx, [0.0, 0.0, 0.0], Un[0]])
    system = Matrices(Acl, Bcl, Ccl, Dcl, model.dt)
    filter_in_loop = use_estimate or state_gain is not None
    loop_states = slice(0, 2 * n + nc) if filter_in_loop else slice(0, n + nc)
    return Loop(system, loop_states)


def with_reference_filter(loop: Loop, reference_filter: control.StateSpace) -> Loop:
    """The loop with the reference passed through a discrete SISO filter first
    (set-point weighting, e.g. an I-PD: see ``controllers.pid.setpoint_filter``).

    The filter's states are appended after the loop's and stay out of
    ``loop_states``: they are outside the feedback, so they add no loop poles
    (the filter is stable by construction).  The system stays of the loop's kind."""
    sys, F = loop.system, reference_filter
    A, B, C, D = (np.asarray(M, dtype=float) for M in (sys.A, sys.B, sys.C, sys.D))
    Af, Bf, Cf, Df = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (F.A, F.B, F.C, F.D))
    j, n, nf = LOOP_INPUTS.index("reference_m"), A.shape[0], Af.shape[0]
    b_r, d_r = B[:, j:j + 1], D[:, j:j + 1]
    A_new = np.block([[A, b_r @ Cf], [np.zeros((nf, n)), Af]])
    B_new = np.vstack([B, np.zeros((nf, B.shape[1]))])
    B_new[:n, j:j + 1], B_new[n:, j:j + 1] = b_r @ Df, Bf
    C_new = np.hstack([C, d_r @ Cf])
    D_new = D.copy()
    D_new[:, j:j + 1] = d_r @ Df
    system = Matrices(A_new, B_new, C_new, D_new, sys.dt)
    return Loop(system if isinstance(sys, Matrices) else _state_space(system), loop.loop_states)


def loop_poles(loop: Loop) -> np.ndarray:
    """Closed-loop poles (z-plane) of the states that take part in the feedback."""
    A = np.asarray(loop.system.A)[loop.loop_states, loop.loop_states]
    return np.linalg.eigvals(A)


def noise_rms(loop: Loop, input_variances: dict[str, float]) -> dict[str, float]:
    """Steady-state RMS of the loop outputs driven by white noise inputs.

    Solves the discrete Lyapunov equation X = A X A^T + B W B^T (scipy) after
    balancing the state scaling.  Returns ``inf`` for every
    output when the loop is unstable.
    """
    sys = loop.system
    return dict(zip(LOOP_OUTPUTS, _output_rms(*(np.asarray(M) for M in (sys.A, sys.B, sys.C, sys.D)),
                                              input_variances)))


def _output_rms(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray,
                input_variances: dict[str, float]) -> np.ndarray:
    """``noise_rms`` on the loop's matrices (inputs ``LOOP_INPUTS``): each output's RMS."""
    if np.max(np.abs(np.linalg.eigvals(A))) >= 1.0:
        return np.full(C.shape[0], np.inf)
    columns = [LOOP_INPUTS.index(name) for name in input_variances]
    Bn, Dn = B[:, columns], D[:, columns]
    W = np.diag(list(input_variances.values()))
    # balance A by a diagonal similarity: states in m, m/s, A and V differ by 1e6
    _, (scale, _) = scipy.linalg.matrix_balance(A, permute=False, separate=True)
    As = A / scale[:, None] * scale[None, :]
    Bs = Bn / scale[:, None]
    Xs = scipy.linalg.solve_discrete_lyapunov(As, Bs @ W @ Bs.T)
    X = Xs * scale[:, None] * scale[None, :]
    covariance = C @ X @ C.T + Dn @ W @ Dn.T
    return np.sqrt(np.maximum(np.diag(covariance), 0.0))


def noise_spectrum(loop: Loop, input_variances: dict[str, float], frequencies_hz,
                   output: str = "x_m") -> np.ndarray:
    """One-sided amplitude spectral density of one loop output [unit/sqrt(Hz)]
    driven by white noise inputs (per-sample variances, as in ``noise_rms``).

    A discrete white sequence of variance sigma^2 at sampling time T has the
    one-sided density 2 sigma^2 T up to the Nyquist frequency, so
    S_y(f) = sum_j |G_j(exp(j 2 pi f T))|^2 2 sigma_j^2 T; its integral over
    0 ... 1/(2T) is the variance that ``noise_rms`` returns.  The frequency
    responses come from python-control."""
    sys, T = loop.system, loop.system.dt
    omega = 2 * np.pi * np.asarray(frequencies_hz, dtype=float)
    columns = [LOOP_INPUTS.index(name) for name in input_variances]
    channels = sys[[LOOP_OUTPUTS.index(output)], columns]
    response = np.asarray(control.frequency_response(channels, omega, squeeze=False).complex)[0]   # (inputs, f)
    variances = np.array(list(input_variances.values()))
    return np.sqrt(np.sum(np.abs(response) ** 2 * (2.0 * T * variances)[:, None], axis=0))


def stability_margins(A_low: np.ndarray, A_high: np.ndarray, low: float, high: float, factors,
                      discrete: bool = True) -> np.ndarray:
    """max |z| − 1 (``discrete``) or max Re s of A(f) at each of ``factors``, for a state matrix affine
    in f given at ``low`` and ``high`` (negative: stable), by one batched eigenvalue call."""
    A_low = np.asarray(A_low, dtype=float)
    slope = (np.asarray(A_high, dtype=float) - A_low) / (high - low)
    stack = A_low[None] + (np.asarray(factors, dtype=float) - low)[:, None, None] * slope[None]
    eigenvalues = np.linalg.eigvals(stack)
    return np.max(np.abs(eigenvalues), axis=1) - 1.0 if discrete else np.max(eigenvalues.real, axis=1)


def first_instability(A_low: np.ndarray, A_high: np.ndarray, low: float, high: float,
                      discrete: bool = True, factors=None) -> float:
    """The smallest factor f in (low, high] at which A(f) loses stability, for a state matrix
    affine in f (a closed loop whose controller output the factor scales) given at both ends and
    stable at ``low``; ``high`` if it stays stable.

    From eigenvalues alone: the stability margin (``stability_margins``: |z| = 1 or Re s = 0 is the
    edge) of A(f) on a grid (``factors``, increasing from ``low``; default 48 geometric steps)
    brackets the first crossing, and Brent's method finds it to 1e-12 relative within the bracket.
    """
    factors = np.geomspace(low, high, 48) if factors is None else np.asarray(factors, dtype=float)

    def margin(at: np.ndarray) -> np.ndarray:
        return stability_margins(A_low, A_high, low, high, at, discrete)

    unstable = np.flatnonzero(margin(factors) >= 0.0)
    if unstable.size == 0:
        return float(high)
    k = int(unstable[0])
    if k == 0:
        return float(low)
    return float(scipy.optimize.brentq(lambda f: margin(np.array([f]))[0], factors[k - 1], factors[k],
                                       xtol=1e-12 * factors[k], rtol=1e-12))


def largest_gain_factor(loop_low: Loop, loop_high: Loop, low: float, high: float,
                        input_variances: dict[str, float], output: str, bound: float,
                        tolerance: float = 1e-4) -> float:
    """Largest gain factor g in [low, high] at which the steady-state RMS of ``output`` (driven by
    ``input_variances``, as ``noise_rms``) stays at or below ``bound``; the loop is given at both ends
    (``loop_low``, ``loop_high``), its matrices affine in g (g scales the controller's output).

    The RMS grows without bound towards the loop's first loss of stability above ``low``
    (``first_instability``, from eigenvalues), and rises with g below it (for a PID on this
    plant), so Brent's method finds the factor between ``low`` and that edge, each step one
    Lyapunov solve on the interpolated matrices.  Returns 0 if even ``low`` exceeds the bound and
    ``high`` if the bound is never reached.
    """
    ends = [[np.asarray(M, dtype=float) for M in (loop.system.A, loop.system.B, loop.system.C, loop.system.D)]
            for loop in (loop_low, loop_high)]
    row = LOOP_OUTPUTS.index(output)

    def excess(g: float) -> float:
        """log(RMS / bound) at factor g (inf where the loop is unstable)."""
        w = (g - low) / (high - low)
        with warnings.catch_warnings():           # next to the edge the solve is ill-conditioned, the RMS huge
            warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
            rms = _output_rms(*((1.0 - w) * M_low + w * M_high for M_low, M_high in zip(*ends)), input_variances)
        return float(np.log(rms[row] / bound)) if rms[row] > 0 else -np.inf

    if not excess(low) <= 0.0:
        return 0.0
    edge = first_instability(ends[0][0], ends[1][0], low, high)
    if edge >= high and excess(high) <= 0.0:
        return float(high)
    top, back = (edge, 1e-6) if edge < high else (high, 0.0)
    while not np.isfinite(excess(top)):           # just below the edge the RMS is finite
        top, back = edge - back * (edge - low), 10.0 * back
    return float(scipy.optimize.brentq(excess, low, top, xtol=tolerance))


def independent_samples(x: np.ndarray) -> float:
    """How many independent samples the mean of x² over a stationary, zero-mean Gaussian
    sequence ``x`` is worth: N / (1 + 2 Σ ρ_k²), ρ_k the sample autocorrelation of x up to its
    first zero crossing (for Gaussian x, x² has autocorrelation ρ_k²).  A filter's estimate
    error is correlated over its error time constant, so far fewer than N."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    n = x.size
    if n < 2:
        return float(n)
    x = x - x.mean()
    size = 1 << int(np.ceil(np.log2(2 * n)))
    spectrum = np.fft.rfft(x, size)
    acf = np.fft.irfft(spectrum * np.conj(spectrum), size)[:n]
    if acf[0] <= 0:
        return float(n)
    rho = acf / acf[0]
    negative = np.flatnonzero(rho[1:] <= 0)
    last = int(negative[0]) + 1 if negative.size else n
    return float(n / (1.0 + 2.0 * np.sum(rho[1:last] ** 2)))


def z_to_s(poles_z: np.ndarray, sample_time_s: float) -> np.ndarray:
    """Map discrete poles to the equivalent continuous ones, s = ln(z) / T [rad/s]."""
    return np.log(np.asarray(poles_z, dtype=complex)) / sample_time_s


# -- loop broken at the plant input (margins and sensitivity: ``loop_sensitivity``) ----------


def compensator(model: control.StateSpace, controller: control.StateSpace, kalman_gain: np.ndarray,
                use_estimate: bool, state_gain: np.ndarray | None = None) -> control.StateSpace:
    """Everything between the measurements and the plant input of ``closed_loop`` (reference 0):
    the steady-state filter (eq. 2), the fed-back position (measured or estimated), the
    controller and the optional state feedback, as one discrete system y [V] (2) -> i_ref [V]."""
    A, B, C = (np.asarray(M) for M in (model.A, model.B, model.C))
    Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(M)) for M in
                      (controller.A, controller.B, controller.C, controller.D))
    n = A.shape[0]
    K, I, Bu = np.asarray(kalman_gain), np.eye(n), B[:, :1]
    k_mx = np.max(np.abs(C[0]))
    if use_estimate:                                   # fed-back position = Fp x_p + Fy y
        h = np.zeros((1, n))
        h[0, 0] = k_mx
        Fp, Fy = h @ (I - K @ C), h @ K
    else:
        Fp, Fy = np.zeros((1, n)), np.array([[1.0, 0.0]])
    Ks = np.zeros((1, n)) if state_gain is None else np.reshape(state_gain, (1, n))
    # u = Cc x_c - Dc fb - Ks x_hat,  x_hat = (I - K C) x_p + K y
    Up, Uy = -Dc @ Fp - Ks @ (I - K @ C), -Dc @ Fy - Ks @ K
    Acomp = np.block([[Ac, -Bc @ Fp], [Bu @ Cc, A @ (I - K @ C) + Bu @ Up]])
    Bcomp = np.vstack([-Bc @ Fy, A @ K + Bu @ Uy])
    Ccomp = np.hstack([Cc, Up])
    return control.ss(Acomp, Bcomp, Ccomp, Uy, model.dt)


def loop_at_plant_input(model: control.StateSpace, compensator_system: control.StateSpace) -> control.StateSpace:
    """Open-loop transfer L with the loop broken at the plant input: a signal injected at
    i_ref runs through the plant (its measurement outputs) and the compensator and comes
    back with the opposite sign, so the closed loop is 1 / (1 + L) there."""
    plant_u = control.ss(np.asarray(model.A), np.asarray(model.B)[:, :1], np.asarray(model.C),
                         np.asarray(model.D)[:, :1], model.dt)
    return -control.series(plant_u, compensator_system)


def state_space_from_step(step, n_states: int, n_inputs: int, dt: float) -> control.StateSpace:
    """The discrete linear system x+ = A x + B u, y = C x + D u that ``step(x, u) -> (x+, y)``
    computes, by pushing unit vectors through one step (the step must be linear in (x, u)).
    Lets a loop written like its compiled kernel give its own linear model."""
    columns = [step(e, np.zeros(n_inputs)) for e in np.eye(n_states)]
    inputs = [step(np.zeros(n_states), e) for e in np.eye(n_inputs)]
    A = np.column_stack([c[0] for c in columns]) if n_states else np.zeros((0, 0))
    B = np.column_stack([c[0] for c in inputs]).reshape(n_states, n_inputs)
    D = np.column_stack([c[1] for c in inputs])
    C = np.column_stack([c[1] for c in columns]) if n_states else np.zeros((D.shape[0], 0))
    return control.ss(A, B, C, D, dt)


# -- physical names of modes (the pole map) ---------------------------------------------------------
@dataclass(frozen=True)
class NamedMode:
    """One eigenvalue of a state matrix with the physics it belongs to."""

    pole_s: complex                   # [rad/s] (a discrete matrix's z mapped by s = ln z / T)
    name: str                         # the physics of the states that dominate it
    shares: tuple                     # ((state label, participation share), ...) largest first, shares sum to 1


def participation(A) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues λ_k of ``A`` and the participation factors p[i, k] = |v_ik w_ik| / Σ_i |v_ik w_ik|
    (right eigenvector v_k, left eigenvector w_k, Pérez-Arriaga, Verghese and Schweppe, IEEE
    Trans. PAS-101 (1982) 3117): how much state i takes part in mode k.  Unlike the eigenvector's
    entries they do not depend on the states' units (a diagonal scaling of the states cancels in
    v_ik w_ik), so metres, amperes and volts compare fairly.  A may be complex (the spinning
    rotor's loop in r = x + i y)."""
    A = np.asarray(A, dtype=complex if np.iscomplexobj(A) else float)
    eigenvalues, right = scipy.linalg.eig(A)
    left = np.linalg.inv(right).T                      # rows of V⁻¹: left eigenvectors with w_kᵀ v_k = 1
    p = np.abs(right * left)
    return eigenvalues, p / np.maximum(p.sum(axis=0, keepdims=True), 1e-300)


def name_modes(A, states, sample_time_s: float | None = None, mixed: float = 0.3) -> list[NamedMode]:
    """Physical names of the modes of a state matrix, from its eigenvectors.

    ``states`` gives for each state of ``A`` (in order) ``(label with unit, physics)``, e.g.
    ``("x [m]", "rotor position/velocity (suspension mode)")``; states that share a physics
    (a position and its velocity) pool their participation factors (``participation``).  A mode
    is named after the physics with the largest share; where the runner-up holds at least
    ``mixed`` of it, both are named ("A + B").  The names follow the physics, not the index of
    an eigenvalue, so they stay with a mode when a slider moves it.  ``sample_time_s``: ``A`` is
    discrete, its eigenvalues z map to s = ln z / T.  Put ``A`` in coordinates with a physical
    meaning first (e.g. a filter's estimation error instead of its estimate, a controller's modal
    states: ``change_basis``), since participation factors depend on the basis."""
    labels = [label for label, _ in states]
    physics = [group for _, group in states]
    if len(states) != np.shape(A)[0]:
        raise ValueError(f"{len(states)} state names for a {np.shape(A)[0]}-state matrix")
    eigenvalues, p = participation(A)
    groups = list(dict.fromkeys(physics))
    out = []
    for k, lam in enumerate(eigenvalues):
        pooled = sorted(((sum(p[i, k] for i in range(len(physics)) if physics[i] == g), g) for g in groups),
                        reverse=True)
        name = pooled[0][1]
        if len(pooled) > 1 and pooled[1][0] >= mixed:
            name = f"{name} + {pooled[1][1]}"
        shares = tuple(sorted(((labels[i], float(p[i, k])) for i in range(len(labels))), key=lambda s: -s[1]))
        with np.errstate(divide="ignore", invalid="ignore"):   # z = 0 (a pure delay) has no s
            s = complex(lam) if sample_time_s is None else complex(z_to_s(lam, sample_time_s))
        out.append(NamedMode(s, name, shares))
    return out


def change_basis(A, T) -> np.ndarray:
    """T⁻¹ A T: the state matrix in the coordinates z' with z = T z' (same eigenvalues)."""
    T = np.asarray(T, dtype=float)
    return np.linalg.solve(T, np.asarray(A, dtype=float) @ T)


def modal_basis(A) -> np.ndarray:
    """A real basis of ``A``'s eigenvectors (a complex pair: real and imaginary part), each
    column scaled to unit length; for putting a controller's states into modal coordinates."""
    eigenvalues, vectors = np.linalg.eig(np.asarray(A, dtype=float))
    columns, done = [], set()
    for k, lam in enumerate(eigenvalues):
        if k in done:
            continue
        v = vectors[:, k]
        if abs(lam.imag) > 1e-12 * max(abs(lam), 1.0):
            partner = min((j for j in range(len(eigenvalues)) if j != k and j not in done),
                          key=lambda j: abs(eigenvalues[j] - np.conj(lam)))
            done.add(partner)
            columns += [v.real, v.imag]
        else:
            columns.append(v.real)
        done.add(k)
    basis = np.column_stack(columns)
    return basis / np.linalg.norm(basis, axis=0)
