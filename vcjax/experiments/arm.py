"""Demo jobs for the CLI: the generic engine on a non-marine system."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from vcjax.mechanics import VirtualConstraints, reaction_force, vcm_gains
from vcjax.rollout import RolloutConfig, rollout
from vcjax.systems import TWO_LINK_ARM, arm_end_effector, arm_params

__all__ = ["arm_demo", "ARM_CIRCLE", "ARM_DT"]

#: RK4 step of the arm demo [s].
ARM_DT = 2e-3

_CENTER = (1.0, 0.6)
_RADIUS = 0.35


def _circle_G(q, t, p):
    d = arm_end_effector(q, p) - jnp.asarray(_CENTER, q.dtype)
    return jnp.atleast_1d(jnp.sqrt(d @ d) - _RADIUS)


def _tangential_K(q, qd, t, p):
    d = arm_end_effector(q, p) - jnp.asarray(_CENTER, q.dtype)
    tangent = jnp.stack([-d[1], d[0]]) / jnp.sqrt(d @ d)
    v = tangent @ (jax.jacfwd(arm_end_effector)(q, p) @ qd)
    return jnp.atleast_1d(v - 0.5)


#: End effector held on a circle (holonomic) moving at 0.5 m/s along it (velocity constraint).
ARM_CIRCLE = VirtualConstraints(holonomic=_circle_G, velocity=_tangential_K)


def _plant(t, x, u, p):
    q, qd = x
    return qd, jnp.linalg.solve(
        TWO_LINK_ARM.mass_matrix(q, p), u - TWO_LINK_ARM.bias_force(q, qd, p)
    )


def _controller(t, x, z, ctrl):
    gains, p = ctrl
    q, qd = x
    tau, _, diag = reaction_force(TWO_LINK_ARM, ARM_CIRCLE, gains, q, qd, t, None, p)
    return tau, z, diag


def arm_demo(out: Path, horizon: float = 6.0, dt: float = ARM_DT) -> list[Path]:
    """Simulate the arm demo and write ``arm_demo.png``; returns the written files."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = arm_params()
    gains = vcm_gains(P_G=[2.0], P_Phi=[1.5, 3.0])
    x0 = (jnp.array([0.35, 1.3], dtype=p.l1.dtype), jnp.array([0.2, -0.1], dtype=p.l1.dtype))
    cfg = RolloutConfig(num_steps=int(round(horizon / dt)))
    run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))
    traj = run(_plant, _controller, cfg, p, (gains, p), x0, jnp.zeros(0, p.l1.dtype), dt)
    ee = np.asarray(jax.vmap(arm_end_effector, in_axes=(0, None))(traj.x[0], p))
    t = np.asarray(traj.t)

    fig, ax = plt.subplots(1, 3, figsize=(14, 4.2))
    th = np.linspace(0, 2 * np.pi, 200)
    ax[0].plot(
        _CENTER[0] + _RADIUS * np.cos(th),
        _CENTER[1] + _RADIUS * np.sin(th),
        "k--",
        label="constraint circle",
    )
    ax[0].plot(ee[:, 0], ee[:, 1], "C0", label="end effector")
    ax[0].plot(ee[0, 0], ee[0, 1], "C0o")
    ax[0].set_aspect("equal")
    ax[0].set_xlabel("x [m]")
    ax[0].set_ylabel("y [m]")
    ax[0].legend(loc="lower left", fontsize=8)
    ax[0].set_title("end-effector path")
    Phi = np.abs(np.asarray(traj.aux.Phi))
    P_Phi = np.asarray(gains.P_Phi)
    tt = t[:-1]
    for i, row in enumerate(("speed row", "circle row")):
        ax[1].semilogy(tt, Phi[:, i], f"C{i}", label=f"|Φ{'₁₂'[i]}| ({row})")
        ax[1].semilogy(
            tt,
            Phi[0, i] * np.exp(-P_Phi[i] * tt),
            color="k",
            linestyle="none",
            marker="o",
            markersize=5,
            markerfacecolor="none",
            markevery=max(len(tt) // 12, 1),
            label=f"|Φ{'₁₂'[i]}(0)| exp(−P_Φ{'₁₂'[i]} t), P_Φ{'₁₂'[i]} = {P_Phi[i]:g} /s",
        )
    ax[1].semilogy(tt, np.abs(np.asarray(traj.aux.G)[:, 0]), "C2", label="|G| (distance to circle)")
    ax[1].set_xlabel("t [s]")
    ax[1].set_ylabel("constraint value [m/s, m]")
    ax[1].set_title("constraint violation vs. the exact decay (14)")
    ax[1].legend(fontsize=7)
    u = np.asarray(traj.u)
    ax[2].plot(t[:-1], u[:, 0], label="τ₁")
    ax[2].plot(t[:-1], u[:, 1], label="τ₂")
    ax[2].set_xlabel("t [s]")
    ax[2].set_ylabel("joint torque [N m]")
    ax[2].set_title("reaction (control) torques")
    ax[2].legend(fontsize=8)
    fig.tight_layout()
    path = Path(out) / "arm_demo.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]
