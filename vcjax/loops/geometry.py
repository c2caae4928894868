"""Path geometry shared by loops: the start parameter nearest to a point, a polyline for
figures, path frames and planar path errors along a run."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vcjax import paths
from vcjax.linalg import rot2
from vcjax.runtime import compiler

__all__ = ["start_parameter", "path_polyline", "path_frames", "path_poses", "path_errors"]


def _search_range(path: paths.Path, coeffs, w_range):
    """Where to look for the nearest point: one turn of a circle, two of a helix, the
    waypoints' span; else ``w_range``."""
    if isinstance(coeffs, paths.CircleCoeffs):
        return 0.0 * coeffs.radius, 2 * jnp.pi * coeffs.radius
    if isinstance(coeffs, paths.HelixCoeffs):
        return -2 * jnp.pi * coeffs.T, 2 * jnp.pi * coeffs.T
    if isinstance(coeffs, paths.SplineCoeffs):
        return coeffs.knots[0], coeffs.knots[-1]
    if isinstance(coeffs, paths.LawnmowerCoeffs):
        n = coeffs.n_legs
        return 0.0 * n, n * coeffs.leg + (n - 1.0) * jnp.pi * coeffs.radius
    return w_range


def _polyline(path: paths.Path, coeffs, points, num: int):
    if isinstance(coeffs, paths.LineCoeffs) and points is not None:
        pts = jnp.asarray(points)
        pts = jnp.concatenate([pts, jnp.zeros(pts.shape[:-1] + (3 - pts.shape[-1],))], axis=-1)
        w = (pts - coeffs.origin) @ coeffs.direction
        lo, hi = jnp.min(w) - 10.0, jnp.max(w) + 10.0
    else:
        lo, hi = _search_range(path, coeffs, (-50.0, 50.0))
    w = lo + (hi - lo) * jnp.linspace(0.0, 1.0, num)
    return jax.vmap(lambda w_: paths.path_point(path, coeffs, w_))(w)


# one program per path kind, shapes and ``num`` (op by op: some thirty one-operation kernels
# compiled at the first figure of a process)
_polyline_jit = compiler.jit(_polyline, static_argnums=(0, 3))


def path_polyline(path: paths.Path, coeffs, points=None, num: int = 400):
    """(num, 3) points of the path for figures: one turn of a circle, two of a helix, the
    waypoints' or survey's span; a line over the projections of ``points`` (M, 2 or 3) ±10 m
    (default ``[-50, 50]``)."""
    try:
        return _polyline_jit(path, coeffs, points, num)
    except Exception:  # a path that is no static argument, or needs Python coefficients
        return _polyline(path, coeffs, points, num)


def start_parameter(path: paths.Path, coeffs, point, w_range=(-50.0, 50.0), num: int = 512):
    """() path parameter of the point of the path nearest to ``point`` (3,) (jit/vmap-safe).

    Exact for a line (projection onto it). Otherwise: the nearest of ``num`` samples over one
    turn of a circle, two turns of a helix, the span of a waypoint spline, or ``w_range`` for
    other kinds, refined by three Newton steps on ``(p(w) - point) . p'(w) = 0``.
    """
    point = jnp.asarray(point)
    if isinstance(coeffs, paths.LineCoeffs):
        return jnp.dot(point - coeffs.origin, coeffs.direction)
    lo, hi = _search_range(path, coeffs, w_range)
    w = jnp.linspace(0.0, 1.0, num, dtype=point.dtype)
    w = lo + (hi - lo) * w
    p = jax.vmap(lambda w_: paths.path_point(path, coeffs, w_))(w)
    w0 = w[jnp.argmin(jnp.sum((p - point) ** 2, axis=1))]

    def g(w_):
        p_, dp = jax.jvp(lambda v: paths.path_point(path, coeffs, v), (w_,), (jnp.ones_like(w_),))
        return jnp.dot(p_ - point, dp)

    def newton(w_, _):
        val, slope = jax.jvp(g, (w_,), (jnp.ones_like(w_),))
        step = jnp.where(slope > 0, val / jnp.where(slope > 0, slope, 1.0), 0.0)
        return jnp.clip(w_ - step, lo, hi), None

    return jax.lax.scan(newton, w0, None, length=3)[0]


def path_frames(path, coeffs, w):
    """[`PathFrame`][vcjax.paths.PathFrame] at every parameter of ``w`` (N,)."""
    return jax.vmap(lambda w1: paths.path_frame(path, coeffs, w1))(w)


def path_poses(path, coeffs, w):
    """[`PathPose`][vcjax.paths.PathPose] at every parameter of ``w`` (N,): the frames' values
    without their rates (what a loop's signals, and so a tuning loss, need)."""
    return jax.vmap(lambda w1: paths.path_pose(path, coeffs, w1))(w)


def path_errors(frames, eta):
    """(N, 2) ``[s, e]`` (23) of the poses ``eta`` (N, >=2) w.r.t. the frames (N,) (path
    frames or poses)."""
    return jax.vmap(lambda psi_p, p, xy: rot2(psi_p).T @ (xy - p[:2]))(
        frames.psi_p, frames.p, eta[:, :2]
    )
