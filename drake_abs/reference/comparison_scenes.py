"""The two scenes on which this package's plant is compared with Drake's contact models: a planar
box pushed off that slides to rest on its two bottom edges, and a ball dropped and thrown
horizontally that lands, slides and rolls. Every simulator gets the same masses, friction and
initial state; :class:`ComparisonScenes` holds the settings and makes each scene, its start,
Drake's contact material and the rigid-body answers (slopes, the box's Coulomb slide) the
simulators are measured against; :func:`box_metrics` and :func:`ball_metrics` measure a
trajectory of each (penetration, the box's slide and hop, the ball's rebound, rest and slip).

- ``"box"``: the shipped scene ``box_push`` (``box_planar.sdf``: x, z, pitch; contact points at
  its four edges in the x-z plane), resting on the ground (centre at ``BOX_HALF[1]``) and moving
  at ``box_speed`` along x, pushed by a constant actuation ``box_push`` (N).
- ``"ball"``: the 0.2 kg ball of ``ball.sdf`` (radius :data:`BALL_RADIUS`; floating base as
  joints, q = (x, y, z, yaw, pitch, roll)), its centre at ``ball_height`` and moving at
  ``ball_speed`` along +y, so that it rolls about x (the roll angle has no singularity). It has
  no actuator.

Units: SI (m, s, kg, N); mu in N s m. A larger mu is more smoothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs.multibody.scene import Scene

__all__ = [
    "BALL_RADIUS", "BOX_HALF", "GRAVITY", "SCENES", "ComparisonScenes", "ball_metrics",
    "box_metrics",
]  # fmt: skip

#: The scenes' names, in the order of the per-scene settings (box, ball).
SCENES = ("box", "ball")
GRAVITY = 9.81  # m/s^2
BOX_HALF = (0.2, 0.1)  # half length (x) and half height (z) of the box, m
#: The ball's radius, m.
BALL_RADIUS = 0.05


@dataclass(frozen=True)
class ComparisonScenes:
    """The box and the ball, and what every simulator of them shares.

    Attributes:
        time_step: the step h the scenes are stated at (s).
        friction: Coulomb coefficient of every contact (Drake: static = dynamic).
        box_speed, box_push: the box's initial x velocity (m/s) and constant actuation (N).
        box_duration: simulated seconds of the box after the push.
        ball_height, ball_speed: the ball's initial centre height (m) and speed along y (m/s).
        ball_duration: simulated seconds of the ball.
        abs_mu_max, abs_length: ABS (contact-aware) parameters per scene (box, ball): mu at
            contact (N s m, at ``time_step``) and decay length (m).
        activation_distance: our plant's activation distance per scene (box, ball), m.
        point_stiffness, hunt_crossley_dissipation, relaxation_time: Drake's point contact
            (N/m, s/m, s; Drake's documented defaults).
    """

    time_step: float = 0.01
    friction: float = 0.5
    box_speed: float = 1.0
    box_push: float = 0.0
    box_duration: float = 0.5
    ball_height: float = 0.3
    ball_speed: float = 1.0
    ball_duration: float = 2.0
    abs_mu_max: tuple[float, float] = (1e-3, 1e-4)
    abs_length: tuple[float, float] = (0.02, 0.02)
    activation_distance: tuple[float, float] = (0.05, 0.1)
    point_stiffness: float = 1.0e6
    hunt_crossley_dissipation: float = 50.0
    relaxation_time: float = 0.1

    def scene(self, name: str, time_step: float | None = None) -> Scene:
        """Scene ``name`` (``"box"`` or ``"ball"``) at ``time_step`` (s; default
        ``self.time_step``), exact contact (a stepper's smoothing is chosen when it is made)."""
        i = _index(name)
        if name == "box":
            data = Scene.load("box_push").to_dict()
            for c in data["contacts"]:
                c["friction"] = self.friction
            data["initial_state"] = {"q": [0.0, BOX_HALF[1], 0.0], "v": [self.box_speed, 0.0, 0.0]}
        else:
            data = {
                "name": "ball_throw",
                "models": [{"file": "drake_abs:models/ball.sdf"}],
                "contacts": [{"body": "ball", "points": [[0.0, 0.0, 0.0]], "radius": BALL_RADIUS,
                              "friction": self.friction}],
                "friction_directions": 4,
                "initial_state": {"q": [0.0, 0.0, self.ball_height, 0.0, 0.0, 0.0],
                                  "v": [0.0, self.ball_speed, 0.0, 0.0, 0.0, 0.0]},
            }  # fmt: skip
        data.update(
            time_step=time_step or self.time_step,
            smoothing={"kind": "exact"},
            activation_distance=self.activation_distance[i],
        )
        return Scene.from_dict(data)

    def start(self, name: str) -> tuple[np.ndarray, np.ndarray, float]:
        """(x_0 (nx,), the constant input u (nu,), the simulated seconds) of scene ``name``:
        the box from rest on the ground with ``u = (box_push,)``; the ball with no input."""
        if name == "box":
            x0 = np.array([0.0, BOX_HALF[1], 0.0, self.box_speed, 0.0, 0.0])
            return x0, np.array([self.box_push]), self.box_duration
        _index(name)
        x0 = np.zeros(12)
        x0[2], x0[7] = self.ball_height, self.ball_speed
        return x0, np.zeros(0), self.ball_duration

    def drake_material(self) -> dict[str, float]:
        """Drake's point-contact parameters, as
        :class:`~drake_abs.reference.drake_plant.DrakePlantStepper` takes them."""
        return {
            "point_stiffness": self.point_stiffness,
            "hunt_crossley_dissipation": self.hunt_crossley_dissipation,
            "relaxation_time": self.relaxation_time,
        }

    def rigid_slopes(self, name: str) -> dict[str, float]:
        """Derivatives of the final state of rigid bodies with continuous-time Coulomb friction
        (no compliance, no restitution), by name (``"dx_T/dvx_0"``: d x_T / d v_x0). The box
        decelerates at ``a = mu g - u / m`` (m = 1 kg) until it stops; the ball falls for
        ``t_l = sqrt(2 (z_0 - r) / g)``, lands inelastically and rolls at 5/7 of v_0. Left out:
        d x_T / d z_0 of the box resting on the ground (raised by d it flies for sqrt(2 d / g)
        without friction: not differentiable at d = 0)."""
        if name == "box":
            a = self.friction * GRAVITY - self.box_push
            v0, T = self.box_speed, self.box_duration
            if a > 0 and v0 / a <= T:  # stopped by T
                return {"dx_T/dvx_0": v0 / a, "dx_T/du": v0**2 / (2 * a**2), "dvx_T/dvx_0": 0.0,
                        "dz_T/dz_0": 0.0, "dpitch_T/dvx_0": 0.0}  # fmt: skip
            return {"dx_T/dvx_0": T, "dx_T/du": T**2 / 2, "dvx_T/dvx_0": 1.0, "dz_T/dz_0": 0.0,
                    "dpitch_T/dvx_0": 0.0}  # fmt: skip
        _index(name)
        v0, T = self.ball_speed, self.ball_duration
        t_land = np.sqrt(2 * (self.ball_height - BALL_RADIUS) / GRAVITY)
        return {
            "dy_T/dvy_0": float(t_land + 5 / 7 * (T - t_land)),
            "dvy_T/dvy_0": 5 / 7,
            "dy_T/dz_0": float(2 / 7 * v0 / (GRAVITY * t_land)),
            "dz_T/dz_0": 0.0,
            "droll_T/dvy_0": float(-5 / 7 * (T - t_land) / BALL_RADIUS),
        }

    def coulomb_slide(self, time_step: float) -> dict[str, float | None]:
        """The box's slide (m) over ``box_duration`` on rigid ground with Coulomb friction, from
        ``box_speed`` under the push, decelerating at ``a = mu g - u / m`` (m = 1 kg; m/s^2,
        ``deceleration_mps2``): ``continuous_m`` = v0 t - a t^2 / 2 (t the stop time or the
        duration) and ``discrete_m`` = h sum_k max(0, v0 - a h k) over the steps k = 1, 2, ...
        of ``time_step`` = h (s) within the duration (semi-implicit Euler). Both None when the
        push overcomes friction (a <= 0)."""
        if not (isinstance(time_step, (int, float)) and np.isfinite(time_step) and time_step > 0):
            raise ValueError(f"time_step must be a number > 0 (s); got {time_step!r}")
        a = self.friction * GRAVITY - self.box_push / 1.0
        if a <= 0:
            return {"continuous_m": None, "discrete_m": None}
        v0, dv, T = self.box_speed, a * time_step, self.box_duration
        k = np.arange(1, min(int(np.floor(v0 / dv)), int(round(T / time_step))) + 1)
        t = min(T, v0 / a)
        discrete = float(time_step * np.sum(v0 - dv * k))
        return {
            "continuous_m": v0 * t - a * t**2 / 2,
            "discrete_m": discrete,
            "deceleration_mps2": a,
        }


def box_metrics(xs: np.ndarray, x0: np.ndarray, slide: dict | None = None) -> dict:
    """Measures of a box trajectory: xs (N, 6) states (x, z, pitch, their rates; m, rad, m/s,
    rad/s) from x0 (6,), the state it was pushed from: the slide ``xs[-1, 0] - x0[0]`` (m), the
    deepest penetration of its two bottom edges over the run and at the first state (m, >= 0),
    the hop (the highest rise of the centre above ``x0``'s, m), the final position, pitch and
    speed, and the slide's relative error against ``slide``'s ``continuous_m`` and
    ``discrete_m`` (:meth:`ComparisonScenes.coulomb_slide`; None where that is None)."""
    xs, x0 = np.asarray(xs, dtype=float), np.asarray(x0, dtype=float)
    if xs.ndim != 2 or xs.shape[1] != 6 or x0.shape != (6,):
        raise ValueError(f"xs must be (N, 6) and x0 (6,); got {xs.shape}, {x0.shape}")
    z, pitch, (a, c) = xs[:, 1], xs[:, 2], BOX_HALF  # the two bottom edges' heights:
    corners = np.stack([z - s * a * np.sin(pitch) - c * np.cos(pitch) for s in (-1.0, 1.0)], 1)
    moved = float(xs[-1, 0] - x0[0])
    out = {
        "slide_m": moved,
        "max_penetration_m": float(max(0.0, -corners.min())),
        "rest_penetration_before_push_m": float(max(0.0, -corners[0].min())),
        "hop_m": float(np.max(xs[:, 1]) - x0[1]),
        "final": {"x_m": float(xs[-1, 0]), "z_m": float(xs[-1, 1]), "pitch_rad": float(xs[-1, 2]),
                  "speed_mps": float(np.linalg.norm(xs[-1, 3:]))},
    }  # fmt: skip
    for key in ("continuous", "discrete"):
        ref = (slide or {}).get(f"{key}_m")
        out[f"rel_err_vs_{key}"] = None if ref is None else (moved - ref) / ref
    return out


def ball_metrics(xs: np.ndarray) -> dict:
    """Measures of a ball trajectory: xs (N, 12) states (x, y, z, yaw, pitch, roll, their
    rates; m, rad, m/s, rad/s); the ball rolls about x, so only roll turns. The deepest
    penetration (m, >= 0), the first impact step (the first step whose vertical speed turns
    from down to up; the last step if none), the highest ground clearance from it on
    (``rebound_height_m``) and at the end (``rest_height_m``; negative: penetration), and the
    final y, v_y, v_z, roll rate and slip (the contact point's velocity along y, m/s)."""
    xs = np.asarray(xs, dtype=float)
    if xs.ndim != 2 or xs.shape[1] != 12:
        raise ValueError(f"xs must be (N, 12) ball states; got {xs.shape}")
    phi, vz = xs[:, 2] - BALL_RADIUS, xs[:, 8]
    going_up = np.flatnonzero((vz[1:] >= 0) & (vz[:-1] < 0))  # the first impact step
    impact = int(going_up[0]) + 1 if going_up.size else len(xs) - 1
    vy, wx = xs[-1, 7], xs[-1, 11]
    return {
        "max_penetration_m": float(max(0.0, -phi.min())),
        "impact_step": impact,
        "rebound_height_m": float(phi[impact:].max()),
        "rest_height_m": float(phi[-1]),
        "final": {"y_m": float(xs[-1, 1]), "vy_mps": float(vy), "vz_mps": float(vz[-1]),
                  "roll_rate_radps": float(wx), "slip_mps": float(vy + BALL_RADIUS * wx)},
    }  # fmt: skip


def _index(name: str) -> int:
    if name not in SCENES:
        raise ValueError(f"scene must be one of {SCENES}; got {name!r}")
    return SCENES.index(name)
