"""The zoom line search of L-BFGS, one evaluation at a time, for a search driven from the host.

The search is Nocedal and Wright's algorithms 3.5 (find an interval holding a step size that
meets both strong Wolfe conditions, doubling the step) and 3.6 (zoom into it by cubic, quadratic
or bisection steps), with Hager and Zhang's approximate sufficient decrease near a minimum: the
arithmetic of ``optax.scale_by_zoom_linesearch`` with its defaults and ``initial_guess_strategy
="one"`` (what ``optax.lbfgs`` runs), written out here step for step so that the iterates are
optax's. optax evaluates the loss inside its ``while_loop``; [`Zoom`][tuning.linesearch.Zoom]
splits each round into the step size it asks for ([`Zoom.point`][tuning.linesearch.Zoom.point]),
an evaluation made by the caller, and the round proper ([`Zoom.advance`]
[tuning.linesearch.Zoom.advance]), so that [`LBFGSStep`][tuning.optim.LBFGSStep] keeps one
compiled ``value_and_grad`` outside the small jitted programs of the search.

References: J. Nocedal, S. J. Wright, *Numerical Optimization*, 1999, algorithms 3.5 and 3.6;
W. W. Hager, H. Zhang, *Algorithm 851: CG_DESCENT*, 2006, equations (23)-(27).
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import optax

__all__ = ["Zoom", "ZoomState"]


class ZoomState(NamedTuple):
    """State of the search (scalars are () arrays; ``params``, ``updates``, ``grad``,
    ``safe_grad`` are like the parameters).

    Attributes:
        count: () int, rounds done (evaluations made).
        params, updates: the start and the search direction (fixed).
        stepsize_guess: () the first step size tried (1).
        stepsize, value, grad, slope: the last point evaluated (its step size, loss,
            gradient, and directional derivative along ``updates``).
        value_init, slope_init: loss and slope at the start.
        decrease_error, curvature_error, error: by how much the last point misses the
            sufficient-decrease and curvature conditions (0: met; inf: not finite).
        interval_found, done, failed: () bool, the phase (zoom once an interval is found)
            and the end of the search.
        low, value_low, slope_low, high, value_high, slope_high: the interval's ends
            (``value_low <= value_high``; not ordered by step size).
        cubic_ref, value_cubic_ref: the third point of the cubic interpolation.
        safe_stepsize, safe_value, safe_grad: the best point meeting sufficient decrease
            (taken when the curvature condition cannot be met).
    """

    count: Any
    params: Any
    updates: Any
    stepsize_guess: Any
    stepsize: Any
    value: Any
    grad: Any
    slope: Any
    value_init: Any
    slope_init: Any
    decrease_error: Any
    curvature_error: Any
    error: Any
    interval_found: Any
    done: Any
    failed: Any
    low: Any
    value_low: Any
    slope_low: Any
    high: Any
    value_high: Any
    slope_high: Any
    cubic_ref: Any
    value_cubic_ref: Any
    safe_stepsize: Any
    safe_value: Any
    safe_grad: Any


def _cubicmin(a, fa, fpa, b, fb, c, fc):
    """Critical point of the cubic through ``(a, fa)``, ``(b, fb)``, ``(c, fc)`` with slope
    ``fpa`` at ``a`` (NaN when it has none; then not used)."""
    C = fpa
    db = b - a
    dc = c - a
    denom = (db * dc) ** 2 * (db - dc)
    d1 = jnp.array([[dc**2, -(db**2)], [-(dc**3), db**3]])
    rhs = jnp.array([fb - fa - C * db, fc - fa - C * dc])
    A, B = jnp.dot(d1, rhs, precision=jax.lax.Precision.HIGHEST) / denom
    radical = B * B - 3.0 * A * C
    return a + (-B + jnp.sqrt(radical)) / (3.0 * A)


def _quadmin(a, fa, fpa, b, fb):
    """Critical point of the parabola through ``(a, fa)``, ``(b, fb)`` with slope ``fpa`` at
    ``a``."""
    C = fpa
    db = b - a
    B = (fb - fa - C * db) / (db**2)
    return a - C / (2.0 * B)


def _slope(grad, updates):
    """() directional derivative ``grad . updates``."""
    return optax.tree.real(optax.tree.vdot(optax.tree.conj(grad), updates))


@dataclasses.dataclass(frozen=True)
class Zoom:
    """The zoom line search with optax's default settings (static: hashable).

    Attributes:
        max_linesearch_steps: most evaluations per search.
        tol: tolerance on both conditions.
        increase_factor: step growth while no interval is found.
        slope_rtol: sufficient-decrease (Armijo) constant ``c1``.
        curv_rtol: curvature constant ``c2``.
        approx_dec_rtol: tolerance of the approximate decrease (relative to the start's loss).
        interval_threshold: an interval shorter than this ends the search once a step with
            sufficient decrease is known.

    Use: ``s = init(d, x, value, grad)``; while ``running(s)``: evaluate ``(v, g)`` at
    ``point(s)``, ``s = advance(s, v, g)``; the step is ``s.stepsize`` (loss ``s.value``,
    gradient ``s.grad`` there).
    """

    max_linesearch_steps: int = 15
    tol: float = 0.0
    increase_factor: float = 2.0
    slope_rtol: float = 1e-4
    curv_rtol: float = 0.9
    approx_dec_rtol: float = 1e-6
    interval_threshold: float = 1e-5

    def init(self, updates, params, value, grad) -> ZoomState:
        """The search from ``params`` along ``updates``, where the loss is ``value`` and its
        gradient ``grad``."""
        placeholder = jnp.empty((), jax.tree.leaves(params)[0].dtype)
        val_dtype = jnp.real(placeholder).dtype
        slope = optax.tree.real(optax.tree.vdot(updates, grad))
        inf, zero = jnp.asarray(jnp.inf), jnp.asarray(0.0)
        return ZoomState(
            count=jnp.asarray(0),
            params=params,
            updates=updates,
            stepsize_guess=jnp.asarray(1.0),
            stepsize=jnp.asarray(0.0, dtype=val_dtype),
            value=jnp.array(value, dtype=val_dtype),
            grad=grad,
            slope=slope,
            value_init=value,
            slope_init=slope,
            decrease_error=inf,
            curvature_error=inf,
            error=inf,
            interval_found=jnp.asarray(False),
            done=jnp.asarray(False),
            failed=jnp.asarray(False),
            low=zero,
            value_low=value,
            slope_low=slope,
            high=zero,
            value_high=value,
            slope_high=slope,
            cubic_ref=zero,
            value_cubic_ref=value,
            safe_stepsize=zero,
            safe_value=value,
            safe_grad=grad,
        )

    def running(self, state: ZoomState):
        """() bool: the search goes on (another evaluation is needed)."""
        return ~(state.done | state.failed)

    def stepsize(self, state: ZoomState):
        """() the step size the next round evaluates."""
        grow = jnp.where(
            state.count == 0, state.stepsize_guess, self.increase_factor * state.stepsize
        )
        return jnp.where(state.interval_found, self._middle(state), grow)

    def point(self, state: ZoomState):
        """The parameters the next round evaluates: ``params + stepsize * updates``."""
        return optax.tree.add_scale(state.params, self.stepsize(state), state.updates)

    def advance(self, state: ZoomState, value, grad) -> ZoomState:
        """The round that evaluated ``value`` and ``grad`` at [`point`]
        [tuning.linesearch.Zoom.point]``(state)``."""
        new = jax.lax.cond(
            state.interval_found,
            lambda s: self._zoom(s, value, grad),
            lambda s: self._search(s, value, grad),
            state,
        )
        new = jax.lax.cond(new.failed, self._safe_step, lambda s: s, new)
        return optax.tree.cast_like(new, other_tree=state)

    def _errors(self, stepsize, value, slope, state: ZoomState):
        """``(decrease_error, curvature_error)`` of a point (0 when met, inf for NaN)."""
        value_init, slope_init = state.value_init, state.slope_init
        decrease = value - value_init - self.slope_rtol * stepsize * slope_init
        approx = slope - (2 * self.slope_rtol - 1.0) * slope_init
        delta_values = value - value_init - self.approx_dec_rtol * jnp.abs(value_init)
        decrease = jnp.minimum(jnp.maximum(approx, delta_values), decrease)
        decrease = jnp.maximum(decrease, 0.0)
        decrease = jnp.where(jnp.isnan(decrease), jnp.inf, decrease)
        curvature = jnp.abs(slope) - self.curv_rtol * jnp.abs(slope_init)
        curvature = jnp.maximum(curvature, 0.0)
        curvature = jnp.where(jnp.isnan(curvature), jnp.inf, curvature)
        return decrease, curvature

    def _search(self, state: ZoomState, value, grad) -> ZoomState:
        """A round of the interval search (algorithm 3.5)."""
        stepsize = jnp.where(
            state.count == 0, state.stepsize_guess, self.increase_factor * state.stepsize
        )
        slope = _slope(grad, state.updates)
        decrease_error, curvature_error = self._errors(stepsize, value, slope, state)
        error = jnp.maximum(decrease_error, curvature_error)
        safe = optax.tree.where(
            decrease_error <= self.tol,
            [stepsize, value, grad],
            [state.safe_stepsize, state.safe_value, state.safe_grad],
        )
        set_high = (decrease_error > 0.0) | ((value >= state.value) & (state.count > 0))
        set_low = (slope >= 0.0) & (~set_high)
        prev = [state.stepsize, state.value, state.slope]
        low, value_low, slope_low, high, value_high, slope_high = optax.tree.where(
            set_low, [stepsize, value, slope, *prev], [*prev, stepsize, value, slope]
        )
        interval_found = set_high | set_low | (error <= self.tol)
        done = error <= self.tol  # (no largest step size: an interval is always found)
        failed = (state.count + 1 >= self.max_linesearch_steps) & (~done)
        new = state._replace(
            count=optax.safe_increment(state.count),
            stepsize=stepsize,
            value=value,
            grad=grad,
            slope=slope,
            decrease_error=decrease_error,
            curvature_error=curvature_error,
            error=error,
            interval_found=jnp.asarray(interval_found),
            done=jnp.asarray(done),
            failed=jnp.asarray(failed),
            low=low,
            value_low=value_low,
            slope_low=slope_low,
            high=high,
            value_high=value_high,
            slope_high=slope_high,
            cubic_ref=low,
            value_cubic_ref=value_low,
            safe_stepsize=safe[0],
            safe_value=safe[1],
            safe_grad=safe[2],
        )
        return optax.tree.cast_like(new, other_tree=state)

    def _middle(self, state: ZoomState):
        """() the zoom's next step size: the cubic's minimiser, else the parabola's, when well
        inside the interval; else its midpoint."""
        low, high = state.low, state.high
        delta = jnp.abs(high - low)
        left, right = jnp.minimum(high, low), jnp.maximum(high, low)
        cubic_chk, quad_chk = 0.2 * delta, 0.1 * delta
        cubic = _cubicmin(
            low,
            state.value_low,
            state.slope_low,
            high,
            state.value_high,
            state.cubic_ref,
            state.value_cubic_ref,
        )
        use_cubic = (cubic > left + cubic_chk) & (cubic < right - cubic_chk)
        quad = _quadmin(low, state.value_low, state.slope_low, high, state.value_high)
        use_quad = (~use_cubic) & (quad > left + quad_chk) & (quad < right - quad_chk)
        use_bisection = (~use_cubic) & (~use_quad)
        middle = jnp.where(use_cubic, cubic, state.cubic_ref)
        middle = jnp.where(use_quad, quad, middle)
        return jnp.where(use_bisection, (low + high) / 2.0, middle)

    def _zoom(self, state: ZoomState, value, grad) -> ZoomState:
        """A round of the zoom (algorithm 3.6)."""
        middle = self._middle(state)
        slope = _slope(grad, state.updates)
        decrease_error, curvature_error = self._errors(middle, value, slope, state)
        error = jnp.maximum(decrease_error, curvature_error)
        better = (decrease_error <= self.tol) & (value < state.safe_value)
        safe = optax.tree.where(
            better, [middle, value, grad], [state.safe_stepsize, state.safe_value, state.safe_grad]
        )
        done = error <= self.tol
        low, high = state.low, state.high
        ends_low = [low, state.value_low, state.slope_low]
        ends_high = [high, state.value_high, state.slope_high]
        mid = [middle, value, slope]
        set_high_to_middle = (decrease_error > 0.0) | (value >= state.value_low)
        set_high_to_low = (slope * (high - low) >= 0.0) & (~set_high_to_middle)
        new_high = optax.tree.where(set_high_to_middle, mid, ends_high)
        new_high = optax.tree.where(set_high_to_low, ends_low, new_high)
        new_low = optax.tree.where(~set_high_to_middle, mid, ends_low)
        cubic_ref = optax.tree.where(
            set_high_to_middle | set_high_to_low, ends_high[:2], ends_low[:2]
        )
        too_small = jnp.abs(high - low) <= self.interval_threshold
        max_iter_reached = (state.count + 1) >= self.max_linesearch_steps
        failed = (jnp.asarray(max_iter_reached) | (too_small & (safe[0] > 0.0))) & ~done
        new = state._replace(
            count=optax.safe_increment(state.count),
            stepsize=middle,
            value=value,
            grad=grad,
            slope=slope,
            decrease_error=decrease_error,
            curvature_error=curvature_error,
            error=error,
            done=done,
            failed=failed,
            low=new_low[0],
            value_low=new_low[1],
            slope_low=new_low[2],
            high=new_high[0],
            value_high=new_high[1],
            slope_high=new_high[2],
            cubic_ref=cubic_ref[0],
            value_cubic_ref=cubic_ref[1],
            safe_stepsize=safe[0],
            safe_value=safe[1],
            safe_grad=safe[2],
        )
        return optax.tree.cast_like(new, other_tree=state)

    def _safe_step(self, state: ZoomState) -> ZoomState:
        """A failed search ends at the best point with sufficient decrease, if any (or, when
        the last point is not finite, at the safe point, possibly the start)."""
        outside_domain = jnp.isinf(state.decrease_error)
        stepsize, value, grad = optax.tree.where(
            (state.safe_stepsize > 0.0) | outside_domain,
            [state.safe_stepsize, state.safe_value, state.safe_grad],
            [state.stepsize, state.value, state.grad],
        )
        new = state._replace(stepsize=stepsize, grad=grad, value=value)
        return optax.tree.cast_like(new, other_tree=state)
