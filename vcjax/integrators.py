"""Fixed-step explicit integrators, kept apart from the dynamics.

An integrator advances ``y' = f(t, y, args)`` by one step ``dt``::

    y_next, aux = rk4(f, t, y, dt, args)

``y`` may be any pytree of arrays. ``f`` returns ``(y_dot, aux)`` where ``aux`` is any pytree of
outputs evaluated at the *start* of the step (control signals, diagnostics); the integrator hands
it back unchanged, so recording it costs no extra evaluation. Every integrator is pure and
differentiable; ``dt`` may be a traced value.
"""

from __future__ import annotations

from collections.abc import Callable

import jax

__all__ = ["euler", "heun", "rk4", "INTEGRATORS", "get_integrator", "ORDER"]


def _axpy(a, x, y):
    """``y + a * x`` over matching pytrees."""
    return jax.tree_util.tree_map(lambda xi, yi: yi + a * xi, x, y)


def euler(f: Callable, t, y, dt, args):
    """Forward Euler, order 1."""
    k1, aux = f(t, y, args)
    return _axpy(dt, k1, y), aux


def heun(f: Callable, t, y, dt, args):
    """Heun's method (explicit trapezoid), order 2."""
    k1, aux = f(t, y, args)
    k2, _ = f(t + dt, _axpy(dt, k1, y), args)
    incr = jax.tree_util.tree_map(lambda a, b: 0.5 * (a + b), k1, k2)
    return _axpy(dt, incr, y), aux


def rk4(f: Callable, t, y, dt, args):
    """Classical fourth-order Runge–Kutta."""
    half = 0.5 * dt
    k1, aux = f(t, y, args)
    k2, _ = f(t + half, _axpy(half, k1, y), args)
    k3, _ = f(t + half, _axpy(half, k2, y), args)
    k4, _ = f(t + dt, _axpy(dt, k3, y), args)
    incr = jax.tree_util.tree_map(lambda a, b, c, d: (a + 2 * b + 2 * c + d) / 6, k1, k2, k3, k4)
    return _axpy(dt, incr, y), aux


INTEGRATORS: dict[str, Callable] = {"euler": euler, "heun": heun, "rk4": rk4}
ORDER: dict[str, int] = {"euler": 1, "heun": 2, "rk4": 4}


def get_integrator(name: str) -> Callable:
    """Look an integrator up by name (``"euler"``, ``"heun"``, ``"rk4"``)."""
    try:
        return INTEGRATORS[name]
    except KeyError:
        raise ValueError(
            f"integrator: unknown integrator {name!r}; choose one of {sorted(INTEGRATORS)}"
        ) from None
