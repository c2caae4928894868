"""Edge cases of :mod:`vcjax.environment.waves` that the mutation run (``tools/mutation.py
waves``) found untested. Eager checks and short computations (milliseconds each)."""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad

from vcjax.environment import waves


def test_steep_share_of_a_range_in_one_quantity_only():
    # hs uniform on (1, 3) m at tp 4 s (wavelength 24.98 m): past 1/14 above hs = 1.784 m,
    # (3 - 1.784) / 2 = 61 % of the range; tp uniform on (4, 6) s at hs 3 m: 59 %
    (w,) = waves.envelope_warnings((1.0, 3.0), 4.0)
    assert "(61 % of its sea states are past 1/14)" in w
    (w,) = waves.envelope_warnings(3.0, (4.0, 6.0))
    assert "(59 % of its sea states are past 1/14)" in w


def test_steep_share_is_the_midpoint_rule_on_400_points():
    # hs uniform on (0, H) at tp 4 s, H chosen so that only the top cell of 400 (q = 0.99875,
    # not q = 0.99625) is past 1/14: 1 / 400 = 0.25 %
    h_limit = waves.peak_wavelength(4.0) * waves.LINEAR_STEEPNESS
    (w,) = waves.envelope_warnings((0.0, h_limit / 0.9975), 4.0)
    assert "(0.25 % of its sea states are past 1/14)" in w


def test_steepness_limits_are_strict():
    lam = waves.peak_wavelength(4.0)  # the quotients below are exact at tp = 4 s
    assert waves.envelope_warnings(lam * waves.LINEAR_STEEPNESS, 4.0) == []  # at 1/14: linear
    (w,) = waves.envelope_warnings(lam * waves.BREAKING_STEEPNESS, 4.0)  # at 1/7: not breaking
    assert "past the 1/14 limit" in w and "steeper than breaking" not in w


def test_small_and_short_seas_are_checked_too():
    # no threshold of 1 m or 1 s: a 0.1 m sea of 0.9 s is as steep as it looks
    assert "past the 1/14 limit" in waves.envelope_warnings(0.1, 0.9)[0]
    assert "steeper than breaking" in waves.envelope_warnings(0.9, 2.0)[0]
    (w,) = waves.envelope_warnings(1.0, 10.0, origin_depth=0.2)  # hs / 2 = 0.5 m > 0.2 m
    assert w.startswith("waves: origin_depth 0.2 m is less than hs / 2 = 0.5 m")


def test_steep_share_only_for_ranges_that_are_ranges():
    # a range of zero width is one sea state: no share; a width of 1 (m or s) is a range
    (w,) = waves.envelope_warnings((3.0, 3.0), (4.0, 4.0))
    assert "sea states" not in w and w.startswith("waves: hs 3 m with tp 4 s")
    assert "of its sea states are past 1/14" in waves.envelope_warnings((2.0, 3.0), 4.0)[0]
    assert "of its sea states are past 1/14" in waves.envelope_warnings(3.0, (4.0, 5.0))[0]


def _normalisation_by_quad(gamma):
    """I(gamma) = int_0^inf 1.25 exp(-1.25 u) gamma^r(u^(-1/4)) du by adaptive quadrature,
    split at the kink u = 1 and where the peak enhancement varies (independent of the module's
    fixed Gauss-Legendre panels)."""

    def f(u):
        x = u**-0.25
        s = 0.07 if x <= 1.0 else 0.09
        return 1.25 * math.exp(
            -1.25 * u + math.exp(-((x - 1.0) ** 2) / (2 * s * s)) * math.log(gamma)
        )

    edges = [1e-300, 0.3, 0.5, 0.7, 0.85, 1.0, 1.15, 1.3, 1.5, 2.0, 3.0, 6.0, 10.0, 20.0, 60.0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # quad's round-off note at 1e-14
        return sum(
            quad(f, a, b, epsabs=1e-16, epsrel=1e-14, limit=200)[0]
            for a, b in zip(edges[:-1], edges[1:], strict=True)
        )


@pytest.mark.parametrize("gamma", [3.3, 7.0, 20.0])
def test_jonswap_normalisation_to_quadrature_accuracy(gamma):
    # the panels' rule agrees with adaptive quadrature to ~2e-14: a moved panel edge near the
    # peak (1e-12 .. 1e-9) shows
    assert float(waves.jonswap_normalisation(gamma)) == pytest.approx(
        _normalisation_by_quad(gamma), rel=5e-13
    )


def test_a_whole_range_past_linear_theory_reads_as_100_percent():
    # every sea state of hs 10-12 m, tp 4-5 s is past 1/14: "100 %", never "1e+02 %"
    (w,) = waves.envelope_warnings((10.0, 12.0), (4.0, 5.0))
    assert "(100 % of its sea states are past 1/14)" in w, w


def test_pierson_moskowitz_is_exactly_zero_at_and_below_its_cut_with_zero_gradient():
    # "0 and negative give 0": below 0.05 omega_p the spectrum is 0 (not the formula's value at a
    # negative frequency, not NaN at 0), and so is its derivative (the cut's branch is NaN-free)
    omega = jnp.array([-3.0, -0.5, 0.0, 0.01])  # omega_p = 0.785 rad/s at tp 8 s
    assert np.array_equal(waves.pierson_moskowitz(omega, 2.0, 8.0), np.zeros(4))
    grad = jax.grad(lambda w: jnp.sum(waves.pierson_moskowitz(w, 2.0, 8.0)))(omega)
    assert np.array_equal(grad, np.zeros(4))
    omega = jnp.array([-0.5, 0.0, 0.8])  # and the derivative in tp is finite there too
    d_tp = jax.grad(lambda tp: jnp.sum(waves.pierson_moskowitz(omega, 2.0, tp)))(8.0)
    assert np.isfinite(d_tp) and d_tp != 0.0


def test_defaults_of_the_spectrum_and_the_sea_are_the_documented_ones():
    omega = jnp.linspace(0.3, 2.0, 7)
    assert np.array_equal(waves.jonswap(omega, 2.0, 8.0), waves.jonswap(omega, 2.0, 8.0, 3.3))
    key = jax.random.key(3)
    shape = jax.eval_shape(lambda k: waves.sea_state(k, 2.0, 8.0, 0.4), key).omega.shape
    assert shape == (64,)
    sea = waves.sea_state(key, hs=2.0, tp=8.0, direction=0.4, components=4)  # keywords: a contract
    assert np.array_equal(sea.direction, np.full(4, 0.4))  # spreading 0: long-crested
    same = waves.sea_state(key, 2.0, 8.0, 0.4, spectrum="jonswap", gamma=3.3, components=4)
    assert all(np.array_equal(x, y) for x, y in zip(sea, same, strict=True))
    with pytest.raises(TypeError):  # the options are keyword-only
        waves.sea_state(key, 2.0, 8.0, 0.4, "pm")


def test_calm_sea_is_one_component_on_the_dispersion_relation():
    sea = waves.calm_sea()
    assert sea.omega.shape == (1,)
    assert np.array_equal(sea.wavenumber, sea.omega**2 / waves.GRAVITY)
    # deep below, e^{-k d} of a wrong (negative) k would overflow: exactly zero water motion
    v, a = waves.water_kinematics(sea, 0.0, jnp.array([0.0, 0.0, 500.0]))
    assert np.array_equal(v, np.zeros(3)) and np.array_equal(a, np.zeros(3))


def test_one_component_and_gamma_one_are_accepted_and_gamma_below_one_is_not():
    key = jax.random.key(0)
    assert waves.sea_state(key, 1.0, 8.0, 0.0, components=1).omega.shape == (1,)
    for gamma in (1.0, 1.5):  # 1: Pierson-Moskowitz
        waves.sea_state(key, 1.0, 8.0, 0.0, gamma=gamma, components=4)
    for spectrum in ("jonswap", "pm"):  # refused whatever the spectrum
        with pytest.raises(ValueError, match="^gamma"):
            waves.sea_state(key, 1.0, 8.0, 0.0, spectrum=spectrum, gamma=0.5, components=4)


def test_a_concrete_positive_spreading_draws_directions():
    # decided in Python: spreading 0 broadcasts the mean direction, a positive one draws
    # (traced only: the two programs differ)
    draw = lambda s: jax.make_jaxpr(
        lambda key: waves.sea_state(key, 1.0, 8.0, 0.3, spreading=s, components=4)
    )(jax.random.key(0))
    assert str(draw(0.0)) != str(draw(2.5))


def test_an_integer_array_hs_gives_a_float_sea():
    sea = waves.sea_state(jax.random.key(0), jnp.asarray(2), 8.0, 0.0, components=4)
    assert all(jnp.issubdtype(x.dtype, jnp.floating) for x in sea)


@pytest.mark.slow  # 3-7 s: compiles jax.random.beta's sampler (no default test draws spreading)
def test_spread_directions_follow_cos_2s_and_the_documented_draw():
    # sin(beta - beta_0) = 2 B - 1, B ~ Beta(s + 1/2, s + 1/2): mean 0, mean square 1 / (2 s + 2)
    # (1/7 at s = 2.5; standard errors 0.006 and 0.003 with 4096 draws)
    key, s, beta0 = jax.random.key(1), 2.5, 0.3
    sea = waves.sea_state(key, 1.0, 8.0, beta0, spreading=s, components=4096)
    x = np.sin(np.asarray(sea.direction) - beta0)
    assert abs(x.mean()) < 0.03 and x.mean() ** 2 < 1e-3
    assert np.mean(x**2) == pytest.approx(1 / (2 * s + 2), abs=0.012)
    # the directions are the module docstring's draw from the key's third split
    s_ = jnp.asarray(s, dtype=sea.omega.dtype)  # as sea_state passes it: one compiled sampler
    b = jax.random.beta(jax.random.split(key, 3)[2], s_ + 0.5, s_ + 0.5, (4096,), s_.dtype)
    assert np.allclose(sea.direction, beta0 + np.arcsin(2 * np.asarray(b) - 1), atol=1e-12)


def test_phases_are_drawn_on_a_whole_turn():
    # uniform on [0, 2 pi): of 256 draws the largest is within 0.8 rad of 2 pi (a shorter or
    # longer interval shows at once)
    phase = np.asarray(waves.sea_state(jax.random.key(2), 1.0, 8.0, 0.0, components=256).phase)
    assert phase.min() >= 0.0 and 2 * math.pi - 0.8 < phase.max() < 2 * math.pi


@pytest.mark.parametrize("dtype, tol", [(jnp.float64, 2e-15), (jnp.float32, 8e-7)])
def test_the_kinematics_sin_and_cos_have_the_documented_accuracy(dtype, tol):
    # one unit component at the origin: theta = -t exactly, so the elevation is cos(t) and the
    # down velocity at the surface sin(t), as the shared reduction and polynomials give them
    # (module docstring of _sincos: 1e-15 absolute in float64, 6e-7 in float32; measured 1.0e-15
    # and 5.7e-7 on [-10, 10])
    one, zero = jnp.ones(1, dtype), jnp.zeros(1, dtype)
    sea = waves.Sea(one, one, one / waves.GRAVITY, zero, zero)
    t = jnp.linspace(-10.0, 10.0, 2001, dtype=dtype)
    p = jnp.zeros(3, dtype)
    zeta, u = jax.jit(
        jax.vmap(lambda t: (waves.elevation(sea, t, p[0], p[1]), waves.orbital_velocity(sea, t, p)))
    )(t)
    t64 = np.asarray(t, np.float64)
    np.testing.assert_allclose(zeta, np.cos(t64), rtol=0, atol=tol)
    np.testing.assert_allclose(u[:, 2], np.sin(t64), rtol=0, atol=tol)


def test_just_below_the_surface_the_kinematics_are_attenuated_and_have_depth_columns():
    # 0.5 m down is below the mean surface: e^{-k d} applies and the d/d(depth) column is live
    one, zero = jnp.ones(1), jnp.zeros(1)
    k = 1.0 / waves.GRAVITY
    sea = waves.Sea(one, one, one * k, zero, zero)  # theta = -t at north = east = 0
    p = jnp.array([0.0, 0.0, 0.5])
    u = waves.orbital_velocity(sea, 0.0, p)
    np.testing.assert_allclose(u, [math.exp(-0.5 * k), 0.0, 0.0], atol=1e-15)
    grad = waves.orbital_velocity_gradient(sea, 0.0, p)
    np.testing.assert_allclose(grad[0, 2], -k * math.exp(-0.5 * k), rtol=1e-14)


@pytest.mark.parametrize("shape", [(4,), (3, 1)])
def test_a_current_that_is_not_3_is_refused(shape):
    sea, p = waves.calm_sea(), jnp.zeros(3)
    with pytest.raises(ValueError, match="^current: expected a"):
        waves.water_kinematics(sea, 0.0, p, jnp.zeros(shape))
    with pytest.raises(ValueError, match="^current_dot: expected a"):
        waves.water_kinematics(sea, 0.0, p, jnp.zeros(3), jnp.zeros(shape))
