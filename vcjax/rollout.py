"""Closed-loop rollouts as one ``lax.scan``.

A closed loop is a plant and a controller, both pure functions:

* plant: ``f(t, x, u, plant_params) -> x_dot`` (any pytree ``x``: pose, velocity, actuator
  states, …);
* controller: ``c(t, x, z, ctrl_params) -> (u, z_dot, aux)`` where ``z`` is the controller's own
  state (path particle, integrators, ``v_d``, …; use an empty array when it has none), ``u`` the
  command handed to the plant and ``aux`` any pytree of signals to record (errors, diagnostics).

Static configuration ([`RolloutConfig`][vcjax.rollout.RolloutConfig]: horizon, integrator,
controller timing,
checkpointing) is kept apart from traced parameters (gains, vehicle, current, ``dt``), so new
parameter values never recompile. The library does not jit for you: jit at your entry point, e.g.
``jax.jit(rollout, static_argnames=("plant", "controller", "config"))``.

Controller timing:

* ``"continuous"``: the controller is evaluated inside the vector field, at every integrator stage
  (what the theory assumes; exactness tests use it);
* ``"sampled"``: the controller is evaluated once at the start of each step and its command held
  over the step (zero-order hold, as on a real vehicle); its state ``z`` is advanced by forward
  Euler with the held ``z_dot``.

Exogenous inputs (optional): ``exogenous(k, t, s, plant_params, ctrl_params) -> (s_next,
plant_params_k, ctrl_params_k)`` is called once at the start of every step ``k`` (an int32
step index) with its own carried state ``s`` (initial value ``s0``, any pytree); plant and
controller see ``plant_params_k`` and ``ctrl_params_k`` during that step. It feeds processes that
do not depend on the closed loop's state into it without precomputed ``(N, ...)`` arrays: a
slowly varying ocean current (a Gauss–Markov state in ``s``), per-step sensor noise drawn from
``jax.random.fold_in(key, k)``, scheduled parameters. Without it (the default) nothing changes.

Health is data: ``Trajectory.finite[k]`` is False when step k produced a non-finite state; the
state is then frozen at its last finite value so that a vmapped sweep never propagates NaNs.
``Trajectory.diverged[k]`` is True when step k's state is non-finite *or* has an entry larger
in magnitude than ``bound`` (a caller-set divergence bound, default 1e9: a state that runs away
while staying finite is not healthy either), or when the controller's ``aux`` reports
``ok = False`` ([`controller_ok`][vcjax.rollout.controller_ok]; e.g. a
[`Diagnostics`][vcjax.mechanics.Diagnostics] whose mass
matrix is not SPD). [`first_unhealthy_step`][vcjax.rollout.first_unhealthy_step] finds the first
such
step. ``dt`` is checked eagerly when it is a concrete value (finite and > 0).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp

from vcjax._checks import is_concrete
from vcjax.integrators import dense_tangent, get_integrator, rk4, rk4_unrolled

__all__ = [
    "RolloutConfig",
    "Trajectory",
    "rollout",
    "rollout_reduce",
    "Reduction",
    "all_finite",
    "controller_ok",
    "first_unhealthy_step",
    "DEFAULT_BOUND",
    "LOOP_STATE",
]

#: Default divergence bound of [`rollout`][vcjax.rollout.rollout]: any state entry beyond it flags
#: divergence.
DEFAULT_BOUND = 1e9

LOOP_STATE = 12
"""``RolloutConfig(stages="auto")`` with a sampled controller runs RK4's stages as a loop on
plants with at least this many state entries (a 6-DOF vehicle's pose and velocities); under
``checkpoint`` the stage loop of such a plant is rematerialised too."""


@dataclasses.dataclass(frozen=True)
class RolloutConfig:
    """Static rollout settings (anything that changes a shape or a code path).

    Attributes:
        num_steps: number of integration steps N (the horizon is ``N * dt``).
        integrator: ``"euler"``, ``"heun"`` or ``"rk4"``.
        timing: ``"continuous"`` or ``"sampled"`` controller (see module docstring).
        checkpoint: rematerialise in the backward pass (``jax.checkpoint``; default True): the
            reverse pass keeps one carry per step (``checkpoint_every = 1``) and recomputes the
            step, instead of storing every intermediate value of every step. No effect on a
            forward rollout or on forward mode; under ``grad`` the same values to round-off, a
            fraction of the memory, a compile up to a tenth shorter (with 10-26 % more
            StableHLO lines: each step is held twice) and, under XLA's default CPU flags, up to
            twice the speed. ``False``: the stored tape. On plants of
            [`LOOP_STATE`][vcjax.rollout.LOOP_STATE] state entries or more (6-DOF vehicles)
            RK4's stages are checkpointed instead (``rk4(..., remat=True)``; with a sampled
            controller, or ``checkpoint_every > 1``, as well): the backward pass evaluates each
            stage's vector field again instead of stacking its thousand or so intermediate
            values for the four stages; with a continuous controller and ``checkpoint_every =
            1`` it keeps the four stages' inputs per step (about 4 carries, not 1). REMUS 100
            ``vcm3d_ilos``'s gradient builds in about two thirds of the time and runs in 0.75x.
            A 3-DOF field has few intermediates, and recomputing it costs more than reading
            them back (a batch of 256 INFANTE gradients: 1.2x the time), so its stages are not.
        checkpoint_every: with ``checkpoint``, the segment length K: ``K = 1`` checkpoints every
            step (memory ~ N x carry); ``K > 1`` checkpoints segments of K steps (memory
            ~ N/K x carry + K x one step's intermediates, minimal near
            ``K = sqrt(N x carry / intermediates)``, typically 5-20), for one extra forward
            pass either way.
        unroll: steps per iteration of the rollout's scan.
        stages: how RK4 evaluates its four stages: ``"loop"`` (one ``lax.scan`` over the
            tableau: the vector field is traced and compiled once, the program is smaller and
            builds faster), ``"unrolled"`` (four traced copies, which XLA fuses better when
            the field is small) or ``"auto"``: the loop with a continuous controller (the whole
            law is in the field) and with a sampled one on plants of
            [`LOOP_STATE`][vcjax.rollout.LOOP_STATE] state entries or more (6-DOF vehicles,
            whose plant dominates a step: REMUS 100's programs are about a third smaller and
            compile about 1.5x faster, its batches run within a few per cent of the unrolled
            form), else unrolled (a 3-DOF plant's batches run faster unrolled). The two forms
            agree to round-off (the same arithmetic in the same order).
    """

    num_steps: int
    integrator: str = "rk4"
    timing: Literal["continuous", "sampled"] = "continuous"
    checkpoint: bool = True
    checkpoint_every: int = 1
    unroll: int = 1
    stages: Literal["auto", "loop", "unrolled"] = "auto"

    def __post_init__(self):
        if not isinstance(self.num_steps, int) or self.num_steps < 1:
            raise ValueError(f"num_steps: expected a positive int, got {self.num_steps!r}")
        if not isinstance(self.unroll, int) or self.unroll < 1:
            raise ValueError(f"unroll: expected a positive int, got {self.unroll!r}")
        if not isinstance(self.checkpoint_every, int) or self.checkpoint_every < 1:
            raise ValueError(
                f"checkpoint_every: expected a positive int, got {self.checkpoint_every!r}"
            )
        get_integrator(self.integrator)
        if self.timing not in ("continuous", "sampled"):
            raise ValueError(f"timing: expected 'continuous' or 'sampled', got {self.timing!r}")
        if self.stages not in ("auto", "loop", "unrolled"):
            raise ValueError(f"stages: expected 'auto', 'loop' or 'unrolled', got {self.stages!r}")


class Trajectory(NamedTuple):
    """A rollout's record; N = ``num_steps``.

    Attributes:
        t: (N+1,) sample times [s].
        x: plant state pytree, leaves stacked along a leading axis of N+1.
        z: controller state pytree, leaves (N+1, ...).
        u: command at the start of each step, leaves (N, ...).
        aux: controller outputs at the start of each step, leaves (N, ...).
        finite: (N,) bool, False where the step produced a non-finite state (then frozen).
        diverged: (N,) bool, True where the step's state is non-finite or has an entry beyond
            the rollout's ``bound`` in magnitude.
    """

    t: Any
    x: Any
    z: Any
    u: Any
    aux: Any
    finite: Any
    diverged: Any

    @property
    def healthy(self):
        """() bool: no step diverged: every state finite and within the bound, and the
        controller's own diagnostics ([`controller_ok`][vcjax.rollout.controller_ok]) usable at
        every step. A path-error
        bound is the metrics' job ([`vcjax.metrics.path_bound`][vcjax.metrics.path_bound],
        ``diverged`` of
        [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics])."""
        return ~jnp.any(self.diverged)


def _has_ok(node) -> bool:
    return (isinstance(node, tuple) and "ok" in getattr(node, "_fields", ())) or (
        isinstance(node, dict) and "ok" in node
    )


def controller_ok(aux) -> jax.Array:
    """() bool: the controller's own health, where its ``aux`` reports one -- every ``ok``
    field found in the ``aux`` pytree (a NamedTuple field or dict key named ``ok``, e.g. a
    [`vcjax.mechanics.Diagnostics`][vcjax.mechanics.Diagnostics] returned as or inside ``aux``) is
    True; True when
    there is none. A step whose controller says its solve was unusable is unhealthy."""
    oks = []

    def visit(node):
        if _has_ok(node):
            ok = node["ok"] if isinstance(node, dict) else node.ok
            oks.append(jnp.all(jnp.asarray(ok, bool)))
        return node

    jax.tree_util.tree_map(visit, aux, is_leaf=_has_ok)
    return jnp.all(jnp.stack(oks)) if oks else jnp.array(True)


def all_finite(tree) -> jax.Array:
    """() bool: every leaf of ``tree`` is finite."""
    leaves = [jnp.all(jnp.isfinite(leaf)) for leaf in jax.tree_util.tree_leaves(tree)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.array(True)


def first_unhealthy_step(traj: Trajectory) -> int | None:
    """Index k of the first step whose state diverged (non-finite or beyond the bound), or
    ``None`` for a healthy run. Eager (call it on a concrete trajectory)."""
    import numpy as np

    bad = np.asarray(traj.diverged).reshape(-1)
    return int(np.argmax(bad)) if bad.any() else None


def _max_abs(tree):
    """() largest ``|entry|`` of the tree's float leaves, NaN if any entry is NaN (one
    reduction over the concatenated leaves: a single kernel per step)."""
    leaves = [
        jnp.ravel(leaf)
        for leaf in jax.tree_util.tree_leaves(tree)
        if leaf.size and jnp.issubdtype(leaf.dtype, jnp.inexact)
    ]
    if not leaves:
        return jnp.zeros(())
    dtype = jnp.result_type(*leaves)
    return jnp.max(jnp.abs(jnp.concatenate([a.astype(dtype) for a in leaves])))


def _check_dt(dt) -> None:
    if is_concrete(dt):
        import numpy as np

        a = np.asarray(dt)
        if a.shape != () or not np.issubdtype(a.dtype, np.number):
            raise ValueError(f"dt: expected a scalar step size [s], got {dt!r}")
        if not (np.isfinite(a) and a > 0):
            raise ValueError(f"dt: expected a finite step size > 0 [s], got {float(a)}")


def _stack0(first, rest):
    return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b], axis=0), first, rest)


def _batched_like(tree, like):
    """``tree`` with every float leaf as ``where(False, s, leaf)``, ``s`` the sum of ``like``'s
    float leaves: the same values, bit for bit, but under ``vmap`` batched whenever ``like``
    is. ``vmap`` of a ``lax.scan`` is a fixpoint over which carries are batched, one batching
    of the whole loop body per round: a controller state that starts from constants (while
    the plant's initial state is per scenario) cost a second round. XLA folds the select."""
    parts = [
        jnp.sum(a)
        for a in jax.tree_util.tree_leaves(like)
        if jnp.issubdtype(jnp.result_type(a), jnp.inexact) and jnp.size(a)
    ]
    if not parts:
        return tree
    total = sum(parts[1:], parts[0])
    never = jnp.zeros((), bool)

    def mark(a):
        a = jnp.asarray(a)
        if not jnp.issubdtype(a.dtype, jnp.inexact):
            return a
        return jnp.where(never, total.astype(a.dtype), a)

    return jax.tree_util.tree_map(mark, tree)


def _dense_carry(init, like):
    """The scan's initial carry through [`dense_tangent`][vcjax.integrators.dense_tangent]: it
    starts
    from constants but picks up the tangents of ``like`` (parameters, ``dt``), so linearising
    the scan settles in one round instead of one per dependency level."""
    return dense_tangent(init, like)


def _check_args(dt, bound) -> None:
    _check_dt(dt)
    if is_concrete(bound) and not float(bound) > 0:
        raise ValueError(f"bound: expected a divergence bound > 0, got {bound}")


def _rk4_loop(config: RolloutConfig, x0) -> bool:
    """Whether RK4's stages run as a loop (``config.stages``; see
    [`RolloutConfig`][vcjax.rollout.RolloutConfig])."""
    if config.stages != "auto":
        return config.stages == "loop"
    if config.timing == "continuous":
        return True
    return _state_size(x0) >= LOOP_STATE


def _state_size(x0) -> int:
    return sum(int(jnp.size(a)) for a in jax.tree_util.tree_leaves(x0))


def _stage_remat(config: RolloutConfig, x0) -> bool:
    """Whether RK4's stages are checkpointed: a stage loop under ``checkpoint`` on a plant of
    [`LOOP_STATE`][vcjax.rollout.LOOP_STATE] state entries or more (see
    [`RolloutConfig`][vcjax.rollout.RolloutConfig])."""
    return (
        config.checkpoint
        and get_integrator(config.integrator) is rk4
        and _rk4_loop(config, x0)
        and _state_size(x0) >= LOOP_STATE
    )


def _stepper(plant, controller, config, plant_params, ctrl_params, x0, dt, t0, exogenous, bound):
    """The scan body of a rollout: ``step(carry, k) -> (carry, (y_next, u, aux, (ok,
    diverged)))`` with ``carry = ((x, z), s)``, and the dtype-converted ``(t0, dt)``."""
    step_fn = get_integrator(config.integrator)
    if step_fn is rk4 and not _rk4_loop(config, x0):
        step_fn = rk4_unrolled
    elif _stage_remat(config, x0):
        step_fn = functools.partial(rk4, remat=True)
    dtype = jnp.result_type(*jax.tree_util.tree_leaves(x0))
    dt = jnp.asarray(dt, dtype=dtype)
    bound = jnp.asarray(bound, dtype=dtype)
    t0 = jnp.asarray(t0, dtype=dtype)

    def advance(t, y, pp, cp):
        if config.timing == "continuous":

            def field(t_, y_, args):
                x, z = y_
                u, z_dot, aux = controller(t_, x, z, cp)
                return (plant(t_, x, u, pp), z_dot), (u, aux)

            return step_fn(field, t, y, dt, None)

        x, z = y
        u, z_dot, aux = controller(t, x, z, cp)

        def field(t_, x_, u_):
            return plant(t_, x_, u_, pp), None

        x_next, _ = step_fn(field, t, x, dt, u)
        z_next = jax.tree_util.tree_map(lambda a, b: a + dt * b, z, z_dot)
        return (x_next, z_next), (u, aux)

    def step(carry, k):
        y, s = carry
        t = t0 + k.astype(dtype) * dt
        if exogenous is None:
            pp, cp = plant_params, ctrl_params
        else:
            s, pp, cp = exogenous(k, t, s, plant_params, ctrl_params)
        y_next, (u, aux) = advance(t, y, pp, cp)
        # one reduction for both flags: the max of |.| is NaN or inf iff some entry is
        peak = _max_abs(y_next)
        ok = jnp.isfinite(peak)
        diverged = ~ok | (peak > bound) | ~controller_ok(aux)
        y_next = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), y_next, y)
        return (y_next, s), (y_next, u, aux, (ok, diverged))

    return step, t0, dt


def rollout(
    plant: Callable,
    controller: Callable,
    config: RolloutConfig,
    plant_params,
    ctrl_params,
    x0,
    z0,
    dt,
    t0=0.0,
    *,
    exogenous: Callable | None = None,
    s0=None,
    bound=DEFAULT_BOUND,
) -> Trajectory:
    """Roll the closed loop out for ``config.num_steps`` steps of size ``dt``.

    Args:
        plant: ``f(t, x, u, plant_params) -> x_dot`` (static).
        controller: ``c(t, x, z, ctrl_params) -> (u, z_dot, aux)`` (static).
        config: [`RolloutConfig`][vcjax.rollout.RolloutConfig] (static).
        plant_params, ctrl_params: pytrees of arrays (traced).
        x0, z0: initial plant and controller states (pytrees of arrays).
        dt: () step size [s] (traced).
        t0: () initial time [s].
        exogenous: optional ``g(k, t, s, plant_params, ctrl_params) -> (s_next, plant_params_k,
            ctrl_params_k)`` (static), evaluated at the start of each step (see module
            docstring); the parameters it returns are held over the step.
        s0: initial state of ``exogenous`` (pytree of arrays; ``None`` when it has none).
        bound: () divergence bound (traced): a step whose plant or controller state has an
            entry with ``|.| > bound`` is flagged in ``Trajectory.diverged``.

    Returns:
        [`Trajectory`][vcjax.rollout.Trajectory].

    Raises:
        ValueError: ``dt`` or ``bound`` concrete and not finite and > 0.
    """
    _check_args(dt, bound)
    step, t0, dt = _stepper(
        plant, controller, config, plant_params, ctrl_params, x0, dt, t0, exogenous, bound
    )
    dtype = t0.dtype
    ks = jnp.arange(config.num_steps, dtype=jnp.int32)
    K = min(config.checkpoint_every, config.num_steps)
    # every state batched like the plant's initial state (vmap: one batching round)
    x0, z0, s0 = _batched_like((x0, z0, s0), x0)
    init = _dense_carry(((x0, z0), s0), (plant_params, ctrl_params, dt))
    if not config.checkpoint:
        _, (ys, us, auxs, oks) = jax.lax.scan(step, init, ks, unroll=config.unroll)
    elif K == 1:
        # a continuous law on a 6-DOF plant: the whole step is RK4's stage loop, whose stages
        # are checkpointed (_stage_remat); checkpointing the step as well would only add one
        # more evaluation of every stage to the backward pass
        whole = _stage_remat(config, x0) and config.timing == "continuous"
        body = step if whole else jax.checkpoint(step)
        _, (ys, us, auxs, oks) = jax.lax.scan(body, init, ks, unroll=config.unroll)
    else:
        # Segments of K steps, each rematerialised as a whole in the backward pass: the forward
        # keeps one carry per segment, the backward the residuals of one segment at a time.
        @jax.checkpoint
        def segment(carry, ks_seg):
            return jax.lax.scan(step, carry, ks_seg)

        n_seg, rest = divmod(config.num_steps, K)
        carry, out = jax.lax.scan(segment, init, ks[: n_seg * K].reshape(n_seg, K))
        out = jax.tree_util.tree_map(lambda a: a.reshape((n_seg * K,) + a.shape[2:]), out)
        if rest:
            _, out_rest = segment(carry, ks[n_seg * K :])
            out = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), out, out_rest)
        ys, us, auxs, oks = out
    xs, zs = ys
    oks, diverged = oks
    t = t0 + jnp.arange(config.num_steps + 1, dtype=dtype) * dt
    return Trajectory(
        t=t,
        x=_stack0(x0, xs),
        z=_stack0(z0, zs),
        u=us,
        aux=auxs,
        finite=oks,
        diverged=diverged,
    )


class Reduction(NamedTuple):
    """What [`rollout_reduce`][vcjax.rollout.rollout_reduce] keeps of a rollout instead of its whole
    record.

    Attributes:
        init: initial accumulator (pytree of arrays).
        update: ``update(acc, seg, ks) -> (acc, out)`` (static): folds one segment into the
            accumulator. ``seg`` is the segment's [`Trajectory`][vcjax.rollout.Trajectory] (``L``
            steps: ``t``, ``x``
            and ``z`` have ``L + 1`` samples, the segment's start first, as a rollout of those
            ``L`` steps would return) and ``ks`` its (L,) int32 global step indices; ``out``
            (any pytree) is kept per segment, e.g. a trace sample.
        segment: static segment length ``L >= 1``: memory grows with ``L``, not with the
            horizon.
    """

    init: Any
    update: Callable
    segment: int


def rollout_reduce(
    plant: Callable,
    controller: Callable,
    config: RolloutConfig,
    plant_params,
    ctrl_params,
    x0,
    z0,
    dt,
    reduction: Reduction,
    t0=0.0,
    *,
    exogenous: Callable | None = None,
    s0=None,
    bound=DEFAULT_BOUND,
):
    """[`rollout`][vcjax.rollout.rollout], folding the record into an accumulator segment by segment
    instead of
    returning it (same arguments, plus ``reduction``): the steps are the same, only ``L``
    (``Reduction.segment``) steps of record exist at a time, so a batch of long rollouts
    needs memory for its states, not for its whole history. ``config.checkpoint``
    rematerialises each segment in the backward pass (``checkpoint_every`` is not used).

    Returns:
        ``(acc, outs)``: the final accumulator, and every segment's ``out`` stacked along a
        leading axis of ``ceil(N / L)`` (the last segment holds the ``N mod L`` remaining
        steps when ``L`` does not divide ``N``).
    """
    _check_args(dt, bound)
    L = reduction.segment
    if not isinstance(L, int) or L < 1:
        raise ValueError(f"segment: expected a positive int, got {L!r}")
    step, t0, dt = _stepper(
        plant, controller, config, plant_params, ctrl_params, x0, dt, t0, exogenous, bound
    )
    dtype = t0.dtype

    def segment(state, ks_seg):
        carry, acc = state
        (xz0, _) = carry
        carry, (ys, us, auxs, (oks, div)) = jax.lax.scan(step, carry, ks_seg, unroll=config.unroll)
        ts = t0 + (ks_seg[0] + jnp.arange(ks_seg.shape[0] + 1, dtype=jnp.int32)).astype(dtype) * dt
        seg = Trajectory(
            t=ts,
            x=_stack0(xz0[0], ys[0]),
            z=_stack0(xz0[1], ys[1]),
            u=us,
            aux=auxs,
            finite=oks,
            diverged=div,
        )
        acc, out = reduction.update(acc, seg, ks_seg)
        return (carry, acc), out

    if config.checkpoint:
        segment = jax.checkpoint(segment)
    N = config.num_steps
    L = min(L, N)
    n_seg, rest = divmod(N, L)
    ks = jnp.arange(N, dtype=jnp.int32)
    x0, z0, s0, acc0 = _batched_like((x0, z0, s0, reduction.init), x0)
    init = _dense_carry((((x0, z0), s0), acc0), (plant_params, ctrl_params, dt))
    state, outs = jax.lax.scan(segment, init, ks[: n_seg * L].reshape(n_seg, L))
    if rest:
        state, out_rest = segment(state, ks[n_seg * L :])
        outs = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b[None]]), outs, out_rest)
    return state[1], outs
