"""Tuning loss: tracking, saturation and effort costs of closed-loop rollouts of any loop
(docs/guides/tuning.md), from the loop's [`Signals`][vcjax.loops.types.Signals].

Per rollout of horizon ``T = N dt`` (every integral normalised by ``T``, i.e. a time average):

* ``eps``: ``1/T ∫ (s² + e²) dt`` [m²], path errors (23);
* ``u_tilde``: ``1/T ∫ ũ² dt`` [(m/s)²], speed error;
* ``psi_tilde``: ``1/T ∫ ψ̃² dt`` [rad²], heading error (25) (0 for loops without one);
* ``depth``: ``1/T ∫ z̃² dt`` [m²], the depth error of 3-D loops (0 for planar ones; weight 0
  by default: ``eps`` is the horizontal path error, so a loop whose depth matters, e.g. in
  waves, weighs it in);
* ``sat_excess``: ``1/T ∫ Σ_i (x_i)² dt`` with ``x_i = max(|cmd_i| - lim_i, 0) / lim_i``: how far
  the actuator *commands* go beyond their limits (INFANTE-class: 920 N, 30°), relative;
* ``sat_time``: ``1/T ∫ Σ_i x_i² / (x_i² + w²) dt``: a smooth count of the time spent beyond the
  limits (0 inside them, → 1 per channel when ``x_i >> w``; ``w = sat_width``, C¹ at the limit so
  the gradient exists everywhere; a plain indicator has zero gradient almost everywhere);
* ``effort``: ``1/T ∫ Σ_i (cmd_i / lim_i)² dt`` (optional, weight 0 by default);
* ``unhealthy``: fraction of steps that produced a non-finite state (the rollout then freezes
  the state; weighted heavily so a diverging candidate never looks good).

The scenario loss is ``Σ_k w_k term_k``; a batch is aggregated by the mean, or by the CVaR at
level ``alpha`` (the mean of the worst ``ceil(alpha B)`` scenario losses). A quadratic penalty
keeps ``theta`` within ``log_box`` of its reference (gains within a factor ``e^log_box`` of the
starting gains), which also gives the black-box tuners a bounded search region.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from tuning.params import GainSpace
from tuning.scenarios import SCENARIO_AXES
from tuning.spec import Weights
from vcjax import loops
from vcjax.rollout import RolloutConfig
from vcjax.sweep.run import in_sea, surface_metrics

__all__ = [
    "TERMS",
    "LossWeights",
    "loss_weights",
    "rollout_terms",
    "TuningProblem",
    "ProblemData",
    "problem_data",
    "scenario_losses",
    "weighted_loss",
    "objective",
    "aggregate",
]

TERMS = ("eps", "u_tilde", "psi_tilde", "sat_excess", "sat_time", "effort", "unhealthy", "depth")


class LossWeights(NamedTuple):
    """Weights of the loss terms (traced scalars; see the module docstring for units).

    Attributes:
        eps, u_tilde, psi_tilde, sat_excess, sat_time, effort, unhealthy, depth: () weights
            >= 0.
        sat_width: () smoothing width ``w`` of the time-over-limit count (fraction of the limit).
    """

    eps: Any
    u_tilde: Any
    psi_tilde: Any
    sat_excess: Any
    sat_time: Any
    effort: Any
    unhealthy: Any
    sat_width: Any
    depth: Any = 0.0


#: The default of every weight of [`loss_weights`][tuning.loss.loss_weights]: the ``[weights]``
#: section's (``tuning.spec.Weights``, declared once), so that a tune from Python and one from a
#: config file that omits the section minimise the same loss.
DEFAULT_WEIGHTS = {f.name: float(f.default) for f in dataclasses.fields(Weights)}


def loss_weights(dtype=None, **weights) -> LossWeights:
    """Validated [`LossWeights`][tuning.loss.LossWeights] of ``dtype`` from the weights given by
    name (``eps=2.0``, ...; the others at ``DEFAULT_WEIGHTS``): every weight finite and >= 0,
    ``sat_width`` > 0."""
    unknown = sorted(set(weights) - set(DEFAULT_WEIGHTS))
    if unknown:
        raise TypeError(f"loss_weights() got an unexpected keyword argument {unknown[0]!r}")
    vals = {**DEFAULT_WEIGHTS, **weights}
    for k, v in vals.items():
        if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer):
            raise ValueError(f"weights.{k}: expected a number, got {v!r}")
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"weights.{k}: expected a finite value >= 0, got {v!r}")
    if not vals["sat_width"] > 0:
        raise ValueError(f"weights.sat_width: expected > 0, got {vals['sat_width']!r}")
    dtype = jnp.zeros(()).dtype if dtype is None else dtype
    return LossWeights(**{k: jnp.asarray(v, dtype=dtype) for k, v in vals.items()})


def rollout_terms(traj, sig: loops.Signals, sat_width) -> dict:
    """Loss terms of one rollout (dict of () arrays, keys ``TERMS``).

    Args:
        traj: the [`Trajectory`][vcjax.rollout.Trajectory] (its health flags).
        sig: the loop's [`Signals`][vcjax.loops.types.Signals] of that run (errors, commands /
            limits).
        sat_width: () smoothing width of the time-over-limit count.
    """
    eps = sig.eps
    x = sig.cmd_ratio
    over = jnp.maximum(jnp.abs(x) - 1.0, jnp.zeros_like(x))
    over2 = over * over
    return {
        "eps": jnp.mean(jnp.sum(eps * eps, axis=-1)),
        "u_tilde": jnp.mean(sig.u_err**2),
        "psi_tilde": jnp.mean(sig.psi_err**2),
        "sat_excess": jnp.mean(jnp.sum(over2, axis=-1)),
        "sat_time": jnp.mean(jnp.sum(over2 / (over2 + sat_width * sat_width), axis=-1)),
        "effort": jnp.mean(jnp.sum(x * x, axis=-1)),
        "unhealthy": jnp.mean((~traj.finite).astype(eps.dtype)),
        "depth": jnp.mean(sig.depth_err**2),
    }


@dataclasses.dataclass(frozen=True)
class TuningProblem:
    """Static description of a tuning objective (hashable; a change recompiles).

    Attributes:
        space: [`GainSpace`][tuning.params.GainSpace] (the loop and its tuned gains).
        num_steps: rollout length N (horizon ``N dt``).
        integrator: ``"rk4"`` (default), ``"heun"`` or ``"euler"``.
        timing: ``"continuous"`` or ``"sampled"`` controller.
        checkpoint: rematerialise in the backward pass (default): under reverse mode the
            backward scan recomputes each segment from its stored state instead of reading a
            tape of every intermediate value. Per step (``checkpoint_every = 1``) the
            gradient of a batch runs faster and compiles faster than without (REMUS 100,
            32 scenarios x 200 steps: 192 -> 140 ms, compile 23 -> 19 s;
            ``docs/performance.md``), and needs the least memory but one.
        checkpoint_every: with ``checkpoint``, the segment length (``RolloutConfig``; default 1).
        surface: in a sea, add each scenario's ``above_surface_fraction`` and
            ``min_surface_clearance`` [m] (``vcjax.sweep.run.SURFACE_METRICS``) to its terms
            (the held-out evaluation of ``vcjax tune``; not part of the loss).
        smooth: tanh actuator saturation in the plant (gradients pass through saturation).
        risk: ``"mean"`` or ``"cvar"`` aggregation over the batch.
        alpha: CVaR level in (0, 1]: the fraction of worst scenarios averaged.
        tile_gains: copy the gains once per scenario before the ``vmap`` (for a batch sharded
            over several devices): the gradient w.r.t. the gains is then accumulated per
            scenario and reduced across devices once, instead of by an all-reduce at every step
            of the backward scan (18x slower measured, 48 scenarios on 2 CPU devices,
            ``benchmarks/perf/sharded_gradient.py``); on one device it brings nothing (measured
            equal to 1.5x slower), so ``vcjax tune`` sets it only when it shards the batch.
    """

    space: GainSpace = GainSpace()
    num_steps: int = 800
    integrator: str = "rk4"
    timing: str = "continuous"
    checkpoint: bool = True
    checkpoint_every: int = 1
    surface: bool = False
    smooth: bool = True
    risk: str = "mean"
    alpha: float = 0.2
    tile_gains: bool = False

    def __post_init__(self):
        if self.risk not in ("mean", "cvar"):
            raise ValueError(f"risk: expected 'mean' or 'cvar', got {self.risk!r}")
        if not (0.0 < float(self.alpha) <= 1.0):
            raise ValueError(f"alpha: expected a value in (0, 1], got {self.alpha!r}")
        if not isinstance(self.tile_gains, bool):
            raise ValueError(f"tile_gains: expected True or False, got {self.tile_gains!r}")
        self.rollout_config()  # validates num_steps, integrator, timing

    @property
    def loop(self) -> loops.Loop:
        """The loop rolled out (the space's, with this problem's actuator saturation)."""
        return dataclasses.replace(self.space.loop, smooth=self.smooth)

    def rollout_config(self) -> RolloutConfig:
        return RolloutConfig(
            num_steps=self.num_steps,
            integrator=self.integrator,
            timing=self.timing,
            checkpoint=self.checkpoint,
            checkpoint_every=self.checkpoint_every,
        )


class ProblemData(NamedTuple):
    """Traced data of a tuning objective.

    Attributes:
        base: the loop's gains (the untuned ones come from here).
        weights: [`LossWeights`][tuning.loss.LossWeights].
        dt: () step [s].
        theta_ref: (n,) centre of the box penalty (usually the encoded starting gains).
        log_box: () half-width of the box; box_weight: () its weight.
    """

    base: Any
    weights: Any
    dt: Any
    theta_ref: Any
    log_box: Any
    box_weight: Any


def problem_data(
    problem: TuningProblem,
    base=None,
    weights: LossWeights | None = None,
    dt: float = 0.1,
    log_box: float = 3.0,
    box_weight: float = 10.0,
) -> ProblemData:
    """Validated [`ProblemData`][tuning.loss.ProblemData]; ``theta_ref`` is the encoding of
    ``base``."""
    base = problem.space.loop.default_gains() if base is None else base
    weights = loss_weights() if weights is None else weights
    for name, v in (("dt", dt), ("log_box", log_box), ("box_weight", box_weight)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name}: expected a finite value > 0, got {v!r}")
    dtype = jnp.asarray(jax.tree_util.tree_leaves(base)[0]).dtype
    f = lambda x: jnp.asarray(x, dtype=dtype)
    theta_ref = problem.space.encode(base)
    return ProblemData(base, weights, f(dt), theta_ref, f(log_box), f(box_weight))


def weighted_loss(terms: dict, weights: LossWeights):
    """The scenario loss ``sum_k w_k term_k`` over every term of ``TERMS``."""
    return sum(getattr(weights, k) * terms[k] for k in TERMS)


def scenario_losses(theta, data: ProblemData, scenarios, problem: TuningProblem):
    """Per-scenario losses ``(B,)`` and terms ``{name: (B,)}`` of the gains ``theta`` (n,)."""
    gains = problem.space.decode(theta, data.base)
    cfg = problem.rollout_config()
    loop = problem.loop
    w = data.weights

    def one(g, sc):
        traj = loops.simulate(loop, g, sc, cfg, data.dt)
        sig = loop.signals(traj, sc)
        terms = rollout_terms(traj, sig, w.sat_width)
        loss = weighted_loss(terms, w)
        if problem.surface and in_sea(sc):  # the samples: the states at each step's start
            terms = terms | surface_metrics(sc, sig.pos, traj.t[: sig.pos.shape[0]])
        return loss, terms

    if not problem.tile_gains:
        return jax.vmap(one, in_axes=(None, SCENARIO_AXES))(gains, scenarios)
    n = scenarios.eta0.shape[0]
    tiled = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (n, *jnp.shape(a))), gains)
    return jax.vmap(one, in_axes=(0, SCENARIO_AXES))(tiled, scenarios)


def aggregate(losses, problem: TuningProblem):
    """Batch loss: mean, or CVaR (mean of the worst ``ceil(alpha B)``) of ``losses`` (B,)."""
    if problem.risk == "mean":
        return jnp.mean(losses)
    k = max(1, math.ceil(problem.alpha * losses.shape[0] - 1e-9))
    return jnp.mean(jax.lax.top_k(losses, k)[0])


def box_penalty(theta, data: ProblemData):
    """Quadratic penalty on ``theta`` leaving ``theta_ref ± log_box``."""
    d = jnp.abs(theta - data.theta_ref) - data.log_box
    d = jnp.maximum(d, jnp.zeros_like(d))
    return data.box_weight * jnp.sum(d * d)


def objective(theta, data: ProblemData, scenarios, problem: TuningProblem):
    """Scalar tuning loss of ``theta`` on a scenario batch, and ``(losses (B,), terms)``.

    Returns:
        ``(loss, (losses, terms))``: aggregated loss + box penalty; per-scenario losses and
        terms (for reports).
    """
    losses, terms = scenario_losses(theta, data, scenarios, problem)
    return aggregate(losses, problem) + box_penalty(theta, data), (losses, terms)
