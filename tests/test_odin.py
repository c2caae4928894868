"""ODIN-class sphere: equilibrium, thruster geometry, energy, damping, thruster lag, currents,
design model, validation, gradients."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from vcjax.environment import WaterMotion
from vcjax.integrators import rk4
from vcjax.vehicles import odin

P = odin.odin_params()
CALM = odin.odin_args(P)
RHO, R = 1025.0, 0.3
VOL = 4 / 3 * math.pi * R**3
MASS = RHO * VOL
K_DRAG = 0.5 * RHO * 0.47 * math.pi * R**2
N_STEPS = 500  # one static horizon for every simulation below: the scan compiles once per plant


@functools.partial(jax.jit, static_argnames=("plant",))
def simulate(plant, x0, cmd, args, dt):
    """RK4 with a constant thruster command; returns the (N_STEPS+1)-stacked states."""

    def f(t, x, a):
        return plant(t, x, cmd, a), None

    def step(x, _):
        x_next, _ = rk4(f, 0.0, x, dt, args)
        return x_next, x_next

    _, xs = jax.lax.scan(step, x0, None, length=N_STEPS)
    return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), x0, xs)


def _ideal(p):
    """No damping, no drag (ideal fluid); mass, added mass, Coriolis and restoring remain."""
    return p._replace(drag_coeff=jnp.zeros(()), body=p.body._replace(D=jnp.zeros((6, 6))))


def test_numbers_from_the_sphere_formulas():
    M = np.asarray(odin.mass_matrix(P))
    assert float(P.body.M_RB[0, 0]) == pytest.approx(MASS, rel=1e-12)
    assert M[0, 0] == pytest.approx(1.5 * MASS, rel=1e-12)  # m + 1/2 rho V
    assert M[5, 5] == pytest.approx(0.4 * MASS * R**2, rel=1e-12)  # no rotational added mass
    assert M[3, 3] == pytest.approx(0.4 * MASS * R**2 + MASS * 0.02**2, rel=1e-12)  # I + m z_g^2
    assert float(P.drag_coeff) == pytest.approx(K_DRAG, rel=1e-12)
    assert float(P.body.W) == pytest.approx(float(P.body.B))  # neutrally buoyant


def test_thruster_matrix_maximum_forces():
    """the vehicle data (docs/reference/vehicles.md) [DER]: 76.37 N, 108 N, 19.24 N m, 38.45 N m with 27 N per thruster."""
    T = np.asarray(P.thrusters)
    reach = np.abs(T) @ np.full(8, 27.0)
    np.testing.assert_allclose(reach, [76.37, 76.37, 108.0, 19.24, 19.24, 38.45], atol=0.01)
    # horizontal thrusters act only in X, Y, N; vertical ones only in Z, K, M
    assert np.all(T[[2, 3, 4], :4] == 0) and np.all(T[[0, 1, 5], 4:] == 0)
    assert np.linalg.matrix_rank(T) == 6


def test_at_rest_with_zero_thrust_stays_at_rest():
    x = odin.odin_state([3.0, -2.0, -102.0, 0.0, 0.0, 0.7])
    xd = odin.odin_plant(0.0, x, jnp.zeros(8), CALM)
    for leaf in xd:
        np.testing.assert_allclose(leaf, 0.0, atol=1e-13)
    xs = simulate(odin.odin_plant, x, jnp.zeros(8), CALM, 0.2)
    np.testing.assert_allclose(xs.eta[-1], x.eta, atol=1e-12)
    np.testing.assert_allclose(xs.nu[-1], 0.0, atol=1e-12)


def test_ideal_fluid_conserves_energy_including_restoring():
    """C(nu) skew-symmetric and g(eta) = grad of the hydrostatic potential: E is conserved."""
    p = _ideal(P)
    args = odin.odin_args(p)
    x0 = odin.odin_state([1.0, 2.0, -50.0, 0.3, -0.2, 0.5], [0.3, -0.2, 0.1, 0.4, -0.3, 0.2])
    xs = simulate(odin.odin_plant, x0, jnp.zeros(8), args, 0.02)  # 10 s, ~4 roll periods
    E = jax.vmap(lambda eta, nu: odin.total_energy(p, odin.OdinState(eta, nu, x0.thrust)))(
        xs.eta, xs.nu
    )
    E = np.asarray(E)
    assert np.max(np.abs(E - E[0])) < 1e-8 * E[0]
    assert np.ptp(np.asarray(xs.eta[:, 3])) > 0.3  # it did roll


def test_damping_dissipates_energy_monotonically():
    x0 = odin.odin_state([0.0, 0.0, -50.0, 0.3, -0.2, 0.0], [0.8, -0.4, 0.2, 0.5, -0.3, 0.4])
    xs = simulate(odin.odin_plant, x0, jnp.zeros(8), CALM, 0.1)  # 50 s
    E = np.asarray(
        jax.vmap(lambda eta, nu: odin.total_energy(P, odin.OdinState(eta, nu, x0.thrust)))(
            xs.eta, xs.nu
        )
    )
    assert np.all(np.diff(E) <= 1e-12 * E[0])
    assert E[-1] < 0.05 * E[0]


def test_terminal_speed_from_quadratic_and_linear_drag():
    """Constant surge force X: steady speed solves k U^2 + D_u U = X (1.06 m/s at 76.4 N)."""
    T = np.asarray(P.thrusters)
    X = 40.0
    cmd = jnp.asarray(np.linalg.pinv(T) @ np.array([X, 0, 0, 0, 0, 0]))
    x0 = odin.odin_state([0.0, 0.0, -50.0, 0.0, 0.0, 0.0], thrust=cmd)
    xs = simulate(odin.odin_plant, x0, cmd, CALM, 0.2)  # 100 s; time constant ~2 s
    D_u = float(P.body.D[0, 0])
    U = (-D_u + math.sqrt(D_u**2 + 4 * K_DRAG * X)) / (2 * K_DRAG)
    np.testing.assert_allclose(xs.nu[-1], [U, 0, 0, 0, 0, 0], atol=1e-9)
    U_max = (-D_u + math.sqrt(D_u**2 + 4 * K_DRAG * 76.37)) / (2 * K_DRAG)
    assert (
        0.95 < U_max < 1.1
    )  # the vehicle data (docs/reference/vehicles.md): ~1.06 m/s without linear damping


def test_thruster_lag_is_first_order_with_its_time_constant_and_saturates():
    x0 = odin.odin_state([0.0, 0.0, -50.0, 0.0, 0.0, 0.0])
    cmd = jnp.array([10.0, -5.0, 100.0, -100.0, 3.0, 0.0, -27.0, 40.0])
    dt = 0.002
    xs = simulate(odin.odin_plant, x0, cmd, CALM, dt)  # 1 s = 5 time constants
    t = np.arange(N_STEPS + 1) * dt
    target = np.clip(np.asarray(cmd), -27.0, 27.0)
    expected = target[None, :] * (1 - np.exp(-t / 0.2))[:, None]
    np.testing.assert_allclose(xs.thrust, expected, atol=1e-9)
    # smooth variant: 27 tanh(cmd / 27)
    xs = simulate(odin.odin_plant_smooth, x0, cmd, CALM, dt)
    target = 27.0 * np.tanh(np.asarray(cmd) / 27.0)
    np.testing.assert_allclose(xs.thrust[-1], target * (1 - math.exp(-1.0 / 0.2)), atol=1e-9)


def test_disturbance_and_current():
    # tau_dist given as 3 forces is padded with zero moments; it accelerates the vehicle
    args = odin.odin_args(P, tau_dist=[0.0, 5.0, 0.0])
    np.testing.assert_allclose(args.tau_dist, [0, 5, 0, 0, 0, 0])
    x = odin.odin_state([0.0, 0.0, -50.0, 0.0, 0.0, 0.0])
    xd = odin.odin_plant(0.0, x, jnp.zeros(8), args)
    M = np.asarray(odin.mass_matrix(P))
    np.testing.assert_allclose(xd.nu, np.linalg.solve(M, [0, 5.0, 0, 0, 0, 0]), rtol=1e-12)
    assert float(xd.nu[1]) == pytest.approx(5.0 / (1.5 * MASS), rel=0.01)  # sway-roll coupling
    # drifting with a constant current (zero relative velocity) is an equilibrium
    v_c = np.array([0.3, -0.2, 0.05])
    psi = 0.8
    Rz = np.array(
        [[math.cos(psi), -math.sin(psi), 0], [math.sin(psi), math.cos(psi), 0], [0, 0, 1]]
    )
    nu = np.concatenate([Rz.T @ v_c, np.zeros(3)])
    x = odin.odin_state([0.0, 0.0, -50.0, 0.0, 0.0, psi], nu)
    xd = odin.odin_plant(0.0, x, jnp.zeros(8), odin.odin_args(P, water=WaterMotion(v_c, None)))
    np.testing.assert_allclose(xd.nu, 0.0, atol=1e-13)
    np.testing.assert_allclose(xd.eta[:3], v_c, atol=1e-13)


def test_design_model_matches_plant_at_design_speed():
    u_d = 0.5
    dm = odin.design_model(P, u_d)
    assert float(dm.m11) == pytest.approx(1.5 * MASS) and float(dm.m22) == pytest.approx(1.5 * MASS)
    assert float(dm.m23) == 0.0
    # d11 u_d is the plant's surge drag at u_d (secant)
    nu = jnp.array([u_d, 0, 0, 0, 0, 0])
    drag = -float(odin.drag_force(P, nu)[0]) + float(P.body.D[0, 0]) * u_d
    assert float(dm.d11) * u_d == pytest.approx(drag, rel=1e-12)
    # d22 is the slope of the plant's sway force at v = 0, u = u_d
    dY = jax.grad(lambda v: odin.drag_force(P, jnp.array([u_d, v, 0, 0, 0, 0]))[1])(0.0)
    assert float(dm.d22) == pytest.approx(-float(dY) + float(P.body.D[1, 1]), rel=1e-9)


def test_validation_errors_name_the_field():
    cases = [
        (lambda: odin.odin_params(radius=-0.3), "radius"),
        (lambda: odin.odin_params(z_g=0.5), "z_g"),
        (lambda: odin.odin_params(z_g=-0.01), "z_g"),
        (lambda: odin.odin_params(T_thrust=0.0), "T_thrust"),
        (lambda: odin.odin_params(thrust_max=float("nan")), "thrust_max"),
        (lambda: odin.odin_params(R_hor=(0.3, 0.3)), "R_hor"),
        (lambda: odin.odin_state([0.0, 0.0, 0.0]), "eta"),
        (lambda: odin.odin_state(np.zeros(6), thrust=np.zeros(6)), "thrust"),
        (lambda: odin.odin_state(np.zeros(6), nu=[0, 0, 0, 0, 0, np.inf]), "nu"),
        (lambda: odin.odin_args(P, tau_dist=[1.0, 2.0, 3.0, 4.0]), "tau_dist"),
        (lambda: odin.odin_args(P, water=WaterMotion([0.0, float("nan"), 0.0], None)), "velocity"),
        (lambda: odin.odin_args(P, water=WaterMotion(None, [0.0, 0.0])), "acceleration"),
        (lambda: odin.odin_args("odin"), "vehicle"),
        (lambda: odin.design_model(P, u_design=0.0), "u_design"),
    ]
    for build, field in cases:
        with pytest.raises(ValueError, match=field):
            build()


def test_gradients_finite_at_rest_and_match_finite_differences():
    @jax.jit
    def f(nu, f_cmd):
        x = odin.OdinState(jnp.array([0.0, 0.0, -50.0, 0.1, -0.1, 0.3]), nu, jnp.ones(8))
        d = odin.odin_plant(0.0, x, f_cmd, CALM)
        return jnp.concatenate([d.eta, d.nu, d.thrust])

    nu = jnp.array([0.4, -0.1, 0.05, 0.02, -0.03, 0.1])
    check_grads(f, (nu, jnp.full(8, 5.0)), order=1, modes=["fwd", "rev"], atol=1e-6, rtol=1e-6)
    J = jax.jacrev(f)(jnp.zeros(6), jnp.zeros(8))  # |v_r| at zero: safe norm
    assert np.all(np.isfinite(np.asarray(J)))


def test_float32():
    p = odin.odin_params(dtype=jnp.float32)
    x = odin.odin_state(np.zeros(6), dtype=jnp.float32)
    xd = odin.odin_plant(0.0, x, jnp.ones(8, jnp.float32), odin.odin_args(p, [0.0, 5.0, 0.0]))
    assert all(leaf.dtype == jnp.float32 for leaf in xd)


def _level(psi):
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_a_neutrally_buoyant_sphere_moves_with_a_uniformly_accelerating_current():
    """Thrusters off, released with the water's velocity in the current ``v_c(t) = v0 + a t``:
    ``nu_r = 0`` for all time, so no drag, no damping and no Coriolis act, and the water's
    acceleration moves the rigid body and the added mass with it (``(M_RB + M_A) R^T a``): the
    sphere follows the water, ``p(t) = p0 + v0 t + a t^2 / 2``, level, on its heading."""
    v0, acc, psi = np.array([0.3, -0.2, 0.05]), np.array([0.02, 0.015, -0.01]), 0.8
    Rt, p0 = _level(psi).T, np.array([1.0, -2.0, 30.0])
    zero6 = jnp.zeros(6)

    def args_at(t, v_c_dot=True):
        return odin.OdinArgs(P, zero6, WaterMotion(v0 + acc * t, acc if v_c_dot else None))

    # (a) the analytic motion solves the plant's equations at every instant ...
    for t in (0.0, 7.0, 30.0):
        eta = np.concatenate([p0 + v0 * t + 0.5 * acc * t**2, [0.0, 0.0, psi]])
        x = odin.odin_state(eta, np.concatenate([Rt @ (v0 + acc * t), np.zeros(3)]))
        xd = odin.odin_plant(t, x, jnp.zeros(8), args_at(t))
        np.testing.assert_allclose(xd.eta, np.concatenate([v0 + acc * t, np.zeros(3)]), atol=1e-14)
        np.testing.assert_allclose(xd.nu, np.concatenate([Rt @ acc, np.zeros(3)]), atol=1e-14)
        np.testing.assert_array_equal(xd.thrust, 0.0)
        # without the water's acceleration the plant would hold the body's velocity instead
        xd0 = odin.odin_plant(t, x, jnp.zeros(8), args_at(t, v_c_dot=False))
        np.testing.assert_allclose(xd0.nu, 0.0, atol=1e-14)

    # (b) ... and RK4 integrates it (20 s) onto the analytic path
    @jax.jit
    def path(x0):
        def f(t, x, _):
            return odin.odin_plant(t, x, jnp.zeros(8), args_at(t)), None

        def step(x, k):
            x, _ = rk4(f, 0.25 * k, x, 0.25, None)
            return x, x.eta

        return jax.lax.scan(step, x0, jnp.arange(80.0))[1]

    x0 = odin.odin_state([*p0, 0.0, 0.0, psi], np.concatenate([Rt @ v0, np.zeros(3)]))
    t = 0.25 * np.arange(1.0, 81.0)[:, None]
    etas = path(x0)
    np.testing.assert_allclose(etas[:, :3], p0 + v0 * t + 0.5 * acc * t**2, atol=1e-9)
    np.testing.assert_allclose(etas[:, 3:], np.broadcast_to([0.0, 0.0, psi], (80, 3)), atol=1e-12)


def test_a_zero_current_rate_changes_no_result():
    """``v_c_dot = 0`` gives the results of the constant-current plant (``v_c_dot=None``)."""
    rng = np.random.default_rng(4)
    for _ in range(3):
        x = odin.OdinState(*(jnp.asarray(rng.normal(size=n)) for n in (6, 6, 8)))
        v_c, u = rng.normal(size=3), jnp.asarray(rng.normal(size=8) * 10)
        a0 = odin.odin_args(P, [1.0, -2.0, 0.5], WaterMotion(v_c, None))
        a1 = odin.odin_args(P, [1.0, -2.0, 0.5], WaterMotion(v_c, np.zeros(3)))
        for plant in (odin.odin_plant, odin.odin_plant_smooth):
            for r0, r1 in zip(plant(0.0, x, u, a0), plant(0.0, x, u, a1), strict=True):
                np.testing.assert_array_equal(r1, r0)
