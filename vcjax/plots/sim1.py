"""Figures of Simulation 1 ([`vcjax.experiments.sim1`][vcjax.experiments.sim1]): the paper's Figs.
4-5."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import vcjax.plots as vplots
from vcjax.plots import STYLE

__all__ = ["sim1_figures", "STYLE"]


def sim1_figures(trajs: dict, scenario, out: Path) -> list[Path]:
    """Figures like the paper's Figs. 4–5 for every variant in ``trajs`` (name -> Trajectory)."""
    plt = vplots.pyplot()
    out = Path(out)
    files = []
    order = [v for v in STYLE if v in trajs]

    # Fig. 4: paths (north up, east right), equal scales: the whole run and the approach
    fig, axes = plt.subplots(2, 1, figsize=(9, 7.5), height_ratios=(1, 1.6))
    y_all = np.concatenate([np.asarray(trajs[v].x.eta[:, 1]) for v in order])
    x_all = np.concatenate([np.asarray(trajs[v].x.eta[:, 0]) for v in order])
    eta0 = np.asarray(scenario.eta0)
    V_c = np.asarray(scenario.current)[:2]
    heading = np.degrees(np.arctan2(V_c[1], V_c[0])) % 360
    for ax in axes:
        ax.plot([y_all.min() - 5, y_all.max() + 5], [10, 10], "k-", lw=3, alpha=0.25, label="path")
        for v in order:
            eta = np.asarray(trajs[v].x.eta)
            ax.plot(eta[:, 1], eta[:, 0], **STYLE[v])
        ax.plot(eta0[1], eta0[0], "ko", label="start")
        ax.set_xlabel("y (east) [m]")
        ax.set_ylabel("x (north) [m]")
        ax.set_aspect("equal", adjustable="datalim")  # one metre is one metre both ways
        ax.grid(alpha=0.3)
    axes[0].set_title(
        f"Simulation 1: paths travelled (current {np.hypot(*V_c):.2f} m/s toward {heading:.0f}°)"
    )
    # the approach: where the paths differ (the vehicles cross x = 10 m and settle)
    span = max(float(np.ptp(x_all)), 10.0)
    axes[1].set_xlim(float(eta0[1]) - 0.5 * span, float(eta0[1]) + 3.0 * span)
    axes[1].set_ylim(float(x_all.min()) - 0.3 * span, float(x_all.max()) + 0.3 * span)
    axes[1].set_aspect("equal", adjustable="box")
    axes[1].set_title("the approach (same scale on both axes)", fontsize=10)
    axes[1].legend(fontsize=8, loc="lower right")
    files.append(vplots.save(fig, out / "sim1_paths.png"))

    def two_panel(name, series, ylabels, t_slice, hlines=((), ())):
        """Two stacked time plots; ``series[i](traj)`` gives panel i's samples; ``hlines[i]``
        is a sequence of ``(values, label)`` reference lines drawn and labelled in panel i."""
        fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
        for v in order:
            tr = trajs[v]
            t = np.asarray(tr.t)[t_slice]
            for i in range(2):
                ax[i].plot(t, series[i](tr), **STYLE[v])
        for i in range(2):
            refs = []
            for values, label in hlines[i]:
                for j, y in enumerate(values):
                    line = ax[i].axhline(y, color="k", lw=1.0, ls="--", alpha=0.6)
                    if j == 0:
                        line.set_label(label)
                        refs.append(line)
            ax[i].set_ylabel(ylabels[i])
            ax[i].grid(alpha=0.3)
            if i == 0:
                ax[i].legend(fontsize=8)
            elif refs:
                ax[i].legend(handles=refs, fontsize=8, loc="upper right")
        ax[1].set_xlabel("t [s]")
        return vplots.save(fig, out / name)

    vehicle = scenario.plant
    thrust_max = float(vehicle.thrust_max)
    rudder_max = np.degrees(float(vehicle.rudder_max))
    head = slice(None, -1)
    # Fig. 5 (left): u and heading error
    files.append(
        two_panel(
            "sim1_speed_heading.png",
            (lambda tr: np.asarray(tr.x.nu[:-1, 0]), lambda tr: np.degrees(tr.aux.psi_tilde)),
            ("u [m/s]", "heading error ψ̃ [deg]"),
            head,
            ((((float(scenario.u_d),), f"desired speed u_d = {float(scenario.u_d):g} m/s"),), ()),
        )
    )
    # Fig. 5 (right): control signals (actual actuator states)
    files.append(
        two_panel(
            "sim1_controls.png",
            (lambda tr: np.asarray(tr.x.act[:, 0]), lambda tr: np.degrees(tr.x.act[:, 1])),
            ("thrust τ_u [N]", "rudder δ [deg]"),
            slice(None),
            (
                (((-thrust_max, thrust_max), f"thrust limit ±{thrust_max:g} N"),),
                (((-rudder_max, rudder_max), f"rudder limit ±{rudder_max:g}°"),),
            ),
        )
    )
    # path-following errors
    files.append(
        two_panel(
            "sim1_errors.png",
            (lambda tr: np.asarray(tr.aux.eps[:, 0]), lambda tr: np.asarray(tr.aux.eps[:, 1])),
            ("along-track s [m]", "cross-track e [m]"),
            head,
        )
    )
    return files
