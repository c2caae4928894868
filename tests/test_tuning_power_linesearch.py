"""More zoom searches against ``optax.scale_by_zoom_linesearch`` (the mutation survivors of
``tuning/linesearch.py`` that the searches of ``tests/test_tuning_power_optim.py`` leave;
docs/development/testing.md, "Mutation testing").

Each search is purpose-built for a branch the others never take: an approximate decrease
inside ``1e-6 |loss|`` but not ``1e-6 / |loss|``, a rise while still doubling, a cubic and a
parabola that land near the interval's far end, a zoom point that misses sufficient decrease by
less than 1 yet lies below the low end, an interval shrinking below ``interval_threshold``
with no safe point, with a safe point of negative loss, and at the last evaluation, a failed
search whose last point is outside the domain. The reference is optax's own search run in one
``jax.jit`` (the module's contract: optax's arithmetic step for step); the test function and
both searches are those of ``tests/test_tuning_power_optim.py`` (the same compiled programs:
only the coefficients change), driven here with a bound on the number of evaluations.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
import test_tuning_power_optim as base

_p = base._p

#: (name, x0, d, p, what the search does: "done", or "failed" with its number of evaluations)
CASES = [
    # at s = 1 the loss is 9.1e-6 above the start's (about 100.5), inside Hager and Zhang's
    # 1e-6 |loss| (1e-4), not 1e-6 / |loss| (1e-8); the slope there is 9e-4 of 2: done at once
    (
        "approx-tol",
        [0.0, 0.0],
        [1.0, 0.0],
        _p(c=100.0, a=2.0, m=(1.0, 0.0), step=0.50005, at=0.5, width=0.1),
        ("done", 1),
    ),
    # doubling towards a minimum at 100 over a step up of 200 at 1.5: s = 2 is higher than
    # s = 1 without sufficient decrease, while its slope is still negative: the interval is
    # [1, 2] (not a third doubling)
    (
        "rise-while-doubling",
        [0.0, 0.0],
        [1.0, 0.0],
        _p(a=1.0, m=(100.0, 0.0), step=200.0, at=1.5, width=0.05),
        ("done", 4),
    ),
    # a kink at 1e-7 (eps 1e-9) under a loss of -1: past the kink the loss rises, so the zoom's
    # parabola steps shrink the interval [0, s] about fivefold a round; it is shorter than 1e-5
    # from the 10th evaluation on, but with no point of sufficient decrease yet the search goes
    # on, and ends, failed, at the first one (the 12th, of negative loss), not at 15
    (
        "kink-at-the-start",
        [0.0, 0.0],
        [1.0, 0.0],
        _p(c=-1.0, a=0.0, kink=1.0, eps=1e-9, m=(1e-7, 0.0)),
        ("failed", 12),
    ),
    # a bowl behind a log barrier at 0.3 (infinite, then NaN, from s = 0.7 on): the zoom
    # brackets the wall for 15 evaluations; the last point is outside the domain, the step
    # taken is the safe one
    (
        "wall-ahead",
        [1.0, 0.0],
        [-1.0, 0.0],
        _p(a=1.0, m=(-30.0, 0.0), bar=1e-6, wall=0.3),
        ("failed", 15),
    ),
    # a rising line under a loss of -5e6: every point is inside the approximate decrease's 5 of
    # the start, judged by its slope alone; points whose slope just misses (1 - 2 c1)|slope0|
    # fail sufficient decrease by less than 1 though lower than the low end and the safe point
    (
        "round-off-rise",
        [0.0, 0.0],
        [1.0, 0.0],
        _p(c=-5e6, a=0.0, m=(0.002, 0.0), kink=0.06, eps=1.25e-4, step=-0.015, at=2.0, width=0.5),
        ("failed", 15),
    ),
    # a kink at x = 0.0025 and a steep step down at x = 1.75, along d = 4.5: the cubic's and
    # the parabola's minimisers fall near the far end of the interval, where they are refused
    (
        "steep-step",
        [0.0, 0.0],
        [4.5, 0.0],
        _p(c=60.0, a=0.0, m=(0.0025, 0.0), kink=0.12, eps=0.0018, step=-31.0, at=1.75, width=0.03),
        ("done", 8),
    ),
    # a kink at x = 0.19 (s = 0.0158) on a quartic, along d = 12: the interval falls below
    # 1e-5 just before the 15th evaluation, when the evaluations run out as well
    (
        "both-limits",
        [0.0, 0.0],
        [12.0, 0.0],
        _p(
            c=0.85,
            a=0.0,
            m=(0.19, 0.4),
            quart=0.15,
            kink=0.9,
            eps=1.4e-8,
            step=0.002,
            at=5.1,
            width=0.35,
        ),
        ("failed", 15),
    ),
]


def _bounded_search(x0, d, p, most=20):
    """``base._zoom_search`` with at most ``most`` evaluations (a search that never ends is a
    failure here, not a hang)."""
    value, grad = base._vg(x0, p)
    s = base._init(d, x0, value, grad)
    points = []
    while bool(base._running(s)) and len(points) < most:
        x = base._point(s)
        points.append(np.asarray(x))
        s = base._advance(s, *base._vg(x, p))
    return points, s


@pytest.mark.parametrize("name, x0, d, p, ends", CASES, ids=[c[0] for c in CASES])
def test_more_zoom_searches_evaluate_optax_points(name, x0, d, p, ends):
    """Every point evaluated, the count, the step, loss, gradient and both errors are optax's;
    the search ends as described (done, or failed after the stated number of evaluations, and
    then at the safe point or the last one as documented)."""
    x0, d = jnp.asarray(x0), jnp.asarray(d)
    points, s = _bounded_search(x0, d, p)
    base._assert_optax_search(x0, d, p, points, s)
    how, count = ends
    assert (bool(s.done), bool(s.failed), len(points)) == (how == "done", how == "failed", count)
    f0, g0 = (np.asarray(v) for v in base._vg(x0, p))
    eta, f1, g1 = float(s.stepsize), float(s.value), np.asarray(s.grad)
    slope0, slope1 = float(g0 @ np.asarray(d)), float(g1 @ np.asarray(d))
    # sufficient decrease (Armijo's, or Hager and Zhang's approximate one) in numpy: at the
    # step of a successful search, and at the safe step a failed one takes
    approx = f1 <= f0 + 1e-6 * abs(f0) and slope1 <= (1 - 2e-4) * abs(slope0)
    assert np.isfinite(f1) and eta > 0.0 and (f1 <= f0 + 1e-4 * eta * slope0 or approx)
    if how == "done":  # and the strong curvature condition
        assert abs(slope1) <= 0.9 * abs(slope0)
    # the state's points are points of the line: each end of the interval (step, loss, slope),
    # the cubic's third point and the safe point (step, loss) are ``f`` and ``f' . d`` there
    for step, value, slope in (
        (s.low, s.value_low, s.slope_low),
        (s.high, s.value_high, s.slope_high),
        (s.cubic_ref, s.value_cubic_ref, None),
        (s.safe_stepsize, s.safe_value, None),
    ):
        v, g = base._vg(x0 + step * d, p)
        np.testing.assert_allclose(float(value), float(v), rtol=1e-14, atol=1e-300)
        if slope is not None:
            want = float(np.asarray(g) @ np.asarray(d))
            np.testing.assert_allclose(float(slope), want, rtol=1e-13, atol=1e-300)
    if name == "approx-tol":  # the rise at s = 1, between the two tolerances
        assert 1e-6 / abs(f0) < f1 - f0 < 1e-6 * abs(f0) and eta == 1.0
    if name == "rise-while-doubling":  # 1, 2, then zoom inside [1, 2]
        steps = [float((pt - np.asarray(x0)) @ np.asarray(d)) for pt in points]
        assert steps[:2] == [1.0, 2.0] and all(1.0 < h < 2.0 for h in steps[2:])
    if name == "wall-ahead":  # the last point is past the wall: the step is the safe one
        last = float((points[-1] - np.asarray(x0)) @ np.asarray(d))
        assert last >= 0.7 and eta < 0.7
