"""Gradient-based tuning loop: optax Adam or L-BFGS (zoom line search), guarded against NaN/inf.

One step ([`make_step`][tuning.optim.make_step]) is loss + gradient + optimiser update. Adam's is
one ``jax.jit``.
L-BFGS's line search evaluates the loss and gradient a variable number of times: run as optax
runs it, inside one jitted step, the gradient is traced and compiled three times (before the
search and in both branches of its loop body), the largest program of the tuner by far. Here
the search is driven from the host instead ([`LBFGSStep`][tuning.optim.LBFGSStep]): one compiled
``value_and_grad`` program, called at every point the search asks for, and small jitted
programs for optax's L-BFGS direction and the zoom line search's rounds
([`tuning.linesearch`][tuning.linesearch]: optax's arithmetic written out, so the same
iterates). Every step reports its loss, gradient norm, whether it was accepted, and how
many batch ``value_and_grad`` evaluations it used.

Guard: a step whose loss, gradient or update is not finite is *rejected*: the parameters and the
optimiser state go back to those of the last accepted step's input and the step size is halved
(a backtrack; for L-BFGS the line search already backtracks, so only the revert applies). Each
rejection is counted and reported ([`TuneResult`][tuning.optim.TuneResult] ``n_bad``,
``history[k]["ok"]``); after
``max_bad_steps`` consecutive rejections the run stops with ``aborted=True`` and a reason.

Gradient modes: ``"reverse"`` (``jax.value_and_grad``) or ``"forward"`` (``jax.jacfwd``: n
forward tangents, worth it when the gains are few and the horizon long, as memory stays O(1) in
the horizon). Forward mode is wrapped in a ``jax.custom_vjp`` so that optax's line search, which
calls ``jax.value_and_grad`` itself, also uses it.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from tuning.linesearch import Zoom
from vcjax.runtime import compiler, distributed, programs

__all__ = [
    "OPTIMIZERS",
    "GRAD_MODES",
    "LBFGS",
    "make_optimizer",
    "forward_mode",
    "StepInfo",
    "LBFGSStep",
    "make_step",
    "init_state",
    "TuneResult",
    "TunerOptions",
    "TunerHooks",
    "run_gradient_tuner",
    "tuner_options",
]

OPTIMIZERS = ("lbfgs", "adam")
GRAD_MODES = ("reverse", "forward")


class LBFGS(NamedTuple):
    """optax's L-BFGS with a zoom line search (``optax.lbfgs``), and its settings.

    ``init`` and ``update`` are those of the optax transformation (an optax optimiser in every
    respect); [`make_step`][tuning.optim.make_step] reads ``memory_size`` and
    ``max_linesearch_steps`` to run the
    line search from the host ([`LBFGSStep`][tuning.optim.LBFGSStep]).
    """

    init: Callable
    update: Callable
    memory_size: int
    max_linesearch_steps: int


def make_optimizer(
    name: str = "lbfgs",
    learning_rate: float = 0.05,
    memory_size: int = 10,
    max_linesearch_steps: int = 15,
):
    """optax optimiser: ``"lbfgs"`` ([`LBFGS`][tuning.optim.LBFGS]: zoom line search;
    ``learning_rate``
    unused) or ``"adam"``."""
    if name == "lbfgs":
        ls = optax.scale_by_zoom_linesearch(
            max_linesearch_steps=max_linesearch_steps, initial_guess_strategy="one"
        )
        opt = optax.lbfgs(memory_size=memory_size, linesearch=ls)
        return LBFGS(opt.init, opt.update, int(memory_size), int(max_linesearch_steps))
    if name == "adam":
        return optax.adam(learning_rate)
    raise ValueError(f"optimizer: expected one of {OPTIMIZERS}, got {name!r}")


def _zero_cotangent(x):
    x = jnp.asarray(x)
    if jnp.issubdtype(x.dtype, jnp.inexact):
        return jnp.zeros_like(x)
    return np.zeros(x.shape, dtype=jax.dtypes.float0)


def forward_mode(f: Callable) -> Callable:
    """``f(theta, *args) -> ()`` whose reverse-mode derivative in ``theta`` uses ``jax.jacfwd``.

    The returned function has the same value; ``jax.grad`` of it (w.r.t. ``theta`` (n,))
    computes the gradient with n forward tangents. ``args`` get zero cotangents.
    """

    @jax.custom_vjp
    def g(theta, *args):
        return f(theta, *args)

    def g_fwd(theta, *args):
        both = lambda th: (lambda v: (v, v))(f(th, *args))
        jac, value = jax.jacfwd(both, has_aux=True)(theta)
        return value, (jac, args)

    def g_bwd(res, ct):
        jac, args = res
        return (ct * jac, *jax.tree_util.tree_map(_zero_cotangent, args))

    g.defvjp(g_fwd, g_bwd)
    return g


class StepInfo(NamedTuple):
    """What one optimiser step reports (traced scalars).

    Attributes:
        loss: () loss at the step's input parameters.
        grad_norm: () Euclidean norm of the gradient there.
        ok: () bool, the step was accepted (loss, gradient and update finite).
        evals: () int, batch ``value_and_grad`` evaluations used.
        update_norm: () norm of the accepted update (0 when rejected).
    """

    loss: Any
    grad_norm: Any
    ok: Any
    evals: Any
    update_norm: Any


def init_state(opt, theta):
    """``opt.init(theta)`` with every leaf strongly typed.

    optax initialises some scalars as weakly typed while its updates return them strongly
    typed; starting strong makes the jitted step compile once, not twice.
    """
    st = opt.init(theta)
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=jnp.asarray(x).dtype), st)


def replicate_like(args, *trees):
    """``trees`` placed, replicated, on the device mesh of the first sharded array in ``args``
    (when that mesh spans several devices; global arrays when they span several processes, the
    same value expected in every process); otherwise unchanged.

    A jitted step whose arguments include a batch sharded over several devices returns its
    parameters and optimiser state replicated over those devices. Fed back in, they differ in
    sharding from the single-device arrays of the first call, and ``jax.jit`` compiles the
    step a second time (the whole reverse-mode rollout: minutes for the 6-DOF loops). Starting
    from the placement the step returns makes it compile once.
    """
    for leaf in jax.tree_util.tree_leaves(args):
        sh = getattr(leaf, "sharding", None)
        mesh = getattr(sh, "mesh", None)
        if mesh is not None and mesh.size > 1:
            return tuple(distributed.replicate(t, mesh) for t in trees)
    return trees


def _finite(tree):
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree)]))


def make_step(
    loss_fn: Callable,
    opt,
    optimizer: str = "lbfgs",
    grad_mode: str = "reverse",
    program_static=None,
):
    """``step(theta, opt_state, scale, args) -> (theta, opt_state, StepInfo)``.

    Args:
        loss_fn: ``loss_fn(theta, *args) -> ()`` (pure, differentiable).
        opt: the optimiser (from [`make_optimizer`][tuning.optim.make_optimizer]).
        optimizer: ``"lbfgs"`` or ``"adam"`` (how the step calls ``opt``).
        grad_mode: ``"reverse"`` or ``"forward"``.
        program_static: L-BFGS: a plain description of everything that fixes ``loss_fn`` (e.g.
            the tuning config): warm runs then load the batch ``value_and_grad`` from
            ``vcjax.runtime.programs``' store instead of tracing it (None: never stored).

    ``scale`` () multiplies the update (the guard's backtracking factor; 1 normally); ``args``
    is a tuple of traced arguments of ``loss_fn`` (e.g. problem data and scenarios), so a new
    batch does not recompile. Adam: one ``jax.jit`` of loss, gradient and update. L-BFGS: an
    [`LBFGSStep`][tuning.optim.LBFGSStep] (one compiled ``value_and_grad``, the line search driven
    from the host).
    """
    if optimizer not in OPTIMIZERS:
        raise ValueError(f"optimizer: expected one of {OPTIMIZERS}, got {optimizer!r}")
    if grad_mode not in GRAD_MODES:
        raise ValueError(f"grad_mode: expected one of {GRAD_MODES}, got {grad_mode!r}")
    f = forward_mode(loss_fn) if grad_mode == "forward" else loss_fn
    if optimizer == "lbfgs":
        if not isinstance(opt, LBFGS):
            raise ValueError("opt: L-BFGS steps need make_optimizer('lbfgs', ...)")
        static = None if program_static is None else (program_static, grad_mode)
        return LBFGSStep(f, opt.memory_size, opt.max_linesearch_steps, static)

    def step(theta, state, scale, args):
        # optax's own arithmetic (e.g. Adam's bias correction, float ** int32 count) is not
        # written for strict dtype promotion: allow standard promotion inside the update only
        with jax.numpy_dtype_promotion("standard"):
            value, grad = jax.value_and_grad(lambda p: f(p, *args))(theta)
            ok = jnp.isfinite(value) & _finite(grad)
            safe = jnp.where(ok, grad, jnp.zeros_like(grad))
            updates, new_state = opt.update(safe, state, theta)
            return _accept(theta, state, value, grad, scale * updates, new_state, ok, 1)

    return compiler.jit(step)


def _accept(theta, state, value, grad, updates, new_state, ok, evals):
    """The guard: apply ``updates`` and take ``new_state`` only when everything is finite."""
    ok = ok & _finite(updates)
    new_theta = theta + jnp.where(ok, updates, jnp.zeros_like(updates))
    new_state = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new_state, state)
    gnorm = jnp.sqrt(jnp.sum(grad * grad))
    unorm = jnp.where(ok, jnp.sqrt(jnp.sum(updates * updates)), jnp.zeros_like(gnorm))
    evals = jnp.asarray(evals, jnp.int32)
    return new_theta, new_state, StepInfo(value, gnorm, ok, evals, unorm)


class LBFGSStep:
    """One L-BFGS step ([`make_step`][tuning.optim.make_step]), the line search driven from the
    host.

    The step is optax's ``lbfgs`` update ([`LBFGS`][tuning.optim.LBFGS]): the two-loop direction,
    then the
    zoom line search (Nocedal and Wright's algorithms 3.5 and 3.6) along it. Each round of the
    search evaluates the loss and gradient once, at a step size its state decides. optax runs
    the rounds in a ``while_loop`` in the jitted step, whose two branches (search an interval,
    zoom into it) each hold the whole batch ``value_and_grad``, besides the one before the
    search: three copies of the largest program. Here the rounds run on the host
    ([`tuning.linesearch.Zoom`][tuning.linesearch.Zoom]): a jitted program gives the point the
    round asks for, the one compiled ``value_and_grad`` evaluates it, and the jitted round proper
    consumes that evaluation. The direction is optax's ``scale_by_lbfgs`` and the search is
    optax's arithmetic step for step, so the iterates are optax's (tested against
    ``optax.lbfgs`` run in one ``jax.jit``).

    Call it as the jitted Adam step: ``step(theta, state, scale, args)``; ``state`` is
    ``LBFGS.init``'s. ``scale`` is not used (the line search already backtracks).
    """

    def __init__(
        self, f: Callable, memory_size: int, max_linesearch_steps: int, program_static=None
    ):
        self._f = f
        self._vg_fn = lambda theta, args: jax.value_and_grad(lambda p: f(p, *args))(theta)
        self._vg = compiler.jit(self._vg_fn)
        # program_static: what fixes loss_fn (e.g. the tuning config), the key of the batch
        # value_and_grad in vcjax.runtime.programs' store (None: traced every run)
        self._program_static = program_static
        self._stored: tuple | None = None  # (argument spec, compiled call) from the store
        zoom = Zoom(max_linesearch_steps=max_linesearch_steps)
        direction = optax.chain(
            optax.scale_by_lbfgs(memory_size=memory_size, scale_init_precond=True),
            optax.scale(-1.0),
        )

        def start(theta, state, value, grad):
            """The direction, and the line search's first point."""
            with jax.numpy_dtype_promotion("standard"):
                d, dir_state = direction.update(grad, state[:2], theta)
                ls = zoom.init(d, theta, value, grad)
                return d, dir_state, ls, zoom.point(ls), zoom.running(ls)

        def advance(ls, value, grad):
            """The round that evaluated ``(value, grad)`` at the last point; the next point."""
            with jax.numpy_dtype_promotion("standard"):
                ls = zoom.advance(ls, value, grad)
                return ls, zoom.point(ls), zoom.running(ls)

        def finish(theta, state, value, grad, d, dir_state, ls, evals):
            """``scale_by_zoom_linesearch``'s update from the search's final state; the guard."""
            with jax.numpy_dtype_promotion("standard"):
                lr = ls.stepsize
                info = optax.ZoomLinesearchInfo(
                    num_linesearch_steps=ls.count,
                    decrease_error=ls.decrease_error,
                    curvature_error=ls.curvature_error,
                )
                ls_state = optax.ScaleByZoomLinesearchState(
                    learning_rate=lr, value=ls.value, grad=ls.grad, info=info
                )
                ls_state = optax.tree.cast_like(ls_state, other_tree=state[2])
                new_state = (*dir_state, ls_state)
                ok = jnp.isfinite(value) & _finite(grad)
                updates = optax.tree.scale(lr, d)
                return _accept(theta, state, value, grad, updates, new_state, ok, evals)

        self._start = compiler.jit(start)
        self._advance = compiler.jit(advance)
        self._finish = compiler.jit(finish)

    def value_and_grad(self, theta, args):
        """The batch loss and its gradient at ``theta`` (the one compiled program)."""
        return self._eval(theta, args)

    def _eval(self, theta, args):
        """``self._vg``, or with a store and ``program_static`` its stored program (built from
        the store, or exported to it, at the first call; the jitted one for other shapes)."""
        if self._stored is None and (self._program_static is None or programs.store_dir() is None):
            return self._vg(theta, args)
        spec = programs.argument_spec((theta, args))
        if self._stored is None:
            call, _ = programs.build(
                "tune:value_and_grad", self._vg_fn, self._program_static, (theta, args)
            )
            self._stored = (spec, call)
        if spec != self._stored[0]:
            return self._vg(theta, args)
        return self._stored[1](theta, args)

    def programs(self, theta, state, args) -> dict:
        """``{name: (jitted, arguments)}`` of every program a step runs (compile-time budgets:
        ``benchmarks/compile_times.py``); the line-search ones at a stand-in state."""
        value, grad = jnp.zeros((), theta.dtype), jnp.zeros_like(theta)  # (not tracing _vg)
        d, dir_state, ls, _, _ = jax.eval_shape(self._start, theta, state, value, grad)
        zeros = lambda t: jax.tree.map(lambda a: jnp.zeros(a.shape, a.dtype), t)
        d, dir_state, ls = zeros(d), zeros(dir_state), zeros(ls)
        return {
            "value_and_grad": (self._vg, (theta, args)),
            "start": (self._start, (theta, state, value, grad)),
            "advance": (self._advance, (ls, value, grad)),
            "finish": (
                self._finish,
                (theta, state, value, grad, d, dir_state, ls, jnp.zeros((), jnp.int32)),
            ),
        }

    def prebuild(self, theta, args) -> None:
        """Build the batch ``value_and_grad`` for arguments like ``(theta, args)`` now (from
        the store when it holds it), e.g. in a thread while other programs compile; a call
        with other shapes or placements still traces and compiles its own."""
        spec = programs.argument_spec((theta, args))
        static = self._program_static if programs.store_dir() is not None else None
        if static is None:
            self._stored = (spec, compiler.jit(self._vg_fn).lower(theta, args).compile())
        else:
            call, _ = programs.build("tune:value_and_grad", self._vg_fn, static, (theta, args))
            self._stored = (spec, call)

    def _cache_size(self) -> int:
        """How often the largest program (the batch ``value_and_grad``) compiled."""
        return self._vg._cache_size() + (self._stored is not None)

    def __call__(self, theta, state, scale, args):
        stored = state[2].value
        evals = 0
        if np.isfinite(float(jax.device_get(stored))):
            value, grad = stored, state[2].grad  # where the last line search ended
        else:
            value, grad = self._eval(theta, args)
            evals += 1
        d, dir_state, ls, point, go = self._start(theta, state, value, grad)
        while bool(jax.device_get(go)):
            v, g = self._eval(point, args)
            ls, point, go = self._advance(ls, v, g)
        evals += int(jax.device_get(ls.count))
        return self._finish(theta, state, value, grad, d, dir_state, ls, evals)


class TuneResult(NamedTuple):
    """Outcome of [`run_gradient_tuner`][tuning.optim.run_gradient_tuner].

    Attributes:
        theta: (n,) best accepted parameters (lowest loss seen at an accepted step's input, or
            the final iterate when its loss is lower).
        loss: () loss at ``theta``.
        history: list of per-step dicts (``iter``, ``loss``, ``grad_norm``, ``ok``, ``evals``,
            ``update_norm``, ``wall_s``; plus whatever ``on_step`` returns).
        n_bad: rejected steps (non-finite loss / gradient / update).
        aborted: stopped after ``max_bad_steps`` consecutive rejections.
        reason: why the loop stopped (``"steps"``, ``"converged"``, ``"stalled"``, ``"aborted:
            ..."``).
        evals: total batch ``value_and_grad`` evaluations.
    """

    theta: Any
    loss: float
    history: list
    n_bad: int
    aborted: bool
    reason: str
    evals: int


def tuner_options(optimizer_section: dict) -> dict:
    """Keyword arguments of [`run_gradient_tuner`][tuning.optim.run_gradient_tuner] (the fields of
    [`TunerOptions`][tuning.optim.TunerOptions]) from a config's ``[optimizer]`` section."""
    o = optimizer_section
    keys = ("steps", "learning_rate", "memory_size", "max_linesearch_steps", "grad_mode")
    opts = {k: o[k] for k in keys + ("max_bad_steps", "grad_tol")}
    return {"optimizer": o["name"], **opts}


@dataclasses.dataclass(frozen=True)
class TunerOptions:
    """Settings of [`run_gradient_tuner`][tuning.optim.run_gradient_tuner] (plain values).

    Attributes:
        optimizer, learning_rate, memory_size, max_linesearch_steps: see
            [`make_optimizer`][tuning.optim.make_optimizer].
        steps: number of optimiser steps.
        grad_mode: ``"reverse"`` or ``"forward"``.
        max_bad_steps: abort after this many consecutive rejected steps.
        grad_tol: stop (``"converged"``) when the gradient norm drops below it.
        program_static: see [`make_step`][tuning.optim.make_step].
    """

    optimizer: str = "lbfgs"
    steps: int = 50
    learning_rate: float = 0.05
    memory_size: int = 10
    max_linesearch_steps: int = 15
    grad_mode: str = "reverse"
    max_bad_steps: int = 5
    grad_tol: float = 1e-8
    program_static: Any = None

    @classmethod
    def from_section(cls, optimizer_section, **overrides) -> TunerOptions:
        """From a config's ``[optimizer]`` section ([`tuner_options`][tuning.optim.tuner_options]),
        with ``overrides``."""
        return cls(**{**tuner_options(optimizer_section), **overrides})

    def optimizer_fn(self):
        """The optax optimiser ([`make_optimizer`][tuning.optim.make_optimizer])."""
        return make_optimizer(
            self.optimizer, self.learning_rate, self.memory_size, self.max_linesearch_steps
        )


class TunerHooks(NamedTuple):
    """Callbacks of [`run_gradient_tuner`][tuning.optim.run_gradient_tuner].

    Attributes:
        on_step: ``on_step(k, theta, record) -> dict | None`` called after each step with the
            new parameters; a returned dict is merged into the history record. Its run time is
            excluded from ``wall_s``.
        progress: ``progress(k, steps, record)`` for a progress bar.
        should_stop: polled after each step; True ends the loop there (``reason``
            ``"interrupted"``; the best parameters so far are returned, no further evaluation).
        refresh: ``refresh(k, theta, args) -> args | None`` called before step ``k``: new
            ``args`` of the same shapes (e.g. robust tuning's new adversarial scenarios,
            [`tuning.robust`][tuning.robust]) replace the old from that step on; the objective
            changed, so L-BFGS restarts its memory and the best parameters are those of the
            latest ``args``.
    """

    on_step: Callable | None = None
    progress: Callable | None = None
    should_stop: Callable[[], bool] | None = None
    refresh: Callable | None = None


_OPTION_FIELDS = tuple(f.name for f in dataclasses.fields(TunerOptions))


def _settings(options, hooks, kwargs) -> tuple[TunerOptions, TunerHooks]:
    """``options`` and ``hooks`` with the keyword arguments of the older signature (every field
    of either, by name) merged in; checked."""
    unknown = sorted(set(kwargs) - set(_OPTION_FIELDS) - set(TunerHooks._fields))
    if unknown:
        raise TypeError(f"run_gradient_tuner() got an unexpected keyword argument {unknown[0]!r}")
    options = dataclasses.replace(
        options or TunerOptions(), **{k: v for k, v in kwargs.items() if k in _OPTION_FIELDS}
    )
    hooks = (hooks or TunerHooks())._replace(
        **{k: v for k, v in kwargs.items() if k in TunerHooks._fields}
    )
    steps, max_bad = options.steps, options.max_bad_steps
    if not (isinstance(steps, int) and steps >= 1):
        raise ValueError(f"steps: expected a positive int, got {steps!r}")
    if not (isinstance(max_bad, int) and max_bad >= 1):
        raise ValueError(f"max_bad_steps: expected a positive int, got {max_bad!r}")
    return options, hooks


class _Loop:
    """The bookkeeping of [`run_gradient_tuner`][tuning.optim.run_gradient_tuner]'s loop: the
    current iterate, the last accepted step's input, the best parameters, the guard's counters."""

    def __init__(self, theta, state):
        self.theta, self.state = theta, state
        self.good = (theta, state)  # input of the last accepted step
        self.best_theta, self.best_loss = theta, np.inf
        self.history: list = []
        self.n_bad = self.consecutive = self.evals = self.stalls = 0
        self.scale = 1.0
        self.wall = 0.0

    def record(self, k: int, info) -> dict:
        """The history record of step ``k`` from its ``StepInfo`` (on the host)."""
        loss = float(info.loss)
        self.evals += int(info.evals)
        return {
            "iter": k,
            "loss": loss if np.isfinite(loss) else None,
            "grad_norm": float(info.grad_norm) if np.isfinite(info.grad_norm) else None,
            "ok": bool(info.ok),
            "evals": int(info.evals),
            "cum_evals": self.evals,
            "update_norm": float(info.update_norm),
            "wall_s": self.wall,
        }

    def restart(self, theta, state) -> None:
        """A new objective (``TunerHooks.refresh``): the best and the last good input are
        those of the new one from here on."""
        self.theta, self.state = theta, state
        self.good = (theta, state)
        self.best_theta, self.best_loss = theta, np.inf
        self.scale = 1.0

    def take(self, new_theta, new_state, loss: float, ok: bool) -> None:
        """The guard: move on after an accepted step; revert and halve the step after a
        rejected one."""
        if ok:
            self.consecutive = 0
            if loss < self.best_loss:
                self.best_theta, self.best_loss = self.theta, loss
            self.good = (self.theta, self.state)
            self.theta, self.state = new_theta, new_state
        else:
            self.n_bad += 1
            self.consecutive += 1
            self.theta, self.state = self.good  # revert to the last good input, smaller step
            self.scale *= 0.5

    def stop(self, rec: dict, options: TunerOptions, should_stop) -> str | None:
        """Why the loop ends after the step of ``rec`` (None: it goes on)."""
        ok = rec["ok"]
        if self.consecutive >= options.max_bad_steps:
            return f"aborted: {self.consecutive} consecutive non-finite steps"
        if ok and rec["grad_norm"] is not None and rec["grad_norm"] < options.grad_tol:
            return "converged"
        self.stalls = self.stalls + 1 if ok and rec["update_norm"] == 0.0 else 0
        if self.stalls >= 3:
            return "stalled"
        if should_stop is not None and should_stop():
            return "interrupted"
        return None

    def finish(self, final: float) -> None:
        """The final iterate's loss ``final``: it is the best when lower."""
        if np.isfinite(final) and final < self.best_loss:
            self.best_theta, self.best_loss = self.theta, final


def run_gradient_tuner(
    loss_fn: Callable,
    theta0,
    args: tuple = (),
    options: TunerOptions | None = None,
    *,
    hooks: TunerHooks | None = None,
    step_fn: Callable | None = None,
    **kwargs,
) -> TuneResult:
    """Minimise ``loss_fn(theta, *args)`` from ``theta0`` (n,).

    Args:
        loss_fn: pure scalar loss.
        theta0: (n,) start.
        args: tuple of traced extra arguments of ``loss_fn``.
        options: the settings ([`TunerOptions`][tuning.optim.TunerOptions]; default: its
            defaults).
        hooks: the callbacks ([`TunerHooks`][tuning.optim.TunerHooks]: ``on_step``,
            ``progress``, ``should_stop``).
        step_fn: a step from [`make_step`][tuning.optim.make_step] to reuse (avoids recompiling).
        **kwargs: any field of ``TunerOptions`` or ``TunerHooks`` by name (``optimizer="adam"``,
            ``steps=30``, ``on_step=...``), over ``options`` and ``hooks``.
    """
    if isinstance(args, TunerOptions) or not isinstance(options, TunerOptions | None):
        raise TypeError("run_gradient_tuner(): give the settings as options=TunerOptions(...)")
    options, hooks = _settings(options, hooks, kwargs)
    opt = options.optimizer_fn()
    step = step_fn or make_step(
        loss_fn, opt, options.optimizer, options.grad_mode, options.program_static
    )
    theta = jnp.asarray(theta0)
    state = init_state(opt, theta)
    theta, state = replicate_like(args, theta, state)  # compile the step once, not twice
    run = _Loop(theta, state)
    reason = "steps"
    for k in range(options.steps):
        if hooks.refresh is not None and (new := hooks.refresh(k, run.theta, args)) is not None:
            args = new
            state = init_state(opt, run.theta) if options.optimizer == "lbfgs" else run.state
            run.restart(*replicate_like(args, run.theta, state))
        t0 = time.perf_counter()
        scale = jnp.asarray(run.scale, run.theta.dtype)
        new_theta, new_state, info = step(run.theta, run.state, scale, args)
        info = jax.device_get(info)
        run.wall += time.perf_counter() - t0
        rec = run.record(k, info)
        run.take(new_theta, new_state, float(info.loss), rec["ok"])
        if hooks.on_step is not None:
            extra = hooks.on_step(k, run.theta, rec)
            if extra:
                rec.update(extra)
        run.history.append(rec)
        if hooks.progress is not None:
            hooks.progress(k + 1, options.steps, rec)
        stop = run.stop(rec, options, hooks.should_stop)
        if stop is not None:
            reason = stop
            break
    aborted = reason.startswith("aborted")
    # the final iterate's loss (L-BFGS keeps it in its state; else evaluate)
    if not aborted and reason != "interrupted":
        if options.optimizer == "lbfgs":
            run.finish(float(jax.device_get(optax.tree.get(run.state, "value"))))
        else:
            run.finish(float(jax.device_get(compiler.jit(loss_fn)(run.theta, *args))))
    return TuneResult(
        theta=run.best_theta,
        loss=float(run.best_loss),
        history=run.history,
        n_bad=run.n_bad,
        aborted=aborted,
        reason=reason,
        evals=run.evals,
    )
