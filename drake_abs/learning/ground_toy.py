"""The 1-D toy of Bianchini et al. (2022, section 2.2): a point mass falling onto ground whose
height theta is the parameter to learn, with perfectly inelastic contact.

State ``x = (z, v)`` (height in m, velocity in m/s, up positive), output ``y = v'`` (m/s), the
velocity after one step of ``dt`` seconds. As a linear complementarity system (the time-stepping
LCP, with impulse ``lam`` in N s): ::

    v' = v - a dt + lam / m                                   (their eq. 8, g)
    0 <= lam  _|_  w = z + v' dt - theta = q + (dt / m) lam >= 0,
    q = z + (v - a dt) dt - theta,

whose solution gives the explicit model (their eq. 7) ::

    f(x; theta) = v - a dt + pos(-v + a dt + (theta - z) / dt).

The implicit form pairs ``lam`` with the gap ``phi = z + v' dt - theta`` at the end of the step
(their eq. 9's h). Here the explicit model is computed through drake-abs's LCP solver
(:func:`drake_abs.solve_lcp`) at any central-path value mu (**larger mu: smoother**; mu = 0 is
eq. 7), with its derivative in theta from the implicit function theorem.

Units: m, s, kg, N s. Defaults are the paper's (phi_max 8 m, v_max 15 m/s, a 9.81 m/s^2,
dt 0.005 s, m 1 kg).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs.lcp.ipm import solve_lcp
from drake_abs.learning.violation import ViolationLoss, neg, pos, violation_loss


@dataclass(frozen=True)
class GroundToy:
    """The toy's constants: mass m (kg), gravity a (m/s^2), time step dt (s), and the data
    domain: heights above the ground up to ``phi_max`` (m), speeds up to ``v_max`` (m/s)."""

    m: float = 1.0
    a: float = 9.81
    dt: float = 0.005
    phi_max: float = 8.0
    v_max: float = 15.0

    def __post_init__(self):
        for name in ("m", "a", "dt", "phi_max", "v_max"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0; got {value!r}")

    @property
    def lambda_max(self) -> float:
        """The largest impulse on the domain, ``m (v_max + a dt)`` (N s): stopping a mass
        falling at v_max within one step."""
        return self.m * (self.v_max + self.a * self.dt)

    # -- the explicit model ------------------------------------------------------------------

    def f(self, theta: float, z: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Eq. 7 in closed form: the next velocity (m/s) for heights z and velocities v."""
        z, v = np.asarray(z, float), np.asarray(v, float)
        return v - self.a * self.dt + pos(-v + self.a * self.dt + (theta - z) / self.dt)

    def lcp(self, theta: float, z: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The step's LCP ``(F, q)``: F (1, 1) = dt / m (m per N s), q (B, 1) in m."""
        z, v = np.atleast_1d(np.asarray(z, float)), np.atleast_1d(np.asarray(v, float))
        q = z + (v - self.a * self.dt) * self.dt - theta
        return np.array([[self.dt / self.m]]), q[:, None]

    def predict(
        self, theta: float, z: np.ndarray, v: np.ndarray, mu: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The explicit model through the LCP solver at central-path value mu (mu = 0: eq. 7).

        Returns ``(v_next, dv_next_dtheta, converged)``, each (B,). Non-converged solves are
        flagged, not hidden (their values are the solver's last iterate).
        """
        F, q = self.lcp(theta, z, v)
        r = solve_lcp(F, q, mu, jacobians=True)
        lam = r.lam[:, 0]
        dlam_dtheta = -r.dlam_dq[:, 0, 0]  # dq/dtheta = -1
        v0 = np.atleast_1d(np.asarray(v, float))
        return v0 - self.a * self.dt + lam / self.m, dlam_dtheta / self.m, r.converged

    # -- the implicit model ------------------------------------------------------------------

    def g(self, z: np.ndarray, v: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """Eq. 8: the next velocity (m/s) for impulse lam (N s); independent of theta."""
        return np.asarray(v, float) - self.a * self.dt + np.asarray(lam, float) / self.m

    def gap(self, theta: float, z: np.ndarray, v_next: np.ndarray) -> np.ndarray:
        """``phi = z + v' dt - theta`` (m), the height above the ground at the step's end."""
        return np.asarray(z, float) + np.asarray(v_next, float) * self.dt - theta

    def h(self, theta: float, z, v, v_next, lam) -> np.ndarray:
        """Eq. 9: ``1/2 neg(phi)^2 + 1/2 neg(lam)^2 + pos(phi) pos(lam)`` with phi the gap at
        the step's end; zero exactly when lam and phi are complementary."""
        phi = self.gap(theta, z, v_next)
        lam = np.asarray(lam, float)
        return 0.5 * neg(phi) ** 2 + 0.5 * neg(lam) ** 2 + pos(phi) * pos(lam)

    # -- the three losses (per data point) ---------------------------------------------------

    def explicit_loss(
        self, theta: float, z, v, y, mu: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(y - f(x))^2`` (their eq. 2) through the solver at mu, its derivative in theta,
        and the solver's converged flags; each (B,)."""
        pred, dpred, ok = self.predict(theta, z, v, mu)
        res = np.asarray(y, float) - pred
        return res**2, -2.0 * res * dpred, ok

    def naive_implicit_loss(self, theta: float, z, v, y) -> tuple[np.ndarray, np.ndarray]:
        """``(y - g(x, lam*))^2`` with ``lam* = argmin_lam h(x, g(x, lam), lam)`` (their eq.
        3): h's minimum, 0, is attained at the LCP's solution (complementary gap and impulse),
        so lam* is the exact solve and this loss equals the explicit one (shared parameters,
        as the paper notes). Returns the loss and its derivative in theta, each (B,)."""
        loss, grad, ok = self.explicit_loss(theta, z, v, y, mu=0.0)
        if not ok.all():
            raise RuntimeError("the exact LCP solve did not converge")
        return loss, grad

    def violation_implicit_loss(self, theta: float, z, v, y, eps: float) -> ViolationLoss:
        """Their eq. 4: ``min_lam (y - g(x, lam))^2 + h(x, y, lam) / eps`` with the gap at the
        observed y, and its gradient in theta (one column): see
        :func:`drake_abs.learning.violation.violation_loss`."""
        z, v, y = (np.atleast_1d(np.asarray(a, float)) for a in (z, v, y))
        B = y.size
        g0 = self.g(z, v, 0.0)[:, None]
        D = np.full((B, 1, 1), 1.0 / self.m)
        phi = self.gap(theta, z, y)[:, None]
        return violation_loss(y[:, None], g0, D, phi, eps, dphi=np.full((B, 1, 1), -1.0))

    # -- data ----------------------------------------------------------------------------------

    def sample(
        self, rng: np.random.Generator, n: int, theta: float, noise: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """n data points ``(z, v, y)`` on the domain: heights above the ground uniform in
        [0, phi_max], velocities uniform in [-v_max, v_max], y from eq. 7 at the true theta
        plus Gaussian noise of standard deviation ``noise`` (m/s)."""
        z = theta + rng.uniform(0.0, self.phi_max, n)
        v = rng.uniform(-self.v_max, self.v_max, n)
        y = self.f(theta, z, v) + noise * rng.standard_normal(n)
        return z, v, y
