"""Waves (vcjax.environment.waves) against independent physics: quadrature of the spectra, the statistics of
long realisations, the Airy potential differentiated by autodiff, the free-surface boundary
condition, finite differences, and a body that must move with the water particles.

Compile time is most of this module's cost (XLA:CPU), so the tests share a few jitted programs
(module level, cached per static configuration) instead of tracing their own: one draw per
(spectrum, components, spread or not, batched or not), one "everything at a point" kinematics
program and one record program per (components, dtype), one body integrator. Short test seas
have 16 components; a regular wave is padded to 16 with zero-amplitude components (which add
exact zeros). The integrators run RK4's four stages as a scan (one copy of the vector field in
the graph; the same arithmetic as the unrolled method). A spread draw compiles
``jax.random.beta`` (~1.5 s of XLA:CPU), so only two programs draw spread seas.
"""

import functools
import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, optimize

from vcjax.environment import WaterMotion, waves
from vcjax.vehicles import remus100, sixdof

G = 9.81
N = 64  # components of every test sea (one shape: one program per function)
SEAS = 1024  # seas of a batch (one batch size: one program per draw configuration)
KEYS = {seed: jax.random.split(jax.random.key(seed), SEAS) for seed in (0, 1, 30, 31)}


# --------------------------------------------------------------------------------------------
# Shared programs
# --------------------------------------------------------------------------------------------


@functools.cache
def _draw_program(spectrum, components, spread, batched):
    def draw(key, hs, tp, beta, gamma, spreading):
        return waves.sea_state(key, hs, tp, beta, spectrum=spectrum, gamma=gamma,
                               spreading=spreading if spread else 0.0, components=components)  # fmt: skip

    return jax.jit(jax.vmap(draw) if batched else draw)


def _draw(key, hs, tp, beta, *, spectrum="jonswap", gamma=3.3, spreading=0.0, components=N):
    """``waves.sea_state`` through one shared jitted program per static configuration."""
    f = _draw_program(spectrum, components, spreading != 0.0, False)
    # Python floats (one weakly typed float64 signature whatever the caller passed)
    args = [x if isinstance(x, jax.Array) else float(x) for x in (hs, tp, beta, gamma, spreading)]
    return f(key, *args)


def _draws(keys, hs, tp, beta, *, spectrum="jonswap", gamma=3.3, spreading=0.0, components=N):
    """``jax.vmap(waves.sea_state)`` over keys (and parameters), one shared program."""
    n = keys.shape[0]
    full = lambda x: jnp.broadcast_to(jnp.asarray(x, dtype=jnp.float64), (n,))
    f = _draw_program(spectrum, components, bool(np.any(np.asarray(spreading) != 0)), True)
    return f(keys, *(full(x) for x in (hs, tp, beta, gamma, spreading)))


def _field_fn(sea, t, p, current, current_dot):
    zeta = lambda t: waves.elevation(sea, t, p[0], p[1])
    return dict(
        zeta=zeta(t),
        dzeta_dt=jax.jvp(zeta, (t,), (jnp.ones_like(t),))[1],
        u=waves.orbital_velocity(sea, t, p),
        du_dt=waves.orbital_acceleration(sea, t, p),
        grad=waves.orbital_velocity_gradient(sea, t, p),
        water=waves.water_kinematics(sea, t, p, current, current_dot),
    )


_field_jit = jax.jit(_field_fn)


def _field(sea, t, p, current=None, current_dot=None):
    """Every kinematic function of the module at one ``(t, p)`` (one program per sea shape)."""
    dtype = sea.omega.dtype
    z = jnp.zeros(3, dtype=dtype)
    cur = lambda c: z if c is None else jnp.asarray(c, dtype=dtype)
    t = jnp.asarray(t, dtype=dtype)
    return _field_jit(sea, t, jnp.asarray(p, dtype=dtype), cur(current), cur(current_dot))


@partial(jax.jit, static_argnames="what")
def _record(sea, t, p, what):
    """Elevation at ``p[:2]`` (``what="zeta"``) or orbital velocity at ``p`` (``"u"``) over the
    times ``t``."""
    if what == "zeta":
        return jax.vmap(lambda ti: waves.elevation(sea, ti, p[0], p[1]))(t)
    return jax.vmap(lambda ti: waves.orbital_velocity(sea, ti, p))(t)


def _regular(a=1.5, omega=0.8, phase=0.4, beta=0.9, components=N):
    """A regular wave, padded with zero-amplitude components (they add exact zeros)."""
    pad = lambda x, fill: jnp.concatenate([jnp.array([x]), jnp.full(components - 1, fill)])
    return waves.Sea(pad(omega, 1.0), pad(a, 0.0), pad(omega**2 / G, 1.0 / G), pad(phase, 0.0),
                     pad(beta, 0.0))  # fmt: skip


def _rk4(f, t, y, dt):
    """Classical RK4, its four stages ``k_i = f(t + c_i dt, y + c_i dt k_{i-1})`` as a scan."""
    add = lambda y, k, h: jax.tree.map(lambda a, b: a + h * b, y, k)
    c = jnp.array([0.0, 0.5, 0.5, 1.0], dtype=jnp.float64)
    w = jnp.array([1.0, 2.0, 2.0, 1.0], dtype=jnp.float64) / 6.0

    def stage(carry, cw):
        k, acc = carry
        ci, wi = cw
        k = f(t + ci * dt, add(y, k, ci * dt))
        return (k, add(acc, k, wi)), None

    zero = jax.tree.map(jnp.zeros_like, y)
    (_, acc), _ = jax.lax.scan(stage, (zero, zero), (c, w))
    return add(y, acc, dt)


_spectrum_jit = {
    "pm": jax.jit(lambda w, hs, tp, gamma: waves.pierson_moskowitz(w, hs, tp)),
    "jonswap": jax.jit(waves.jonswap),
}


def _np_spectrum(spectrum, hs, tp, gamma=3.3):
    """The spectrum as a numpy function of a scalar omega (for scipy's quadrature)."""
    f = _spectrum_jit[spectrum]
    return lambda w: float(f(float(w), hs, tp, gamma))


def _quad(f, lo, hi, peak):
    # split at the peak (the JONSWAP width changes there) for scipy's adaptive rule
    return sum(integrate.quad(f, a, b, limit=400, epsabs=0, epsrel=1e-11)[0] for a, b in
               ((lo, peak), (peak, hi)))  # fmt: skip


# --------------------------------------------------------------------------------------------
# Spectra
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "spectrum, gamma", [("pm", 1.0), ("jonswap", 1.0), ("jonswap", 3.3), ("jonswap", 7.0)]
)
def test_spectrum_zeroth_moment_and_peak(spectrum, gamma):
    hs, tp = 2.5, 9.0
    wp = 2 * math.pi / tp
    f = _np_spectrum(spectrum, hs, tp, gamma)
    m0 = _quad(f, 0.05 * wp, 200 * wp, wp) + 5 / 16 * hs**2 / 4 / 200**4  # + analytic PM tail
    assert m0 == pytest.approx(hs**2 / 16, rel=1e-8)
    res = optimize.minimize_scalar(lambda w: -f(w), bounds=(0.5 * wp, 2 * wp), method="bounded",
                                   options={"xatol": 1e-10})  # fmt: skip
    assert res.x == pytest.approx(wp, rel=1e-5)


def test_jonswap_with_gamma_one_is_pierson_moskowitz_and_dnv_factor_is_close():
    w = np.linspace(0.1, 3.0, 50)
    pm = np.array([_np_spectrum("pm", 3.0, 8.0)(x) for x in w])
    np.testing.assert_allclose([_np_spectrum("jonswap", 3.0, 8.0, 1.0)(x) for x in w], pm,
                               rtol=1e-12)  # fmt: skip
    # the closed-form PM (Hs, Tp) spectrum written out independently
    wp = 2 * np.pi / 8.0
    ref = 5 / 16 * 9.0 * wp**4 * w**-5 * np.exp(-1.25 * (wp / w) ** 4)
    np.testing.assert_allclose(pm, ref, rtol=1e-12, atol=1e-300)
    # the exact normalisation agrees with DNV's 1 - 0.287 ln(gamma) to its stated accuracy;
    # S_J / S_PM at omega_p is gamma / I(gamma)
    i33 = 3.3 * _np_spectrum("pm", 1.0, 8.0)(wp) / _np_spectrum("jonswap", 1.0, 8.0, 3.3)(wp)
    assert 1 / i33 == pytest.approx(1 - 0.287 * np.log(3.3), rel=5e-3)
    # differentiable in gamma: d S / d gamma against central differences
    f = lambda g: _spectrum_jit["jonswap"](0.7, 2.0, 9.0, g)
    g0, h = 3.3, 1e-5
    fd = (f(g0 + h) - f(g0 - h)) / (2 * h)
    grad = jax.jit(jax.grad(lambda g: waves.jonswap(0.7, 2.0, 9.0, g)))(g0)
    assert float(grad) == pytest.approx(float(fd), rel=1e-7)


# --------------------------------------------------------------------------------------------
# Realisations
# --------------------------------------------------------------------------------------------


def _record_sigma(s_of_w, lo, hi, duration):
    """Standard deviation of a record's variance estimate for a Gaussian process with one-sided
    spectrum ``s_of_w`` observed for ``duration``: ``var(m0_hat) = 2 pi / T int S^2 d omega``."""
    return math.sqrt(2 * np.pi / duration * integrate.quad(lambda w: s_of_w(w) ** 2, lo, hi,
                                                           limit=400)[0])  # fmt: skip


def _bins_sigma(s_of_w, lo, hi, n):
    """Standard deviation of ``sum_i S(omega_i) d_omega`` with ``omega_i`` uniform in bin ``i``
    (the draw-to-draw scatter of a realised sea's variance), by quadrature."""
    d_omega, var = (hi - lo) / n, 0.0
    for i in range(n):
        a, b = lo + i * d_omega, lo + (i + 1) * d_omega
        m1 = integrate.quad(s_of_w, a, b)[0] / d_omega
        m2 = integrate.quad(lambda w: s_of_w(w) ** 2, a, b)[0] / d_omega
        var += d_omega**2 * max(m2 - m1 * m1, 0.0)
    return math.sqrt(var)


def _band(tp):
    wp = 2 * np.pi / tp
    return waves.BAND[0] * wp, waves.BAND[1] * wp, wp


DURATION, DT = 20 * 3600.0, 0.5  # the long records: 20 h at 2 Hz


def test_long_realisation_has_the_significant_wave_height():
    hs, tp, beta, n = 2.0, 8.0, 0.4, 64
    seas = _draws(KEYS[30], hs, tp, beta, components=n)
    sea = jax.tree.map(lambda x: x[0], seas)
    zeta = _record(sea, jnp.arange(0.0, DURATION, DT), jnp.array([10.0, -4.0, 0.0]), "zeta")
    m0_hat = float(np.var(np.asarray(zeta)))
    m0_sea = float(np.sum(np.asarray(sea.amplitude) ** 2) / 2)  # this realisation's own variance

    lo, hi, wp = _band(tp)
    f = _np_spectrum("jonswap", hs, tp)
    m0_band = integrate.quad(f, lo, hi, limit=400, points=[wp])[0]
    # the band holds > 99.5 % of m0 (module docstring)
    assert m0_band / (hs**2 / 16) == pytest.approx(1.0, abs=0.005)
    # (a) the 20 h record's variance is the sea's: 4 sigma (a false alarm once in ~16 000
    # records), sigma / m0 = 1.3 % for this record length
    sig_rec = _record_sigma(f, lo, hi, DURATION)
    assert abs(m0_hat - m0_sea) < 4 * sig_rec, (m0_hat, m0_sea, sig_rec)
    # (b) a sea's variance scatters about the band's integral by the random frequencies
    # within bins (3.1 % of m0 for 64 components, i.e. 1.5 % in Hs); over 1024 seas the mean is
    # the integral (unbiased draws) within 4 sigma / sqrt(1024) = 0.4 %
    sig_bins = _bins_sigma(f, lo, hi, n)
    assert abs(m0_sea - m0_band) < 4 * sig_bins
    m0_seas = np.sum(np.asarray(seas.amplitude) ** 2, axis=1) / 2
    assert abs(m0_seas.mean() - m0_band) < 4 * sig_bins / math.sqrt(SEAS)
    assert np.std(m0_seas) == pytest.approx(sig_bins, rel=0.2)  # 1024 samples: std within ~4 %
    # so 4 std(zeta) is Hs: within 4 sqrt(sig_rec^2 + sig_bins^2) / 2 / m0 + 0.25 % = 7 %
    assert 4 * math.sqrt(m0_hat) == pytest.approx(hs, rel=0.07)


def test_orbital_velocity_variance_at_depth():
    hs, tp, beta, n, depth = 3.0, 10.0, 2.2, 64, 8.0
    seas = _draws(KEYS[31], hs, tp, beta, spectrum="pm", components=n)  # fmt: skip
    sea = jax.tree.map(lambda x: x[0], seas)
    u = np.asarray(_record(sea, jnp.arange(0.0, DURATION, DT), jnp.array([3.0, 1.0, depth]), "u"))
    along = u[:, 0] * np.cos(beta) + u[:, 1] * np.sin(beta)
    across = -u[:, 0] * np.sin(beta) + u[:, 1] * np.cos(beta)
    np.testing.assert_allclose(across, 0.0, atol=1e-13)  # long-crested: no cross velocity

    lo, hi, wp = _band(tp)
    s_pm = _np_spectrum("pm", hs, tp)
    s_u = lambda w: s_pm(w) * w**2 * np.exp(-2 * w**2 / G * depth)
    ref = integrate.quad(s_u, lo, hi, limit=400)[0]
    # the full-line integral: the band's cut-off loses < 0.01 % of the velocity variance at 8 m
    assert integrate.quad(s_u, 0.3 * wp, 20 * wp, limit=400)[0] == pytest.approx(ref, rel=1e-4)
    a, w, k = (np.asarray(x) for x in (seas.amplitude, seas.omega, seas.wavenumber))
    var_seas = np.sum((a * w) ** 2 * np.exp(-2 * k * depth), axis=1) / 2
    var_sea = float(var_seas[0])
    sig_rec = _record_sigma(s_u, lo, hi, DURATION)
    for comp in (along, u[:, 2]):  # horizontal and vertical variances are equal in deep water
        assert abs(float(np.var(comp)) - var_sea) < 4 * sig_rec, (np.var(comp), var_sea)
    sig_bins = _bins_sigma(s_u, lo, hi, n)
    assert abs(var_sea - ref) < 4 * sig_bins
    assert abs(float(np.mean(var_seas)) - ref) < 4 * sig_bins / math.sqrt(SEAS)


def test_spread_directions_have_the_cos2s_moments():
    """The default run's check of spreading (the draw program of the tests below, 16 seas of 64
    components): ``sin(beta - beta_0) = 2 B - 1``, ``B ~ Beta(s + 1/2, s + 1/2)``, has mean 0 and
    mean square ``1 / (2 s + 2)``; standard errors 0.013 and 0.006 with 1024 draws."""
    s, beta0 = 2.0, 0.3
    dev = np.concatenate([
        np.asarray(_draw(key, 2.0, 7.0, beta0, spreading=s).direction) - beta0
        for key in jax.random.split(jax.random.key(4), 16)
    ])  # fmt: skip
    x = np.sin(dev)
    assert np.all(np.abs(dev) <= np.pi / 2)
    assert abs(np.mean(x)) < 0.05
    assert abs(np.mean(x**2) - 1 / (2 * s + 2)) < 0.024


@pytest.mark.slow  # 7 s
def test_spreading_draws_cos2s_directions_and_draws_are_the_same_in_and_out_of_vmap():
    """The spread directions follow cos^2s (65 536 draws), and every draw of a batch is the draw
    of its key alone (``vmap`` inside ``jit`` against the unbatched jitted draw)."""
    s, beta0, n_seas, keys = 4.0, 1.0, SEAS, KEYS[1]
    sea = _draws(keys, 1.0, 8.0, beta0, spreading=s)
    dev = np.asarray(sea.direction).ravel() - beta0
    n = dev.size
    assert np.all(np.abs(dev) <= np.pi / 2)
    dens = lambda x: np.cos(x) ** (2 * s)
    norm = integrate.quad(dens, -np.pi / 2, np.pi / 2)[0]
    for fn in (np.cos, lambda x: x**2):
        mean = integrate.quad(lambda x, f=fn: f(x) * dens(x), -np.pi / 2, np.pi / 2)[0] / norm
        var = integrate.quad(lambda x, f=fn: f(x) ** 2 * dens(x), -np.pi / 2, np.pi / 2)[0] / norm
        assert abs(np.mean(fn(dev)) - mean) < 4 * math.sqrt((var - mean**2) / n)
    # the mean direction is beta0 (odd moment zero) and spreading leaves frequencies/phases alone
    assert abs(np.mean(dev)) < 4 * math.sqrt(np.var(dev) / n)
    sea0 = _draws(keys, 1.0, 8.0, beta0)  # (the long-crested program of the tests above)
    np.testing.assert_array_equal(sea.omega, sea0.omega)
    np.testing.assert_array_equal(sea.phase, sea0.phase)
    np.testing.assert_array_equal(sea0.direction, beta0)

    # one sea per scenario: parameters differ per key (hs = 0 included)
    rng = np.random.default_rng(11)
    hs = rng.uniform(0.0, 3.0, n_seas)
    hs[3] = 0.0
    tp, beta, spread = (rng.uniform(4.0, 14.0, n_seas), rng.uniform(-3.0, 3.0, n_seas),
                        rng.uniform(0.5, 6.0, n_seas))  # fmt: skip
    # (long-crested draws share everything but the directions: asserted above)
    batched = _draws(keys, hs, tp, beta, spreading=spread)
    for i in (0, 3, 7, n_seas - 1):
        one = _draw(keys[i], float(hs[i]), float(tp[i]), float(beta[i]), spreading=spread[i])
        for a, b in zip(one, batched, strict=True):
            np.testing.assert_allclose(b[i], a, rtol=1e-14)
    np.testing.assert_array_equal(batched.amplitude[3], 0.0)
    # and the kinematics vmap over seas (one sea per scenario)
    p = jnp.array([1.0, 2.0, 3.0])
    vb = jax.jit(jax.vmap(lambda s: waves.orbital_velocity(s, 2.0, p)))(batched)
    for i in (0, 7):
        sea_i = jax.tree.map(lambda x, i=i: x[i], batched)
        np.testing.assert_allclose(vb[i], _field(sea_i, 2.0, p)["u"], rtol=1e-13)


@pytest.mark.slow
@pytest.mark.parametrize("spreading", [0.0, 2.5])
def test_draws_are_the_same_out_of_jit(spreading):
    """Eager (op-by-op) draws against the jitted unbatched and batched programs (slow: eager
    dispatch compiles ~60 small kernels and the beta sampler once more)."""
    keys = KEYS[1]
    hs, tp, beta = np.array([0.5, 1.0, 2.0, 0.0]), np.array([5.0, 7.0, 12.0, 9.0]), np.arange(4.0)
    full = lambda x: np.resize(x, SEAS)
    batched = _draws(keys, full(hs), full(tp), full(beta), spreading=spreading)
    for i in range(4):
        args = (keys[i], float(hs[i]), float(tp[i]), float(beta[i]))
        one = waves.sea_state(*args, spreading=spreading, components=N)
        for a, b, c in zip(one, _draw(*args, spreading=spreading), batched, strict=True):
            np.testing.assert_allclose(b, a, rtol=1e-14)
            np.testing.assert_allclose(c[i], a, rtol=1e-14)


# --------------------------------------------------------------------------------------------
# Regular waves: closed-form Airy kinematics and signs
# --------------------------------------------------------------------------------------------


def test_regular_wave_against_the_airy_potential():
    a, w, phi, beta = 1.5, 0.8, 0.4, 0.9
    sea = _regular(a, w, phi, beta)
    k = w**2 / G
    g_a_w = G * a / w

    def potential(t, n, e, z_up):  # deep-water Airy potential, z up
        return g_a_w * jnp.exp(k * z_up) * jnp.sin(k * (n * np.cos(beta) + e * np.sin(beta))
                                                    - w * t + phi)  # fmt: skip

    grads = jax.jit(jax.grad(potential, argnums=(0, 1, 2, 3)))
    for t, n, e, d in [(0.3, 1.0, -2.0, 0.0), (7.1, 30.0, 4.0, 5.0), (-3.0, -8.0, 11.0, 25.0)]:
        _, vn, ve, vup = grads(t, n, e, -d)
        ref = jnp.stack([vn, ve, -vup])  # NED: down = -up
        fld = _field(sea, t, [n, e, d])
        np.testing.assert_allclose(fld["u"], ref, rtol=1e-12, atol=1e-14)
        # linearised Bernoulli at the surface: g zeta = -dPhi/dt
        zeta_ref = -grads(t, n, e, 0.0)[0] / G
        assert float(_field(sea, t, [n, e, 0.0])["zeta"]) == pytest.approx(float(zeta_ref),
                                                                            rel=1e-12)  # fmt: skip


def test_regular_wave_signs_and_free_surface_condition():
    a, w, phi, beta = 0.8, 1.1, 0.0, 0.6
    sea = _regular(a, w, phi, beta)
    k, depth = w**2 / G, 4.0
    h = np.array([np.cos(beta), np.sin(beta)])
    speed = a * w * np.exp(-k * depth)
    # a crest at the origin at t = 0 (theta = 0)
    fld = _field(sea, 0.0, [0.0, 0.0, depth])
    assert float(fld["zeta"]) == pytest.approx(a)
    np.testing.assert_allclose(fld["u"][:2], speed * h, rtol=1e-12)  # along the direction of travel
    assert abs(float(fld["u"][2])) < 1e-15
    # under the crest the water accelerates downwards (positive down)
    assert float(fld["du_dt"][2]) == pytest.approx(a * w**2 * np.exp(-k * depth), rel=1e-12)
    # a quarter wavelength ahead of the crest the surface is rising: the water moves up (w < 0)
    ahead = (np.pi / 2 / k) * h
    fld = _field(sea, 0.0, [ahead[0], ahead[1], depth])
    assert float(fld["u"][2]) == pytest.approx(-speed, rel=1e-12)
    assert float(fld["dzeta_dt"]) > 0
    # kinematic free-surface condition d zeta / dt = -u_down(depth = 0) (holds only if k = w^2/g)
    for t, n, e in [(0.0, 0.0, 0.0), (1.3, 5.0, 2.0), (4.0, -7.0, 9.0)]:
        fld = _field(sea, t, [n, e, 0.0])
        assert float(fld["dzeta_dt"]) == pytest.approx(-float(fld["u"][2]), rel=1e-12, abs=1e-14)
    # the wave travels towards beta: a crest moves by c t along h (phase speed w / k)
    t1 = 2.0
    crest = (w / k) * t1 * h
    assert float(_field(sea, t1, [crest[0], crest[1], 0.0])["zeta"]) == pytest.approx(a)


def test_above_the_mean_surface_the_kinematics_are_those_at_the_surface():
    sea = _draw(jax.random.key(2), 2.0, 7.0, 0.0, spreading=2.0)
    top, above = _field(sea, 1.0, [1.0, 2.0, 0.0]), _field(sea, 1.0, [1.0, 2.0, -0.5])
    for key in ("u", "du_dt", "water"):
        for x, y in zip(jax.tree.leaves(above[key]), jax.tree.leaves(top[key]), strict=True):
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("dtype, tol", [(jnp.float64, 1e-12), (jnp.float32, 2e-5)])
def test_phases_far_from_zero_are_accurate(dtype, tol):
    """The kinematics' shared sin/cos reduction holds over long runs (phases of thousands of
    rad): a regular wave's elevation and velocity against numpy's cos/sin in float64."""
    a, w, phi, beta, k = 1.0, 1.3, 0.2, 0.4, 1.3**2 / G
    sea = jax.tree.map(lambda x: x.astype(dtype), _regular(a, w, phi, beta))
    t = np.concatenate([np.linspace(0.0, 20.0, 401), np.linspace(3000.0, 3020.0, 401)])
    if dtype == jnp.float32:
        t = t[:401]  # float32 cannot represent phases of 4000 rad to better than 2.4e-4
    n, e, d = 3.0, -2.0, 1.5
    theta = k * (n * np.cos(beta) + e * np.sin(beta)) - w * t + phi
    t, p = jnp.asarray(t, dtype), jnp.array([n, e, d], dtype=dtype)
    zeta, u = _record(sea, t, p, "zeta"), _record(sea, t, p, "u")
    np.testing.assert_allclose(zeta, a * np.cos(theta), atol=tol)
    ref_w = -a * w * np.exp(-k * d) * np.sin(theta)
    np.testing.assert_allclose(u[:, 2], ref_w, atol=tol * a * w)


# --------------------------------------------------------------------------------------------
# Derivatives
# --------------------------------------------------------------------------------------------


@jax.jit
def _derivatives(sea, t, p, current):
    vel = lambda t: waves.orbital_velocity(sea, t, p)
    h = 1e-5
    v0, _ = waves.water_kinematics(sea, t, p, current)
    line = lambda s: waves.orbital_velocity(sea, t + s, p + v0 * s) + current
    one = jnp.ones_like(t)
    return dict(
        fd=(vel(t + h) - vel(t - h)) / (2 * h),
        jvp=jax.jvp(vel, (t,), (one,))[1],
        jacfwd=jax.jacfwd(lambda q: waves.orbital_velocity(sea, t, q))(p),
        line=line(0.0 * t),
        line_dot=jax.jvp(line, (0.0 * t,), (one,))[1],
    )


def test_acceleration_and_gradient_are_the_derivatives_of_the_velocity():
    sea = _draw(jax.random.key(5), 2.5, 9.0, 1.2, spreading=3.0)
    current = jnp.array([0.3, -0.2, 0.05])
    for t, p in [(2.0, jnp.array([4.0, -3.0, 6.0])), (13.0, jnp.array([-20.0, 7.0, 1.5]))]:
        fld, ref = _field(sea, t, p, current), _derivatives(sea, jnp.asarray(t), p, current)
        acc, gp = fld["du_dt"], fld["grad"]
        np.testing.assert_allclose(acc, ref["fd"], rtol=1e-7, atol=1e-10)
        np.testing.assert_allclose(acc, ref["jvp"], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(gp, ref["jacfwd"], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(gp, gp.T, atol=1e-14)  # irrotational
        assert abs(float(np.trace(gp))) < 1e-14  # incompressible
        # water_kinematics: the particle's acceleration d/dt v(t, p + v0 (t - t0)) at t0
        v0, a0 = fld["water"]
        np.testing.assert_allclose(v0, ref["line"], rtol=1e-14)
        np.testing.assert_allclose(a0, ref["line_dot"], rtol=1e-12, atol=1e-14)


@partial(jax.jit, static_argnames="forward")
def _final_position_and_derivatives(key, theta, tangent, h, forward):
    """d/d(hs, tp, direction, gamma) of where a water particle ends up after 15 s in a drawn
    sea: reverse mode, central differences and (``forward``) forward mode, in one program."""
    dt, steps = 0.25, 60

    def final(theta):
        hs, tp, beta, gamma = theta
        sea = waves.sea_state(key, hs, tp, beta, gamma=gamma, spreading=0.0, components=8)

        def field(t, y):
            return waves.water_kinematics(sea, t, y, jnp.array([0.3, 0.0, 0.0]))[0]

        def step(x, k):
            return _rk4(field, k * dt, x, dt), None

        x, _ = jax.lax.scan(step, jnp.array([0.0, 0.0, 2.0]), jnp.arange(steps, dtype=jnp.float64))
        return x @ jnp.array([0.3, -0.5, 1.0])

    steps_h = jnp.concatenate([jnp.eye(4), -jnp.eye(4)]) * h
    f = jax.vmap(final)(theta + steps_h)
    fd = (f[:4] - f[4:]) / (2 * h)
    d_fwd = jax.jvp(final, (theta,), (tangent,))[1] if forward else None
    return jax.grad(final)(theta), d_fwd, fd


@pytest.mark.parametrize("forward", [False, pytest.param(True, marks=pytest.mark.slow)])
def test_gradients_through_a_sea_state_match_finite_differences(forward):
    """Gradients w.r.t. the sea's parameters through a drawn sea and an RK4 particle path:
    reverse mode against central differences (float64); slow: forward = reverse mode too (a
    second differentiated program, +1 s of compilation; forward mode of the kinematics is in
    the default run through the acceleration test)."""
    theta = jnp.array([1.8, 7.0, 0.6, 2.5])
    tangent = jnp.array([0.3, -0.7, 1.1, 0.4])
    key = jax.random.key(8)
    g_rev, d_fwd, fd = _final_position_and_derivatives(key, theta, tangent, 1e-5, forward)
    if forward:
        np.testing.assert_allclose(d_fwd, g_rev @ tangent, rtol=1e-10)
    np.testing.assert_allclose(g_rev, fd, rtol=1e-6, atol=1e-9)
    assert np.all(np.abs(np.asarray(g_rev)) > 1e-6)  # every parameter matters


# --------------------------------------------------------------------------------------------
# Calm sea, dtypes, bad input
# --------------------------------------------------------------------------------------------


def test_zero_hs_is_exactly_calm_and_differentiable():
    for spectrum in waves.SPECTRA:  # every one of 1024 seas of 64 components
        seas = _draws(KEYS[0], 0.0, 8.0, 0.5, spectrum=spectrum, components=64)
        assert not np.any(np.asarray(seas.amplitude))
    sea = _draw(jax.random.key(0), 0.0, 8.0, 0.5, spreading=2.0)
    assert not np.any(np.asarray(sea.amplitude))
    p = jnp.array([3.0, 4.0, 2.0])
    current, current_dot = jnp.array([0.1, 0.5, 0.0]), jnp.array([1e-3, 0.0, 0.0])
    for s in (sea, waves.calm_sea(N)):
        fld = _field(s, 1.7, p, current, current_dot)
        v, a = fld["water"]
        np.testing.assert_array_equal(v, current)  # bit-identical to no waves
        np.testing.assert_array_equal(a, current_dot)
        for key in ("u", "du_dt", "grad", "zeta"):
            np.testing.assert_array_equal(fld[key], 0.0)

    @jax.jit
    def grads_at_calm(hs):
        draw = lambda hs: waves.sea_state(jax.random.key(0), hs, 8.0, 0.5, components=N)
        speed2 = lambda hs: jnp.sum(waves.orbital_velocity(draw(hs), 1.0, p) ** 2)
        zeta = lambda hs: waves.elevation(draw(hs), 1.0, 0.0, 0.0)
        return jax.grad(speed2)(hs), jax.grad(zeta)(hs)

    g0, gz = grads_at_calm(0.0)
    assert float(g0) == 0.0  # exactly 0 (quadratic in hs), and finite at hs = 0
    assert np.isfinite(float(gz)) and float(gz) != 0.0  # linear in hs


def test_float32():
    key = jax.random.key(4)
    f32 = lambda x: jnp.asarray(x, dtype=jnp.float32)
    s32 = _draw(key, f32(2.0), f32(8.0), f32(0.3), gamma=f32(3.3))  # dtype from the arguments
    assert all(x.dtype == jnp.float32 for x in s32)
    # the spread draw and the explicit dtype, traced only (their dtypes, no promotion error)
    for shape in (
        jax.eval_shape(
            lambda k: waves.sea_state(k, 2.0, 8.0, 0.3, spreading=1.0, dtype=jnp.float32), key
        ),  # fmt: skip
        jax.eval_shape(
            lambda k: waves.sea_state(k, f32(2.0), f32(8.0), f32(0.3), spreading=1.0), key
        ),  # fmt: skip
    ):
        assert all(x.dtype == jnp.float32 and x.shape == (64,) for x in shape)
    p = [1.0, 2.0, 3.0]
    out = _field(s32, 4.0, p)
    assert all(o.dtype == jnp.float32 for o in jax.tree.leaves(out))
    # jax.random draws other bits for float32, so s32 is another realisation: compare the
    # float32 kinematics with float64 ones of the same sea, and the draws' statistics
    s32_64 = jax.tree.map(lambda x: x.astype(jnp.float64), s32)
    ref = _field(s32_64, 4.0, p)
    for key_ in ("zeta", "u", "du_dt", "water"):
        for o, r in zip(jax.tree.leaves(out[key_]), jax.tree.leaves(ref[key_]), strict=True):
            np.testing.assert_allclose(o, r, atol=1e-5 * float(np.max(np.abs(r))))
    # the float32 draw's amplitudes are sqrt(2 S(omega_i) d_omega) at its own frequencies
    lo, hi, _ = _band(8.0)
    s_ref = _np_spectrum("jonswap", 2.0, 8.0)
    a_ref = [math.sqrt(2 * s_ref(w) * (hi - lo) / N) for w in np.asarray(s32_64.omega)]
    np.testing.assert_allclose(s32.amplitude, a_ref, rtol=1e-5)
    omega = np.asarray(s32_64.omega)
    assert np.all(np.diff(omega) > 0) and lo < omega[0] and omega[-1] < hi
    w32 = jax.ShapeDtypeStruct((5,), jnp.float32)
    assert jax.eval_shape(lambda w: waves.jonswap(w, 1.0, 8.0), w32).dtype == jnp.float32


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(hs=-1.0), "hs"),
        (dict(tp=0.0), "tp"),
        (dict(spectrum="bretschneider"), "spectrum"),
        (dict(components=0), "components"),
        (dict(components=8.0), "components"),
        (dict(gamma=0.5), "gamma"),
        (dict(spreading=-1.0), "spreading"),
        (dict(direction=float("nan")), "direction"),
    ],
)
def test_bad_input_names_the_field(kwargs, field):
    args = dict(hs=1.0, tp=8.0, direction=0.0) | kwargs
    with pytest.raises(ValueError, match=f"^{field}"):
        waves.sea_state(jax.random.key(0), args.pop("hs"), args.pop("tp"), args.pop("direction"),
                        **args)  # fmt: skip


# --------------------------------------------------------------------------------------------
# A body in the wave field (the plant-side seam)
# --------------------------------------------------------------------------------------------


@functools.cache
def _remus_params():
    return remus100.remus100_params()


@functools.cache
def _remus_body(cg_at_cb):
    """REMUS 100's rigid-body and added mass, damping, W = B (PVS numbers); CG at the CB or
    PVS's 2 cm below it."""
    b = _remus_params().body
    if not cg_at_cb:
        return b
    h_inv = sixdof.Hmtrx(-b.r_bg)  # M_RB = H(r)^T M_CG H(r), H(r)^-1 = H(-r)
    m_cg = h_inv.T @ b.M_RB @ h_inv
    return b._replace(M_RB=m_cg, r_bg=jnp.zeros(3))


def _explicit_nu_dot(b, eta, nu, tau, v_w, a_w, m_d):
    """The body equation of the module docstring, written out: (M_RB + M_A) nu_dot = tau +
    tau_FK + M_A nu_w_dot - C_RB(nu) nu - C_A(nu_r) nu_r - D nu_r - g(eta)."""
    R = sixdof.Rzyx(eta[3], eta[4], eta[5])
    vb = R.T @ v_w
    nu_r = nu - jnp.concatenate([vb, jnp.zeros(3)])
    nu_w_dot = jnp.concatenate([R.T @ a_w - jnp.cross(nu[3:], vb), jnp.zeros(3)])
    rhs = (
        tau
        + waves.froude_krylov(R, a_w, m_d, b.r_bb)
        + b.M_A @ nu_w_dot
        - sixdof.m2c(b.M_RB, nu) @ nu
        - sixdof.m2c(b.M_A, nu_r) @ nu_r
        - b.D @ nu_r
        - sixdof.restoring(b, eta)
    )
    return jnp.linalg.solve(b.M_RB + b.M_A, rhs)


@jax.jit
def _door_and_explicit(b, eta, nu, tau, v_w, a_w, m_d):
    R = sixdof.Rzyx(eta[3], eta[4], eta[5])
    corr = waves.current_door_correction(R, a_w, b.M_RB, m_d, b.r_bb)
    _, nu_dot = sixdof.vector_field(b, eta, nu, tau + corr, WaterMotion(v_w, a_w))
    return nu_dot, _explicit_nu_dot(b, eta, nu, tau, v_w, a_w, m_d), corr


def test_the_current_door_plus_correction_is_the_froude_krylov_body():
    rng = np.random.default_rng(0)
    for cg_at_cb, m_scale, r_bb in [(False, 1.0, (0, 0, 0)), (True, 1.07, (0.01, -0.02, 0.0))]:
        b = _remus_body(cg_at_cb)
        m_d = m_scale * float(b.B) / 9.81
        b = b._replace(r_bb=jnp.asarray(r_bb, dtype=jnp.float64), B=jnp.asarray(m_d * 9.81))
        for _ in range(3):
            x = [jnp.asarray(rng.normal(size=n) * s) for n, s in ((6, 0.4), (6, 1), (6, 5))]
            v_w, a_w = jnp.asarray(rng.normal(size=3)), jnp.asarray(rng.normal(size=3))
            nu_dot, ref, _ = _door_and_explicit(b, *x, v_w, a_w, jnp.asarray(m_d))
            np.testing.assert_allclose(nu_dot, ref, rtol=1e-10, atol=1e-10)
    # neutrally buoyant with CG = CB: the plant's current door alone is the physics
    b = _remus_body(True)
    m_d = float(b.B) / 9.81
    b = b._replace(r_bb=jnp.asarray(b.r_bb, dtype=jnp.float64), B=jnp.asarray(m_d * 9.81))
    _, _, corr = _door_and_explicit(b, *x, v_w, a_w, jnp.asarray(m_d))
    np.testing.assert_allclose(corr, 0.0, atol=1e-12)


STEPS = 300  # two wave periods of the body-in-waves runs below


@jax.jit
def _follow(sea, current, b, m_d, p0, psi, period):
    """RK4 of the body (the sixdof plant taking the water as its current, plus the correction)
    and of the water particle ``x' = v_w(t, x)`` released at the same point, over two periods."""
    dt = 2 * period / STEPS

    def kin(t, p):
        return waves.water_kinematics(sea, t, p, current)

    def both(t, y):
        (eta, nu), x = y
        v_w, a_w = kin(t, eta[:3])
        R = sixdof.Rzyx(eta[3], eta[4], eta[5])
        tau = waves.current_door_correction(R, a_w, b.M_RB, m_d, b.r_bb)
        return sixdof.vector_field(b, eta, nu, tau, WaterMotion(v_w, a_w)), kin(t, x)[0]

    z = jnp.zeros_like(psi)
    eta0 = jnp.concatenate([p0, jnp.stack([z, z, psi])])
    R0 = sixdof.Rzyx(z, z, psi)
    nu0 = jnp.concatenate([R0.T @ kin(0.0, p0)[0], jnp.zeros(3)])

    def step(y, k):
        y = _rk4(both, k * dt, y, dt)
        return y, (y[0][0], y[1])

    return jax.lax.scan(step, ((eta0, nu0), p0), jnp.arange(STEPS, dtype=p0.dtype))[1]


@pytest.mark.parametrize("regular", [True, False])
def test_a_neutrally_buoyant_body_moves_with_the_water_particles(regular):
    """Actuators off, released with the water's velocity: the body's position follows the
    particle's path (an identity of the model when CG = CB: both solve x'' = a_w(t, x)); the
    Froude–Krylov term is what makes it so (without it the body lags visibly)."""
    period, depth = 6.0, 3.0
    if regular:
        sea = _regular(a=0.5, omega=2 * np.pi / period, phase=0.3, beta=0.5)
    else:
        sea = _draw(jax.random.key(9), 1.5, period, 0.5, spreading=2.0)
    current = jnp.array([0.2, -0.1, 0.0])
    p0 = jnp.array([1.0, 2.0, depth])
    b = _remus_body(cg_at_cb=True)
    m_d, psi, n = jnp.asarray(float(b.B) / 9.81), jnp.asarray(0.7), STEPS
    run = lambda b, m_d: [np.asarray(x) for x in _follow(sea, current, b, m_d, p0, psi, period)]
    etas, xs = run(b, m_d)
    orbit = (
        xs
        - np.asarray(p0)
        - np.asarray(current) * (np.arange(1.0, n + 1.0)[:, None] * 2 * period / n)
    )
    assert float(np.max(np.abs(orbit))) > 0.2  # the particle's excursion is not small
    np.testing.assert_allclose(etas[:, :3], xs, atol=1e-7)
    np.testing.assert_allclose(etas[:, 3:] - np.array([0.0, 0.0, 0.7]), 0.0, atol=1e-7)
    # negative control: drop the Froude-Krylov force (m_d = 0 in the load): the body lags
    etas_nofk, _ = run(b, 0.0 * m_d)
    assert float(np.max(np.abs(etas_nofk[:, :3] - xs))) > 0.1 * float(np.max(np.abs(orbit)))
    # with PVS's CG 2 cm below the CB the body sways like a pendulum (pitch/roll up to ~2 deg
    # here), yet its origin (the CB) stays on the particle's path to within |r_bg| x tilt
    etas_pvs, _ = run(_remus_body(cg_at_cb=False), m_d)
    dev = float(np.max(np.abs(etas_pvs[:, :3] - xs)))
    tilt = float(np.max(np.abs(etas_pvs[:, 3:5])))
    assert tilt > 0.005
    assert dev < 2 * 0.02 * tilt


def _in_full(p, v_w, a_w):
    """REMUS 100's arguments with the whole water rotated in full (no share named uniform)."""
    still = WaterMotion(jnp.zeros_like(v_w), jnp.zeros_like(a_w))
    return remus100.Remus100Args(p, WaterMotion(v_w, a_w), uniform=still)


@partial(jax.jit, static_argnames="steps")
def _follow_remus(sea, current, p, p0, period, steps):
    """The REMUS 100 plant itself (actuators off), taking the water as its (3,) current, with
    :func:`waves.current_door_correction` added as a body force, and the water particle."""
    dt = 2 * period / steps
    m_d = p.body.B / p.body.W * p.body.M_RB[0, 0]  # W = B: the displaced mass is the mass

    def both(t, y):
        x, q = y
        v_w, a_w = waves.water_kinematics(sea, t, x.eta[:3], current)
        args = _in_full(p, v_w, a_w)
        dx = remus100.remus100_plant(t, x, jnp.zeros(3), args)
        R = sixdof.Rzyx(x.eta[3], x.eta[4], x.eta[5])
        corr = waves.current_door_correction(R, a_w, p.body.M_RB, m_d, p.body.r_bb)
        dx = dx._replace(nu=dx.nu + jnp.linalg.solve(remus100.mass_matrix(p), corr))
        return dx, waves.water_kinematics(sea, t, q, current)[0]

    nu0 = jnp.concatenate([waves.water_kinematics(sea, 0.0, p0, current)[0], jnp.zeros(3)])
    x0 = remus100.Remus100State(jnp.concatenate([p0, jnp.zeros(3)]), nu0, jnp.zeros(3))

    def step(y, k):
        y = _rk4(both, k * dt, y, dt)
        return y, (y[0].eta, y[1])

    return jax.lax.scan(step, (x0, p0), jnp.arange(steps, dtype=p0.dtype))[1]


@jax.jit
def _remus_on_the_particle(sea, current, p, t, x, psi):
    """The REMUS 100 plant (actuators off) plus :func:`waves.current_door_correction`, level on
    heading ``psi`` at the water particle's place ``x`` and with its velocity, at time ``t``;
    and the particle's velocity and acceleration."""
    v_w, a_w = waves.water_kinematics(sea, t, x, current)
    z = jnp.zeros_like(psi)
    R = sixdof.Rzyx(z, z, psi)
    state = remus100.Remus100State(
        jnp.concatenate([x, jnp.stack([z, z, psi])]),
        jnp.concatenate([R.T @ v_w, jnp.zeros(3)]),
        jnp.zeros(3),
    )
    dx = remus100.remus100_plant(t, state, jnp.zeros(3), _in_full(p, v_w, a_w))
    m_d = p.body.B / p.body.W * p.body.M_RB[0, 0]
    corr = waves.current_door_correction(R, a_w, p.body.M_RB, m_d, p.body.r_bb)
    nu_dot = dx.nu + jnp.linalg.solve(remus100.mass_matrix(p), corr)
    return dx.eta, nu_dot, v_w, R.T @ a_w


def test_the_remus100_plant_moving_with_the_water_solves_its_equations():
    """The REMUS 100 plant (hull lift/drag, cross-flow drag, fins, propeller, PVS damping) with
    its actuators off and the CG moved to the CB (W = B): a body at a water particle's place,
    level, moving with the water's velocity, has the particle's velocity and acceleration
    (``eta_dot = [v_w; 0]``, ``nu_dot = [R^T a_w; 0]`` at zero rotation rate), so the particle's
    path solves the plant's equations: the vehicle moves with the water (by uniqueness). The
    integrated version with PVS's CG below the CB is the slow test below."""
    p = _remus_params()._replace(body=_remus_body(cg_at_cb=True))
    current = jnp.array([0.2, -0.1, 0.05])
    seas = (
        _regular(a=0.5, omega=2 * np.pi / 6.0, phase=0.3, beta=0.5),
        _draw(jax.random.key(9), 2.0, 7.0, 0.5, spreading=2.0),
    )
    for sea in seas:
        for t, x, psi in [(0.0, [1.0, 2.0, 3.0], 0.7), (4.3, [-7.0, 5.0, 1.2], -2.0)]:
            eta_dot, nu_dot, v_w, a_b = _remus_on_the_particle(
                sea, current, p, jnp.asarray(t), jnp.asarray(x), jnp.asarray(psi)
            )
            assert float(np.max(np.abs(a_b))) > 0.05  # the water accelerates
            np.testing.assert_allclose(eta_dot[:3], v_w, rtol=1e-12, atol=1e-14)
            np.testing.assert_allclose(eta_dot[3:], 0.0, atol=1e-14)
            np.testing.assert_allclose(nu_dot[:3], a_b, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(nu_dot[3:], 0.0, atol=1e-12)


@pytest.mark.slow
def test_the_remus100_plant_moves_with_the_water_particles():
    """The REMUS 100 plant (hull lift/drag, cross-flow drag, PVS damping, CG 2 cm below the CB)
    with its actuators off, released with the water's velocity in a regular wave plus a
    current: its origin (the CB) stays on the particle path to within |r_bg| x tilt."""
    period = 6.0
    sea = _regular(a=0.5, omega=2 * np.pi / period, phase=0.3, beta=0.5, components=1)
    current = jnp.array([0.2, -0.1, 0.0])
    p0 = jnp.array([1.0, 2.0, 3.0])
    p = _remus_params()
    etas, xs = _follow_remus(sea, current, p, p0, period, 300)
    orbit = float(jnp.max(jnp.abs(xs - p0 - current * (jnp.arange(1.0, 301.0)[:, None] * 0.04))))
    dev = float(jnp.max(jnp.abs(etas[:, :3] - xs)))
    tilt = float(jnp.max(jnp.abs(etas[:, 3:5])))
    assert orbit > 0.2 and tilt > 0.005
    assert dev < 2 * 0.02 * tilt, (dev, tilt, orbit)
    # the body sways in roll and pitch; its heading barely moves
    assert float(jnp.max(jnp.abs(etas[:, 5]))) < tilt


def test_remus100_takes_a_3d_water_velocity():
    """A (3,) current takes the full rotation R^T; level and horizontal it is PVS's (2,) door."""
    nu = jnp.array([1.0, 0.1, -0.2, 0.01, 0.02, 0.3])
    v2, d2 = jnp.array([0.3, -0.4]), jnp.array([0.01, 0.02])
    v3, d3 = jnp.append(v2, 0.0), jnp.append(d2, 0.0)
    level = jnp.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.8])
    yawing = nu.at[3:5].set(0.0)  # PVS's door rotates with the yaw rate only
    for a, b in zip(remus100.current_in_body(level, yawing, v2, d2),
                    remus100.current_in_body(level, yawing, v3, d3), strict=True):  # fmt: skip
        np.testing.assert_allclose(b, a, rtol=1e-14, atol=1e-16)
    tilted = jnp.array([1.0, 2.0, 3.0, 0.2, -0.3, 0.8])
    v3 = jnp.array([0.3, -0.4, 0.25])
    for a, b in zip(remus100.current_in_body(tilted, nu, v3, d3),
                    sixdof.current_in_body(tilted, nu, v3, d3), strict=True):  # fmt: skip
        np.testing.assert_array_equal(a, b)


# --------------------------------------------------------------------------------------------
# JONSWAP's shape against an independent evaluation (issue 31: planted shape bugs)
# --------------------------------------------------------------------------------------------


def _jonswap_oracle(w, hs, tp, gamma, sigma_a=0.07, sigma_b=0.09):
    """JONSWAP written out from its definition (numpy, scalar ``w``): the PM (Hs, Tp) shape
    times ``gamma^r``, ``r = exp(-(w - wp)^2 / (2 sigma^2 wp^2))``, sigma_a left of the peak and
    sigma_b right of it, scaled so that m0 = Hs^2 / 16 by scipy's adaptive quadrature in omega
    (not the module's Gauss-Legendre rule in u = (wp / w)^4)."""
    wp = 2.0 * math.pi / tp

    def shape(x):
        if x <= 0.0:
            return 0.0
        pm = 5.0 / 16.0 * wp**4 * x**-5 * math.exp(-1.25 * (wp / x) ** 4)
        s = sigma_a if x <= wp else sigma_b
        return pm * gamma ** math.exp(-((x - wp) ** 2) / (2.0 * s * s * wp * wp))

    m0 = sum(
        integrate.quad(shape, a, b, limit=400, epsabs=0, epsrel=1e-12)[0]
        for a, b in ((0.05 * wp, wp), (wp, 50.0 * wp), (50.0 * wp, np.inf))
    )
    return hs * hs / 16.0 * shape(w) / m0


@pytest.mark.parametrize("gamma", [1.0, 2.0, 3.3, 7.0])
def test_jonswap_equals_an_independent_evaluation(gamma):
    """Kills: sigma_a / sigma_b swapped or changed, the peak exponent's square or factor 2
    dropped, the normalisation computed for another gamma (every omega near and far from the
    peak, both sides)."""
    hs, tp = 2.5, 9.0
    wp = 2.0 * math.pi / tp
    x = np.array([0.6, 0.8, 0.9, 0.95, 0.98, 1.0, 1.02, 1.05, 1.1, 1.2, 1.5, 2.5, 4.0])
    got = np.asarray(waves.jonswap(jnp.asarray(x * wp, jnp.float64), hs, tp, gamma))
    want = np.array([_jonswap_oracle(v * wp, hs, tp, gamma) for v in x])
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_jonswap_peak_widths_are_sigma_a_left_and_sigma_b_right():
    """The enhancement ``S_J / S_PM`` normalised at the peak is ``gamma^(r - 1)``: solving
    ``r = exp(-x^2 / (2 sigma^2))`` for sigma at ``omega = wp (1 -+ x)`` gives 0.07 below the
    peak and 0.09 above it (the two JONSWAP widths, read back from the spectrum itself)."""
    hs, tp, gamma = 1.0, 8.0, 3.3
    wp = 2.0 * math.pi / tp
    for side, sigma in ((-1, 0.07), (1, 0.09)):
        for x in (0.03, 0.08, 0.15):
            w = jnp.asarray([wp, wp * (1 + side * x)], jnp.float64)
            sj = np.asarray(waves.jonswap(w, hs, tp, gamma))
            spm = np.asarray(waves.pierson_moskowitz(w, hs, tp))
            r = 1.0 + math.log((sj[1] / spm[1]) / (sj[0] / spm[0])) / math.log(gamma)
            assert x / math.sqrt(-2.0 * math.log(r)) == pytest.approx(sigma, rel=1e-9)


def test_jonswap_enhancement_at_the_peak_is_gamma_over_its_normalisation():
    """At omega_p the enhancement is exactly gamma (r = 1), and the normalisation I(gamma) is
    the oracle's m0 ratio: S_J(wp) / S_PM(wp) = gamma / I(gamma), I(1) = 1, I increasing."""
    wp = 2.0 * math.pi / 8.0
    values = []
    for gamma in (1.0, 2.0, 3.3, 7.0):
        ratio = float(waves.jonswap(wp, 1.0, 8.0, gamma) / waves.pierson_moskowitz(wp, 1.0, 8.0))
        i_oracle = (
            gamma
            * float(waves.pierson_moskowitz(wp, 1.0, 8.0))
            / _jonswap_oracle(wp, 1.0, 8.0, gamma)
        )
        assert gamma / ratio == pytest.approx(i_oracle, rel=1e-9)
        assert float(waves.jonswap_normalisation(gamma)) == pytest.approx(i_oracle, rel=1e-9)
        values.append(i_oracle)
    assert values[0] == pytest.approx(1.0, rel=1e-10) and np.all(np.diff(values) > 0)
