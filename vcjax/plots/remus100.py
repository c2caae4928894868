"""Figures of the REMUS 100 survey mission
([`vcjax.experiments.remus100`][vcjax.experiments.remus100])."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import paths
from vcjax.plots import pyplot, save
from vcjax.vehicles.remus100 import remus100_params

__all__ = ["remus100_figures"]


def _path_points(path, coeffs, num=3000):
    c = coeffs
    total = float(c.n_legs) * float(c.leg) + (float(c.n_legs) - 1) * np.pi * float(c.radius)
    ws = jnp.linspace(0.0, total, num)
    return np.asarray(jax.vmap(lambda w: paths.path_point(path, coeffs, w))(ws))


def remus100_figures(trajs: dict, path, coeffs, out: Path, labels: dict) -> list[Path]:
    """3-D path, plan view, errors ``s, e, h`` and 3-D distance, fins and rpm vs limits."""
    plt = pyplot()
    out = Path(out)
    pp = _path_points(path, coeffs)
    files = []

    fig = plt.figure(figsize=(8, 6))
    ax = fig.add_subplot(projection="3d")
    ax.plot(pp[:, 1], pp[:, 0], -pp[:, 2], "k--", lw=1, label="path")
    for v, tr in trajs.items():
        eta = np.asarray(tr.x.eta)
        ax.plot(eta[:, 1], eta[:, 0], -eta[:, 2], lw=1, label=labels.get(v, v))
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_zlabel("height (-depth) [m]")
    ax.set_title("REMUS 100 survey, 0.3 m/s current towards east")
    ax.legend(fontsize=7)
    files.append(save(fig, out / "remus100_path3d.png"))

    fig, ax = plt.subplots(figsize=(7, 7))
    ax.plot(pp[:, 1], pp[:, 0], "k--", lw=1, label="path")
    for v, tr in trajs.items():
        eta = np.asarray(tr.x.eta)
        ax.plot(eta[:, 1], eta[:, 0], lw=1, label=labels.get(v, v))
    ax.annotate("", xy=(20, -20), xytext=(0, -20), arrowprops=dict(arrowstyle="->"))
    ax.text(0, -28, "current 0.3 m/s", fontsize=8)
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal")
    ax.set_title("plan view")
    ax.legend(fontsize=7)
    files.append(save(fig, out / "remus100_plan.png"))

    fig, axs = plt.subplots(4, 1, figsize=(9, 9), sharex=True)
    names = ("along-track s [m]", "cross-track e [m]", "vertical h [m]", "distance |eps| [m]")
    for v, tr in trajs.items():
        t = np.asarray(tr.t[:-1])
        eps = np.asarray(tr.aux.eps)
        for i in range(3):
            axs[i].plot(t, eps[:, i], lw=1, label=labels.get(v, v))
        axs[3].semilogy(t, np.maximum(np.linalg.norm(eps, axis=1), 1e-4), lw=1)
    for a, n in zip(axs, names, strict=True):
        a.set_ylabel(n)
        a.grid(alpha=0.3)
    for a in axs[:3]:
        a.set_ylim(-3, 3)
    axs[0].legend(fontsize=7, ncol=2)
    axs[-1].set_xlabel("t [s]")
    axs[0].set_title("path-frame errors at each law's path particle")
    files.append(save(fig, out / "remus100_errors.png"))

    fig, axs = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for v, tr in trajs.items():
        t = np.asarray(tr.t)
        act = np.asarray(tr.x.act)
        axs[0].plot(t, np.degrees(act[:, 0]), lw=0.8, label=labels.get(v, v))
        axs[1].plot(t, np.degrees(act[:, 1]), lw=0.8)
        axs[2].plot(t, act[:, 2], lw=0.8)
    lim = np.asarray(remus100_params().act_max)
    for a, L, n in zip(
        axs,
        (np.degrees(lim[0]), np.degrees(lim[1]), lim[2]),
        ("rudder [deg]", "stern planes [deg]", "propeller [rpm]"),
        strict=True,
    ):
        a.axhline(L, color="r", ls=":", lw=1)
        a.axhline(-L, color="r", ls=":", lw=1)
        a.set_ylabel(n)
        a.grid(alpha=0.3)
    axs[2].set_ylim(0, 1.1 * lim[2])
    axs[0].legend(fontsize=7, ncol=2)
    axs[0].set_title("actuators (limits dotted)")
    axs[-1].set_xlabel("t [s]")
    files.append(save(fig, out / "remus100_actuators.png"))
    return files
