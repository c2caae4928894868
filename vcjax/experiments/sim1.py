"""The paper's Simulation 1 (Section 4.3, Figs. 4–5; docs/experiments) and its baselines.

INFANTE-class (NPS-AUV-derived) plant, underactuated in sway; path ``p_p(w) = [10, w]``;
``q0 = [0, 0, pi/2]``, ``nu0 = [2 m/s, 0, 0]``; ocean current ``[0, 0.5] m/s`` (unknown to the
controllers). Four controllers on the identical scenario:

* ``vcm``: VCM path maneuvering (31)/(38), no integral action;
* ``vcm_integral``: the same gains plus integral action (41);
* ``ilos``: integral LOS (40) with a heading PD;
* ``los_pid``: LOS heading with the PID yaw law (39);
* ``vcm_ilos`` (an extension, not in the paper): ``vcm_integral`` with the integral-LOS approach
  angle inside the VCM heading row (``VCMConfig(guidance="ilos")``), which removes the
  cross-track offset a cross current leaves with the paper's LOS angle;
* ``alos`` (a baseline not in the paper): Fossen's adaptive LOS (2023) with the same heading PD
  and surge loop as ``ilos`` and ``los_pid``.

Every controller maps its ``[tau_u, tau_r]`` to thrust and rudder commands with the vehicle's
actuator model (:func:`vcjax.vehicles.infante.actuator_commands`), using the *measured* velocity
over ground (the current is unknown).
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import loops, metrics, paths
from vcjax._checks import check_array, check_positive
from vcjax.loops import InfanteGains, InfanteLoop, infante_gains
from vcjax.rollout import RolloutConfig
from vcjax.runtime.outputs import write_json_atomic
from vcjax.vehicles import infante

__all__ = [
    "sim1_scenario",
    "VARIANTS",
    "PAPER_VARIANTS",
    "default_gains",
    "gains_to_json",
    "gains_from_json",
    "run_variant",
    "simulate",
    "closed_loop",
    "path_coeffs",
    "PATH",
    "run_sim1",
    "tracking_metrics",
    "health_extras",
    "METRIC_KEYS",
]

VARIANTS = ("vcm", "vcm_integral", "ilos", "los_pid", "vcm_ilos", "alos")
#: The four controllers of the paper's comparison (Simulation 1).
PAPER_VARIANTS = VARIANTS[:4]
#: What ``metrics.json`` reports per variant (see :mod:`vcjax.metrics`), plus ``healthy``.
METRIC_KEYS = (
    "ss_abs_e",
    "ss_abs_s",
    "ss_abs_u_err",
    "iae_e",
    "max_abs_tau_u",
    "max_abs_rudder_deg",
    "sat_fraction",
)

#: Static path kind of Simulation 1 (the line ``[10, w]``); its coefficients: :func:`path_coeffs`.
PATH = paths.paper_line()[0]
#: The line's coefficients in float64 numpy (validated once, at import, by ``paper_line``).
_LINE = paths.LineCoeffs(origin=np.array([10.0, 0.0, 0.0]), direction=np.array([0.0, 1.0, 0.0]))


def path_coeffs(dtype=None):
    """Coefficients of Simulation 1's line ``[10, w]`` as arrays of ``dtype`` (default: JAX's
    default float when called, not at import, so enabling float64 after importing vcjax works).
    Safe to call inside ``jit``."""
    dtype = jnp.asarray(0.0).dtype if dtype is None else dtype
    return jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype=dtype), _LINE)


def sim1_scenario(
    eta0=(0.0, 0.0, np.pi / 2),
    nu0=(2.0, 0.0, 0.0),
    current=(0.0, 0.5, 0.0),
    u_d=2.0,
    vehicle=None,
    design_vehicle=None,
) -> loops.Scenario:
    """The paper's Simulation 1 scenario (defaults), validated eagerly.

    Args:
        eta0: (3,) initial pose ``[x, y, psi]`` [m, m, rad] (paper: ``[0, 0, pi/2]``).
        nu0: (3,) initial body velocity (paper: ``[2, 0, 0]``).
        current: (2,) or (3,) water velocity in NED [m/s] (paper: ``[0, 0.5]``, along the path).
        u_d: () desired surge speed [m/s].
        vehicle: plant parameters (default :func:`~vcjax.vehicles.infante.infante_params`).
        design_vehicle: the controller's belief (default: ``vehicle``).

    Returns:
        :class:`~vcjax.loops.Scenario` (:func:`vcjax.loops.make_scenario` of the ``infante``
        loop); the particle starts abreast of the vehicle (``varpi0 = y0``, the nearest point
        of the line).
    """
    check_array("eta0", eta0, (3,))
    check_array("nu0", nu0, (3,))
    cur = check_array("current", current, (None,))
    if cur is not None and cur.shape not in ((2,), (3,)):
        raise ValueError(f"current: expected shape (2,) or (3,), got {cur.shape}")
    check_positive("u_d", u_d, ())
    vehicle = infante.infante_params() if vehicle is None else vehicle
    design_vehicle = vehicle if design_vehicle is None else design_vehicle
    for name, v in (("vehicle", vehicle), ("design_vehicle", design_vehicle)):
        infante.validate(v, name)
    dtype = jnp.asarray(vehicle.mass).dtype
    return loops.make_scenario(
        closed_loop("vcm"),
        path_coeffs(dtype),
        eta0=eta0,
        nu0=nu0,
        current=current,
        u_d=u_d,
        plant=vehicle,
        design=design_vehicle,
    )  # the particle starts abreast of the vehicle: the point of the line x = 10 nearest to it


def default_gains() -> InfanteGains:
    """The gains of every controller in the comparison (:func:`vcjax.loops.infante_gains`)."""
    return infante_gains()


def gains_to_json(g: InfanteGains) -> dict:
    """Plain-JSON form of the gains (what ``vcjax simulate sim1 --gains`` loads)."""
    return loops.gains_to_json(g)


def gains_from_json(d: dict) -> InfanteGains:
    """Inverse of :func:`gains_to_json`, validated; missing entries take the defaults."""
    return closed_loop("vcm").gains_from_json(d)


@functools.cache
def closed_loop(variant: str, edd: str = "paper", smooth: bool = False) -> InfanteLoop:
    """The :class:`~vcjax.loops.infante.InfanteLoop` of one variant on Simulation 1's line."""
    if variant not in VARIANTS:
        raise ValueError(f"variant: expected one of {VARIANTS}, got {variant!r}")
    return loops.make_loop("infante", variant, path=PATH, edd=edd, smooth=smooth)


def simulate(
    variant: str,
    gains: InfanteGains,
    scenario: loops.Scenario,
    config: RolloutConfig,
    dt,
    edd: str = "paper",
    smooth: bool = False,
):
    """Pure closed-loop rollout of one controller on a scenario (not jitted).

    ``variant``, ``config``, ``edd`` and ``smooth`` are static; ``gains``, ``scenario`` and ``dt``
    are traced, so this function can be ``jax.vmap``-ed over scenarios (or gains) and
    differentiated (:func:`vcjax.loops.simulate` of :func:`closed_loop`).

    Returns:
        :class:`~vcjax.rollout.Trajectory` (plant state: ``InfanteState``).
    """
    return loops.simulate(closed_loop(variant, edd, smooth), gains, scenario, config, dt)


_run = jax.jit(simulate, static_argnames=("variant", "config", "edd", "smooth"))


def run_variant(
    variant: str,
    gains: InfanteGains | None = None,
    scenario: loops.Scenario | None = None,
    horizon: float = 150.0,
    dt: float = 0.05,
    edd: str = "paper",
    timing: str = "continuous",
    smooth: bool = False,
):
    """Roll one controller out on the scenario (jitted; compiled once per static setting).

    Returns the :class:`~vcjax.rollout.Trajectory`.
    """
    if variant not in VARIANTS:
        raise ValueError(f"variant: expected one of {VARIANTS}, got {variant!r}")
    if not (horizon > 0 and dt > 0 and horizon / dt >= 1):
        raise ValueError(f"horizon and dt must be positive with horizon >= dt, got {horizon}, {dt}")
    gains = default_gains() if gains is None else gains
    sc = sim1_scenario() if scenario is None else scenario
    cfg = RolloutConfig(num_steps=int(round(horizon / dt)), integrator="rk4", timing=timing)
    return _run(variant, gains, sc, cfg, dt, edd, smooth)


def health_extras(traj, bound: float) -> dict:
    """Simulation 1's health as extras of :func:`vcjax.metrics.run_metrics` (jnp):
    ``unhealthy_step``, the first step whose state diverged (non-finite or beyond the rollout's
    bound, :attr:`vcjax.rollout.Trajectory.diverged`) or whose cross-track error left ``bound``
    [m] (NaN counts), -1 if none; ``healthy``, whether there is none."""

    def bad(sig):
        return traj.diverged | ~(jnp.abs(sig.eps[:, 1]) <= bound)

    return {
        "unhealthy_step": lambda sig, win: metrics.first_true(bad(sig)),
        "healthy": lambda sig, win: ~jnp.any(bad(sig)),
    }


def tracking_metrics(
    variant: str, traj, scenario: loops.Scenario, tail: float = 0.2, diverge_e=None
) -> dict:
    """Simulation 1's metrics of one run (:func:`vcjax.metrics.run_metrics`, steady-state
    window the last ``tail`` of the run, with :func:`health_extras` added), as Python values:
    :data:`METRIC_KEYS`, ``healthy`` (no step diverged: every state finite and within the
    rollout's bound, and the cross-track error within the path bound
    :func:`vcjax.metrics.path_bound`, default scaled to ``u_d x horizon``, or ``diverge_e``
    [m]) and ``unhealthy_step`` (the first such step, or ``None``)."""
    loop = closed_loop(variant)
    sig = loop.signals(traj, scenario)
    t = np.asarray(traj.t)
    bound = metrics.path_bound(float(np.asarray(scenario.u_d)), t[-1] - t[0], diverge_e)
    extras = health_extras(traj, bound)
    m = metrics.run_metrics(sig, traj.finite, traj.t[1] - traj.t[0], 1.0 - tail, extras=extras)
    out = {k: float(m[k]) for k in METRIC_KEYS}
    out["healthy"] = bool(m["healthy"])
    k = int(m["unhealthy_step"])
    out["unhealthy_step"] = None if k < 0 else k
    return out


def run_sim1(
    out: Path,
    gains: InfanteGains | None = None,
    horizon: float = 150.0,
    dt: float = 0.05,
    edd: str = "paper",
    timing: str = "continuous",
    progress=print,
    scenario: loops.Scenario | None = None,
    diverge_e: float | None = None,
) -> dict:
    """Run every variant (:data:`VARIANTS`), write ``metrics.json`` and the figures into ``out``.
    ``diverge_e``: path-error bound [m] of ``healthy`` (default :func:`vcjax.metrics.path_bound`).

    ``scenario`` defaults to the paper's (:func:`sim1_scenario`); pass another current or start
    to compare the controllers elsewhere.
    """
    from vcjax.plots.sim1 import sim1_figures

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sc = sim1_scenario() if scenario is None else scenario
    trajs, results = {}, {}
    for i, v in enumerate(VARIANTS):
        progress(f"[{i + 1}/{len(VARIANTS)}] simulating {v} ({horizon:g} s, dt {dt:g} s)")
        trajs[v] = jax.device_get(run_variant(v, gains, sc, horizon, dt, edd, timing))
        results[v] = tracking_metrics(v, trajs[v], sc, diverge_e=diverge_e)
    write_json_atomic(out / "metrics.json", results)
    files = sim1_figures(trajs, sc, out)
    t = {v: np.asarray(tr.t) for v, tr in trajs.items()}
    unhealthy = {
        v: (m["unhealthy_step"], float(t[v][m["unhealthy_step"] + 1]))
        for v, m in results.items()
        if not m["healthy"]
    }
    return {"metrics": results, "files": [out / "metrics.json", *files], "unhealthy": unhealthy}


def load_gains(d: dict, **_options) -> InfanteGains:
    """The experiment's gains from a gains-JSON object (:func:`gains_from_json`)."""
    return gains_from_json(d)


def run_experiment(
    out,
    gains,
    *,
    horizon,
    dt,
    current,
    progress=print,
    edd="paper",
    timing="continuous",
    diverge_e=None,
) -> dict:
    """``vcjax simulate sim1`` (:mod:`vcjax.experiments`): :func:`run_sim1` on the paper's
    scenario under ``current`` ``(north, east)`` [m/s]."""
    scenario = sim1_scenario(current=current)
    result = run_sim1(out, gains, horizon, dt, edd, timing, progress, scenario, diverge_e)
    result["printed"] = result["metrics"]
    result["unhealthy"] = [
        f"{v} diverged at step {k} (t = {t:g} s, dt {dt:g} s): its state became non-finite "
        "or left the divergence bound (then frozen there), or it left the path-error bound "
        "(--diverge-e); its metrics and figures after that time are not meaningful"
        for v, (k, t) in result["unhealthy"].items()
    ]
    result["config"] = {"scenario": scenario}
    return result
