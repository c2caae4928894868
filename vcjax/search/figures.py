"""Figures of a falsification (Agg backend, files, never windows).

* ``falsify_worst.png``: the worst scenario's track against the path (plan view, east
  horizontal), and its cross-track error and 3-D distance to the path against time;
* ``falsify_curve.png``: the worst metric found against the rollouts run and against wall
  time (compilation included; a dashed line where the gradient search first beat random
  sampling's worst), gradient search and random sampling (with the ``--bound``, when given).
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import loops
from vcjax.plots import pyplot, save
from vcjax.rollout import RolloutConfig
from vcjax.runtime import compiler
from vcjax.search.envelope import Envelope, Setting, scenario_from
from vcjax.sweep.run import in_sea, surface_clearance, to_scenario

__all__ = ["worst_trajectory", "worst_run", "plot_worst", "plot_curve"]


def worst_trajectory(loop, gains, env: Envelope, setting: Setting, x, index):
    """``(t (N,), pos (N, 3), e (N,), dist (N,), path (P, 3))`` of one scenario (numpy)."""
    return worst_run(loop, gains, env, setting, x, index)[0]


def worst_run(loop, gains, env: Envelope, setting: Setting, x, index):
    """``(trajectory, clearance)`` of one scenario from one simulation: its
    [`worst_trajectory`][vcjax.search.figures.worst_trajectory], and how far below the local
    sea surface its vehicle runs, ``(t (N,), clearance (N,))`` [s, m] (numpy; negative: above
    the surface, where the submerged model -- no free surface, no loss of buoyancy or fin
    lift -- does not describe a vehicle), or None for a scenario without a sea.
    ``clearance = origin_depth + z + zeta(t, north, east)``: the vehicle's depth below the
    mean surface plus the elevation of the sea above it."""
    traj, sig, s, _ = _simulate(loop, gains, env, setting, x, index)
    pos = np.asarray(sig.pos)
    path = np.asarray(loops.path_polyline(loop.path, setting.nominal[2], pos))
    t = np.asarray(traj.t[: pos.shape[0]])  # the samples: the states at the start of each step
    e = np.asarray(sig.eps[:, 1])
    d = np.sqrt(np.sum(np.asarray(sig.p_err) ** 2, axis=1))
    clearance = None
    if in_sea(s):
        c = surface_clearance(s, jnp.asarray(pos), jnp.asarray(t))
        clearance = (t, np.asarray(c))
    return (t[: e.size], pos, e, d, path), clearance


def _simulate(loop, gains, env: Envelope, setting: Setting, x, index):
    """``(trajectory, signals, loop scenario, search scenario)`` of one scenario."""
    dtype = jnp.asarray(jax.tree_util.tree_leaves(setting.nominal)[0]).dtype
    sc = scenario_from(jnp.asarray(np.asarray(x, float), dtype), index, env, setting)
    plant, design, coeffs = setting.nominal
    s = to_scenario(loop, sc, plant, design, coeffs, setting.config)
    from vcjax.loops import DisturbanceParams, Disturbances, gauss_markov_params

    c = setting.config
    rcfg = RolloutConfig(num_steps=c.num_steps, integrator=c.integrator, timing=c.timing)
    dist = Disturbances(gauss_markov=c.current_model == "gauss_markov", sensor_noise=c.sensor_noise)
    dp = DisturbanceParams(
        current=gauss_markov_params(s, sc.current_sigma, sc.current_tau, sc.current_max_speed),
        noise_std=sc.noise_std,
        key=sc.key,
    )
    traj = compiler.jit(lambda g, s_: loops.simulate(loop, g, s_, rcfg, setting.dt, dist, dp))(
        gains, s
    )
    return traj, loop.signals(traj, s), s, sc


def plot_worst(traj, title: str, path) -> Path:
    t, pos, e, d, pts = traj
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.5))
    a1.plot(pts[:, 1], pts[:, 0], "k--", lw=1, label="path")
    a1.plot(pos[:, 1], pos[:, 0], "tab:red", lw=1.5, label="worst scenario")
    a1.plot(pos[0, 1], pos[0, 0], "o", color="tab:red", ms=4)
    a1.set_xlabel("east [m]")
    a1.set_ylabel("north [m]")
    a1.set_aspect("equal", adjustable="datalim")
    a1.legend(loc="best", fontsize=8)
    a2.plot(t, e, "tab:red", lw=1, label="cross-track error e")
    a2.plot(t, d, "tab:blue", lw=1, label="3-D distance to the path point")
    a2.set_xlabel("t [s]")
    a2.set_ylabel("[m]")
    a2.legend(loc="best", fontsize=8)
    fig.suptitle(title, fontsize=10)
    return save(fig, path)


def _time_steps(result):
    """``(seconds, worst)`` of each search against wall time: the gradient search after each
    step, random sampling after each batch (the worst of the rollouts done by then)."""
    grad = [(t, w) for (_, w), t in zip(result.curve, result.curve_s, strict=False)]
    worst = dict(result.random_curve)
    rand = [(t, worst[n]) for n, t in result.random_curve_s if n in worst]
    return grad, rand


def plot_curve(result, path) -> Path:
    """The worst metric found against the rollouts run (left) and against wall time,
    compilation included (right, when the times were recorded), for both searches."""
    plt = pyplot()
    timed = bool(result.curve_s or result.random_curve_s)
    fig, axes = plt.subplots(1, 2 if timed else 1, figsize=(11.5 if timed else 6.5, 4.2))
    axes = list(np.atleast_1d(axes))
    ax = axes[0]
    if result.curve:
        r, w = np.asarray(result.curve, float).T
        ax.step(r, w, where="post", color="tab:red", label="gradient search")
    if result.random_curve:
        r, w = np.asarray(result.random_curve, float).T
        ax.step(r, w, where="post", color="tab:gray", label="random sampling")
    ax.set_xscale("log")
    ax.set_xlabel("rollouts")
    if timed:
        grad, rand = _time_steps(result)
        for pts, color, label in ((grad, "tab:red", "gradient search"),
                                  (rand, "tab:gray", "random sampling")):  # fmt: skip
            if pts:
                t, w = np.asarray(pts, float).T
                axes[1].step(t, w, where="post", color=color, marker=".", label=label)
        axes[1].set_xlabel("wall time since the search began [s] (compilation included)")
        beat = result.beat_random
        if beat is not None:
            axes[1].axvline(beat[1], color="tab:red", ls="--", lw=0.8)
    for a in axes:
        if result.bound is not None:
            a.axhline(result.bound, color="k", ls=":", lw=1, label="bound")
        a.set_ylabel(f"worst {result.metric} found")
        a.legend(loc="best", fontsize=8)
        a.grid(alpha=0.3)
    return save(fig, path)
