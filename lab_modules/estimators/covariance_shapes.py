"""A covariance as a shape: the ellipsoid of three states of a filter sample, seen around the true state.

For a Gaussian estimate x̂ with covariance P, the states z with (z − x̂)ᵀ P⁻¹ (z − x̂) = k² lie on
the k-sigma ellipsoid.  With P = V Λ Vᵀ (eigen-decomposition, V orthonormal), its half-axes are
k √λⱼ along the columns of V: a unit sphere scaled by k √λ and turned by V.

Three states rarely share a unit (m, m/s, A), so they are drawn in a box of their own: each state
divided by a length of its own, large enough that the box ±1 holds the prior's 3σ and both
estimates, with the true state at the centre.  Dividing by the lengths D turns P into D⁻¹ P D⁻¹
(the correlations stay as they are)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

SIGMAS = 3.0                    # the box holds the prior's 3-sigma extent ...
MARGIN = 1.1                    # ... with a tenth to spare


@dataclass(frozen=True)
class Ellipsoid:
    """The 1σ ellipsoid of a 3 × 3 covariance: ``centre`` (3,), ``semi_axes`` (3,) √λⱼ and
    ``rotation`` (3, 3), a proper rotation whose columns are the principal directions."""

    centre: np.ndarray
    semi_axes: np.ndarray
    rotation: np.ndarray

    def wxyz(self) -> tuple[float, float, float, float]:
        """The rotation as a unit quaternion (w, x, y, z)."""
        x, y, z, w = Rotation.from_matrix(self.rotation).as_quat()
        return float(w), float(x), float(y), float(z)


def ellipsoid(centre, covariance) -> Ellipsoid:
    """The 1σ ellipsoid of ``covariance`` (3 × 3, symmetric positive semi-definite) around ``centre``."""
    P = np.asarray(covariance, float)
    eigenvalues, V = np.linalg.eigh((P + P.T) / 2)                  # P = V Λ Vᵀ
    if np.linalg.det(V) < 0:
        V = V * np.array([-1.0, 1.0, 1.0])                          # a rotation, not a reflection
    return Ellipsoid(np.asarray(centre, float), np.sqrt(np.clip(eigenvalues, 0.0, None)), V)


@dataclass(frozen=True)
class StateBox:
    """Three states of a filter sample, each divided by its ``lengths`` entry (SI units per box
    half-width) and measured from ``centre``: the true state, or the prior estimate where the
    simulation does not know the truth (``known_truth`` False)."""

    states: tuple[int, int, int]
    centre: np.ndarray
    lengths: np.ndarray
    known_truth: np.ndarray

    def point(self, x) -> np.ndarray:
        """A state vector's place in the box: (x − centre) / lengths."""
        return (np.asarray(x, float)[list(self.states)] - self.centre) / self.lengths

    def ellipsoid(self, x, P) -> Ellipsoid:
        """The 1σ ellipsoid of (x, P) in the box: P becomes D⁻¹ P D⁻¹."""
        index = np.ix_(self.states, self.states)
        scale = 1.0 / self.lengths
        return ellipsoid(self.point(x), np.asarray(P, float)[index] * np.outer(scale, scale))


def state_box(sample: dict, states: tuple[int, int, int]) -> StateBox:
    """The box for ``sample`` (a ``FilterHistory.sample``): the prior's 3σ and both estimates inside."""
    index = list(states)
    truth, prior, posterior = (np.asarray(sample[name], float)[index] for name in ("truth", "x_prior", "x_post"))
    known = np.isfinite(truth)
    centre = np.where(known, truth, prior)
    sigma_prior = np.sqrt(np.clip(np.diag(np.asarray(sample["P_prior"], float))[index], 0.0, None))
    reach = np.max([SIGMAS * sigma_prior, np.abs(prior - centre), np.abs(posterior - centre)], axis=0) * MARGIN
    lengths = np.where(reach > 0, reach, 1.0)                          # a state without spread: unit length
    return StateBox(tuple(states), centre, lengths, known)
