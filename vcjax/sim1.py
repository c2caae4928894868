"""The paper's Simulation 1 (Section 4.3, Figs. 4–5; SPEC §5) and its baselines.

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

import dataclasses
import functools
import json
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import paths
from vcjax._checks import check_array, check_positive
from vcjax.control.baselines import (
    BaselineConfig,
    baseline_gains,
    baseline_law,
    baseline_params,
    baseline_state,
)
from vcjax.control.vcm import VCMConfig, pm_gains, vcm_law, vcm_params, vcm_state
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import infante

__all__ = [
    "Sim1Scenario",
    "sim1_scenario",
    "VARIANTS",
    "PAPER_VARIANTS",
    "Sim1Gains",
    "default_gains",
    "gains_to_json",
    "gains_from_json",
    "run_variant",
    "simulate",
    "closed_loop",
    "controller_params",
    "initial_controller_state",
    "path_coeffs",
    "PATH",
    "run_sim1",
    "tracking_metrics",
]

VARIANTS = ("vcm", "vcm_integral", "ilos", "los_pid", "vcm_ilos", "alos")
#: The four controllers of the paper's comparison (Simulation 1).
PAPER_VARIANTS = VARIANTS[:4]


class Sim1Scenario(NamedTuple):
    """Traced scenario data.

    Attributes:
        eta0: (3,) initial pose; nu0: (3,) initial body velocity; V_c: (2,) current [m/s];
        u_d: () desired speed [m/s]; vehicle: :class:`~vcjax.vehicles.infante.InfanteParams`
        of the simulated plant; path: coefficients of the path (kind :data:`PATH`);
        design_vehicle: the parameters the *controller* believes (its design model (20) and
        rudder map are derived from them). Equal to ``vehicle`` unless a study perturbs the
        plant (model-error Monte-Carlo runs).
    """

    eta0: Any
    nu0: Any
    V_c: Any
    u_d: Any
    vehicle: Any
    path: Any
    design_vehicle: Any


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
    V_c=(0.0, 0.5),
    u_d=2.0,
    vehicle=None,
    design_vehicle=None,
) -> Sim1Scenario:
    """The paper's Simulation 1 scenario (defaults), validated eagerly.

    Args:
        eta0: (3,) initial pose ``[x, y, psi]`` [m, m, rad] (paper: ``[0, 0, pi/2]``).
        nu0: (3,) initial body velocity (paper: ``[2, 0, 0]``).
        V_c: (2,) ocean current in NED [m/s] (paper: ``[0, 0.5]``, along the path).
        u_d: () desired surge speed [m/s].
        vehicle: plant parameters (default :func:`~vcjax.vehicles.infante.infante_params`).
        design_vehicle: the controller's belief (default: ``vehicle``).
    """
    check_array("eta0", eta0, (3,))
    check_array("nu0", nu0, (3,))
    check_array("V_c", V_c, (2,))
    check_positive("u_d", u_d, ())
    vehicle = infante.infante_params() if vehicle is None else vehicle
    design_vehicle = vehicle if design_vehicle is None else design_vehicle
    for name, v in (("vehicle", vehicle), ("design_vehicle", design_vehicle)):
        if not isinstance(v, infante.InfanteParams):
            raise ValueError(f"{name}: expected InfanteParams, got {type(v).__name__}")
    dt = jnp.asarray(vehicle.mass).dtype
    f = lambda x: jnp.asarray(x, dtype=dt)
    return Sim1Scenario(f(eta0), f(nu0), f(V_c), f(u_d), vehicle, path_coeffs(dt), design_vehicle)


class Sim1Gains(NamedTuple):
    """Gains of every controller in the comparison (traced)."""

    vcm: Any  # PMGains, shared by vcm and vcm_integral (as in the paper)
    baseline: Any  # BaselineGains, shared by ilos, los_pid and alos


def default_gains() -> Sim1Gains:
    """SPEC §3's order-one VCM gains, with integral action on the along-track error only.

    In the underactuated configuration the cross-track integral of (41) can act only through
    the sway row, which the vehicle cannot actuate: ``v_d`` absorbs it (38), the resulting
    sideslip needs a cross-track offset to follow the path, and the integral grows — positive
    feedback (measured: with ``P_int = (0.05, 0.01)`` the run settles with the integrator on its
    anti-windup clamp and |e| = 0.29 m). The along-track integral removes the current-induced
    speed and along-track offsets without that problem.
    """
    return Sim1Gains(vcm=pm_gains(P_int=(0.05, 0.0)), baseline=baseline_gains())


def gains_to_json(g: Sim1Gains) -> dict:
    """Plain-JSON form of :class:`Sim1Gains` (what ``vcjax simulate --gains`` loads)."""
    return {
        "vcm": {k: np.asarray(v).tolist() for k, v in g.vcm._asdict().items()},
        "baseline": {k: np.asarray(v).tolist() for k, v in g.baseline._asdict().items()},
    }


def gains_from_json(d: dict) -> Sim1Gains:
    """Inverse of :func:`gains_to_json`, validated; missing entries take the defaults."""
    unknown = set(d) - {"vcm", "baseline"}
    if unknown:
        raise ValueError(f"gains file: unknown sections {sorted(unknown)}")
    try:
        vcm = pm_gains(**d.get("vcm", {}))
        base = baseline_gains(**d.get("baseline", {}))
    except TypeError as err:
        raise ValueError(f"gains file: {err}") from None
    return Sim1Gains(vcm=vcm, baseline=base)


@dataclasses.dataclass(frozen=True)
class _Loop:
    plant: Any
    controller: Any


@functools.cache
def closed_loop(variant: str, edd: str = "paper", smooth: bool = False) -> _Loop:
    """``(plant, controller)`` of one variant for :func:`vcjax.rollout.rollout`; cached, so the
    same function objects come back and jitted rollouts compile once per variant."""
    if variant in ("vcm", "vcm_integral", "vcm_ilos"):
        cfg = VCMConfig(
            path=PATH,
            actuation="underactuated",
            edd=edd,
            integral=variant != "vcm",
            guidance="ilos" if variant == "vcm_ilos" else "los",
        )
        law = functools.partial(vcm_law, cfg)
    elif variant in ("ilos", "los_pid", "alos"):
        law = functools.partial(baseline_law, BaselineConfig(path=PATH, kind=variant))
    else:
        raise ValueError(f"variant: expected one of {VARIANTS}, got {variant!r}")

    def controller(t, x, z, params):
        ctrl, vehicle = params
        tau, z_dot, aux = law(ctrl, t, x.eta, x.nu, z)
        return infante.actuator_commands(vehicle, x.nu, tau[0], tau[2]), z_dot, aux

    plant = infante.infante_plant_smooth if smooth else infante.infante_plant
    return _Loop(plant=plant, controller=controller)


def controller_params(variant, gains: Sim1Gains, sc: Sim1Scenario):
    """The traced controller parameters of ``variant``: its law's params (design model derived
    from ``sc.design_vehicle``, rudder sway ratio, desired speed, path)."""
    model = infante.design_model(sc.design_vehicle)
    k_rudder = _rudder_ratio(sc.design_vehicle)
    if variant.startswith("vcm"):
        return vcm_params(gains.vcm, model, sc.path, u_d=sc.u_d, k_rudder=k_rudder)
    return baseline_params(gains.baseline, model, sc.path, u_d=sc.u_d, k_rudder=k_rudder)


def _rudder_ratio(vehicle):
    """Sway force per unit yaw moment of the rudder (speed-independent: both scale with U^2)."""
    Y, N = infante.rudder_gains(vehicle, jnp.array([1.0, 0.0, 0.0], dtype=vehicle.mass.dtype))
    return Y / N


def initial_controller_state(variant, sc: Sim1Scenario):
    """Initial controller state: the particle starts abreast of the vehicle (``w0 = y0``)."""
    # particle starts at the point of the path closest to the start (the line x = 10: w = y0)
    w0 = sc.eta0[1]
    return vcm_state(varpi0=w0) if variant.startswith("vcm") else baseline_state(varpi0=w0)


def simulate(
    variant: str,
    gains: Sim1Gains,
    scenario: Sim1Scenario,
    config: RolloutConfig,
    dt,
    edd: str = "paper",
    smooth: bool = False,
):
    """Pure closed-loop rollout of one controller on a scenario (not jitted).

    ``variant``, ``config``, ``edd`` and ``smooth`` are static; ``gains``, ``scenario`` and ``dt``
    are traced, so this function can be ``jax.vmap``-ed over scenarios (or gains) and
    differentiated. The controller maps its ``[tau_u, tau_r]`` to thrust and rudder commands
    with the *design* vehicle's actuator model, from the measured velocity over ground.

    Returns:
        :class:`~vcjax.rollout.Trajectory` (plant state: ``InfanteState``).
    """
    loop = closed_loop(variant, edd, smooth)
    x0 = infante.InfanteState(
        eta=scenario.eta0, nu=scenario.nu0, act=jnp.zeros(2, scenario.eta0.dtype)
    )
    zero2 = jnp.zeros(2, scenario.eta0.dtype)
    args = infante.PlantArgs(vehicle=scenario.vehicle, V_c=scenario.V_c, V_c_dot=zero2)
    ctrl = (controller_params(variant, gains, scenario), scenario.design_vehicle)
    z0 = initial_controller_state(variant, scenario)
    return rollout(loop.plant, loop.controller, config, args, ctrl, x0, z0, dt)


_run = jax.jit(simulate, static_argnames=("variant", "config", "edd", "smooth"))


def run_variant(
    variant: str,
    gains: Sim1Gains | None = None,
    scenario: Sim1Scenario | None = None,
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


def tracking_metrics(traj, vehicle, tail: float = 0.2) -> dict:
    """Metrics of one run (SPEC / issue 3).

    ``ss_abs_*``: mean absolute value over the last ``tail`` fraction of the run; ``iae_e``:
    integral of |e| dt; ``max_abs_tau_u``: largest actual thrust [N]; ``max_abs_rudder_deg``:
    largest actual rudder angle [deg]; ``sat_fraction``: fraction of steps in which any command
    exceeded its actuator limit; ``healthy``: every step finite.
    """
    t = np.asarray(traj.t)
    dt = float(t[1] - t[0])
    eps = np.asarray(traj.aux.eps)
    u_err = np.asarray(traj.aux.u_tilde)
    n = eps.shape[0]
    k0 = int(np.floor((1 - tail) * n))
    act = np.asarray(traj.x.act)
    cmd = np.asarray(traj.u)
    sat = (np.abs(cmd[:, 0]) > float(vehicle.thrust_max)) | (
        np.abs(cmd[:, 1]) > float(vehicle.rudder_max)
    )
    return {
        "ss_abs_e": float(np.mean(np.abs(eps[k0:, 1]))),
        "ss_abs_s": float(np.mean(np.abs(eps[k0:, 0]))),
        "ss_abs_u_err": float(np.mean(np.abs(u_err[k0:]))),
        "iae_e": float(np.sum(np.abs(eps[:, 1])) * dt),
        "max_abs_tau_u": float(np.max(np.abs(act[:, 0]))),
        "max_abs_rudder_deg": float(np.degrees(np.max(np.abs(act[:, 1])))),
        "sat_fraction": float(np.mean(sat)),
        "healthy": bool(np.all(np.asarray(traj.finite))),
    }


def run_sim1(
    out: Path,
    gains: Sim1Gains | None = None,
    horizon: float = 150.0,
    dt: float = 0.05,
    edd: str = "paper",
    timing: str = "continuous",
    progress=print,
    scenario: Sim1Scenario | None = None,
) -> dict:
    """Run every variant (:data:`VARIANTS`), write ``metrics.json`` and the figures into ``out``.

    ``scenario`` defaults to the paper's (:func:`sim1_scenario`); pass another current or start
    to compare the controllers elsewhere.
    """
    from vcjax import plots

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sc = sim1_scenario() if scenario is None else scenario
    trajs, metrics = {}, {}
    for i, v in enumerate(VARIANTS):
        progress(f"[{i + 1}/{len(VARIANTS)}] simulating {v} ({horizon:g} s, dt {dt:g} s)")
        trajs[v] = jax.device_get(run_variant(v, gains, sc, horizon, dt, edd, timing))
        metrics[v] = tracking_metrics(trajs[v], sc.vehicle)
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    files = plots.sim1_figures(trajs, sc, out)
    return {"metrics": metrics, "files": [out / "metrics.json", *files]}
