"""Figure of the arm demo ([`vcjax.experiments.arm`][vcjax.experiments.arm])."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vcjax.plots import pyplot, save

__all__ = ["arm_figure"]


def arm_figure(t, ee, Phi, e, u, P_Phi, center, radius, path) -> Path:
    """End-effector path, constraint decay against the exact exponential (14), torques; written
    to ``path``. ``t``: (N+1,) times; ``ee``: (N, 2) end-effector positions, ``Phi``: (N, 2)
    the constraint rows ``[s, e]`` of the engine (``EngineAux.Phi``), ``e``: (N,) cross-track
    error [m] and ``u``: (N, 2) torques [N m], at the start of each step; ``P_Phi``: (2,)
    their decay rates [1/s]."""
    plt = pyplot()
    fig, ax = plt.subplots(1, 3, figsize=(14, 4.2))
    th = np.linspace(0, 2 * np.pi, 200)
    ax[0].plot(
        center[0] + radius * np.cos(th),
        center[1] + radius * np.sin(th),
        "k--",
        label="path: circle",
    )
    ee = np.asarray(ee)
    ax[0].plot(ee[:, 0], ee[:, 1], "C0", label="end effector")
    ax[0].plot(ee[0, 0], ee[0, 1], "C0o")
    ax[0].set_aspect("equal")
    ax[0].set_xlabel("x [m]")
    ax[0].set_ylabel("y [m]")
    ax[0].legend(loc="lower left", fontsize=8)
    ax[0].set_title("end-effector path")
    Phi = np.abs(np.asarray(Phi))
    P_Phi = np.asarray(P_Phi)
    tt = np.asarray(t)[:-1]
    for i, row in enumerate(("along-track row", "cross-track row")):
        ax[1].semilogy(tt, Phi[:, i], f"C{i}", label=f"|Φ{'₁₂'[i]}| ({row})")
        ax[1].semilogy(
            tt,
            Phi[0, i] * np.exp(-P_Phi[i] * (tt - tt[0])),
            color="k",
            linestyle="none",
            marker="o",
            markersize=5,
            markerfacecolor="none",
            markevery=max(len(tt) // 12, 1),
            label=f"|Φ{'₁₂'[i]}(0)| exp(−P_Φ{'₁₂'[i]} t), P_Φ{'₁₂'[i]} = {P_Phi[i]:g} /s",
        )
    ax[1].semilogy(tt, np.abs(np.asarray(e)), "C2", label="|e| (cross-track error)")
    ax[1].set_xlabel("t [s]")
    ax[1].set_ylabel("constraint value [m/s, m]")
    ax[1].set_title("constraint violation vs. the exact decay (14)")
    ax[1].legend(fontsize=7)
    u = np.asarray(u)
    ax[2].plot(tt, u[:, 0], label="τ₁")
    ax[2].plot(tt, u[:, 1], label="τ₂")
    ax[2].set_xlabel("t [s]")
    ax[2].set_ylabel("joint torque [N m]")
    ax[2].set_title("reaction (control) torques")
    ax[2].legend(fontsize=8)
    return save(fig, path)
