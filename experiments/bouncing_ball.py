"""The bouncing ball of Zhang et al. (2023) (Figure 1a, Figure 2), exact and smoothed.

A ball is thrown horizontally and hits the ground. The same LCS is run under hard contact (Exact),
barrier smoothing (BS, fixed mu) at a few mu, and adaptive barrier smoothing (ABS: contact-aware
and Gaussian-matched), side by side in one Drake diagram. Written to the results folder:

- ``vy_vs_x.png``: vertical velocity against horizontal position (Zhang et al. 2023, Figure 2a);
- ``dvy_dx.png``: its derivative along the trajectory (Figure 2b; -g / v_x away from contact, an
  impulse at contact for Exact, a bump of finite height when smoothed);
- ``step_jacobian.png``: the implicit one-step Jacobian d v_y+ / d y (the stiffness ABS targets);
- ``contact_impulse.png``: impulse against contact distance for each policy (Figure 1d);
- ``bouncing_ball.html``: a self-contained Meshcat recording of all balls;
- ``summary.json``: per case, the numbers behind the plots.

:func:`guide` says what to look at in each file (``drake-abs demo`` prints it).

Two things the plots show that follow from how ABS is defined, not from a fault:

- **The ABS impulse jumps at z = 0.** Contact-aware ABS
  (:class:`~drake_abs.contact.smoothing.ContactAware`, Zhang et al. 2023, Algorithm 1) sets
  ``mu = mu_min + (mu_max - mu_min) exp(-dist / length)`` from the distance ``dist`` of the
  nearest *inactive* contact (``z > 0``, z the LCP's contact distance: the gap the free step
  would leave), and ``mu = mu_min`` once every contact is active (``z <= 0``). Here
  ``mu_min = 0``: an active contact is solved exactly (the solver reports the requested 0 as its
  exact floor, about 1e-34 here, ``LCPResult.mu_target``). As z falls to 0 from above, mu rises
  to ``mu_max`` and the softened impulse ``lam = (sqrt(z^2 + 4 mu h / m) - z) m / (2 h)`` rises
  to ``sqrt(mu_max m / h)`` (1 N s with the defaults: ``mu_max = 1e-2`` N s m, m = 1 kg,
  h = 0.01 s); at ``z = 0`` the contact is active, mu drops to 0 and the impulse to the exact
  one, 0. So ``contact_impulse.png`` has a step of ``sqrt(mu_max m / h)`` at z = 0, and in a
  rollout the last step before touching gets up to that impulse. The jump is the method's: mu
  is non-increasing in the distance with its largest value at contact, and exact once the
  contact is active; a schedule continuous at z = 0 would have to smooth active contacts too, or
  lower mu again just before contact. The ``total`` gradient mode differentiates g, not the
  jump.
- **ABS and exact contact have the same largest one-step Jacobian.** While the contact is
  active ABS is exact contact (``mu = 0``), so in those steps both have
  ``|d v_y+ / d y| = 1/h`` (the active-set Jacobian of ``lam = -z m / h``): the largest value
  over a whole rollout (the ball rests on the ground for most of it) is 1/h for both. They
  differ only while the ball approaches (``z > 0``), where exact contact's Jacobian is 0 and
  ABS's is what its smoothing adds; the summary reports the two maxima separately
  (``max_abs_dvy_plus_dy_approaching``, ``max_abs_dvy_plus_dy_in_contact``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, GaussianMatched, Smoothing
from drake_abs.experiments.outputs import (
    file_list,
    pyplot,
    readable,
    results_dir,
    save_figure,
    write_json,
)
from drake_abs.lcp.ipm import solve_lcp
from drake_abs.tasks.point_mass import point_mass_lcs

NAME = "bouncing-ball"


@dataclass(frozen=True)
class Config:
    """Scene and smoothing settings (SI units: s, m, kg, m/s)."""

    time_step: float = 0.01
    duration: float = 1.0
    height: float = 1.0
    speed: float = 1.0
    mass: float = 1.0
    gravity: float = 9.81
    bs_mu: tuple[float, ...] = (1e-4, 1e-3, 1e-2)
    abs_mu_max: float = 1e-2
    abs_length: float = 0.05
    gaussian_sigma: float = 0.02
    meshcat: bool = True

    def __post_init__(self):
        for key in ("time_step", "duration", "height", "speed", "mass", "gravity"):
            value = getattr(self, key)
            if not (isinstance(value, int | float) and np.isfinite(value) and value > 0):
                raise ValueError(f"Config.{key} must be a finite number > 0; got {value!r}")
        if self.duration < self.time_step:
            raise ValueError(
                f"Config.duration must be at least one time step ({self.time_step:g} s); "
                f"got {self.duration!r}"
            )

    @classmethod
    def test_size(cls) -> Config:
        """The reduced size CI runs (0.6 s: the first impact and the bounce)."""
        return cls(duration=0.6)

    def labels(self) -> dict[str, str]:
        """Case name -> the readable name the plots and the report use."""
        return {name: readable(name) for name in self.cases()}

    def cases(self) -> dict[str, Smoothing]:
        """Case name -> smoothing (larger mu = more smoothing)."""
        out: dict[str, Smoothing] = {"exact": Exact()}
        for mu in self.bs_mu:
            out[f"bs_mu={mu:g}"] = Fixed(mu)
        out["abs_contact_aware"] = ContactAware(mu_max=self.abs_mu_max, length=self.abs_length)
        out["abs_gaussian"] = GaussianMatched(sigma=self.gaussian_sigma)
        return out


def simulate(config: Config, *, meshcat=None) -> dict[str, np.ndarray]:
    """Run every case in one Drake diagram; returns name -> states (N + 1, 4) as logged."""
    from pydrake.systems.analysis import Simulator

    from drake_abs.diagrams.point_mass_scene import make_point_mass_scene

    lcs = point_mass_lcs(2, time_step=config.time_step, mass=config.mass, gravity=config.gravity)
    scene = make_point_mass_scene(lcs, config.cases(), dim=2, meshcat=meshcat)
    simulator = Simulator(scene.diagram)
    context = simulator.get_mutable_context()
    x0 = np.array([0.0, config.height, config.speed, 0.0])
    for plant in scene.plants.values():
        plant.SetInitialState(plant.GetMyMutableContextFromRoot(context), x0)
    n = int(round(config.duration / config.time_step))
    if meshcat is not None:
        frame_camera(meshcat, config)
        meshcat.StartRecording(1.0 / config.time_step, False)
    simulator.AdvanceTo(n * config.time_step)
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
    return {name: log.FindLog(context).data().T[: n + 1] for name, log in scene.state_logs.items()}


def frame_camera(meshcat, config: Config) -> None:
    """Point the Meshcat camera at the balls' flight (the balls move in the x-z plane, spread
    in depth along y): from the front, a little to the side and above, far enough to see the
    whole throw."""
    reach = config.speed * config.duration  # m travelled along x
    target = np.array([0.5 * reach, 0.0, 0.4 * config.height])
    extent = max(reach, config.height, 0.5)
    direction = np.array([0.25, -1.0, 0.3])
    camera = target + 1.7 * extent * direction / np.linalg.norm(direction)
    meshcat.SetCameraPose(camera, target)


def step_jacobians(config: Config, states: np.ndarray, smoothing) -> np.ndarray:
    """The implicit one-step Jacobians (N, 4, 4) along a logged trajectory (frozen mu, as paper
    000 Algorithm 1 differentiates): one batched call."""
    lcs = point_mass_lcs(2, time_step=config.time_step, mass=config.mass, gravity=config.gravity)
    return lcs.step(states[:-1], np.zeros(2), smoothing, gradient="frozen").dx_dx


def contact_distances(config: Config, states: np.ndarray) -> np.ndarray:
    """The contact distance z (m) of each step along a logged trajectory (N,): the LCP's q,
    the gap the step would leave without an impulse. A step with ``z > 0`` has its contact
    inactive (the ball approaching or in the air), one with ``z <= 0`` active (in contact)."""
    lcs = point_mass_lcs(2, time_step=config.time_step, mass=config.mass, gravity=config.gravity)
    return lcs.contact_distance(states[:-1], np.zeros((len(states) - 1, 2)))[:, 0]


def _largest(values: np.ndarray) -> float:
    """The largest of ``values``, 0 for none."""
    return float(np.max(values)) if values.size else 0.0


def abs_impulse_jump(config: Config) -> float:
    """The contact-aware ABS impulse as z falls to 0 from above, ``sqrt(mu_max m / h)`` (N s):
    the step of ``contact_impulse.png`` at z = 0, where the contact turns active and ABS
    becomes exact contact (impulse 0; module docstring)."""
    return _impulse_jump(config.abs_mu_max, config.mass, config.time_step)


def _impulse_jump(mu_max: float, mass: float, time_step: float) -> float:
    """``sqrt(mu_max m / h)``: the softened one-contact impulse at z = 0 with ``mu = mu_max``
    (``lam s = mu`` with ``s = z + (h / m) lam``)."""
    return float(np.sqrt(mu_max * mass / time_step))


def contact_impulse_curves(config: Config, z: np.ndarray) -> dict[str, np.ndarray]:
    """Impulse lam(z) of each case's policy on a grid of contact distances z (m)."""
    F = np.array([[config.time_step / config.mass]])
    return {name: solve_lcp(F, z[:, None], policy.mu(z[:, None], F), strict=True).lam[:, 0]
            for name, policy in config.cases().items()}  # fmt: skip


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Run the demo, write plots, the Meshcat HTML and summary.json to ``out`` (default
    results/bouncing-ball); ``summary["files"]`` lists them with absolute paths."""
    config = config or Config()
    out = results_dir(NAME, out)
    meshcat = None
    if config.meshcat:
        from pydrake.geometry import Meshcat, MeshcatParams

        meshcat = Meshcat(MeshcatParams(host="localhost"))
    trajectories = simulate(config, meshcat=meshcat)
    cases, labels = config.cases(), config.labels()
    files = {}
    if meshcat is not None:
        files["meshcat_html"] = out / "bouncing_ball.html"
        files["meshcat_html"].write_text(meshcat.StaticHtml())
    jac = {name: step_jacobians(config, trajectories[name], cases[name]) for name in cases}
    summary = {"config": asdict(config), "cases": {}}
    for name, xs in trajectories.items():
        rises = np.diff(xs[:, 3]) > 0
        impact = int(np.argmax(xs[1:, 3] > xs[:-1, 3] + 1e-12)) if np.any(rises) else -1
        stiffness = np.abs(jac[name][:, 3, 1])
        approaching = contact_distances(config, xs) > 0
        summary["cases"][name] = {
            "label": labels[name],
            "policy": repr(cases[name]),
            "min_height_m": float(xs[:, 1].min()),
            "final_vy_mps": float(xs[-1, 3]),
            "first_upward_velocity_change_at_x_m": None if impact < 0 else float(xs[impact, 0]),
            "max_dvy_dx_per_s": float(np.max(np.diff(xs[:, 3]) / np.diff(xs[:, 0]))),
            "max_abs_dvy_plus_dy": float(np.max(stiffness)),
            "max_abs_dvy_plus_dy_approaching": _largest(stiffness[approaching]),
            "max_abs_dvy_plus_dy_in_contact": _largest(stiffness[~approaching]),
            "steps_in_contact": int(np.sum(~approaching)),
            "dvy_plus_dy_exact_bound_1_over_h": 1.0 / config.time_step,
        }
    files.update(_plots(out, config, trajectories, jac))
    files["summary"] = out / "summary.json"
    summary["folder"] = str(out)
    summary["files"] = file_list(files)
    write_json(files["summary"], summary)
    return summary


#: The linear range of the symlog axis of ``dvy_dx.png`` (1/s): +-20 holds -g / v_x in the air.
SYMLOG_LINEAR = 20.0

#: plot name -> its axes' settings (a "yscale" of "symlog" is linear within +-SYMLOG_LINEAR)
_AXES = {
    "vy_vs_x": {"xlabel": "x (m)", "ylabel": "v_y (m/s)",
                "title": "Vertical velocity along the throw (Fig. 2a)"},
    "dvy_dx": {"xlabel": "x (m)", "ylabel": "d v_y / d x (1/s)",
               "title": "Derivative along the throw (Fig. 2b)", "yscale": "symlog"},
    "step_jacobian": {"xlabel": "x (m)", "ylabel": "|d v_y+ / d y| (1/s)",
                      "title": "Implicit one-step Jacobian (stiffness)", "yscale": "log"},
    "contact_impulse": {"xlabel": "contact distance z (m)", "ylabel": "impulse lam (N s)",
                        "title": "Contact impulse against distance (Fig. 1d)"},
}  # fmt: skip


def _plots(out: Path, config, trajectories, jac) -> dict[str, Path]:
    """Write the :func:`figures` to ``out`` as ``<plot>.png``; returns plot name -> path."""
    figs = figures(config, trajectories, jac)
    return {plot: save_figure(fig, out / f"{plot}.png") for plot, fig in figs.items()}


def figures(config: Config, trajectories: dict[str, np.ndarray], jac: dict[str, np.ndarray]):
    """One matplotlib figure per plot of ``_AXES`` (plot name -> figure, not yet saved), one
    line per case in the scene's palette (case 0, Exact, drawn thicker).

    Args:
        config: the demo's settings.
        trajectories: case name -> states (N + 1, 4), as :func:`simulate` returns them.
        jac: case name -> one-step Jacobians (N, 4, 4), as :func:`step_jacobians` returns them.
    """
    from drake_abs.diagrams.point_mass_scene import palette

    z = np.linspace(-0.1, 0.1, 801)
    impulses = contact_impulse_curves(config, z)
    series = {
        name: {
            "vy_vs_x": (xs[:, 0], xs[:, 3]),
            "dvy_dx": (0.5 * (xs[1:, 0] + xs[:-1, 0]), np.diff(xs[:, 3]) / np.diff(xs[:, 0])),
            "step_jacobian": (xs[:-1, 0], np.abs(jac[name][:, 3, 1]) + 1e-16),
            "contact_impulse": (z, impulses[name]),
        }
        for name, xs in trajectories.items()
    }
    labels, figs = config.labels(), {}
    for plot, axes in _AXES.items():
        fig, ax = pyplot().subplots(figsize=(6.4, 4.2))
        for i, (name, curves) in enumerate(series.items()):
            x, y = curves[plot]
            ax.plot(x, y, label=labels[name], color=palette(i), lw=2.2 if i == 0 else 1.5)
        axes = dict(axes)
        scale = axes.pop("yscale", None)
        if scale == "symlog":
            values = np.concatenate([curves[plot][1] for curves in series.values()])
            symlog_axis(ax, float(np.min(values)), float(np.max(values)), SYMLOG_LINEAR)
        elif scale is not None:
            ax.set_yscale(scale)
        if plot == "step_jacobian":
            axes["ylim"] = (1e-6, 10.0 / config.time_step)
        ax.set(**axes)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        figs[plot] = fig
    return figs


def symlog_axis(ax, low: float, high: float, linear: float) -> None:
    """A symmetric-log y axis (linear within ``+-linear``, logarithmic beyond) with every tick
    labelled, negative ones included.

    Matplotlib's default symlog ticks are the powers of ten and 0, so data whose negative part
    lies inside the linear range (``dvy_dx.png``: -g / v_x = -9.81 1/s in the air) got no
    negative tick at all. Here the linear range has evenly spaced ticks (1, 2 or 5 times a power
    of ten, about two on each side of 0 that the data reaches) and the logarithmic ranges the
    powers of ten, each labelled with its value (``-10``, ``0``, ``10``, ``10^2``, ...); the
    limits take the data (``low`` to ``high``) with a margin.
    """
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    ax.set_yscale("symlog", linthresh=linear)
    reach = max(-low, high, 0.0)
    inner = min(reach, linear)
    step = _nice_step(inner / 2.0) if inner > 0 else linear
    k = np.arange(-np.floor(linear / step), np.floor(linear / step) + 1)
    ticks = [t for t in k * step if low - step <= t <= high + step and abs(t) <= linear]
    top = int(np.floor(np.log10(max(reach, linear))))
    for e in range(int(np.ceil(np.log10(linear))), top + 1):
        if 10.0**e > linear:
            ticks += [t for t in (10.0**e, -(10.0**e)) if low * 1.5 <= t <= high * 1.5]
    ticks = sorted(set(ticks))
    bottom = min(low * 1.5, -step) if low < 0 else -step
    ax.set_ylim(bottom, max(high * 1.5, step))
    ax.yaxis.set_major_locator(FixedLocator(ticks))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(lambda t, _pos: _tick_label(t, linear)))


def _nice_step(size: float) -> float:
    """The smallest of 1, 2, 5 times a power of ten at least ``size`` (> 0)."""
    power = 10.0 ** np.floor(np.log10(size))
    return float(next(m * power for m in (1.0, 2.0, 5.0, 10.0) if m * power >= size))


def _tick_label(value: float, linear: float) -> str:
    """A tick's label: the number in the linear range, ``10^k`` (mathtext) beyond it; a minus
    sign where negative."""
    if value == 0:
        return "0"
    sign = "\u2212" if value < 0 else ""
    if abs(value) <= linear:
        return f"{sign}{abs(value):g}"
    return f"{sign}$10^{{{int(round(np.log10(abs(value))))}}}$"


def report(summary: dict) -> str:
    """The numbers to look at, one line per case, then :func:`guide`."""
    lines = [
        "bouncing ball (Zhang et al. 2023, Figure 2): exact contact, barrier smoothing (BS) and "
        "adaptive barrier smoothing (ABS) side by side"
    ]
    lines.append(f"  {'':34s} {'':>10s}   {'max |dv_y+/dy| (1/s)':^23s}".rstrip())
    lines.append(
        f"  {'case':34s} {'min height':>10s}   {'approaching':>11s} {'in contact':>11s}   "
        f"{'final v_y':>10s}"
    )
    for name, case in summary["cases"].items():
        lines.append(
            f"  {case.get('label', name):34s} {case['min_height_m']:+8.4f} m   "
            f"{_get(case, 'max_abs_dvy_plus_dy_approaching'):11.3g} "
            f"{_get(case, 'max_abs_dvy_plus_dy_in_contact'):11.3g}   "
            f"{case['final_vy_mps']:+6.3f} m/s"
        )
    abs_case = summary["cases"].get("abs_contact_aware")
    if abs_case is not None and "max_abs_dvy_plus_dy_in_contact" in abs_case:
        h = summary["config"]["time_step"]
        lines.append(
            f"  In contact (the step's contact distance z <= 0) contact-aware ABS is exact contact "
            f"(mu = 0), so its largest |dv_y+/dy| there is exact contact's, 1/h = {1 / h:g} 1/s; "
            "the two differ only while the ball approaches (z > 0), where exact contact's is 0 (to "
            f"rounding) and ABS's {abs_case['max_abs_dvy_plus_dy_approaching']:.3g} 1/s."
        )
    return "\n".join(lines) + "\n\n" + guide(summary)


def _get(case: dict, key: str) -> float:
    """A case's number, NaN where an older summary lacks it."""
    return float(case.get(key, float("nan")))


#: file key -> (what it shows, what to notice)
_GUIDE = {
    "vy_vs_x": (
        "vertical velocity against horizontal position (the paper's Figure 2a)",
        "exact contact (black) stops the fall in a single step at x = {impact}; barrier "
        "smoothing with a larger mu starts braking before the ball touches and bounces it back "
        "up; the adaptive (ABS, contact-aware) curve stays on the exact one",
    ),
    "dvy_dx": (
        "the derivative d v_y / d x along the throw (Figure 2b)",
        "away from the ground every curve sits at -g / v_x = {slope} 1/s; at the impact exact "
        "contact jumps in one step, barrier smoothing spreads the jump into a wider, lower bump "
        "as mu grows (the smoothing that helps gradients), ABS matches exact away from contact",
    ),
    "step_jacobian": (
        "the one-step Jacobian |d v_y+ / d y| (log scale), the stiffness the gradient sees",
        "exact is 0 in the air and 1/h = {stiff} 1/s in contact; barrier smoothing is non-zero "
        "everywhere (its barrier acts at a distance: bias far from contact), ABS falls below "
        "1e-6 away from the ground and rises smoothly as the ball approaches it; once the ball "
        "is in contact ABS is exact contact (mu = 0), so there its curve lies on the exact one "
        "at 1/h",
    ),
    "contact_impulse": (
        "the contact impulse each policy returns against the distance to the ground",
        "exact is zero above the ground; barrier smoothing pushes at a distance, more for a "
        "larger mu; contact-aware ABS pushes only within its length scale, most at z -> 0+ "
        "(mu -> mu_max: sqrt(mu_max m / h) = {jump} N s), and at z = 0 its impulse drops to "
        "exact contact's 0: the contact is active there and ABS, as defined, is exact contact "
        "(mu = 0; the solver shows it as its exact floor, about 1e-34)",
    ),
    "meshcat_html": (
        "the balls side by side in Meshcat (open the file in a browser, no server needed; "
        "press play in the Animations menu)",
        "the colours are those of the plots; the smoothed balls slow down before touching "
        "the ground",
    ),
    "summary": ("the numbers above, per case, as JSON", ""),
}


def guide(summary: dict) -> str:
    """What to look at: which file shows what and what to notice, with absolute paths."""
    files = summary["files"]
    config = summary["config"]
    exact = summary["cases"].get("exact", {})
    impact = exact.get("first_upward_velocity_change_at_x_m")
    values = {
        "impact": "?" if impact is None else f"{impact:.2f} m",
        "slope": f"{-config['gravity'] / config['speed']:.3g}",
        "stiff": f"{1.0 / config['time_step']:g}",
        "jump": f"{_impulse_jump(config['abs_mu_max'], config['mass'], config['time_step']):.3g}",
    }
    folder = summary.get("folder") or str(Path(next(iter(files.values()))).parent)
    lines = [f"What to look at (in {folder}):"]
    for key, (what, notice) in _GUIDE.items():
        if key not in files:
            continue
        lines.append(f"  {files[key]}")
        lines.append(f"      {what}.")
        if notice:
            lines.append(f"      Notice: {notice.format(**values)}.")
    return "\n".join(lines)
