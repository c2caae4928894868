"""INFANTE-class, NPS-AUV-derived plant: calibration, scaling, energy, currents, actuators."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax.environment import WaterMotion
from vcjax.integrators import rk4
from vcjax.vehicles import design3dof as d3
from vcjax.vehicles import infante as inf

P = inf.infante_params()
CALM = inf.plant_args(P)

# Prime coefficients of npsauv.m (the vehicle data (docs/reference/vehicles.md)), typed in independently of the module.
YDR, NDR = 2.7e-2, -1.3e-2


N_STEPS = 400  # one static horizon for every test: the scan compiles once per plant and dtype


@functools.partial(jax.jit, static_argnames=("plant", "n"))
def simulate(plant, x0, cmd, args, dt, n=N_STEPS):
    """RK4 with a constant command; returns the (n+1)-stacked states."""

    def f(t, x, a):
        return plant(t, x, cmd, a), None

    def step(x, _):
        x_next, _ = rk4(f, 0.0, x, dt, args)
        return x_next, x_next

    _, xs = jax.lax.scan(step, x0, None, length=n)
    return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), x0, xs)


def _water(v_c, v_c_dot=None):
    """The plant's water door for a horizontal current (2,) and its rate (2,)."""
    pad = lambda a: None if a is None else jnp.append(jnp.asarray(a, float), 0.0)
    return WaterMotion(pad(v_c), pad(v_c_dot))


def cmd(thrust, rudder, dtype=jnp.float64):
    return jnp.asarray([thrust, rudder], dtype=dtype)


# ---------------------------------------------------------------------------------------------


def test_calibration_920N_gives_5mps():
    assert float(P.X_uu) == pytest.approx(-920.0 / 25.0, rel=1e-12)
    # Steady equation: at u = 5 m/s with 920 N applied, every derivative vanishes.
    xs = inf.infante_state([0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [920.0, 0.0])
    xd = inf.infante_plant(0.0, xs, cmd(920.0, 0.0), CALM)
    np.testing.assert_allclose(xd.nu, 0.0, atol=1e-12)
    np.testing.assert_allclose(xd.act, 0.0, atol=1e-12)
    # ... and a simulation from the paper's initial speed, actuators at rest, gets there.
    x0 = inf.infante_state([0.0, 0.0, 0.3], [2.0, 0.0, 0.0])

    def steady_speed(thrust):  # 2 x 400 RK4 steps of 0.25 s = 200 s (surge time scale ~10 s)
        x = x0
        for _ in range(2):
            x = jax.tree_util.tree_map(
                lambda l: l[-1], simulate(inf.infante_plant, x, cmd(thrust, 0.0), CALM, 0.25)
            )
        np.testing.assert_allclose(x.nu[1:], 0.0, atol=1e-12)
        return float(x.nu[0])

    assert abs(steady_speed(920.0) - 5.0) < 1e-3
    # a different thrust gives the quadratic-drag speed sqrt(T / 36.8)
    assert steady_speed(460.0) == pytest.approx(math.sqrt(0.5) * 5.0, abs=1e-3)


def test_scaling_matches_vehicles_md_table():
    dm = inf.design_model(P, 1.0, match_coriolis=False)
    table = {  # the vehicle data (docs/reference/vehicles.md), "prime-scaled to L = 4.5 m" column
        "mass": (P.mass, 3331.8),
        "Iz": (P.Iz, 5995.2),
        "m11": (dm.m11, 3686.8),
        "m22": (dm.m22, 5900.4),
        "m23": (dm.m23, -252.2),
        "m33": (dm.m33, 9210.6),
        "d22/u": (dm.d22, 1037.8),
        "d23/u": (dm.d23, -1401.0),
        "d32/u": (dm.d32, 345.6),
        "d33/u": (dm.d33, 3362.5),
    }
    for name, (got, want) in table.items():
        assert float(got) == pytest.approx(want, rel=5e-3), name
    Yd, Nd = inf.rudder_gains(P, jnp.array([1.0, 0.0, 0.0]))
    assert float(Yd) == pytest.approx(280.2, rel=5e-3)
    assert float(Nd) == pytest.approx(-607.1, rel=5e-3)
    # at L = 5.3 m the unscaled NPS AUV II numbers come back
    nps = inf.design_model(inf.infante_params(length=5.3), 1.0, match_coriolis=False)
    for got, want in [(nps.m11, 6023.3), (nps.m22, 9639.9), (nps.m23, -485.3), (nps.m33, 20874.1)]:
        assert float(got) == pytest.approx(want, rel=5e-3)


def test_design_model_reproduces_plant_linearisation():
    ud = 2.0
    dm = inf.design_model(P, ud)
    nu0 = jnp.array([ud, 0.0, 0.0])
    zero_act = jnp.zeros(2)
    # plant: M nu_r_dot = body_forces; design: M_b nu_r_dot = -(C_b nu + D_b nu)
    J_plant = jax.jacfwd(lambda n: -inf.body_forces(P, n, zero_act))(nu0)
    J_design = jax.jacfwd(lambda n: d3.body_bias(dm, n))(nu0)
    np.testing.assert_allclose(J_design[1:], J_plant[1:], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(d3.mass_matrix(dm), inf.mass_matrix(P), rtol=1e-12)
    # surge: the secant d11 gives the plant's drag force at u_d exactly
    assert float(d3.body_bias(dm, nu0)[0]) == pytest.approx(
        -float(inf.body_forces(P, nu0, zero_act)[0]), rel=1e-12
    )
    # without the Coriolis matching the (20) model double-counts the Munk moment
    raw = inf.design_model(P, ud, match_coriolis=False)
    J_raw = jax.jacfwd(lambda n: d3.body_bias(raw, n))(nu0)
    assert abs(float(J_raw[2, 1] - J_plant[2, 1])) > 1000.0


@pytest.mark.parametrize("x_g", [0.0, 0.25])
def test_energy_conserved_without_hydrodynamics(x_g):
    p = inf.ideal_fluid(inf.infante_params(x_g=x_g))
    args = inf.plant_args(p)
    nu0 = jnp.array([2.0, 0.7, 0.3])
    # C_RB does no work
    assert abs(float(nu0 @ inf.body_forces(p, nu0, jnp.zeros(2)))) < 1e-9
    x0 = inf.infante_state([0.0, 0.0, 0.0], nu0)
    traj = simulate(inf.infante_plant, x0, cmd(0.0, 0.0), args, 0.05)
    E = jax.vmap(lambda n: inf.kinetic_energy(p, n))(traj.nu)
    assert float(jnp.max(jnp.abs(E / E[0] - 1.0))) < 1e-9
    assert float(jnp.max(jnp.abs(traj.nu - nu0))) > 0.1  # the motion is not trivial


def test_drifting_with_the_current_stays_drifting():
    V_c = jnp.array([0.3, -0.5])
    psi0 = 0.7
    args = inf.plant_args(P, _water(V_c))
    nu_c, _ = d3.current_in_body(jnp.array(psi0), jnp.array(0.0), V_c)
    x0 = inf.infante_state([1.0, 2.0, psi0], nu_c)
    traj = simulate(inf.infante_plant, x0, cmd(0.0, 0.0), args, 0.05)
    np.testing.assert_allclose(traj.eta[-1, :2], jnp.array([1.0, 2.0]) + 20.0 * V_c, atol=1e-9)
    np.testing.assert_allclose(traj.eta[:, 2], psi0, atol=1e-12)
    nu_r = traj.nu - nu_c  # r stays 0, so R(psi)^T V_c is constant
    np.testing.assert_allclose(nu_r, 0.0, atol=1e-12)


def test_current_enters_through_relative_velocity():
    # Same relative motion in a current and in calm water gives the same nu_r_dot.
    V_c = jnp.array([0.2, 0.5])
    psi = 0.4
    nu_c, nu_c_dot = d3.current_in_body(jnp.array(psi), jnp.array(0.05), V_c)
    nu_r = jnp.array([2.5, 0.1, 0.05])
    act = jnp.array([500.0, 0.1])
    u = cmd(500.0, 0.1)
    x_cur = inf.infante_state([0.0, 0.0, psi], nu_r + nu_c, act)
    x_calm = inf.infante_state([0.0, 0.0, psi], nu_r, act)
    a_cur = inf.infante_plant(0.0, x_cur, u, inf.plant_args(P, _water(V_c))).nu
    a_calm = inf.infante_plant(0.0, x_calm, u, CALM).nu
    np.testing.assert_allclose(a_cur - nu_c_dot, a_calm, rtol=1e-12, atol=1e-14)
    assert float(jnp.max(jnp.abs(nu_c_dot))) > 1e-3


def test_saturation_hard_and_smooth():
    x0 = inf.infante_state([0.0, 0.0, 0.0], [2.0, 0.0, 0.0])
    lim = jnp.stack([P.thrust_max, P.rudder_max])
    for plant in (inf.infante_plant, inf.infante_plant_smooth):
        for sign in (1.0, -1.0):
            traj = simulate(plant, x0, cmd(sign * 5000.0, sign * 1.5), CALM, 0.02)
            assert bool(jnp.all(jnp.abs(traj.act) <= lim * (1 + 1e-12)))
    traj = simulate(inf.infante_plant, x0, cmd(5000.0, 1.5), CALM, 0.02)
    np.testing.assert_allclose(traj.act[-1], lim, rtol=1e-4)

    # smooth saturation passes gradients at a saturated command; the hard clip does not
    @functools.partial(jax.jit, static_argnums=0)
    def act_rate_jac(plant, c):
        return jax.jacfwd(lambda c: plant(0.0, x0, c, CALM).act)(c)

    c_sat = cmd(2000.0, 0.8)
    g_smooth = act_rate_jac(inf.infante_plant_smooth, c_sat)
    g_hard = act_rate_jac(inf.infante_plant, c_sat)
    assert bool(jnp.all(jnp.isfinite(g_smooth)))
    assert float(g_smooth[0, 0]) > 1e-3 and float(g_smooth[1, 1]) > 1e-3
    np.testing.assert_allclose(g_hard, 0.0, atol=0)


def test_rudder_signs_and_ratio():
    for u in (1.0, 3.0):
        nu = jnp.array([u, 0.0, 0.0])
        delta = 0.1
        F = inf.body_forces(P, nu, jnp.array([0.0, delta]))
        F0 = inf.body_forces(P, nu, jnp.zeros(2))
        Y, N = float(F[1] - F0[1]), float(F[2] - F0[2])
        assert Y > 0 and N < 0  # stern pushed to starboard, bow turns to port
        assert Y / N == pytest.approx(YDR / NDR / 4.5, rel=1e-12)
        Yd, Nd = inf.rudder_gains(P, nu)
        assert float(Yd) * delta == pytest.approx(Y, rel=1e-12)
        assert float(Nd) * delta == pytest.approx(N, rel=1e-12)
    # through the plant: positive rudder turns to port (r_dot < 0) at forward speed
    x = inf.infante_state([0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 0.2])
    assert float(inf.infante_plant(0.0, x, cmd(0.0, 0.2), CALM).nu[2]) < 0


def test_actuator_commands_and_rudder_sway_force():
    nu = jnp.array([3.0, 0.2, 0.01])
    c = inf.actuator_commands(P, nu, 400.0, 1500.0)
    _, Nd = inf.rudder_gains(P, nu)
    assert float(c[0]) == 400.0
    assert float(Nd * c[1]) == pytest.approx(1500.0, rel=1e-12)
    tau0v = inf.rudder_sway_force(P, nu, 1500.0)
    assert float(tau0v) == pytest.approx(1500.0 * YDR / (NDR * 4.5), rel=1e-12)
    # safe at zero speed: finite values and gradients
    nu0 = jnp.zeros(3)
    c0 = inf.actuator_commands(P, nu0, 0.0, 100.0)
    assert bool(jnp.all(jnp.isfinite(c0)))
    g = jax.grad(lambda n: inf.actuator_commands(P, n, 0.0, 100.0)[1])(nu0)
    assert bool(jnp.all(jnp.isfinite(g)))


def test_validation_errors():
    with pytest.raises(ValueError, match="thrust_max"):
        inf.infante_params(thrust_max=-920.0)
    with pytest.raises(ValueError, match="rudder_max_deg"):
        inf.infante_params(rudder_max_deg=95.0)
    with pytest.raises(ValueError, match="T_thrust"):
        inf.infante_params(T_thrust=0.0)
    with pytest.raises(ValueError, match="eta"):
        inf.infante_state([0.0, float("nan"), 0.0], [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="nu"):
        inf.infante_state([0.0, 0.0, 0.0], [1.0, 0.0])
    with pytest.raises(ValueError, match="act"):
        inf.infante_state([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="velocity"):
        inf.plant_args(P, WaterMotion([0.0, 0.5], None))
    with pytest.raises(ValueError, match="u_design"):
        inf.design_model(P, -1.0)


def test_jit_matches_nojit_and_gradients_are_finite_at_rest():
    args = inf.plant_args(P, _water([0.1, 0.5], [0.01, -0.02]))
    x = inf.infante_state([1.0, -2.0, 0.3], [2.0, 0.3, -0.05], [300.0, 0.1])
    u = cmd(600.0, -0.2)
    a = inf.infante_plant(0.0, x, u, args)
    b = jax.jit(inf.infante_plant)(0.0, x, u, args)
    for la, lb in zip(a, b, strict=True):
        np.testing.assert_allclose(la, lb, rtol=1e-13, atol=1e-12)
    # at rest (u = v = r = 0) the vector field has finite Jacobians in both modes
    x_rest = inf.infante_state([0.0, 0.0, 0.0], [0.0, 0.0, 0.0])

    @jax.jit
    def jacobians(nu):
        f = lambda nu: inf.infante_plant(0.0, x_rest._replace(nu=nu), u, CALM).nu
        return jax.jacfwd(f)(nu), jax.jacrev(f)(nu)

    J_fwd, J_rev = jacobians(x_rest.nu)
    assert bool(jnp.all(jnp.isfinite(J_fwd)))
    np.testing.assert_allclose(J_fwd, J_rev, rtol=1e-12, atol=1e-15)
    # vmap over states agrees with a loop
    xs = jax.tree_util.tree_map(lambda l: jnp.stack([l, 1.1 * l]), x)
    vm = jax.vmap(inf.infante_plant, in_axes=(None, 0, None, None))(0.0, xs, u, args)
    one = inf.infante_plant(0.0, jax.tree_util.tree_map(lambda l: l[1], xs), u, args)
    np.testing.assert_allclose(vm.nu[1], one.nu, rtol=1e-13)


def test_float32_runs_and_tracks_float64():
    def run(dtype):
        p = inf.infante_params(dtype=dtype)
        args = inf.plant_args(p, _water([0.0, 0.5]))
        x0 = inf.infante_state([0.0, 0.0, math.pi / 2], [2.0, 0.0, 0.0], dtype=dtype)
        return simulate(inf.infante_plant, x0, cmd(700.0, 0.15, dtype), args, 0.025)

    t32, t64 = run(jnp.float32), run(jnp.float64)
    for leaf in jax.tree_util.tree_leaves(t32):
        assert leaf.dtype == jnp.float32
    np.testing.assert_allclose(t32.eta, t64.eta, rtol=0, atol=2e-3)
    np.testing.assert_allclose(t32.nu, t64.nu, rtol=0, atol=2e-4)
    assert float(jnp.abs(t64.eta[-1, 2] - t64.eta[0, 2])) > 0.1  # it did turn


def test_describe_names_the_model():
    text = inf.describe(P)
    assert "NPS-AUV-derived" in text
    assert "3686.76" in text and "-36.80" in text


def _strip_sum(v, r):
    """npsauv.m's cross-flow strips, summed term by term (11 stations -L/2 .. L/2, dx = L/10)."""
    L = float(P.length)
    x = np.linspace(-L / 2, L / 2, 11)
    k = float(P.cf_coeff) * L / 10
    h = v + x * r
    Y = -k * np.sum(h * np.abs(h))
    N = -k * np.sum(x * h * np.abs(h))
    # gradients of h|h| are 2|h|: d/dv, d/dr of Y and N
    dY = -k * np.array([np.sum(2 * np.abs(h)), np.sum(2 * np.abs(h) * x)])
    dN = -k * np.array([np.sum(2 * np.abs(h) * x), np.sum(2 * np.abs(h) * x * x)])
    scale = k * np.sum(h * h) * (1 + L)  # magnitude of the terms: round-off is relative to it
    return Y, N, dY, dN, scale


@pytest.mark.parametrize(
    "v, r",
    [
        (0.3, 0.0),  # no yaw: one sign, N cancels
        (-0.4, 0.0),
        (0.0, 0.2),  # sign change at mid-ships
        (0.17, -0.31),  # sign change between stations
        (0.45, 0.2),  # h = 0 exactly at the station x = -2.25 m (v + x r = 0)
        (-0.9, 0.2),  # h = 0 beyond the bow: one sign
        (2.0, 0.05),
        (-1e-3, 3e-4),
        (0.0, 0.0),
    ],
)
def test_crossflow_closed_form_equals_strip_sum(v, r):
    Y, N, dY, dN, scale = _strip_sum(v, r)
    f = lambda vr: jnp.stack(inf.crossflow_forces(P, vr[0], vr[1]))
    vr = jnp.asarray([v, r])
    got = f(vr)
    np.testing.assert_allclose(got, [Y, N], rtol=0, atol=1e-13 * max(scale, 1.0))
    jac = jax.jacfwd(f)(vr)
    np.testing.assert_allclose(jac, np.stack([dY, dN]), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(jax.jacrev(f)(vr), jac, rtol=1e-12, atol=1e-12)


def test_crossflow_closed_form_random_and_float32():
    rng = np.random.default_rng(3)
    vr = rng.normal(size=(500, 2)) * np.array([0.5, 0.3])
    got = jax.vmap(lambda a: jnp.stack(inf.crossflow_forces(P, a[0], a[1])))(jnp.asarray(vr))
    for (v, r), g in zip(vr, np.asarray(got), strict=True):
        Y, N, _, _, scale = _strip_sum(v, r)
        np.testing.assert_allclose(g, [Y, N], rtol=0, atol=1e-13 * max(scale, 1.0))
    P32 = inf.infante_params(dtype=jnp.float32)
    v, r = 0.17, -0.31
    g32 = inf.crossflow_forces(P32, jnp.float32(v), jnp.float32(r))
    assert g32[0].dtype == jnp.float32
    Y, N, _, _, scale = _strip_sum(v, r)
    np.testing.assert_allclose(np.asarray(g32, dtype=float), [Y, N], rtol=0, atol=1e-5 * scale)
