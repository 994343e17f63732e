"""A body translating in the vertical x-z plane on frictional ground, as a constant-matrix LCS:
the box of Zhang et al. 2023, Figure 6b (and the ball of section 8.3 once it has landed).

Without rotation the mass matrix ``M = m I`` and the contact Jacobians are constant, so the
rigid-body time-stepping LCP of docs/math.md section 6 (:mod:`drake_abs.contact.contact_lcp`) is
affine in the state and input: it is an :class:`~drake_abs.contact.lcs.LCS`. One contact, at the
bottom of the body, with a linearised friction cone of k = 2 directions (+x, -x):

    v+ = v + h (u e_x / m - g e_z) + (1/m) (e_z gamma + e_x (beta_1 - beta_2))      (N s)
    p+ = p + h v+
    lam = (gamma, beta_1, beta_2, omega)


and the LCP rows, matrix F and offsets z are those of
:func:`drake_abs.contact.stewart_trinkle.assemble_lcp` (built by calling it, not re-derived here):
normal (m), two friction rows (m/s) with the same tangential regularisation, and the cone row (N s).

State ``x = (p_x, p_z, v_x, v_z)`` (m, m/s; p_z is the height of the body's centre, the ground
is z = 0), input ``u`` the horizontal push (N). The frictional F is copositive but not a
P-matrix: the LCS is built with ``on_bad_matrix="attempt"`` (no matrix check; convergence is
reported per step) and the contact solver defaults of
:mod:`drake_abs.contact.contact_lcp`.

Smoothing is applied per contact as :func:`drake_abs.contact.contact_lcp.contact_step` applies it:
the policy sees only the normal row (distance and compliance) and its mu (m N s; **larger is
smoother**) is given to the normal row, mu / h to the friction and cone rows
(:class:`PerContactSmoothing`). Use :meth:`TranslatingBox.stepper` to get the two together.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from drake_abs.contact.cone import FrictionCone, expand_mu
from drake_abs.contact.contact_lcp import CONTACT_SOLVER_DEFAULTS
from drake_abs.contact.lcs import LCS, GradientMode, LcsStepper
from drake_abs.contact.smoothing import Exact, Smoothing, WrappedSmoothing
from drake_abs.contact.step_data import StepQuantities
from drake_abs.contact.stewart_trinkle import assemble_lcp

#: Tangent directions of the planar cone, in (x, z) velocity coordinates: +x, -x (the order of
#: ``systems.multibody_quantities.tangent_directions`` for the normal +z and k = 2).
_TANGENTS = np.array([[1.0, 0.0], [-1.0, 0.0]])
_NORMAL = np.array([[0.0, 1.0]])


@dataclass(frozen=True)
class PerContactSmoothing(WrappedSmoothing):
    """A smoothing applied to a frictional LCP's rows the way ``contact_step`` does.

    ``contact`` sees the normal rows (z (B, nc), F_nn) and gives one mu per contact (larger is
    smoother); friction and cone rows of that contact get mu / h. In the ``total`` gradient mode
    mu is differentiated through the normal rows' z only. Its numeric parameters are
    ``contact``'s.
    """

    contact: Smoothing
    cone: FrictionCone
    time_step: float

    inner_field = "contact"

    def _rows(self, z, F, contact_level, square: bool = False) -> np.ndarray:
        """A contact-level quantity ``contact_level(z_n, F_nn)`` (B, nc, ...) on the rows
        (B, d, ...); with ``square`` its trailing contact axis padded to the d rows (a derivative
        with respect to the rows' z or F diagonal, zero for friction and cone rows)."""
        nc = self.cone.sizes()[0]
        Z = np.atleast_2d(z)
        value = contact_level(Z[:, :nc], F[..., :nc, :nc])
        rows = expand_mu(np.atleast_2d(value), self.cone, self.time_step)
        if square:
            out = np.zeros(Z.shape + Z.shape[-1:])
            out[:, :, :nc] = rows
            rows = out
        return rows.reshape(z.shape + rows.shape[2:])

    def mu(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self._rows(z, F, self.contact.mu)

    def dmu_dz(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self._rows(z, F, self.contact.dmu_dz, square=True)

    def dmu_dparameters(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self._rows(z, F, self.contact.dmu_dparameters)

    def dmu_dF_diagonal(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self._rows(z, F, self.contact.dmu_dF_diagonal, square=True)


@dataclass(frozen=True)
class TranslatingBox:
    """A body of mass ``mass`` (kg) translating in x-z on the ground z = 0, one frictional
    contact at its bottom, ``half_height`` (m) below its centre.

    Attributes:
        mass: kg. half_height: m. friction: Coulomb coefficient (>= 0). time_step: h in s.
        gravity: m/s^2. regularization: the cone's tangential compliance (see
            :class:`~drake_abs.contact.cone.FrictionCone`).
        lcs: the LCS (dx = 4, du = 1, d = 4), built at construction.
        cone: the friction cone (one contact, k = 2).
    """

    mass: float = 1.0
    half_height: float = 0.1
    friction: float = 0.5
    time_step: float = 0.01
    gravity: float = 9.81
    regularization: float = 1e-8
    lcs: LCS = field(init=False, repr=False, compare=False)
    cone: FrictionCone = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        for name in ("mass", "time_step"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(
                    f"TranslatingBox.{name} must be a finite number > 0; got {value!r}"
                )
        for name in ("half_height", "friction", "gravity"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"TranslatingBox.{name} must be finite and >= 0; got {value!r}")
        cone = FrictionCone(np.array([self.friction]), 2, self.regularization)
        object.__setattr__(self, "cone", cone)
        object.__setattr__(self, "lcs", self._build())

    def _lcp_rows(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``assemble_lcp`` at a batch of states x (B, 4) and pushes u (B, 1): F, z."""
        h, m, g = self.time_step, self.mass, self.gravity
        B = x.shape[0]
        v_free = x[:, 2:] + h * (np.column_stack([u[:, 0], np.zeros(B)]) / m - [0.0, g])
        quant = StepQuantities(
            q=x[:, :2],
            v=x[:, 2:],
            W=np.broadcast_to(np.eye(2) / m, (B, 2, 2)),
            v_free=v_free,
            phi=x[:, 1:2] - self.half_height,
            Jn=np.broadcast_to(_NORMAL, (B, 1, 2)),
            Jt=np.broadcast_to(_TANGENTS, (B, 2, 2)),
            N=np.broadcast_to(np.eye(2), (B, 2, 2)),
        )
        F, z, _ = assemble_lcp(quant, self.cone, h)
        return F, z

    def _build(self) -> LCS:
        h, m, g = self.time_step, self.mass, self.gravity
        # z is affine in (x, u): evaluate the contact LCP at the origin and the unit vectors
        basis = np.vstack([np.zeros(5), np.eye(5)])
        F, z = self._lcp_rows(basis[:, :4], basis[:, 4:])
        d = z[0]
        DE = (z[1:] - d).T  # (4 rows, 5 columns)
        eye = np.eye(2)
        WGt = np.hstack([_NORMAL.T, _TANGENTS.T]) / m  # (2, 3): v+ = v_free + W G^T lam_v
        Cv = np.hstack([WGt, np.zeros((2, 1))])  # omega does not act on v
        A = np.block([[eye, h * eye], [np.zeros((2, 2)), eye]])
        Bv = np.array([[1.0 / m], [0.0]])
        return LCS(
            A=A,
            B=np.vstack([h * h * Bv, h * Bv]),
            C=np.vstack([h * Cv, Cv]),
            c=np.array([0.0, -h * h * g, 0.0, -h * g]),
            D=DE[:, :4],
            E=DE[:, 4:],
            F=F[0],
            d=d,
            on_bad_matrix="attempt",
            solver_options=dict(CONTACT_SOLVER_DEFAULTS),
            time_step=h,
        )

    def smoothing(self, contact: Smoothing | None = None) -> PerContactSmoothing:
        """The per-contact policy ``contact`` (default Exact) applied to this LCS's rows."""
        return PerContactSmoothing(
            Exact() if contact is None else contact, self.cone, self.time_step
        )

    def stepper(
        self, contact: Smoothing | None = None, gradient: GradientMode = "total"
    ) -> LcsStepper:
        """A batched :class:`~drake_abs.contact.lcs.LcsStepper` of this box."""
        return LcsStepper(self.lcs, self.smoothing(contact), gradient)

    def resting_state(self, p_x: float = 0.0, v_x: float = 0.0) -> np.ndarray:
        """``(p_x, half_height, v_x, 0)``: on the ground, (optionally) sliding."""
        return np.array([p_x, self.half_height, v_x, 0.0])
