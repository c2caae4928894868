"""Figures of Simulation 2 (like the paper's Figs. 6–7), written as PNG files (Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vcjax.paths import path_point
from vcjax.plots import pyplot, save

__all__ = ["sim2_figures", "STYLE"]

#: Line styles per actuation mode.
STYLE = {
    "underactuated": dict(color="C0", ls="-", label="VCM, underactuated (τ_v = 0, paper)"),
    "full": dict(color="C3", ls="--", label="VCM, fully actuated (sway thrust)"),
}


def _desired(path, coeffs, trajs):
    """(K, 3) the path sampled over the range of ``w`` the particles covered."""
    import jax

    w_end = max(float(np.asarray(tr.z.vcm.varpi)[-1]) for tr in trajs.values())
    w_start = min(float(np.asarray(tr.z.vcm.varpi)[0]) for tr in trajs.values())
    ws = np.linspace(w_start, w_end, 800)
    return np.asarray(jax.vmap(lambda w: path_point(path, coeffs, w))(ws))


def sim2_figures(trajs: dict, scenario, path, out: Path) -> list[Path]:
    """Figures for every actuation mode in ``trajs`` (name -> Trajectory).

    * ``sim2_path_3d.png`` (Fig. 6): desired and travelled paths in 3-D (depth axis pointing
      down, NED);
    * ``sim2_horizontal.png`` (Fig. 7, left): horizontal-plane view, north up, east right;
    * ``sim2_errors.png`` (Fig. 7, right): distance-error components ``p - p_p(w)`` (NED) and
      the path-frame errors ``s``, ``e`` and depth error vs time;
    * ``sim2_thrusters.png``: thruster forces of the headline mode and the commanded vs
      allocated generalised forces.
    """
    plt = pyplot()
    out = Path(out)
    files = []
    order = [m for m in STYLE if m in trajs]
    pd = _desired(path, scenario.path, trajs)

    # Fig. 6: 3-D
    fig = plt.figure(figsize=(8, 7))
    ax = fig.add_subplot(projection="3d")
    ax.plot(pd[:, 1], pd[:, 0], pd[:, 2], "k-", lw=3, alpha=0.3, label="desired path")
    for m in order:
        eta = np.asarray(trajs[m].x.eta)
        ax.plot(eta[:, 1], eta[:, 0], eta[:, 2], **STYLE[m])
    eta0 = np.asarray(scenario.eta0)
    ax.scatter([eta0[1]], [eta0[0]], [eta0[2]], color="k", marker="o", label="start")
    ax.set_xlabel("y (east) [m]")
    ax.set_ylabel("x (north) [m]")
    ax.set_zlabel("z (down) [m]")
    ax.invert_zaxis()
    ax.set_title("Simulation 2: ODIN-class AUV on the helix")
    ax.legend(fontsize=8, loc="upper left")
    files.append(save(fig, out / "sim2_path_3d.png"))

    # Fig. 7 (left): horizontal plane
    fig, ax = plt.subplots(figsize=(7, 7))
    ax.plot(pd[:, 1], pd[:, 0], "k-", lw=3, alpha=0.3, label="desired path")
    for m in order:
        eta = np.asarray(trajs[m].x.eta)
        ax.plot(eta[:, 1], eta[:, 0], **STYLE[m])
    ax.plot(eta0[1], eta0[0], "ko", label="start")
    td = np.asarray(scenario.disturbance)
    ax.set_title(
        f"horizontal plane (body disturbance τ_dist = [{td[0]:g}, {td[1]:g}, {td[2]:g}] N)"
    )
    ax.set_xlabel("y (east) [m]")
    ax.set_ylabel("x (north) [m]")
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    files.append(save(fig, out / "sim2_horizontal.png"))

    # Fig. 7 (right): distance-error components
    fig, ax = plt.subplots(4, 1, figsize=(8, 9), sharex=True)
    comp = ["x - x_p (north) [m]", "y - y_p (east) [m]", "z - z_p (down) [m]"]
    for m in order:
        tr = trajs[m]
        t = np.asarray(tr.t[:-1])
        pe = np.asarray(tr.aux.p_err)
        for i in range(3):
            ax[i].plot(t, pe[:, i], **STYLE[m])
        ax[3].plot(t, np.linalg.norm(pe, axis=1), **STYLE[m])
    for i in range(3):
        ax[i].set_ylabel(comp[i])
    ax[3].set_ylabel("|p - p_p(w)| [m]")
    ax[3].set_yscale("log")
    ax[3].set_xlabel("t [s]")
    ax[0].legend(fontsize=8)
    for a in ax:
        a.grid(alpha=0.3)
    files.append(save(fig, out / "sim2_errors.png"))

    fig, ax = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for m in order:
        tr = trajs[m]
        t = np.asarray(tr.t[:-1])
        eps = np.asarray(tr.aux.vcm.eps)
        ax[0].plot(t, eps[:, 0], **STYLE[m])
        ax[1].plot(t, eps[:, 1], **STYLE[m])
        ax[2].plot(t, np.asarray(tr.aux.depth_err), **STYLE[m])
    ax[0].set_ylabel("along-track s [m]")
    ax[1].set_ylabel("cross-track e [m]")
    ax[2].set_ylabel("depth error [m]")
    ax[2].set_xlabel("t [s]")
    ax[0].legend(fontsize=8)
    for a in ax:
        a.grid(alpha=0.3)
    files.append(save(fig, out / "sim2_path_errors.png"))

    # thrusters of the headline mode
    m = order[0]
    tr = trajs[m]
    t = np.asarray(tr.t)
    f = np.asarray(tr.x.thrust)
    fmax = float(np.max(np.asarray(scenario.plant.thrust_max)))
    fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for i in range(4):
        ax[0].plot(t, f[:, i], label=f"H{i + 1}")
        ax[1].plot(t, f[:, 4 + i], label=f"V{i + 1}")
    for a, name in zip(ax[:2], ("horizontal", "vertical"), strict=True):
        for s in (-1, 1):
            a.axhline(s * fmax, color="k", lw=0.8, ls="--", alpha=0.5)
        a.set_ylabel(f"{name} thrust [N]")
        a.legend(fontsize=7, ncol=4)
    tc = np.asarray(tr.aux.tau_cmd)
    ta = np.asarray(tr.aux.tau_alloc)
    names = ["X [N]", "Y [N]", "Z [N]", "K [N m]", "M [N m]", "N [N m]"]
    for i in (0, 1, 2, 5):
        (line,) = ax[2].plot(t[:-1], tc[:, i], lw=1, label=f"{names[i]} cmd")
        ax[2].plot(t[:-1], ta[:, i], lw=2, alpha=0.4, color=line.get_color())
    ax[2].set_ylabel("τ commanded / allocated")
    ax[2].legend(fontsize=7, ncol=4)
    ax[2].set_xlabel("t [s]")
    ax[0].set_title(f"thrusters ({m})")
    for a in ax:
        a.grid(alpha=0.3)
    files.append(save(fig, out / "sim2_thrusters.png"))
    return files
