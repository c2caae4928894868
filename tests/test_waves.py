"""Waves (vcjax.waves) against independent physics: quadrature of the spectra, the statistics of
long realisations, the Airy potential differentiated by autodiff, the free-surface boundary
condition, finite differences, and a body that must move with the water particles."""

import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, optimize

from vcjax import waves
from vcjax.vehicles import remus100, sixdof

G = 9.81


def _np_spectrum(spectrum, hs, tp, gamma=3.3):
    """The spectrum as a vectorised numpy function of omega (for scipy's quadrature)."""
    if spectrum == "pm":
        f = jax.jit(lambda w: waves.pierson_moskowitz(w, hs, tp))
    else:
        f = jax.jit(lambda w: waves.jonswap(w, hs, tp, gamma))
    return lambda w: float(f(jnp.asarray(w, dtype=jnp.float64)))


def _quad(f, lo, hi, peak):
    # split at the peak (the JONSWAP width changes there) for scipy's adaptive rule
    return sum(integrate.quad(f, a, b, limit=400, epsabs=0, epsrel=1e-11)[0] for a, b in
               ((lo, peak), (peak, hi)))  # fmt: skip


# --------------------------------------------------------------------------------------------
# Spectra
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "spectrum, gamma", [("pm", None), ("jonswap", 1.0), ("jonswap", 3.3), ("jonswap", 7.0)]
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
    w = jnp.linspace(0.1, 3.0, 50)
    pm = waves.pierson_moskowitz(w, 3.0, 8.0)
    np.testing.assert_allclose(waves.jonswap(w, 3.0, 8.0, 1.0), pm, rtol=1e-12)
    # the closed-form PM (Hs, Tp) spectrum written out independently
    wp = 2 * np.pi / 8.0
    ref = 5 / 16 * 9.0 * wp**4 * np.asarray(w) ** -5 * np.exp(-1.25 * (wp / np.asarray(w)) ** 4)
    np.testing.assert_allclose(pm, ref, rtol=1e-12, atol=1e-300)
    # the exact normalisation agrees with DNV's 1 - 0.287 ln(gamma) to its stated accuracy
    i33 = float(waves.jonswap_normalisation(3.3))
    assert 1 / i33 == pytest.approx(1 - 0.287 * np.log(3.3), rel=5e-3)


def test_jonswap_is_differentiable_in_gamma():
    f = lambda g: waves.jonswap(jnp.asarray(0.7), 2.0, 9.0, g)
    g0, h = 3.3, 1e-5
    fd = (f(g0 + h) - f(g0 - h)) / (2 * h)
    assert float(jax.grad(f)(g0)) == pytest.approx(float(fd), rel=1e-7)


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


def test_long_realisation_has_the_significant_wave_height():
    hs, tp, beta, n = 2.0, 8.0, 0.4, 64
    sea = waves.sea_state(jax.random.key(3), hs, tp, beta, components=n)
    duration, dt = 20 * 3600.0, 0.5
    t = jnp.arange(0.0, duration, dt)
    zeta = jax.jit(jax.vmap(lambda ti: waves.elevation(sea, ti, 10.0, -4.0)))(t)
    m0_hat = float(jnp.var(zeta))
    m0_sea = float(jnp.sum(sea.amplitude**2) / 2)  # this realisation's own variance

    lo, hi, wp = _band(tp)
    f = _np_spectrum("jonswap", hs, tp)
    m0_band = integrate.quad(f, lo, hi, limit=400, points=[wp])[0]
    # the band holds > 99.5 % of m0 (module docstring)
    assert m0_band / (hs**2 / 16) == pytest.approx(1.0, abs=0.005)
    # (a) the 20 h record's variance is the sea's: 4 sigma (a false alarm once in ~16 000
    # records), sigma / m0 = 1.3 % for this record length
    sig_rec = _record_sigma(f, lo, hi, duration)
    assert abs(m0_hat - m0_sea) < 4 * sig_rec, (m0_hat, m0_sea, sig_rec)
    # (b) a sea's variance scatters about the band's integral by the random frequencies
    # within bins (3.1 % of m0 for 64 components, i.e. 1.5 % in Hs); over 400 seas the mean is
    # the integral (unbiased draws) within 4 sigma / sqrt(400) = 0.6 %
    sig_bins = _bins_sigma(f, lo, hi, n)
    assert abs(m0_sea - m0_band) < 4 * sig_bins
    seas = jax.vmap(lambda k: waves.sea_state(k, hs, tp, beta, components=n))(
        jax.random.split(jax.random.key(30), 400)
    )
    m0_seas = np.asarray(jnp.sum(seas.amplitude**2, axis=1) / 2)
    assert abs(m0_seas.mean() - m0_band) < 4 * sig_bins / math.sqrt(400)
    assert np.std(m0_seas) == pytest.approx(sig_bins, rel=0.2)  # 400 samples: std within ~7 %
    # so 4 std(zeta) is Hs: within 4 sqrt(sig_rec^2 + sig_bins^2) / 2 / m0 + 0.25 % = 7 %
    assert 4 * math.sqrt(m0_hat) == pytest.approx(hs, rel=0.07)


def test_orbital_velocity_variance_at_depth():
    hs, tp, beta, n, depth = 3.0, 10.0, 2.2, 64, 8.0
    sea = waves.sea_state(jax.random.key(7), hs, tp, beta, spectrum="pm", components=n)
    duration, dt = 20 * 3600.0, 0.5
    t = jnp.arange(0.0, duration, dt)
    p = jnp.array([3.0, 1.0, depth])
    u = jax.jit(jax.vmap(lambda ti: waves.orbital_velocity(sea, ti, p)))(t)
    along = u[:, 0] * np.cos(beta) + u[:, 1] * np.sin(beta)
    across = -u[:, 0] * np.sin(beta) + u[:, 1] * np.cos(beta)
    np.testing.assert_allclose(across, 0.0, atol=1e-13)  # long-crested: no cross velocity

    lo, hi, wp = _band(tp)
    s_pm = _np_spectrum("pm", hs, tp)
    s_u = lambda w: s_pm(w) * w**2 * np.exp(-2 * w**2 / G * depth)
    ref = integrate.quad(s_u, lo, hi, limit=400)[0]
    # the full-line integral: the band's cut-off loses < 0.01 % of the velocity variance at 8 m
    assert integrate.quad(s_u, 0.3 * wp, 20 * wp, limit=400)[0] == pytest.approx(ref, rel=1e-4)
    var_sea = float(jnp.sum((sea.amplitude * sea.omega) ** 2 * jnp.exp(-2 * sea.wavenumber *
                                                                        depth)) / 2)  # fmt: skip
    sig_rec = _record_sigma(s_u, lo, hi, duration)
    for comp in (along, u[:, 2]):  # horizontal and vertical variances are equal in deep water
        assert abs(float(jnp.var(comp)) - var_sea) < 4 * sig_rec, (jnp.var(comp), var_sea)
    assert abs(var_sea - ref) < 4 * _bins_sigma(s_u, lo, hi, n)
    seas = jax.vmap(lambda k: waves.sea_state(k, hs, tp, beta, spectrum="pm", components=n))(
        jax.random.split(jax.random.key(31), 400)
    )
    var_seas = jnp.sum((seas.amplitude * seas.omega) ** 2 * jnp.exp(-2 * seas.wavenumber *
                                                                     depth), axis=1) / 2  # fmt: skip
    assert abs(float(jnp.mean(var_seas)) - ref) < 4 * _bins_sigma(s_u, lo, hi, n) / 20


def test_spreading_draws_cos2s_directions():
    s, beta0, n = 4.0, 1.0, 20000
    sea = waves.sea_state(jax.random.key(1), 1.0, 8.0, beta0, spreading=s, components=n)
    dev = np.asarray(sea.direction) - beta0
    assert np.all(np.abs(dev) <= np.pi / 2)
    dens = lambda x: np.cos(x) ** (2 * s)
    norm = integrate.quad(dens, -np.pi / 2, np.pi / 2)[0]
    for fn in (np.cos, lambda x: x**2):
        mean = integrate.quad(lambda x, f=fn: f(x) * dens(x), -np.pi / 2, np.pi / 2)[0] / norm
        var = integrate.quad(lambda x, f=fn: f(x) ** 2 * dens(x), -np.pi / 2, np.pi / 2)[0] / norm
        assert abs(np.mean(fn(dev)) - mean) < 4 * math.sqrt((var - mean**2) / n)
    # the mean direction is beta0 (odd moment zero) and spreading leaves frequencies/phases alone
    assert abs(np.mean(dev)) < 4 * math.sqrt(np.var(dev) / n)
    sea0 = waves.sea_state(jax.random.key(1), 1.0, 8.0, beta0, components=n)
    np.testing.assert_array_equal(sea.omega, sea0.omega)
    np.testing.assert_array_equal(sea.phase, sea0.phase)
    np.testing.assert_array_equal(sea0.direction, beta0)


# --------------------------------------------------------------------------------------------
# Regular waves: closed-form Airy kinematics and signs
# --------------------------------------------------------------------------------------------


def _regular(a=1.5, omega=0.8, phase=0.4, beta=0.9):
    one = lambda x: jnp.array([x])
    return waves.Sea(one(omega), one(a), one(omega**2 / G), one(phase), one(beta))


def test_regular_wave_against_the_airy_potential():
    a, w, phi, beta = 1.5, 0.8, 0.4, 0.9
    sea = _regular(a, w, phi, beta)
    k = w**2 / G

    def potential(t, n, e, z_up):  # deep-water Airy potential, z up
        return g_a_w * jnp.exp(k * z_up) * jnp.sin(k * (n * np.cos(beta) + e * np.sin(beta))
                                                    - w * t + phi)  # fmt: skip

    g_a_w = G * a / w
    grad = jax.grad(potential, argnums=(1, 2, 3))
    for t, n, e, d in [(0.3, 1.0, -2.0, 0.0), (7.1, 30.0, 4.0, 5.0), (-3.0, -8.0, 11.0, 25.0)]:
        vn, ve, vup = grad(t, n, e, -d)
        ref = jnp.stack([vn, ve, -vup])  # NED: down = -up
        np.testing.assert_allclose(waves.orbital_velocity(sea, t, jnp.array([n, e, d])), ref,
                                   rtol=1e-12, atol=1e-14)  # fmt: skip
        # linearised Bernoulli at the surface: g zeta = -dPhi/dt
        zeta_ref = -jax.grad(potential)(t, n, e, 0.0) / G
        assert float(waves.elevation(sea, t, n, e)) == pytest.approx(float(zeta_ref), rel=1e-12)


def test_regular_wave_signs_and_free_surface_condition():
    a, w, phi, beta = 0.8, 1.1, 0.0, 0.6
    sea = _regular(a, w, phi, beta)
    k, depth = w**2 / G, 4.0
    h = jnp.array([np.cos(beta), np.sin(beta)])
    speed = a * w * np.exp(-k * depth)
    # a crest at the origin at t = 0 (theta = 0)
    assert float(waves.elevation(sea, 0.0, 0.0, 0.0)) == pytest.approx(a)
    u = waves.orbital_velocity(sea, 0.0, jnp.array([0.0, 0.0, depth]))
    np.testing.assert_allclose(u[:2], speed * h, rtol=1e-12)  # along the direction of travel
    assert abs(float(u[2])) < 1e-15
    # under the crest the water accelerates downwards (positive down)
    acc = waves.orbital_acceleration(sea, 0.0, jnp.array([0.0, 0.0, depth]))
    assert float(acc[2]) == pytest.approx(a * w**2 * np.exp(-k * depth), rel=1e-12)
    # a quarter wavelength ahead of the crest the surface is rising: the water moves up (w < 0)
    ahead = (np.pi / 2 / k) * h
    u = waves.orbital_velocity(sea, 0.0, jnp.array([ahead[0], ahead[1], depth]))
    assert float(u[2]) == pytest.approx(-speed, rel=1e-12)
    assert float(jax.grad(lambda t: waves.elevation(sea, t, ahead[0], ahead[1]))(0.0)) > 0
    # kinematic free-surface condition d zeta / dt = -u_down(depth = 0) (holds only if k = w^2/g)
    for t, n, e in [(0.0, 0.0, 0.0), (1.3, 5.0, 2.0), (4.0, -7.0, 9.0)]:
        dz = jax.grad(lambda t, n=n, e=e: waves.elevation(sea, t, n, e))(t)
        ud = waves.orbital_velocity(sea, t, jnp.array([n, e, 0.0]))[2]
        assert float(dz) == pytest.approx(-float(ud), rel=1e-12, abs=1e-14)
    # the wave travels towards beta: a crest moves by c t along h (phase speed w / k)
    t1 = 2.0
    crest = (w / k) * t1 * h
    assert float(waves.elevation(sea, t1, crest[0], crest[1])) == pytest.approx(a)


def test_above_the_mean_surface_the_kinematics_are_those_at_the_surface():
    sea = waves.sea_state(jax.random.key(2), 2.0, 7.0, 0.0, components=16)
    top = waves.orbital_velocity(sea, 1.0, jnp.array([1.0, 2.0, 0.0]))
    np.testing.assert_array_equal(waves.orbital_velocity(sea, 1.0, jnp.array([1.0, 2.0, -0.5])),
                                  top)  # fmt: skip


# --------------------------------------------------------------------------------------------
# Derivatives
# --------------------------------------------------------------------------------------------


def test_acceleration_and_gradient_are_the_derivatives_of_the_velocity():
    sea = waves.sea_state(jax.random.key(5), 2.5, 9.0, 1.2, spreading=3.0, components=32)
    current = jnp.array([0.3, -0.2, 0.05])
    for t, p in [(2.0, jnp.array([4.0, -3.0, 6.0])), (13.0, jnp.array([-20.0, 7.0, 1.5]))]:
        vel = lambda t, p=p: waves.orbital_velocity(sea, t, p)
        h = 1e-4
        fd = (vel(t + h) - vel(t - h)) / (2 * h)
        acc = waves.orbital_acceleration(sea, t, p)
        np.testing.assert_allclose(acc, fd, rtol=1e-7, atol=1e-10)
        np.testing.assert_allclose(acc, jax.jvp(vel, (t,), (1.0,))[1], rtol=1e-12, atol=1e-14)
        gp = waves.orbital_velocity_gradient(sea, t, p)
        np.testing.assert_allclose(gp, jax.jacfwd(lambda q, t=t: waves.orbital_velocity(sea, t, q))(p),
                                   rtol=1e-12, atol=1e-14)  # fmt: skip
        np.testing.assert_allclose(gp, gp.T, atol=1e-14)  # irrotational
        assert abs(float(jnp.trace(gp))) < 1e-14  # incompressible
        # water_kinematics: the particle's acceleration d/dt v(t, p + v0 (t - t0)) at t0
        v0, a0 = waves.water_kinematics(sea, t, p, current)
        line = lambda s, t=t, p=p, v0=v0: waves.orbital_velocity(sea, t + s, p + v0 * s) + current
        np.testing.assert_allclose(v0, line(0.0), rtol=1e-14)
        np.testing.assert_allclose(a0, jax.jvp(line, (0.0,), (1.0,))[1], rtol=1e-12, atol=1e-14)


# --------------------------------------------------------------------------------------------
# Calm sea, reproducibility, dtypes, bad input
# --------------------------------------------------------------------------------------------


def test_zero_hs_is_exactly_calm_and_differentiable():
    for spectrum in waves.SPECTRA:
        sea = waves.sea_state(jax.random.key(0), 0.0, 8.0, 0.5, spectrum=spectrum, spreading=2.0)
        assert not np.any(np.asarray(sea.amplitude))
        p = jnp.array([3.0, 4.0, 2.0])
        current, current_dot = jnp.array([0.1, 0.5, 0.0]), jnp.array([1e-3, 0.0, 0.0])
        v, a = waves.water_kinematics(sea, 1.7, p, current, current_dot)
        np.testing.assert_array_equal(v, current)  # bit-identical to no waves
        np.testing.assert_array_equal(a, current_dot)
        for fn in (waves.orbital_velocity, waves.orbital_acceleration):
            np.testing.assert_array_equal(fn(sea, 1.7, p), 0.0)
        assert float(waves.elevation(sea, 1.7, 3.0, 4.0)) == 0.0
    calm = waves.calm_sea(4)
    np.testing.assert_array_equal(waves.water_kinematics(calm, 2.0, p, current)[0], current)

    def speed2(hs):
        sea = waves.sea_state(jax.random.key(0), hs, 8.0, 0.5)
        return jnp.sum(waves.orbital_velocity(sea, 1.0, jnp.array([0.0, 0.0, 2.0])) ** 2)

    g0 = jax.grad(speed2)(0.0)  # exactly 0 (quadratic in hs), and finite at hs = 0
    assert float(g0) == 0.0
    assert np.isfinite(float(jax.grad(lambda hs: waves.elevation(
        waves.sea_state(jax.random.key(0), hs, 8.0, 0.5), 1.0, 0.0, 0.0))(0.0)))  # fmt: skip


@pytest.mark.parametrize("spreading", [0.0, 2.0])
def test_draws_are_the_same_in_and_out_of_vmap_and_jit(spreading):
    keys = jax.random.split(jax.random.key(11), 4)
    hs = jnp.array([0.5, 1.0, 2.0, 0.0])
    tp = jnp.array([5.0, 7.0, 12.0, 9.0])
    beta = jnp.array([0.0, 1.0, -2.0, 3.0])
    draw = lambda k, h, t, b: waves.sea_state(k, h, t, b, spreading=spreading, components=16)
    batched = jax.vmap(draw)(keys, hs, tp, beta)
    jitted = jax.jit(jax.vmap(draw))(keys, hs, tp, beta)
    for i in range(4):
        one = draw(keys[i], float(hs[i]), float(tp[i]), float(beta[i]))
        one_jit = jax.jit(draw)(keys[i], hs[i], tp[i], beta[i])
        for a, b, c, d in zip(one, one_jit, batched, jitted, strict=True):
            np.testing.assert_allclose(b, a, rtol=1e-14)
            np.testing.assert_allclose(c[i], a, rtol=1e-14)
            np.testing.assert_allclose(d[i], a, rtol=1e-14)
    # and the kinematics vmap over seas (one sea per scenario)
    p = jnp.array([1.0, 2.0, 3.0])
    vb = jax.vmap(lambda s: waves.orbital_velocity(s, 2.0, p))(batched)
    for i in range(4):
        sea_i = jax.tree.map(lambda x, i=i: x[i], batched)
        np.testing.assert_allclose(vb[i], waves.orbital_velocity(sea_i, 2.0, p), rtol=1e-13)


def test_float32():
    args = (jax.random.key(4), 2.0, 8.0, 0.3)
    s64 = waves.sea_state(*args, spreading=1.0)
    s32 = waves.sea_state(*args, spreading=1.0, dtype=jnp.float32)
    s32b = waves.sea_state(args[0], jnp.float32(2.0), jnp.float32(8.0), jnp.float32(0.3),
                           spreading=1.0)  # fmt: skip
    assert all(x.dtype == jnp.float32 for x in (*s32, *s32b))
    p32 = jnp.array([1.0, 2.0, 3.0], dtype=jnp.float32)
    out = jax.jit(lambda s, t: waves.water_kinematics(s, t, p32, jnp.zeros(3, jnp.float32)))(
        s32, jnp.float32(4.0)
    )
    assert all(o.dtype == jnp.float32 for o in out)
    # jax.random draws other bits for float32, so s32 is another realisation: compare the
    # float32 kinematics with float64 ones of the same sea, and the draws' statistics
    s32_64 = jax.tree.map(lambda x: x.astype(jnp.float64), s32)
    u64 = waves.water_kinematics(s32_64, 4.0, jnp.array([1.0, 2.0, 3.0]), jnp.zeros(3))
    for o, r in zip(out, u64, strict=True):
        np.testing.assert_allclose(o, r, atol=1e-5 * float(jnp.max(jnp.abs(r))))
    np.testing.assert_allclose(jnp.sum(s32_64.amplitude**2), jnp.sum(s64.amplitude**2), rtol=0.2)
    assert waves.jonswap(jnp.linspace(0.2, 2.0, 5, dtype=jnp.float32), 1.0, 8.0).dtype == (
        jnp.float32
    )


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


def _remus_body(cg_at_cb):
    """REMUS 100's rigid-body and added mass, damping, W = B (PVS numbers); CG at the CB or
    PVS's 2 cm below it."""
    b = remus100.remus100_params().body
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


def test_the_current_door_plus_correction_is_the_froude_krylov_body():
    rng = np.random.default_rng(0)
    for cg_at_cb, m_scale, r_bb in [(False, 1.0, (0, 0, 0)), (True, 1.07, (0.01, -0.02, 0.0))]:
        b = _remus_body(cg_at_cb)
        m_d = m_scale * float(b.B) / 9.81
        b = b._replace(r_bb=jnp.asarray(r_bb, dtype=jnp.float64), B=jnp.asarray(m_d * 9.81))
        for _ in range(3):
            eta = jnp.asarray(rng.normal(size=6) * 0.4)
            nu, tau = jnp.asarray(rng.normal(size=6)), jnp.asarray(rng.normal(size=6) * 5)
            v_w, a_w = jnp.asarray(rng.normal(size=3)), jnp.asarray(rng.normal(size=3))
            R = sixdof.Rzyx(eta[3], eta[4], eta[5])
            corr = waves.current_door_correction(R, a_w, b.M_RB, m_d, b.r_bb)
            _, nu_dot = sixdof.vector_field(b, eta, nu, tau + corr, v_w, a_w)
            ref = _explicit_nu_dot(b, eta, nu, tau, v_w, a_w, m_d)
            np.testing.assert_allclose(nu_dot, ref, rtol=1e-10, atol=1e-10)
    # neutrally buoyant with CG = CB: the plant's current door alone is the physics
    b = _remus_body(True)
    corr = waves.current_door_correction(R, a_w, b.M_RB, float(b.B) / 9.81, b.r_bb)
    np.testing.assert_allclose(corr, 0.0, atol=1e-12)


def _rk4(f, t, y, dt):
    add = lambda y, k, h: jax.tree.map(lambda a, b: a + h * b, y, k)
    k1 = f(t, y)
    k2 = f(t + dt / 2, add(y, k1, dt / 2))
    k3 = f(t + dt / 2, add(y, k2, dt / 2))
    k4 = f(t + dt, add(y, k3, dt))
    ks = jax.tree.map(lambda a, b, c, d: (a + 2 * b + 2 * c + d) / 6, k1, k2, k3, k4)
    return add(y, ks, dt)


@partial(jax.jit, static_argnames="steps")
def _follow(sea, current, b, m_d, p0, psi, period, steps):
    """RK4 of the body (the sixdof plant taking the water as its current, plus the correction)
    and of the water particle ``x' = v_w(t, x)`` released at the same point, over two periods."""
    dt = 2 * period / steps

    def kin(t, p):
        return waves.water_kinematics(sea, t, p, current)

    def body(t, y):
        eta, nu = y
        v_w, a_w = kin(t, eta[:3])
        R = sixdof.Rzyx(eta[3], eta[4], eta[5])
        tau = waves.current_door_correction(R, a_w, b.M_RB, m_d, b.r_bb)
        return sixdof.vector_field(b, eta, nu, tau, v_w, a_w)

    def particle(t, x):
        return kin(t, x)[0]

    z = jnp.zeros_like(psi)
    eta0 = jnp.concatenate([p0, jnp.stack([z, z, psi])])
    R0 = sixdof.Rzyx(z, z, psi)
    nu0 = jnp.concatenate([R0.T @ kin(0.0, p0)[0], jnp.zeros(3)])

    def step(carry, k):
        y, x = carry
        t = k * dt
        y, x = _rk4(body, t, y, dt), _rk4(particle, t, x, dt)
        return (y, x), (y[0], x)

    steps_f = jnp.arange(steps, dtype=p0.dtype)
    return jax.lax.scan(step, ((eta0, nu0), p0), steps_f)[1]


@pytest.mark.parametrize("regular", [True, False])
def test_a_neutrally_buoyant_body_moves_with_the_water_particles(regular):
    """Actuators off, released with the water's velocity: the body's position follows the
    particle's path (an identity of the model when CG = CB: both solve x'' = a_w(t, x)); the
    Froude–Krylov term is what makes it so (without it the body lags visibly)."""
    period, depth = 6.0, 3.0
    if regular:
        w = 2 * np.pi / period
        sea = _regular(a=0.5, omega=w, phase=0.3, beta=0.5)
    else:
        sea = waves.sea_state(jax.random.key(9), 1.5, period, 0.5, spreading=2.0, components=16)
    current = jnp.array([0.2, -0.1, 0.0])
    p0 = jnp.array([1.0, 2.0, depth])
    b = _remus_body(cg_at_cb=True)
    m_d, psi, n = jnp.asarray(float(b.B) / 9.81), jnp.asarray(0.7), 300
    etas, xs = _follow(sea, current, b, m_d, p0, psi, period, n)
    orbit = xs - p0 - current * (jnp.arange(1.0, n + 1.0)[:, None] * 2 * period / n)
    assert float(jnp.max(jnp.abs(orbit))) > 0.2  # the particle's excursion is not small
    np.testing.assert_allclose(etas[:, :3], xs, atol=1e-7)
    np.testing.assert_allclose(etas[:, 3:] - jnp.array([0.0, 0.0, 0.7]), 0.0, atol=1e-7)
    # negative control: drop the Froude-Krylov force (m_d = 0 in the load): the body lags
    etas_nofk, _ = _follow(sea, current, b, 0.0 * m_d, p0, psi, period, n)
    assert float(jnp.max(jnp.abs(etas_nofk[:, :3] - xs))) > 0.1 * float(jnp.max(jnp.abs(orbit)))
    # with PVS's CG 2 cm below the CB the body sways like a pendulum (pitch/roll up to ~2 deg
    # here), yet its origin (the CB) stays on the particle's path to within |r_bg| x tilt
    b_pvs = _remus_body(cg_at_cb=False)
    etas_pvs, _ = _follow(sea, current, b_pvs, m_d, p0, psi, period, n)
    dev = float(jnp.max(jnp.abs(etas_pvs[:, :3] - xs)))
    tilt = float(jnp.max(jnp.abs(etas_pvs[:, 3:5])))
    assert tilt > 0.005
    assert dev < 2 * 0.02 * tilt


@partial(jax.jit, static_argnames="steps")
def _follow_remus(sea, current, p, p0, period, steps):
    """The REMUS 100 plant itself (actuators off), taking the water as its (3,) current, with
    :func:`waves.current_door_correction` added as a body force, and the water particle."""
    dt = 2 * period / steps
    m_d = p.body.B / p.body.W * p.body.M_RB[0, 0]  # W = B: the displaced mass is the mass

    def body(t, x):
        v_w, a_w = waves.water_kinematics(sea, t, x.eta[:3], current)
        args = remus100.Remus100Args(p, v_w, a_w)
        dx = remus100.remus100_plant(t, x, jnp.zeros(3), args)
        R = sixdof.Rzyx(x.eta[3], x.eta[4], x.eta[5])
        corr = waves.current_door_correction(R, a_w, p.body.M_RB, m_d, p.body.r_bb)
        return dx._replace(nu=dx.nu + jnp.linalg.solve(remus100.mass_matrix(p), corr))

    particle = lambda t, x: waves.water_kinematics(sea, t, x, current)[0]
    nu0 = jnp.concatenate([waves.water_kinematics(sea, 0.0, p0, current)[0], jnp.zeros(3)])
    x0 = remus100.Remus100State(jnp.concatenate([p0, jnp.zeros(3)]), nu0, jnp.zeros(3))

    def step(carry, k):
        x, q = carry
        x, q = _rk4(body, k * dt, x, dt), _rk4(particle, k * dt, q, dt)
        return (x, q), (x.eta, q)

    return jax.lax.scan(step, (x0, p0), jnp.arange(steps, dtype=p0.dtype))[1]


def test_the_remus100_plant_moves_with_the_water_particles():
    """The REMUS 100 plant (hull lift/drag, cross-flow drag, PVS damping, CG 2 cm below the CB)
    with its actuators off, released with the water's velocity in a regular wave plus a
    current: its origin (the CB) stays on the particle path to within |r_bg| x tilt."""
    period = 6.0
    sea = _regular(a=0.5, omega=2 * np.pi / period, phase=0.3, beta=0.5)
    current = jnp.array([0.2, -0.1, 0.0])
    p0 = jnp.array([1.0, 2.0, 3.0])
    p = remus100.remus100_params()
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
    p = jnp.array([n, e, d], dtype=dtype)
    zeta = jax.vmap(lambda ti: waves.elevation(sea, ti, p[0], p[1]))(jnp.asarray(t, dtype))
    u = jax.vmap(lambda ti: waves.orbital_velocity(sea, ti, p))(jnp.asarray(t, dtype))
    np.testing.assert_allclose(zeta, a * np.cos(theta), atol=tol)
    ref_w = -a * w * np.exp(-k * d) * np.sin(theta)
    np.testing.assert_allclose(u[:, 2], ref_w, atol=tol * a * w)


def test_gradients_through_a_sea_state_match_finite_differences():
    """d/d(hs, tp, direction, gamma) of where a water particle ends up after 15 s in a drawn,
    spread sea: forward and reverse mode against central differences (float64)."""
    key, dt, steps = jax.random.key(8), 0.25, 60

    def final_depth(theta):
        hs, tp, beta, gamma = theta
        sea = waves.sea_state(key, hs, tp, beta, gamma=gamma, spreading=0.0, components=8)

        def field(t, y):
            return waves.water_kinematics(sea, t, y, jnp.array([0.3, 0.0, 0.0]))[0]

        def step(x, k):
            return _rk4(field, k * dt, x, dt), None

        x, _ = jax.lax.scan(step, jnp.array([0.0, 0.0, 2.0]), jnp.arange(steps, dtype=jnp.float64))
        return x @ jnp.array([0.3, -0.5, 1.0])

    theta = jnp.array([1.8, 7.0, 0.6, 2.5])
    tangent = jnp.array([0.3, -0.7, 1.1, 0.4])
    both = jax.jit(
        lambda th: (jax.grad(final_depth)(th), jax.jvp(final_depth, (th,), (tangent,))[1])
    )
    g_rev, d_fwd = both(theta)
    h = 1e-5
    steps_h = jnp.concatenate([jnp.eye(4), -jnp.eye(4)]) * h
    f = jax.jit(jax.vmap(final_depth))(theta + steps_h)
    fd = (f[:4] - f[4:]) / (2 * h)
    np.testing.assert_allclose(d_fwd, g_rev @ tangent, rtol=1e-10)
    np.testing.assert_allclose(g_rev, fd, rtol=1e-6, atol=1e-9)
    assert np.all(np.abs(np.asarray(g_rev)) > 1e-6)  # every parameter matters
