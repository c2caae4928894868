"""Logged manoeuvres for identification studies: a "true" vehicle, standard trials, sensor noise.

The INFANTE-class craft ([`vcjax.vehicles.infante`][vcjax.vehicles.infante]) is put through the
classical trials
(ITTC): a 20/20 zig-zag (rudder to +-20 deg, reversed each time the heading passes +-20 deg from
the initial one), a turning circle (rudder held at 25 deg) and speed steps (thrust stepped with
the rudder at zero). Each trial is one ``lax.scan`` of the plant (rk4, command held over each
step); the commands come from a small feedback rule evaluated on the *true* state, as a
helmsman would. Measurements are the true states plus white Gaussian noise.

[`perturbed_params`][vcjax.identify.manoeuvres.perturbed_params] builds the "true" plant of a study:
chosen coefficients multiplied by
``1 +- frac`` (signs drawn from a seed).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from vcjax.identify.data import save_log_csv
from vcjax.identify.models import get_fit_model
from vcjax.runtime import compiler

__all__ = [
    "STUDY_PARAMS",
    "SENSOR_NOISE",
    "perturbed_params",
    "simulate_trial",
    "infante_logs",
]

#: The INFANTE-class coefficients a study perturbs (and fits): surge drag, sway/yaw damping
#: and lift, rudder force and moment, cross-flow drag.
STUDY_PARAMS = ("X_uu", "Y_uv", "Y_ur", "N_uv", "N_ur", "Y_uudr", "N_uudr", "cf_coeff")

#: Sensor noise (one standard deviation) per INFANTE log channel.
SENSOR_NOISE = {
    "x": 0.1,
    "y": 0.1,
    "psi": math.radians(0.2),
    "u": 0.02,
    "v": 0.02,
    "r": math.radians(0.1),
    "thrust": 5.0,
    "delta": math.radians(0.2),
}


def perturbed_params(base, frac: float, seed: int = 0, names=STUDY_PARAMS):
    """``base`` with every field in ``names`` multiplied by ``1 + frac`` or ``1 - frac``
    (the sign of each drawn with ``seed``)."""
    rng = np.random.default_rng(seed)
    signs = rng.choice([-1.0, 1.0], size=len(names))
    return base._replace(
        **{n: getattr(base, n) * (1.0 + s * frac) for n, s in zip(names, signs, strict=True)}
    )


def simulate_trial(params, trial: str, dt: float, horizon: float, thrust: float = 600.0):
    """One trial of the INFANTE-class plant from straight running at 2.5 m/s.

    Args:
        params: [`InfanteParams`][vcjax.vehicles.infante.InfanteParams] (the true plant).
        trial: ``"zigzag"``, ``"turning_circle"`` or ``"speed_steps"``.
        dt: sample time [s]; horizon: duration [s]; thrust: the trial's thrust [N].

    Returns:
        ``(t (N,), x (N, 8), u (N, 2))`` numpy arrays (the last row's command repeats).
    """
    model = get_fit_model("infante")
    step = model.make_step("rk4")
    n = int(round(horizon / dt))
    dtype = jnp.asarray(params.mass).dtype
    x0 = jnp.asarray([0.0, 0.0, 0.0, 2.5, 0.0, 0.0, thrust, 0.0], dtype)
    v_c = jnp.zeros(2, dtype)
    d20, d25 = math.radians(20.0), math.radians(25.0)

    def command(k, x, sign):
        t = jnp.asarray(k, dtype) * dt
        if trial == "zigzag":
            psi = x[2]  # positive rudder turns the bow to port (psi decreasing)
            sign = jnp.where(psi <= -d20, -1.0, jnp.where(psi >= d20, 1.0, sign))
            u = jnp.stack([thrust + 0.0 * psi, sign * d20])
        elif trial == "turning_circle":
            u = jnp.stack([jnp.asarray(thrust, dtype), jnp.where(t >= 5.0, d25, 0.0)])
        elif trial == "speed_steps":
            level = jnp.floor(t / (horizon / 4.0))
            T = jnp.asarray([thrust, 1.5 * thrust, 0.5 * thrust, thrust], dtype)
            u = jnp.stack([T[jnp.clip(level.astype(jnp.int32), 0, 3)], jnp.asarray(0.0, dtype)])
        else:
            raise ValueError(
                f"trial: {trial!r} is not one of 'zigzag', 'turning_circle', 'speed_steps'"
            )
        return u.astype(dtype), sign

    command(0, x0, jnp.asarray(1.0, dtype))  # raises on an unknown trial before tracing the scan

    @compiler.jit
    def run(p):
        def body(carry, k):
            x, sign = carry
            u, sign = command(k, x, sign)
            x_next = step(p, v_c, x, u, jnp.asarray(dt, dtype))
            return (x_next, sign), (x, u)

        ks = jnp.arange(n + 1)
        _, (xs, us) = jax.lax.scan(body, (x0, jnp.asarray(1.0, dtype)), ks)
        return xs, us

    xs, us = run(params)
    t = np.arange(n + 1) * dt
    return t, np.asarray(xs, np.float64), np.asarray(us, np.float64)


def infante_logs(
    params,
    out,
    dt: float = 0.1,
    horizon: float = 120.0,
    noise: dict | None = SENSOR_NOISE,
    seed: int = 0,
    trials=("zigzag", "turning_circle", "speed_steps"),
) -> list[Path]:
    """Write one CSV log per trial into ``out`` (``infante_<trial>.csv``), with sensor noise
    ``noise`` (channel -> std; ``None``: noise-free), and return their paths."""
    model = get_fit_model("infante")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    sig = np.array([(noise or {}).get(c, 0.0) for c in model.state_columns])
    files = []
    for trial in trials:
        t, x, u = simulate_trial(params, trial, dt, horizon)
        if not np.all(np.isfinite(x)):
            raise ValueError(f"trial {trial!r}: the plant diverged")
        x = x + rng.normal(size=x.shape) * sig
        prov = f"INFANTE-class {trial}, rk4, dt {dt} s, sensor noise {json.dumps(noise or {})}"
        files.append(
            save_log_csv(
                out / f"infante_{trial}.csv",
                t,
                x,
                u,
                model.state_columns,
                model.command_columns,
                provenance=prov,
            )  # fmt: skip
        )
    return files
