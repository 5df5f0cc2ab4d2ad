"""The test rig's flexible rotor at speed: gyroscopic coupling of the two bending
planes, whirl modes, the unbalance of a balance grade and the displacement zones
of ISO 14839-2 (the closed loop lives in ``loops.spinning_rotor_loop``).

The rotor is ``plants.flexible_rotor``'s (paper 000 §I, Fig. 2: 25 kg, 910 mm,
laminations Ø 272 mm, unilaterally levitated, a ball bearing as pivot at the
drive end), axisymmetric, spinning at Omega [rad/s] about its axis z.  In each
bending plane (x-z and y-z) a node carries a displacement and a slope; with
x = (w, a) of the x-z plane and y = (w, b) of the y-z plane per node:

    M x'' + Omega P y' + K x = f_x
    M y'' - Omega P x' + K y = f_y                                       (1)

``M``, ``K`` and the polar-inertia matrix ``P`` [kg m^2 on the slopes] are the
plane matrices of ``FlexibleRotor``; G = [[0, P], [-P, 0]] is the gyroscopic
matrix per unit speed (skew: it moves no energy, it only splits each mode into a
backward and a forward whirl).  Rotor, supports and bearing axes are isotropic,
so the complex coordinate r = x + i y turns eq. 1 into one complex system of a
single plane's size:

    M r'' - i Omega P r' + K r = f_x + i f_y                             (2)

A solution r = phi e^{i omega t} whirls *forward* (with the spin) for omega > 0 and
*backward* for omega < 0; x = Re r, y = Im r.  A controller that acts alike in both
planes (the same PID on x and on y) is real, so it acts on r unchanged: the closed
loop in both planes is eq. 2 closed by one compensator.

Modal reduction: r = Phi eta with the first n mass-normalised modes Phi of the
rotor at standstill (on its ball bearing, magnetic bearing off):

    eta'' + (2 zeta Omega_0 - i Omega P_r) eta' + Omega_0^2 eta = Phi^T f,   P_r = Phi^T P Phi     (3)

Truncation error (tested against the full finite-element model): below 0.1 % for
the first three bending modes up to 12,000 rpm with six modes kept.

Unbalance (ISO 21940-11): a rotor of mass m balanced to grade G (e Omega_max = G,
G in mm/s) keeps a permissible residual unbalance U = m G / Omega_max [kg m]; at
speed Omega it pulls with F = U Omega^2 e^{i Omega t}, a forward synchronous force.
The lab places it at the lamination stack (the bearing plane).

Displacement zones of ISO 14839-2:2004 (rotating machinery with active magnetic
bearings, part 2: evaluation of vibration), its table of zone limits for the shaft
displacement at rated speed, as fractions of the touchdown bearing's minimum clearance
C_min: A below 0.3 C_min (newly commissioned), B below 0.4 C_min (unrestricted
long-term operation), C below 0.5 C_min (limited operation), D beyond (damage
possible).  The lab reads the displacement as the orbit's radius (zero to peak) at the
bearing.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg

from lab_modules.plants.flexible_rotor import FlexibleRotor, modal_plant
from lab_modules.plants.radial_bearing import RIG, BearingAxis

#: Speeds the lab's Campbell diagram covers [rpm].
SPEED_RANGE_RPM = (0.0, 12000.0)
#: ISO 21940-11 balance grades G [mm/s] offered (G 2.5: turbines, machine-tool drives, electric
#: armatures with special requirements; G 6.3: electric motors and general machinery).
BALANCE_GRADES_MM_S = {"G 1": 1.0, "G 2.5": 2.5, "G 6.3": 6.3, "G 16": 16.0}
#: ISO 14839-2 zone limits as fractions of the touchdown bearing's minimum clearance C_min.
ISO_14839_2_LIMITS = (("A", 0.3), ("B", 0.4), ("C", 0.5))


def rad_s(speed_rpm):
    """Omega [rad/s] = 2 pi n / 60 of a speed n [rpm]."""
    return np.asarray(speed_rpm, dtype=float) * np.pi / 30


def permissible_unbalance_kg_m(rotor_mass_kg: float, grade_mm_s: float, max_speed_rpm: float) -> float:
    """ISO 21940-11: U_per = m e_per, e_per = G / Omega_max [m] (G in mm/s -> m/s)."""
    return rotor_mass_kg * grade_mm_s * 1e-3 / float(rad_s(max_speed_rpm))


def iso_14839_2_zone(displacement_m: float, clearance_m: float) -> str:
    """Zone A-D of a peak displacement [m] against the minimum clearance C_min [m]."""
    return next((zone for zone, limit in ISO_14839_2_LIMITS if displacement_m < limit * clearance_m), "D")


def two_plane_matrices(rotor: FlexibleRotor) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Real matrices of eq. 1 on (x-z plane, y-z plane) degrees of freedom:
    (M2, G2, K2) with M2 q'' + Omega G2 q' + K2 q = f; constraints not yet applied."""
    zero = np.zeros_like(rotor.M)
    M2 = np.block([[rotor.M, zero], [zero, rotor.M]])
    K2 = np.block([[rotor.K, zero], [zero, rotor.K]])
    G2 = np.block([[zero, rotor.P], [-rotor.P, zero]])
    return M2, G2, K2


def whirl_frequencies_hz(rotor: FlexibleRotor, speed_rpm: float, n_bending: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Backward and forward whirl frequencies [Hz] (both positive) of the first ``n_bending``
    bending modes of the full finite-element model (eq. 2, every degree of freedom), the rotor
    on its ball bearing with the magnetic bearing off.  The rigid tilting about the pivot (a
    backward whirl at 0 Hz and a slow forward nutation) is left out."""
    free = np.setdiff1d(np.arange(rotor.K.shape[0]), rotor.constrained_dofs)
    M, K, P = (X[np.ix_(free, free)] for X in (rotor.M, rotor.K, rotor.P))
    n = len(free)
    # first-order form of eq. 2: (r, r')' = [[0, I], [-M^-1 K, i Omega M^-1 P]] (r, r')
    A = np.block([[np.zeros((n, n)), np.eye(n)],
                  [-np.linalg.solve(M, K), 1j * float(rad_s(speed_rpm)) * np.linalg.solve(M, P)]])
    omega = np.sort(np.linalg.eigvals(A).imag)             # s = i omega: whirl at omega [rad/s]
    rigid = np.argsort(np.abs(omega))[:2]                  # the tilting about the pivot
    omega = np.delete(omega, rigid)
    forward, backward = omega[omega > 0], -omega[omega < 0][::-1]
    return backward[:n_bending] / (2 * np.pi), forward[:n_bending] / (2 * np.pi)


@dataclass(frozen=True)
class SpinningPlant:
    """Eq. 3 with the bearing axis of ``plants.flexible_rotor.modal_plant`` in both planes,
    complex: A(Omega) = A0 + Omega A1.

    States (eta_1..n [m kg^½], eta'_1..n, i [A], x_d [m]) as in ``modal_plant`` (complex:
    real part the x-z plane, imaginary part the y-z plane); inputs (i_ref [V], f [N] at
    the bearing plane); outputs (K_mx x_d [V], r_b [m], r_s [m], K_mi i [V])."""

    A0: np.ndarray
    A1: np.ndarray
    B: np.ndarray
    C: np.ndarray
    n_modes: int

    def A(self, speed_rad_s: float) -> np.ndarray:
        return self.A0 + speed_rad_s * self.A1

    def discrete(self, speed_rad_s: float, sample_time_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Zero-order hold at the given speed: (A_d, B_d) = blocks of expm([[A, B], [0, 0]] T)."""
        n, m = self.B.shape
        augmented = np.zeros((n + m, n + m), dtype=complex)
        augmented[:n, :n], augmented[:n, n:] = self.A(speed_rad_s), self.B
        step = scipy.linalg.expm(augmented * sample_time_s)
        return step[:n, :n], step[:n, n:]


class SpinningRotor:
    """The flexible rotor's modal model at speed: ``plant`` for the bearing axis in both planes,
    ``free_whirl_hz`` for the Campbell diagram of the rotor on its ball bearing alone."""

    def __init__(self, rotor: FlexibleRotor):
        self.rotor = rotor
        self.geometry = rotor.geometry

    @cached_property
    def _polar_modal(self) -> np.ndarray:
        shapes = self.rotor.mode_shapes(self.rotor.K.shape[0] - len(self.rotor.constrained_dofs))
        return shapes.T @ self.rotor.P @ shapes

    def polar_modal(self, n_modes: int) -> np.ndarray:
        """P_r = Phi^T P Phi of eq. 3 [1/s per rad/s] for the first ``n_modes`` modes."""
        return self._polar_modal[:n_modes, :n_modes]

    def plant(self, sensor_z_m: float, n_modes: int, sensor_lag_s: float, rig: BearingAxis = RIG) -> SpinningPlant:
        """The bearing axis at speed (eq. 3 closed by the magnet's k_x, ``modal_plant``)."""
        still = modal_plant(self.rotor, sensor_z_m, n_modes, sensor_lag_s, rig)
        A0 = np.asarray(still.A, dtype=complex)
        A1 = np.zeros_like(A0)
        rate = slice(n_modes, 2 * n_modes)
        A1[rate, rate] = 1j * self.polar_modal(n_modes)         # eta'' = ... + i Omega P_r eta'
        return SpinningPlant(A0, A1, np.asarray(still.B, dtype=complex), np.asarray(still.C, dtype=complex),
                             n_modes)

    def free_whirl_hz(self, speeds_rpm, n_modes: int) -> np.ndarray:
        """Whirl frequencies [Hz] of the undamped reduced model (eq. 3, magnetic bearing off), per
        speed (rows) and mode (columns): signed, + forward, - backward; mode 1 is the rigid
        tilting (backward 0 Hz).  Shape (speeds, n_modes, 2): [..., 0] backward, [..., 1] forward."""
        omega_0 = 2 * np.pi * self.rotor.natural_frequencies_hz(n_modes)
        P = self.polar_modal(n_modes)
        out = np.empty((len(np.atleast_1d(speeds_rpm)), n_modes, 2))
        for k, speed in enumerate(rad_s(np.atleast_1d(speeds_rpm))):
            A = np.block([[np.zeros((n_modes, n_modes)), np.eye(n_modes)],
                          [-np.diag(omega_0**2), 1j * speed * P]])
            s, vectors = np.linalg.eig(A)
            out[k] = s[whirl_by_mode(s, energy_share(s, vectors[:n_modes], omega_0))].imag
        return out / (2 * np.pi)


def whirl_by_mode(s: np.ndarray, share: np.ndarray) -> np.ndarray:
    """Index into ``s`` of each mode j's backward and forward eigenvalue (shape (n, 2)):
    ``share[j, k]`` is mode j's part in eigenvalue k; each mode takes, among the eigenvalues of
    its whirl direction (Im s < 0 backward, >= 0 forward), the one it has the largest part in,
    the most distinct modes choosing first, each eigenvalue used once; a pole that does not
    oscillate only when no oscillating one is left.  Not oscillating: |Im s| < 0.5 Hz, or a
    damping ratio zeta = -Re s / |s| above 0.95 (a compensator's real pole, which the gyroscopic
    coupling moves off the real axis by a fraction of a hertz at speed)."""
    chosen = np.zeros((share.shape[0], 2), dtype=int)
    still = (np.abs(s.imag) < np.pi) | (-s.real > 0.95 * np.abs(s))
    for direction, side in enumerate((s.imag < 0, s.imag >= 0)):
        candidates = np.where(side[None, :], share - 2.0 * still[None, :], -np.inf)
        taken: set[int] = set()
        for j in np.argsort(-candidates.max(axis=1)):
            k = next(k for k in np.argsort(-candidates[j]) if k not in taken)
            taken.add(k)
            chosen[j, direction] = k
    return chosen


def energy_share(s: np.ndarray, modal_part: np.ndarray, omega_0: np.ndarray) -> np.ndarray:
    """Mode j's share of eigenvalue k's modal energy |eta_j|^2 (omega_j^2 + |s_k|^2), from the
    eigenvectors' rows of eta_1..n (``modal_part``): for systems of rotor states only."""
    energy = np.abs(modal_part) ** 2 * (omega_0[:, None] ** 2 + np.abs(s)[None, :] ** 2)
    return energy / np.maximum(energy.sum(axis=0), 1e-300)
