"""Parametric paths ``p_p(w)`` and their frames (paper eq. (21); docs/method.md).

A path is two things, kept apart like every other part of vcjax:

* a static [`Path`][vcjax.paths.Path] — the *kind* of curve, a pure function ``fn(w, coeffs) ->
(3,)`` position
  in NED [m] (hashable, so a jitted rollout compiles once per kind);
* its traced coefficients ``coeffs`` (any pytree of arrays), so that moving a line, resizing a
  circle or a helix, or changing waypoint positions never recompiles.

Every constructor returns the pair ``(path, coeffs)``::

    path, coeffs = paths.line(origin=(10.0, 0.0), direction=(0.0, 1.0))
    frame = paths.path_frame(path, coeffs, w)

Kinds: [`line`][vcjax.paths.line], [`circle`][vcjax.paths.circle], [`helix`][vcjax.paths.helix],
[`lawnmower`][vcjax.paths.lawnmower] (a survey pattern),
[`waypoints`][vcjax.paths.waypoints] (a C² cubic spline through
user waypoints, parametrised by chord length) and [`custom`][vcjax.paths.custom] (any user callable
``p_p(w)``).
The paper's two paths are [`paper_line`][vcjax.paths.paper_line] (Simulation 1, ``[10, w]``) and
[`paper_helix`][vcjax.paths.paper_helix]
(Simulation 2, ``[10 sin(w/5), 8 cos(w/5), 0.1 w - 100]``).

The azimuth ``psi_p = atan2(y', x')`` and elevation ``theta_p = atan2(-z', ||p_bar'||)`` (21) and
their ``w``-derivatives come from JAX autodiff of ``fn`` (nested ``jvp``); nobody differentiates
a path by hand. The 2-D guidance needs the horizontal tangent ``p_bar'(w)`` to be non-zero: every
constructor samples the path over a range of ``w`` and raises a ``ValueError`` if it vanishes
there (e.g. a vertical segment, or a user curve with a cusp). Inside ``jit`` the division by
``||p_bar'||`` is floored, so a bad path never yields NaN gradients; ``PathFrame.regular``
reports it as data.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero

from vcjax._checks import check_array, check_positive
from vcjax.runtime import compiler

__all__ = [
    "Path",
    "LineCoeffs",
    "CircleCoeffs",
    "HelixCoeffs",
    "SplineCoeffs",
    "PathFrame",
    "path_frame",
    "PathPose",
    "path_pose",
    "path_point",
    "validate_path",
    "line",
    "circle",
    "helix",
    "waypoints",
    "custom",
    "paper_line",
    "paper_helix",
    "LINE",
    "CIRCLE",
    "HELIX",
    "SPLINE",
    "MIN_TANGENT",
    "LawnmowerCoeffs",
    "lawnmower",
    "LAWNMOWER",
]

#: Smallest admissible horizontal tangent length ``||p_bar'(w)||`` (relative to the path's
#: typical tangent length) accepted by [`validate_path`][vcjax.paths.validate_path].
MIN_TANGENT = 1e-6


@dataclasses.dataclass(frozen=True)
class Path:
    """Static path kind: ``fn(w, coeffs) -> (3,)`` NED position [m] of the point at parameter w.

    Attributes:
        fn: the curve; must be smooth (at least C³ where it is used: ``psi_p''`` needs ``p'''``).
        name: a label for plots and messages.
    """

    fn: Callable[[Any, Any], Any]
    name: str = "path"


class PathFrame(NamedTuple):
    """The path and its frame at one parameter value ``w`` (scalars unless noted).

    Attributes:
        w: () path parameter.
        p: (3,) position ``p_p(w)`` [m]; p_bar: (2,) its horizontal projection.
        dp_dw: (3,) tangent ``p_p'(w)``.
        psi_p, dpsi_dw, d2psi_dw2: azimuth (21) [rad] and its first two w-derivatives.
        theta_p, dtheta_dw: elevation (21) [rad] and its w-derivative.
        speed_bar, dspeed_bar_dw: ``||p_bar'(w)||`` and its w-derivative; (22) reads
            ``w_dot = ubar_p / speed_bar``.
        z_p, dz_dw, d2z_dw2: depth of the path [m] and its w-derivatives (for depth loops).
        regular: () bool, ``speed_bar`` above the floor (False: the frame is not defined there).
    """

    w: Any
    p: Any
    p_bar: Any
    dp_dw: Any
    psi_p: Any
    dpsi_dw: Any
    d2psi_dw2: Any
    theta_p: Any
    dtheta_dw: Any
    speed_bar: Any
    dspeed_bar_dw: Any
    z_p: Any
    dz_dw: Any
    d2z_dw2: Any
    regular: Any


def path_point(path: Path, coeffs, w):
    """(3,) position ``p_p(w)``; 2-D curves are lifted to z = 0."""
    p = jnp.asarray(path.fn(w, coeffs))
    if p.shape == (2,):
        p = jnp.concatenate([p, jnp.zeros((1,), p.dtype)])
    if p.shape != (3,):
        raise ValueError(f"path {path.name!r}: fn must return shape (2,) or (3,), got {p.shape}")
    return p


def _float_w(w):
    w = jnp.asarray(w)
    if not jnp.issubdtype(w.dtype, jnp.floating):
        w = w.astype(jnp.result_type(float))
    return w


def _angles(d, tiny):
    """``([psi_p, speed_bar, theta_p], regular)`` (21) from a tangent ``d = p_p'(w)`` (3,)."""
    hx, hy = d[0], d[1]
    sq = hx * hx + hy * hy
    ok = sq > tiny * tiny
    # double-where: atan2/sqrt are never evaluated at the zero vector (no NaN gradients)
    hx_s = jnp.where(ok, hx, jnp.ones_like(hx))
    hy_s = jnp.where(ok, hy, jnp.zeros_like(hy))
    sb = jnp.sqrt(jnp.where(ok, sq, tiny * tiny))
    return jnp.stack([jnp.arctan2(hy_s, hx_s), sb, jnp.arctan2(-d[2], sb)]), ok


def path_frame(path: Path, coeffs, w) -> PathFrame:
    """Evaluate the path and its frame (21) at ``w`` by autodiff (jit/vmap/grad-safe).

    For laws that differentiate the path *again* (the generic engine's constraints), use
    [`path_pose`][vcjax.paths.path_pose]: the same values, and derivatives at any order without
    nested autodiff
    through this function's own."""
    w = _float_w(w)

    def tangent(w_):
        return jax.jvp(lambda a: path_point(path, coeffs, a), (w_,), (jnp.ones_like(w_),))

    (p, dp), (_, d2p) = jax.jvp(tangent, (w,), (jnp.ones_like(w),))
    tiny = jnp.asarray(MIN_TANGENT, w.dtype)

    def angles(w_):
        return _angles(tangent(w_)[1], tiny)

    def angles_d(w_):
        return jax.jvp(lambda a: angles(a)[0], (w_,), (jnp.ones_like(w_),))

    (a0, a1), (_, a2) = jax.jvp(angles_d, (w,), (jnp.ones_like(w),))
    ok = angles(w)[1]
    return PathFrame(
        w=w,
        p=p,
        p_bar=p[:2],
        dp_dw=dp,
        psi_p=a0[0],
        dpsi_dw=a1[0],
        d2psi_dw2=a2[0],
        theta_p=a0[2],
        dtheta_dw=a1[2],
        speed_bar=a0[1],
        dspeed_bar_dw=a1[1],
        z_p=p[2],
        dz_dw=dp[2],
        d2z_dw2=d2p[2],
        regular=ok,
    )


class PathPose(NamedTuple):
    """The path at one parameter value ``w``, without its rates (scalars unless noted).

    Attributes:
        p: (3,) position ``p_p(w)`` [m].
        psi_p, theta_p: azimuth and elevation (21) [rad].
        speed_bar: ``||p_bar'(w)||`` (floored as in [`PathFrame`][vcjax.paths.PathFrame]).
    """

    p: Any
    psi_p: Any
    theta_p: Any
    speed_bar: Any


def path_pose(path: Path, coeffs, w) -> PathPose:
    """[`PathPose`][vcjax.paths.PathPose] at ``w``: the values of
    [`path_frame`][vcjax.paths.path_frame]'s ``p``, ``psi_p``,
    ``theta_p``, ``speed_bar``, for code that differentiates them (e.g. constraints handed to
    the engine, [`vcjax.mechanics`][vcjax.mechanics], which takes their first and second time
    derivatives).

    Its derivative in ``w`` is defined by a rule (``jax.custom_jvp``): differentiating the
    order-k Taylor tower of the pose gives the order-(k+1) tower, computed directly by k + 1
    nested ``jvp`` of the path. Differentiating [`path_frame`][vcjax.paths.path_frame] instead
    differentiates its
    own nested autodiff (every field, used or not): a doubly differentiated constraint traces
    the path about ten times less this way. Derivatives in ``coeffs`` are ordinary autodiff.
    """
    row = _pose_tower(path, 0)(_float_w(w), coeffs)[0]
    return PathPose(p=row[:3], psi_p=row[3], theta_p=row[5], speed_bar=row[4])


def _pose_direct(path: Path, coeffs, w, order: int):
    """(order + 1, 6) rows ``d^k/dw^k [p (3), psi_p, speed_bar, theta_p]``, k = 0..order, by
    nested ``jvp`` (each level: value and derivative of the level below)."""
    tiny = jnp.asarray(MIN_TANGENT, w.dtype)

    def base(w_):
        p, d = jax.jvp(lambda a: path_point(path, coeffs, a), (w_,), (jnp.ones_like(w_),))
        return jnp.concatenate([p, _angles(d, tiny)[0]])[None]

    fn = base
    for _ in range(order):

        def fn(w_, lower=fn):
            rows, d = jax.jvp(lower, (w_,), (jnp.ones_like(w_),))
            return jnp.concatenate([rows, d[-1:]])

    return fn(w)


def _materialise(t, primal):
    if isinstance(t, SymbolicZero):
        return jnp.zeros_like(primal) if jnp.issubdtype(primal.dtype, jnp.inexact) else t
    return t


@functools.cache
def _pose_tower(path: Path, order: int):
    """``tower(w, coeffs) -> (order + 1, 6)`` (``_pose_direct``) whose ``w``-tangent is
    the next order's rows 1.. times the tangent of ``w`` (the tower one order up)."""

    @jax.custom_jvp
    def tower(w, coeffs):
        return _pose_direct(path, coeffs, w, order)

    def rule(primals, tangents):
        w, coeffs = primals
        t_w, t_c = tangents
        leaves_c = jax.tree_util.tree_leaves(t_c, is_leaf=lambda x: isinstance(x, SymbolicZero))
        if isinstance(t_w, SymbolicZero):
            out = tower(w, coeffs)
            t_out = jnp.zeros_like(out)
        else:
            up = _pose_tower(path, order + 1)(w, coeffs)
            out, t_out = up[:-1], up[1:] * t_w
        if not all(isinstance(t, SymbolicZero) for t in leaves_c):
            t_c = jax.tree_util.tree_map(
                _materialise, t_c, coeffs, is_leaf=lambda x: isinstance(x, SymbolicZero)
            )
            t_out = t_out + jax.jvp(lambda c: _pose_direct(path, c, w, order), (coeffs,), (t_c,))[1]
        return out, t_out

    tower.defjvp(rule, symbolic_zeros=True)
    return tower


def _path_samples(path: Path, coeffs, w0, w1, num: int):
    """``(ws, p, dp)``: ``num`` parameters from ``w0`` to ``w1``, the path's points (num, 3) and
    tangents (num, 3) there."""
    ws = jnp.linspace(w0, w1, num)

    def tangent(w_):
        return jax.jvp(lambda a: path_point(path, coeffs, a), (w_,), (jnp.ones_like(w_),))

    return (ws, *jax.vmap(tangent)(ws))


# ``_path_samples`` as one program per path kind and coefficient shapes: op by op, the first
# check of a process compiled some fifty one-operation kernels (a second of a cold start); light
# (LLVM's level 1: a fifth of the compile): its samples feed the check alone, never a result
_path_samples_jit = compiler.jit(_path_samples, static_argnums=(0, 4), light=True)


def _samples(path: Path, coeffs, w0, w1, num: int):
    """``_path_samples``, jitted where it can be: a path that is no
    static argument (its function cannot be hashed), or whose function needs its coefficients
    as Python values (branches on them, strings), is evaluated op by op, as before."""
    try:
        return _path_samples_jit(path, coeffs, w0, w1, num)
    except Exception:  # the op-by-op evaluation raises what it raises (as before)
        return _path_samples(path, coeffs, w0, w1, num)


#: the checks ``validate_path`` passed in this process (path, range, samples and coefficient
#: values): a path built again with the same values (a loop of each controller of a config, a
#: study's nominal path) is not checked again
_PASSED: dict = {}
_PASSED_MAX = 256


def _passed_key(path: Path, coeffs, w0: float, w1: float, num: int):
    """The memo's key of a check, None where it cannot be kept (traced or unhashable inputs)."""
    try:
        hash(path)
    except TypeError:
        return None
    leaves = []
    for leaf in jax.tree_util.tree_leaves(coeffs):
        try:
            a = np.asarray(leaf)
        except Exception:  # noqa: BLE001 - a traced value, or no array: no memo
            return None
        if a.dtype == object:
            return None
        leaves.append((a.dtype.str, a.shape, a.tobytes()))
    return (path, jax.tree_util.tree_structure(coeffs), tuple(leaves), w0, w1, int(num))


def validate_path(path: Path, coeffs, w_range=(-50.0, 50.0), num: int = 401) -> None:
    """Eagerly check a path: finite values and a non-vanishing horizontal tangent on ``w_range``.

    A check passed once in this process for the same path, coefficient values, range and
    ``num`` is not repeated.

    Raises:
        ValueError: naming the path and the first ``w`` where ``||p_bar'(w)||`` vanishes (or where
            the path is not finite).
    """
    w0, w1 = (float(x) for x in w_range)
    if not (np.isfinite(w0) and np.isfinite(w1) and w1 > w0):
        raise ValueError(f"path {path.name!r}: w_range must be finite with w0 < w1, got {w_range}")
    key = _passed_key(path, coeffs, w0, w1, num)
    if key is not None and key in _PASSED:
        return
    _check_samples(path, coeffs, w0, w1, num)
    if key is not None:
        if len(_PASSED) >= _PASSED_MAX:
            _PASSED.clear()
        _PASSED[key] = True


def _check_samples(path: Path, coeffs, w0: float, w1: float, num: int) -> None:
    """``validate_path``'s check itself."""
    try:
        ws, p, dp = _samples(path, coeffs, w0, w1, num)
    except (TypeError, ValueError) as err:
        raise ValueError(f"path {path.name!r}: cannot evaluate p_p(w): {err}") from None
    ws, p, dp = np.asarray(ws), np.asarray(p), np.asarray(dp)
    bad = ~np.all(np.isfinite(p), axis=1) | ~np.all(np.isfinite(dp), axis=1)
    if np.any(bad):
        w_bad = float(ws[int(np.argmax(bad))])
        raise ValueError(f"path {path.name!r}: p_p or its derivative is not finite at w = {w_bad}")
    sb = np.hypot(dp[:, 0], dp[:, 1])
    scale = max(float(np.median(np.linalg.norm(dp, axis=1))), 1.0)
    small = sb <= MIN_TANGENT * scale
    if np.any(small):
        w_bad = float(ws[int(np.argmax(small))])
        raise ValueError(
            f"path {path.name!r}: the horizontal derivative p_bar'(w) vanishes at w = {w_bad:.6g} "
            f"(|p_bar'| = {sb[int(np.argmax(small))]:.3g}); the azimuth psi_p and the particle "
            "speed (22) are undefined there. Reparametrise the path or avoid vertical segments."
        )


def _vec(name, x, n=None, dtype=None):
    a = check_array(name, x, (n,) if n is not None else None)
    dtype = dtype or jnp.result_type(float)
    return jnp.asarray(a if a is not None else x, dtype=dtype)


def _lift3(name, x):
    a = np.asarray(x, dtype=float)
    if a.shape == (2,):
        a = np.concatenate([a, [0.0]])
    check_array(name, a, (3,))
    return a


# ------------------------------------------------------------------------------------ line


class LineCoeffs(NamedTuple):
    """``p(w) = origin + w * direction`` (direction a unit vector: w is arc length)."""

    origin: Any  # (3,)
    direction: Any  # (3,)


def _line_fn(w, c: LineCoeffs):
    return c.origin + w * c.direction


#: Straight line kind (coefficients [`LineCoeffs`][vcjax.paths.LineCoeffs]).
LINE = Path(_line_fn, "line")


def line(origin=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0)):
    """A straight line through ``origin`` along ``direction`` (2- or 3-vectors, NED [m]).

    ``direction`` is normalised, so ``w`` is arc length. A vertical line is rejected (no
    horizontal tangent).
    """
    o = _lift3("origin", origin)
    d = _lift3("direction", direction)
    n = np.linalg.norm(d)
    if n == 0:
        raise ValueError("direction: must be a non-zero vector")
    coeffs = LineCoeffs(_vec("origin", o, 3), _vec("direction", d / n, 3))
    validate_path(LINE, coeffs, (-1.0, 1.0), num=3)
    return LINE, coeffs


def paper_line():
    """Simulation 1's path ``p_p(w) = [10, w]`` (a line x = 10 m heading east)."""
    return line(origin=(10.0, 0.0, 0.0), direction=(0.0, 1.0, 0.0))


# ---------------------------------------------------------------------------------- circle


class CircleCoeffs(NamedTuple):
    """``p(w) = center + radius [cos(phi), sign sin(phi), 0]``, ``phi = phase + w / radius``."""

    center: Any  # (3,)
    radius: Any  # ()
    sign: Any  # () +1 clockwise seen from above in NED (north -> east), -1 counter-clockwise
    phase: Any  # () [rad]


def _circle_fn(w, c: CircleCoeffs):
    phi = c.phase + w / c.radius
    return c.center + c.radius * jnp.stack(
        [jnp.cos(phi), c.sign * jnp.sin(phi), jnp.zeros_like(phi)]
    )


#: Circle kind (coefficients [`CircleCoeffs`][vcjax.paths.CircleCoeffs]).
CIRCLE = Path(_circle_fn, "circle")


def circle(center=(0.0, 0.0, 0.0), radius=10.0, clockwise=True, phase=0.0):
    """A horizontal circle, parametrised by arc length ``w`` [m].

    ``clockwise`` is as seen from above on a north-up, east-right chart (NED: a right turn,
    positive yaw rate).
    """
    check_positive("radius", radius, ())
    check_array("phase", phase, ())
    c = _lift3("center", center)
    coeffs = CircleCoeffs(
        _vec("center", c, 3),
        _vec("radius", radius),
        _vec("sign", 1.0 if clockwise else -1.0),
        _vec("phase", phase),
    )
    validate_path(CIRCLE, coeffs, (0.0, 2 * np.pi * float(radius)))
    return CIRCLE, coeffs


# ----------------------------------------------------------------------------------- helix


class HelixCoeffs(NamedTuple):
    """``p(w) = center + [a sin(w / T + phase), b cos(w / T + phase), climb w]``."""

    center: Any  # (3,)
    a: Any  # () semi-axis along north [m]
    b: Any  # () semi-axis along east [m]
    T: Any  # () parameter scale [m/rad]
    climb: Any  # () dz/dw (positive: deeper, NED)
    phase: Any  # () [rad]


def _helix_fn(w, c: HelixCoeffs):
    phi = w / c.T + c.phase
    return c.center + jnp.stack([c.a * jnp.sin(phi), c.b * jnp.cos(phi), c.climb * w])


#: Helix kind (coefficients [`HelixCoeffs`][vcjax.paths.HelixCoeffs]), elliptic in general.
HELIX = Path(_helix_fn, "helix")


def helix(center=(0.0, 0.0, 0.0), a=10.0, b=10.0, T=5.0, climb=0.1, phase=0.0):
    """An (elliptic) helix ``center + [a sin(w/T + phase), b cos(w/T + phase), climb w]``.

    With ``a = b`` and ``T = a`` it is a circular helix parametrised by horizontal arc length.
    """
    for name, v in dict(a=a, b=b, T=T).items():
        check_positive(name, v, ())
    check_array("climb", climb, ())
    check_array("phase", phase, ())
    c = _lift3("center", center)
    coeffs = HelixCoeffs(
        _vec("center", c, 3),
        _vec("a", a),
        _vec("b", b),
        _vec("T", T),
        _vec("climb", climb),
        _vec("phase", phase),
    )
    validate_path(HELIX, coeffs, (0.0, 2 * np.pi * float(T)))
    return HELIX, coeffs


def paper_helix():
    """Simulation 2's helix ``p_p(w) = [10 sin(w/5), 8 cos(w/5), 0.1 w - 100]``."""
    return helix(center=(0.0, 0.0, -100.0), a=10.0, b=8.0, T=5.0, climb=0.1)


# --------------------------------------------------------------------------- cubic spline


class SplineCoeffs(NamedTuple):
    """Piecewise cubic ``p(w) = c0 + c1 d + c2 d^2 + c3 d^3``, ``d = w - knots[i]`` on piece i.

    Attributes:
        knots: (n,) parameter at each waypoint (cumulative chord length [m]).
        c: (n - 1, 4, 3) polynomial coefficients of each piece.
    """

    knots: Any
    c: Any


def _spline_fn(w, c: SplineCoeffs):
    n = c.knots.shape[0]
    i = jnp.clip(jnp.searchsorted(c.knots, w, side="right") - 1, 0, n - 2)
    d = w - c.knots[i]
    k = c.c[i]
    return k[0] + d * (k[1] + d * (k[2] + d * k[3]))


#: Cubic-spline kind (coefficients [`SplineCoeffs`][vcjax.paths.SplineCoeffs]).
SPLINE = Path(_spline_fn, "waypoints")


def _natural_cubic(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(n-1, 4) coefficients of the natural cubic spline through ``(t, y)`` (C², y''(ends) = 0)."""
    n = t.size
    h = np.diff(t)
    A = np.zeros((n, n))
    rhs = np.zeros(n)
    A[0, 0] = A[-1, -1] = 1.0
    for i in range(1, n - 1):
        A[i, i - 1] = h[i - 1]
        A[i, i] = 2 * (h[i - 1] + h[i])
        A[i, i + 1] = h[i]
        rhs[i] = 3 * ((y[i + 1] - y[i]) / h[i] - (y[i] - y[i - 1]) / h[i - 1])
    c2 = np.linalg.solve(A, rhs)
    c1 = (y[1:] - y[:-1]) / h - h * (2 * c2[:-1] + c2[1:]) / 3
    c3 = (c2[1:] - c2[:-1]) / (3 * h)
    return np.stack([y[:-1], c1, c2[:-1], c3], axis=1)


def waypoints(points, extend: float = 0.0):
    """A C² natural cubic spline through waypoints, parametrised by cumulative chord length.

    Args:
        points: (n, 2) or (n, 3) waypoints, NED [m], n >= 2, consecutive points distinct.
        extend: not used for interpolation; the path is validated over
            ``[-extend, length + extend]`` (outside the waypoints the end cubics extrapolate,
            which is what the particle follows if it overshoots).

    Raises:
        ValueError: for bad shapes, repeated consecutive waypoints or a spline whose horizontal
            tangent vanishes between waypoints (e.g. a sharp reversal).
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3) or pts.shape[0] < 2:
        raise ValueError(f"points: expected shape (n, 2) or (n, 3) with n >= 2, got {pts.shape}")
    check_array("points", pts, (None, None))
    if pts.shape[1] == 2:
        pts = np.concatenate([pts, np.zeros((pts.shape[0], 1))], axis=1)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    if np.any(seg <= 0):
        i = int(np.argmax(seg <= 0))
        raise ValueError(f"points: waypoints {i} and {i + 1} coincide")
    knots = np.concatenate([[0.0], np.cumsum(seg)])
    c = np.stack([_natural_cubic(knots, pts[:, j]) for j in range(3)], axis=2)
    coeffs = SplineCoeffs(_vec("knots", knots), jnp.asarray(c, dtype=jnp.result_type(float)))
    check_positive("extend", extend, (), strict=False)
    validate_path(SPLINE, coeffs, (-float(extend), knots[-1] + float(extend)), num=2001)
    return SPLINE, coeffs


# ---------------------------------------------------------------------------------- custom


def custom(fn: Callable, coeffs=None, w_range=(-50.0, 50.0), name: str = "custom"):
    """Wrap a user curve.

    Args:
        fn: ``fn(w) -> (2,) or (3,)`` when ``coeffs`` is None, else ``fn(w, coeffs)``; written in
            ``jax.numpy`` so that it can be differentiated. Keep the function object the same
            between calls (a module-level function) to reuse compiled rollouts.
        coeffs: optional pytree of arrays (traced).
        w_range: the range of ``w`` on which the path will be used; validated eagerly.
        name: label.

    Raises:
        ValueError: if the path is not finite or its horizontal tangent vanishes on ``w_range``.
    """
    if not callable(fn):
        raise ValueError(f"fn: expected a callable p_p(w), got {type(fn).__name__}")
    path = Path(fn if coeffs is not None else _NoCoeffs(fn), name)
    coeffs = () if coeffs is None else coeffs
    validate_path(path, coeffs, w_range)
    return path, coeffs


@dataclasses.dataclass(frozen=True)
class _NoCoeffs:
    fn: Callable

    def __call__(self, w, coeffs):
        return self.fn(w)


# ------------------------------------------------------------------------------- lawnmower


class LawnmowerCoeffs(NamedTuple):
    """Coefficients of [`lawnmower`][vcjax.paths.lawnmower] (traced; scalars unless noted)."""

    start: Any  # (3,) NED start of the first leg [m]
    leg: Any  # () leg length [m]
    radius: Any  # () turn radius [m]; the legs are 2 radius apart
    n_legs: Any  # () number of legs (a float, so that it can be traced)
    depth: Any  # () depth change of the descent [m] (positive: deeper)
    descent: Any  # () horizontal distance of the descent from the start [m]


def _lawnmower_fn(w, c: LawnmowerCoeffs):
    L, R = c.leg, c.radius
    period = L + jnp.pi * R
    k = jnp.clip(jnp.floor(w / period), 0.0, c.n_legs - 1.0)
    om = w - k * period  # distance along leg k and its turn
    d = 1.0 - 2.0 * jnp.mod(k, 2.0)  # +1 northwards, -1 southwards
    turn = (om > L) & (k < c.n_legs - 1.0)  # the last leg runs on straight
    x0 = c.start[0] + jnp.where(d > 0, 0.0 * L, L)
    y0 = c.start[1] + 2.0 * R * k
    a = (jnp.where(turn, om, L) - L) / R  # double-where: the arc is evaluated only on turns
    x = jnp.where(turn, x0 + d * (L + R * jnp.sin(a)), x0 + d * om)
    y = jnp.where(turn, y0 + R * (1.0 - jnp.cos(a)), y0)
    xi = jnp.clip(w / c.descent, 0.0, 1.0)
    z = c.start[2] + c.depth * xi**3 * (10.0 - 15.0 * xi + 6.0 * xi * xi)
    return jnp.stack([x, y, z])


LAWNMOWER = Path(_lawnmower_fn, "lawnmower")


def lawnmower(start=(0.0, 0.0, 0.0), leg=150.0, radius=20.0, n_legs=4, depth=15.0, descent=150.0):
    """A survey pattern: ``n_legs`` straight legs along north (alternating direction, stepping
    east by ``2 radius``) joined by half circles, with a smooth (C², quintic) descent of
    ``depth`` metres over the first ``descent`` metres. ``w`` is the horizontal arc length [m];
    before 0 the first leg and after the last leg the last leg extend straight.

    Curvature jumps where a leg meets a turn (as in a Dubins survey plan): the path angles are
    continuous, their rates step there.
    """
    check_array("start", start, (3,))
    for name, v in dict(leg=leg, radius=radius, descent=descent).items():
        check_positive(name, v, ())
    check_array("depth", depth, ())
    if not (isinstance(n_legs, int | np.integer) and n_legs >= 1):
        raise ValueError(f"n_legs: expected an int >= 1, got {n_legs!r}")
    f = lambda x: jnp.asarray(x, dtype=jnp.result_type(float))
    coeffs = LawnmowerCoeffs(f(start), f(leg), f(radius), f(float(n_legs)), f(depth), f(descent))
    total = n_legs * float(leg) + (n_legs - 1) * np.pi * float(radius)
    validate_path(LAWNMOWER, coeffs, (-10.0, total + 10.0), num=2001)
    return LAWNMOWER, coeffs
