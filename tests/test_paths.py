"""Paths (21): frames by autodiff against closed forms, spline interpolation and C² continuity,
user callables, rejection of vanishing tangents, no recompilation for new coefficients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import paths


def test_line_frame_is_constant_and_arc_length():
    path, c = paths.line(origin=(3.0, -1.0, 2.0), direction=(1.0, 1.0, 0.0))
    f = paths.path_frame(path, c, 2.0)
    np.testing.assert_allclose(f.p, [3.0 + np.sqrt(2.0), -1.0 + np.sqrt(2.0), 2.0], atol=1e-14)
    assert float(f.psi_p) == pytest.approx(np.pi / 4)
    assert float(f.speed_bar) == pytest.approx(1.0)
    for x in (f.dpsi_dw, f.d2psi_dw2, f.dspeed_bar_dw, f.theta_p, f.dz_dw):
        assert abs(float(x)) < 1e-14
    # Simulation 1's line [10, w]
    path, c = paths.paper_line()
    f = paths.path_frame(path, c, 7.0)
    np.testing.assert_allclose(f.p_bar, [10.0, 7.0])
    assert float(f.psi_p) == pytest.approx(np.pi / 2)


@pytest.mark.parametrize("clockwise", [True, False])
def test_circle_curvature(clockwise):
    R = 12.0
    path, c = paths.circle(center=(1.0, 2.0), radius=R, clockwise=clockwise, phase=0.3)
    for w in (0.0, 5.0, 40.0):
        f = paths.path_frame(path, c, w)
        sign = 1.0 if clockwise else -1.0
        # azimuth rate = signed curvature (arc-length parametrisation), constant
        assert float(f.dpsi_dw) == pytest.approx(sign / R, rel=1e-12)
        assert abs(float(f.d2psi_dw2)) < 1e-12
        assert float(f.speed_bar) == pytest.approx(1.0, rel=1e-12)
        assert np.linalg.norm(np.asarray(f.p_bar) - [1.0, 2.0]) == pytest.approx(R)
        # the tangent is perpendicular to the radius
        radial = np.asarray(f.p_bar) - [1.0, 2.0]
        tangent = [np.cos(float(f.psi_p)), np.sin(float(f.psi_p))]
        assert abs(np.dot(radial, tangent)) < 1e-10


def test_paper_helix_against_closed_form():
    path, c = paths.paper_helix()
    for w in (0.0, 3.0, 17.0, 40.0):
        f = paths.path_frame(path, c, w)
        xp, yp = 2.0 * np.cos(w / 5), -1.6 * np.sin(w / 5)  # x' = 10/5 cos, y' = -8/5 sin
        xpp, ypp = -0.4 * np.sin(w / 5), -0.32 * np.cos(w / 5)
        sb = np.hypot(xp, yp)
        np.testing.assert_allclose(f.p, [10 * np.sin(w / 5), 8 * np.cos(w / 5), 0.1 * w - 100])
        assert float(f.speed_bar) == pytest.approx(sb, rel=1e-12)
        dpsi = (xp * ypp - yp * xpp) / sb**2
        assert float(f.dpsi_dw) == pytest.approx(dpsi, rel=1e-10)
        assert float(f.theta_p) == pytest.approx(np.arctan2(-0.1, sb), rel=1e-12)
        assert float(f.dz_dw) == pytest.approx(0.1)
        # second derivative of psi: central difference of the autodiff first derivative
        h = 1e-4
        d1 = [float(paths.path_frame(path, c, w + s * h).dpsi_dw) for s in (-1, 1)]
        assert float(f.d2psi_dw2) == pytest.approx((d1[1] - d1[0]) / (2 * h), rel=1e-6, abs=1e-9)
        # speed derivative likewise
        s1 = [float(paths.path_frame(path, c, w + s * h).speed_bar) for s in (-1, 1)]
        assert float(f.dspeed_bar_dw) == pytest.approx((s1[1] - s1[0]) / (2 * h), abs=1e-8)


def test_waypoint_spline_interpolates_and_is_c2():
    pts = np.array([[0.0, 0.0], [20.0, 5.0], [35.0, 30.0], [20.0, 55.0], [0.0, 60.0]])
    path, c = paths.waypoints(pts)
    knots = np.asarray(c.knots)
    for k, p in zip(knots, pts, strict=True):
        np.testing.assert_allclose(paths.path_frame(path, c, k).p_bar, p, atol=1e-10)

    def derivs(w):
        f = lambda a: paths.path_point(path, c, a)
        d1 = lambda a: jax.jvp(f, (a,), (1.0,))[1]
        d2 = lambda a: jax.jvp(d1, (a,), (1.0,))[1]
        return f(w), d1(w), d2(w)

    eps = 1e-9
    for k in knots[1:-1]:
        left, right = derivs(k - eps), derivs(k + eps)
        for a, b in zip(left, right, strict=True):
            np.testing.assert_allclose(a, b, atol=1e-6)
    # natural end conditions
    np.testing.assert_allclose(derivs(knots[0])[2], 0.0, atol=1e-12)
    np.testing.assert_allclose(derivs(knots[-1] - 1e-12)[2], 0.0, atol=1e-9)


def test_custom_callable_matches_builtin():
    def p_fn(w):
        return jnp.stack([10.0 + 0.0 * w, w])

    path, c = paths.custom(p_fn)
    ref_path, ref_c = paths.paper_line()
    for w in (-3.0, 0.0, 11.0):
        a, b = paths.path_frame(path, c, w), paths.path_frame(ref_path, ref_c, w)
        for x, y in zip(a, b, strict=True):
            np.testing.assert_allclose(x, y, atol=1e-14)


def test_vanishing_derivative_is_rejected():
    with pytest.raises(ValueError, match="vanishes"):
        paths.line(direction=(0.0, 0.0, 1.0))  # vertical: no horizontal tangent
    with pytest.raises(ValueError, match="vanishes"):
        paths.custom(lambda w: jnp.stack([w**3, 2 * w**3]), w_range=(-1.0, 1.0))  # cusp at 0
    with pytest.raises(ValueError, match="coincide"):
        paths.waypoints([[0.0, 0.0], [1.0, 1.0], [1.0, 1.0]])
    with pytest.raises(ValueError, match="not finite"):
        paths.custom(lambda w: jnp.stack([w, jnp.log(w)]), w_range=(-1.0, 1.0))
    with pytest.raises(ValueError, match="radius"):
        paths.circle(radius=-1.0)
    with pytest.raises(ValueError, match="points"):
        paths.waypoints([[0.0, 0.0, 0.0, 0.0]])


def test_frame_is_nan_free_at_a_singular_point():
    path, c = paths.custom(lambda w: jnp.stack([w**3, w]), w_range=(0.5, 1.0))
    # at w = 0 the tangent is [0, 1]: fine. Build one that vanishes and evaluate under grad.
    path2 = paths.Path(lambda w, c: jnp.stack([w**2, w**2, 0.0 * w]), "cusp")
    g = jax.grad(lambda w: paths.path_frame(path2, (), w).psi_p)(0.0)
    assert np.isfinite(float(g))
    assert not bool(paths.path_frame(path2, (), 0.0).regular)
    assert bool(paths.path_frame(path, c, 0.7).regular)


def test_new_coefficients_do_not_recompile():
    traces = {"n": 0}

    @jax.jit
    def psi_at(c, w):
        traces["n"] += 1
        return paths.path_frame(paths.CIRCLE, c, w).psi_p

    _, c1 = paths.circle(radius=5.0)
    _, c2 = paths.circle(center=(3.0, 4.0), radius=9.0, clockwise=False)
    psi_at(c1, 1.0)
    psi_at(c2, 2.0)
    assert traces["n"] == 1


def test_float32_frames():
    path, c = paths.paper_helix()
    c32 = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32), c)
    f = paths.path_frame(path, c32, jnp.float32(3.0))
    assert f.psi_p.dtype == jnp.float32
    f64 = paths.path_frame(path, c, 3.0)
    assert float(f.dpsi_dw) == pytest.approx(float(f64.dpsi_dw), rel=1e-5)


def test_path_pose_derivatives_equal_the_frames_at_every_order():
    """path_pose's derivative rule (the Taylor tower one order up) against a second
    derivation: autodiff *through* path_frame's own autodiff (first and second order, forward
    over reverse), its central difference (third order), and path_frame's own fields; the
    coefficients' derivative against path_frame's."""
    # on a turn during the descent's curved part: every component varies
    path, c = paths.lawnmower((0.0, 0.0, 1.0), 120.0, 30.0, 4, 15.0, 150.0)
    w = 140.0

    def pose(w_, cc):
        f = paths.path_pose(path, cc, w_)
        return jnp.concatenate([f.p, jnp.stack([f.psi_p, f.theta_p, f.speed_bar])])

    def frame(w_, cc):
        f = paths.path_frame(path, cc, w_)
        return jnp.concatenate([f.p, jnp.stack([f.psi_p, f.theta_p, f.speed_bar])])

    @jax.jit
    def both(w_, cc):
        d2 = lambda fn: jax.jacfwd(jax.jacrev(fn))(w_, cc)
        dc = lambda fn: jax.jacrev(lambda c_: jax.jacfwd(fn)(w_, c_))(cc)
        d3 = jax.jacfwd(jax.jacfwd(jax.jacrev(pose)))(w_, cc)
        return (pose(w_, cc), jax.jacrev(pose)(w_, cc), d2(pose), dc(pose), d3), (
            frame(w_, cc),
            jax.jacrev(frame)(w_, cc),
            d2(frame),
            dc(frame),
        )

    got, want = both(w, c)
    np.testing.assert_array_equal(got[0], want[0])  # the same values, bit for bit
    leaves = jax.tree_util.tree_leaves
    for a, b in zip(leaves(got[1:4]), leaves(want[1:]), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-14)
    h = 1e-3
    fd3 = (both(w + h, c)[1][2] - both(w - h, c)[1][2]) / (2 * h)
    np.testing.assert_allclose(got[4], fd3, rtol=1e-5, atol=1e-9)
    assert np.any(np.abs(got[4][3:]) > 1e-6)  # a third derivative that is not trivially zero
    f = paths.path_frame(path, c, w)  # and the frame's own fields
    np.testing.assert_allclose(got[1][3:], [f.dpsi_dw, f.dtheta_dw, f.dspeed_bar_dw], rtol=1e-12)
    assert float(got[2][3]) == pytest.approx(float(f.d2psi_dw2), rel=1e-12)


def test_a_path_check_passed_once_is_not_repeated_for_the_same_values(monkeypatch):
    """``validate_path`` keeps the checks it passed (path, coefficient values, range, samples):
    a config building its path once per controller checks it once; other values, another range
    and a failing check are checked every time."""
    from vcjax import paths

    calls = []
    real = paths._check_samples
    monkeypatch.setattr(paths, "_PASSED", {})
    monkeypatch.setattr(paths, "_check_samples", lambda *a: (calls.append(a[1:]), real(*a))[1])
    for _ in range(3):
        paths.lawnmower((0.0, 0.0, 1.0), 250.0, 30.0, 4, 15.0, 150.0)
    assert len(calls) == 1
    paths.lawnmower((0.0, 0.0, 1.0), 250.0, 30.0, 4, 16.0, 150.0)  # another depth
    path, coeffs = paths.circle(radius=7.0)
    paths.validate_path(path, coeffs, (-5.0, 5.0))
    paths.validate_path(path, coeffs, (-5.0, 6.0))  # another range
    paths.validate_path(path, coeffs, (-5.0, 6.0))
    assert len(calls) == 5  # the circle checked as it was built, and on each new range
    cusp = paths.Path(paths._NoCoeffs(lambda w: jnp.stack([w**3, 2 * w**3])), "cusp")
    for _ in range(2):
        with pytest.raises(ValueError, match="vanishes"):
            paths.validate_path(cusp, (), (-1.0, 1.0))
    assert len(calls) == 7
