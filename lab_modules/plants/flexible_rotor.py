"""The test rig's flexible rotor: beam finite elements, modes, and the bearing
axis as a state-space plant with the sensor anywhere along the shaft (its
closed loop lives in ``loops.flexible_rotor_loop``).

Source: paper 000 (Schuhmann, Hofmann, Werner), §I, Fig. 2 and Appendix: a
rotor of 25 kg and 910 mm, laminations Ø 272 mm, levitated *unilaterally*
(one radial magnetic bearing); its third natural mode has a node close to the
bearing laminations, so an external sensor beyond that node feeds mode 3 back
with the wrong sign.

The paper gives no drawing with dimensions.  The geometry below is chosen
(not in the paper) to match every number it does give:

* **Unilateral support.**  One end of the shaft runs in a ball bearing that
  carries the radial load but no moment (a self-aligning ball bearing: a
  *pivot*, the shaft's displacement there is zero, its slope free); the
  magnetic bearing holds the other end.  The rotor's first mode is then the
  rigid tilting about the pivot, levitated by the magnetic bearing alone.
* **Mass 25 kg, length 910 mm:** a steel shaft Ø 38 mm × 910 mm (8.1 kg), the
  lamination stack Ø 272 mm × 40 mm centred 800 mm from the drive end
  (16.6 kg, electrical steel at a 0.95 stacking factor) and a 0.45 kg
  coupling hub at the drive end; total 25.1 kg.  The ball bearing sits 40 mm
  from the drive end.
* **Equivalent mass.**  The rigid mode's modal mass seen at the bearing plane
  is 20.1 kg, close to the appendix's equivalent rotor mass m = 21.5 kg of
  eq. 3 (the paper's rigid one-axis model); the stack must sit near the
  shaft's end and carry most of the mass for that to hold, as it does here.
* **Mode 3's node near the laminations.**  The stack's large diametral inertia
  nearly pins the bending modes there: mode 2 has a node 13 mm inboard of the
  bearing plane, mode 3 one 18 mm outboard, i.e. at the stack's outer face.
  An outboard sensor track therefore sees mode 3 with the opposite sign.
  Natural frequencies (rotor on its ball bearing, magnetic bearing off):
  0, 109, 296, 710 Hz.
* The shaft diameter sets the bending frequencies.  Ø 38 mm puts mode 3
  (296 Hz) above the bearing's closed-loop mode (~250 Hz): there the PID's
  phase lead has run out, so the mode is lightly damped even with the
  integrated sensor, and the wrong sign of an external sensor tips it over.
* Bending modes carry 0.5 % modal damping (not in the paper; typical of a
  steel shaft with a shrink-fitted stack).

The laminations add mass, diametral and polar inertia but no bending stiffness
(thin insulated sheets); they are lumped onto the stack's end and centre nodes.
Elements are Euler-Bernoulli beams with consistent mass matrices (the default,
as in ``sensor_placement``) or Timoshenko beams (shear deformation and rotary
inertia, Friswell et al., *Dynamics of Rotating Machines*, 2010, §5.4); the
eigenproblem K phi = omega^2 M phi is solved by ``scipy.linalg.eigh``.  The
polar-inertia matrix ``P`` (the gyroscopic matrix per unit speed, used by
``plants.spinning_rotor``) holds the shaft's distributed and the stack's and
hub's lumped polar inertia.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import control
import numpy as np
import scipy.linalg

from lab_modules.plants.radial_bearing import RIG, BearingAxis

STEEL_YOUNGS_PA = 210e9
STEEL_DENSITY_KG_M3 = 7850.0
#: Electrical steel at a stacking factor of 0.95 (7650 kg/m³ × 0.95).
LAMINATION_DENSITY_KG_M3 = 7650.0 * 0.95


def beam_element(length_m: float, bending_stiffness_n_m2: float, mass_per_length_kg_m: float,
                 shear_ratio: float = 0.0):
    """Stiffness and translational consistent mass matrices of one beam element.

    Degrees of freedom (w1, theta1, w2, theta2): displacement [m] and slope
    [rad] at both ends.  ``shear_ratio`` phi = 12 EI / (kappa G A l^2) (Timoshenko,
    Friswell et al. eq. 5.104-5.105); phi = 0 is the Euler-Bernoulli element with
    cubic Hermite shape functions.
    """
    l, phi = length_m, shear_ratio
    K = bending_stiffness_n_m2 / ((1 + phi) * l**3) * np.array([
        [12, 6 * l, -12, 6 * l],
        [6 * l, (4 + phi) * l * l, -6 * l, (2 - phi) * l * l],
        [-12, -6 * l, 12, -6 * l],
        [6 * l, (2 - phi) * l * l, -6 * l, (4 + phi) * l * l]])
    m1, m2, m3 = 312 + 588 * phi + 280 * phi**2, (44 + 77 * phi + 35 * phi**2) * l, 108 + 252 * phi + 140 * phi**2
    m4, m5 = -(26 + 63 * phi + 35 * phi**2) * l, (8 + 14 * phi + 7 * phi**2) * l * l
    m6 = -(6 + 14 * phi + 7 * phi**2) * l * l
    M = mass_per_length_kg_m * l / (840 * (1 + phi) ** 2) * np.array([
        [m1, m2, m3, m4],
        [m2, m5, -m4, m6],
        [m3, -m4, m1, -m2],
        [m4, m6, -m2, m5]])
    return K, M


def rotary_element(length_m: float, section_inertia_kg_m: float, shear_ratio: float = 0.0) -> np.ndarray:
    """Rotary-inertia matrix of one beam element (Friswell et al. eq. 5.106), rho I [kg m] the
    diametral inertia per length; a circular section's polar inertia is twice it, so the
    element's gyroscopic matrix per unit speed is twice this matrix (eq. 5.107)."""
    l, phi = length_m, shear_ratio
    m7, m8 = 36, (3 - 15 * phi) * l
    m9, m10 = (4 + 5 * phi + 10 * phi**2) * l * l, (-1 - 5 * phi + 5 * phi**2) * l * l
    return section_inertia_kg_m / (30 * (1 + phi) ** 2 * l) * np.array([
        [m7, m8, -m7, m8],
        [m8, m9, -m8, m10],
        [-m7, -m8, m7, -m8],
        [m8, m10, -m8, m9]])


def hermite_interpolate(node_z_m: np.ndarray, nodal: np.ndarray, z_m, shear_ratio=0.0) -> np.ndarray:
    """Displacement at positions ``z_m`` from nodal (w, theta) rows (2 per node),
    with the elements' own shape functions (cubic Hermite; with a Timoshenko element's
    ``shear_ratio`` phi, one per element or one for all, Friswell et al. eq. 5.102).
    ``nodal`` may have columns (one per mode); the result has shape (len(z_m), columns)."""
    z = np.atleast_1d(np.asarray(z_m, dtype=float))
    nodal = nodal.reshape(2 * len(node_z_m), -1)
    e = np.clip(np.searchsorted(node_z_m, z, side="right") - 1, 0, len(node_z_m) - 2)
    l = node_z_m[e + 1] - node_z_m[e]
    phi = np.broadcast_to(np.asarray(shear_ratio, dtype=float), (len(node_z_m) - 1,))[e]
    s = (z - node_z_m[e]) / l
    h = np.stack([1 - 3 * s**2 + 2 * s**3 + (1 - s) * phi, l * (s - 2 * s**2 + s**3 + (s - s**2) * phi / 2),
                  3 * s**2 - 2 * s**3 + s * phi, l * (-s**2 + s**3 - (s - s**2) * phi / 2)], axis=1)
    h /= (1 + phi)[:, None]
    rows = np.stack([2 * e, 2 * e + 1, 2 * e + 2, 2 * e + 3], axis=1)
    return np.einsum("pk,pkm->pm", h, nodal[rows])


@dataclass(frozen=True)
class RotorGeometry:
    """The rotor's dimensions [m], masses [kg] and supports (see module docstring)."""

    length_m: float = 0.910
    shaft_diameter_m: float = 0.038
    pivot_m: float = 0.040                    # ball bearing (pivot) from the drive end
    bearing_m: float = 0.800                  # magnetic bearing plane = lamination stack centre
    stack_length_m: float = 0.040
    stack_diameter_m: float = 0.272
    hub_position_m: float = 0.015             # coupling hub at the drive end
    hub_mass_kg: float = 0.45
    hub_diameter_m: float = 0.070
    modal_damping: float = 0.005              # bending modes (not in the paper)

    @property
    def stack_mass_kg(self) -> float:
        area = np.pi / 4 * (self.stack_diameter_m**2 - self.shaft_diameter_m**2)
        return LAMINATION_DENSITY_KG_M3 * area * self.stack_length_m

    @property
    def stack_inertia_kg_m2(self) -> float:
        """Diametral moment of inertia of the stack about its centre, annulus part
        m (D^2 + d^2) / 16; the length part m L^2 / 12 comes from its lumped masses."""
        return self.stack_mass_kg * (self.stack_diameter_m**2 + self.shaft_diameter_m**2) / 16

    @property
    def stack_polar_inertia_kg_m2(self) -> float:
        """Polar moment of inertia of the stack (an annulus): m (D^2 + d^2) / 8."""
        return self.stack_mass_kg * (self.stack_diameter_m**2 + self.shaft_diameter_m**2) / 8

    @property
    def shaft_mass_kg(self) -> float:
        return STEEL_DENSITY_KG_M3 * np.pi / 4 * self.shaft_diameter_m**2 * self.length_m

    @property
    def total_mass_kg(self) -> float:
        return self.shaft_mass_kg + self.stack_mass_kg + self.hub_mass_kg

    @property
    def stack_ends_m(self) -> tuple[float, float]:
        return self.bearing_m - self.stack_length_m / 2, self.bearing_m + self.stack_length_m / 2


def assemble_beam(node_z_m: np.ndarray, bending_stiffness_n_m2: float, mass_per_length_kg_m: float,
                  shear_ratio=0.0):
    """Global stiffness and translational consistent mass matrices of a uniform beam on the
    given nodes (``shear_ratio``: one phi per element or one for all, 0 = Euler-Bernoulli)."""
    lengths = np.diff(node_z_m)
    phi = np.broadcast_to(np.asarray(shear_ratio, dtype=float), lengths.shape)
    n_dof = 2 * len(node_z_m)
    K, M = np.zeros((n_dof, n_dof)), np.zeros((n_dof, n_dof))
    for e, l in enumerate(lengths):
        Ke, Me = beam_element(l, bending_stiffness_n_m2, mass_per_length_kg_m, phi[e])
        dofs = slice(2 * e, 2 * e + 4)
        K[dofs, dofs] += Ke
        M[dofs, dofs] += Me
    return K, M


def assemble_rotary(node_z_m: np.ndarray, section_inertia_kg_m: float, shear_ratio=0.0) -> np.ndarray:
    """Global rotary-inertia matrix of a uniform beam (``rotary_element`` per element)."""
    lengths = np.diff(node_z_m)
    phi = np.broadcast_to(np.asarray(shear_ratio, dtype=float), lengths.shape)
    n_dof = 2 * len(node_z_m)
    R = np.zeros((n_dof, n_dof))
    for e, l in enumerate(lengths):
        R[2 * e:2 * e + 4, 2 * e:2 * e + 4] += rotary_element(l, section_inertia_kg_m, phi[e])
    return R


def solve_modes(K: np.ndarray, M: np.ndarray, constrained_dofs=()) -> tuple[np.ndarray, np.ndarray]:
    """Natural angular frequencies [rad/s] (ascending) and mass-normalised shapes
    (all degrees of freedom, zeros at the constrained ones) of K phi = omega^2 M phi."""
    free = np.setdiff1d(np.arange(K.shape[0]), constrained_dofs)
    omega_sq, vectors = scipy.linalg.eigh(K[np.ix_(free, free)], M[np.ix_(free, free)])
    shapes = np.zeros((K.shape[0], len(free)))
    shapes[free] = vectors
    return np.sqrt(np.maximum(omega_sq, 0.0)), shapes


#: Element theories: Euler-Bernoulli (no shear, no rotary inertia in the mass matrix: ``sensor_placement``'s
#: model) and Timoshenko (shear deformation and rotary inertia).  Both spin with the shaft's polar
#: inertia in the gyroscopic matrix, as ROSS's shaft elements do.
THEORIES = ("euler-bernoulli", "timoshenko")
STEEL_POISSON = 0.3


def cowper_shear_factor(poisson: float = STEEL_POISSON) -> float:
    """Timoshenko shear coefficient kappa of a solid circular section (Cowper 1966):
    kappa = 6 (1 + nu) / (7 + 6 nu)."""
    return 6 * (1 + poisson) / (7 + 6 * poisson)


class FlexibleRotor:
    """Finite-element model of the rotor on its pivot, and its modes.

    ``elements`` sets the mesh density (elements over the whole length); the
    pivot, the stack's ends and centre and the disc are always nodes.  ``theory``
    is one of ``THEORIES``.  Matrices per bending plane: ``K`` [N/m, N, N m],
    ``M`` (translational and, for Timoshenko, rotary inertia) and ``P``, the polar
    inertia [kg m^2 on slopes] whose product with the speed is the gyroscopic
    matrix (``plants.spinning_rotor``).
    """

    def __init__(self, geometry: RotorGeometry = RotorGeometry(), elements: int = 60,
                 theory: str = "euler-bernoulli"):
        if theory not in THEORIES:
            raise ValueError(f"unknown beam theory {theory!r}: expected one of {', '.join(THEORIES)}")
        self.geometry = g = geometry
        self.theory = theory
        key_points = np.array([0.0, g.length_m, g.pivot_m, *g.stack_ends_m, g.bearing_m, g.hub_position_m])
        grid = np.linspace(0.0, g.length_m, elements + 1)
        # a grid node closer than a quarter element to a key point would leave a sliver of an element
        # (ill-conditioned mass matrix); the key point takes its place
        near = np.min(np.abs(grid[:, None] - key_points[None, :]), axis=1) < 0.25 * g.length_m / elements
        self.node_z_m = np.unique(np.round(np.concatenate([grid[~near], key_points]), 9))
        area_m2 = np.pi / 4 * g.shaft_diameter_m**2
        second_moment_m4 = np.pi * g.shaft_diameter_m**4 / 64
        bending_stiffness_n_m2 = STEEL_YOUNGS_PA * second_moment_m4
        shear_modulus_pa = STEEL_YOUNGS_PA / (2 * (1 + STEEL_POISSON))
        # phi = 12 EI / (kappa G A l^2) per element (Friswell et al. eq. 5.103); 0 for Euler-Bernoulli
        self.shear_ratio = (12 * bending_stiffness_n_m2 / (cowper_shear_factor() * shear_modulus_pa * area_m2
                                                           * np.diff(self.node_z_m) ** 2)
                            if theory == "timoshenko" else np.zeros(len(self.node_z_m) - 1))
        self.K, self.M = assemble_beam(self.node_z_m, bending_stiffness_n_m2, STEEL_DENSITY_KG_M3 * area_m2,
                                       self.shear_ratio)
        rotary = assemble_rotary(self.node_z_m, STEEL_DENSITY_KG_M3 * second_moment_m4, self.shear_ratio)
        if theory == "timoshenko":
            self.M += rotary
        self.P = 2 * rotary                  # a circular section's polar inertia is twice its diametral one
        # the stack as a rigid body on its end and centre nodes with Simpson's weights 1/6, 2/3, 1/6:
        # they reproduce its mass and its length's share of inertia (m L^2 / 12) on any mesh
        low, high = g.stack_ends_m
        for z, share in ((low, 1 / 6), (g.bearing_m, 2 / 3), (high, 1 / 6)):
            self.add_lumped(self.node(z), share * g.stack_mass_kg, 0.0)
        self.add_lumped(self.node(g.bearing_m), 0.0, g.stack_inertia_kg_m2, g.stack_polar_inertia_kg_m2)
        self.add_lumped(self.node(g.hub_position_m), g.hub_mass_kg, g.hub_mass_kg * g.hub_diameter_m**2 / 16,
                        g.hub_mass_kg * g.hub_diameter_m**2 / 8)
        self.constrained_dofs = (2 * self.node(g.pivot_m),)

    def node(self, z_m: float) -> int:
        return int(np.argmin(np.abs(self.node_z_m - z_m)))

    def add_lumped(self, node: int, mass_kg: float, inertia_kg_m2: float, polar_inertia_kg_m2: float = 0.0) -> None:
        """A rigid body at a node: mass [kg], diametral and polar moments of inertia [kg m^2]."""
        self.M[2 * node, 2 * node] += mass_kg
        self.M[2 * node + 1, 2 * node + 1] += inertia_kg_m2
        self.P[2 * node + 1, 2 * node + 1] += polar_inertia_kg_m2

    @property
    def total_mass_kg(self) -> float:
        translation = np.tile([1.0, 0.0], len(self.node_z_m))
        return float(translation @ self.M @ translation)

    @cached_property
    def _modes(self) -> tuple[np.ndarray, np.ndarray]:
        omega, shapes = solve_modes(self.K, self.M, self.constrained_dofs)
        # mode 1 is the rigid tilting about the pivot, w = z - z_pivot, theta = 1, which K annihilates
        # exactly; eigh returns it with a round-off frequency of ~eps times the mesh's highest one
        tilting = np.column_stack([self.node_z_m - self.geometry.pivot_m, np.ones(len(self.node_z_m))]).ravel()
        omega[0], shapes[:, 0] = 0.0, tilting / np.sqrt(tilting @ self.M @ tilting)
        # sign convention: every mode moves positively at the free end
        return omega, shapes * np.where(shapes[-2] < 0, -1.0, 1.0)

    def natural_frequencies_hz(self, n_modes: int) -> np.ndarray:
        return self._modes[0][:n_modes] / (2 * np.pi)

    def mode_shapes(self, n_modes: int) -> np.ndarray:
        """Mass-normalised nodal shapes (w, theta per node) of the first modes, one column each."""
        return self._modes[1][:, :n_modes]

    def displacement(self, z_m, n_modes: int) -> np.ndarray:
        """Modal displacements phi_i(z) [m per unit modal coordinate], shape (len(z), n_modes)."""
        return hermite_interpolate(self.node_z_m, self.mode_shapes(n_modes), z_m, self.shear_ratio)

    def nodal_points_m(self, mode: int) -> np.ndarray:
        """Axial positions [m] where mode ``mode`` (0-based) crosses zero (pivot excluded)."""
        z = np.linspace(0.0, self.geometry.length_m, 2001)
        w = self.displacement(z, mode + 1)[:, mode]
        w = np.where(np.abs(w) < 1e-9 * np.max(np.abs(w)), 0.0, w)
        crossing = np.flatnonzero(w[:-1] * w[1:] < 0)
        points = z[crossing] - w[crossing] * (z[crossing + 1] - z[crossing]) / (w[crossing + 1] - w[crossing])
        return points[np.abs(points - self.geometry.pivot_m) > 5e-3]


def modal_plant(rotor: FlexibleRotor, sensor_z_m: float, n_modes: int, sensor_lag_s: float,
                rig: BearingAxis = RIG) -> control.StateSpace:
    """Continuous plant of one bearing axis on the flexible rotor (modal truncation).

    Paper 000 eq. 3-4 and 12 with the rigid mass replaced by ``n_modes`` modes:

        eta_j'' + 2 zeta_j omega_j eta_j' + omega_j^2 eta_j = phi_j(z_b) (k_x x_b + k_i i + f_z)
        x_b = sum_j phi_j(z_b) eta_j          (rotor at the bearing plane)
        x_s = sum_j phi_j(z_s) eta_j          (rotor at the sensor)
        T_a i' + i = K_a i_ref                (eq. 4)
        T_mx x_d' + x_d = x_s                 (eq. 12, dropped when T_mx = 0)

    States (eta_1..n [m·kg^½], eta'_1..n, i [A], x_d [m]); inputs (i_ref [V],
    f_z [N] at the bearing); outputs (K_mx x_d [V], x_b [m], x_s [m], K_mi i [V]).
    """
    omega = 2 * np.pi * rotor.natural_frequencies_hz(n_modes)
    zeta = np.where(omega > 1e-6, rotor.geometry.modal_damping, 0.0)
    phi_b = rotor.displacement(rotor.geometry.bearing_m, n_modes)[0]
    phi_s = rotor.displacement(sensor_z_m, n_modes)[0]
    lag = sensor_lag_s > 0
    n = 2 * n_modes + 1 + lag
    A, B, C = np.zeros((n, n)), np.zeros((n, 2)), np.zeros((4, n))
    modal, rate, current = slice(0, n_modes), slice(n_modes, 2 * n_modes), 2 * n_modes
    A[modal, rate] = np.eye(n_modes)
    A[rate, modal] = -np.diag(omega**2) + rig.kx_n_per_m * np.outer(phi_b, phi_b)
    A[rate, rate] = -np.diag(2 * zeta * omega)
    A[rate, current] = rig.ki_n_per_a * phi_b
    A[current, current] = -1.0 / rig.amplifier_lag_s
    B[current, 0] = rig.amplifier_gain_a_per_v / rig.amplifier_lag_s
    B[rate, 1] = phi_b
    if lag:
        A[-1, modal], A[-1, -1] = phi_s / sensor_lag_s, -1.0 / sensor_lag_s
        C[0, -1] = rig.position_sensor_gain_v_per_m
    else:
        C[0, modal] = rig.position_sensor_gain_v_per_m * phi_s
    C[1, modal], C[2, modal] = phi_b, phi_s
    C[3, current] = rig.current_sensor_gain_v_per_a
    return control.ss(A, B, C, np.zeros((4, 2)), inputs=["i_ref", "f_z"],
                      outputs=["y_position", "x_bearing", "x_sensor", "y_current"])
