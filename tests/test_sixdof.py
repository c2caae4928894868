"""Generic 6-DOF model (2): kinematics, Coriolis, restoring, energy, currents, validation, AD."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from vcjax.environment import WaterMotion
from vcjax.integrators import euler, rk4
from vcjax.vehicles import sixdof as sd

RNG = np.random.default_rng(1234)


def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _skew(a):
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def _random_spd(n, scale=1.0):
    A = RNG.normal(size=(n, n))
    return scale * (A @ A.T + n * np.eye(n))


def _vehicle(damped=True, restoring=True, dtype=jnp.float64):
    """A generic, fully coupled vehicle: off-centre CG, non-diagonal inertia and added mass."""
    r_bg = np.array([0.05, -0.02, 0.08])
    I_g = np.array([[2.0, 0.1, -0.05], [0.1, 5.0, 0.2], [-0.05, 0.2, 5.5]])
    M_RB = np.asarray(sd.rigid_body_mass_matrix(40.0, jnp.asarray(I_g), jnp.asarray(r_bg)))
    A = np.random.default_rng(7).normal(size=(6, 6))
    M_A = 0.5 * (A @ A.T + 6 * np.eye(6))  # the same fully coupled added mass on every call
    D = np.diag([5.0, 20.0, 20.0, 1.0, 4.0, 4.0]) if damped else np.zeros((6, 6))
    W = 40.0 * 9.81 if restoring else 0.0
    B = W * 1.01
    return sd.sixdof_params(M_RB, M_A, D, W, B, r_bg, [0.0, 0.0, 0.0], dtype=dtype)


# ---------------------------------------------------------------------------------------------
# Kinematics
# ---------------------------------------------------------------------------------------------


def test_rotation_is_zyx_composition_and_orthonormal():
    for _ in range(5):
        phi, theta, psi = RNG.uniform(-1.4, 1.4, size=3)
        R = np.asarray(sd.Rzyx(jnp.float64(phi), jnp.float64(theta), jnp.float64(psi)))
        np.testing.assert_allclose(R, _rot_z(psi) @ _rot_y(theta) @ _rot_x(phi), atol=1e-14)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)


def test_attitude_transform_matches_rotation_derivative():
    """T(Theta) is right iff d/dt R(Theta) = R S(omega) when Theta_dot = T(Theta) omega."""

    def R_of(Th):
        return sd.Rzyx(Th[0], Th[1], Th[2])

    for _ in range(5):
        Th = jnp.asarray(RNG.uniform(-1.2, 1.2, size=3))
        omega = jnp.asarray(RNG.normal(size=3))
        Th_dot = sd.Tzyx(Th[0], Th[1]) @ omega
        _, R_dot = jax.jvp(R_of, (Th,), (Th_dot,))
        np.testing.assert_allclose(R_dot, R_of(Th) @ _skew(np.asarray(omega)), atol=1e-13)
        # ... and against a central finite difference of the rotation composition
        h = 1e-6
        R_fd = (
            _rot_z(Th[2] + h * Th_dot[2])
            @ _rot_y(Th[1] + h * Th_dot[1])
            @ _rot_x(Th[0] + h * Th_dot[0])
            - _rot_z(Th[2] - h * Th_dot[2])
            @ _rot_y(Th[1] - h * Th_dot[1])
            @ _rot_x(Th[0] - h * Th_dot[0])
        ) / (2 * h)
        np.testing.assert_allclose(R_fd, R_of(Th) @ _skew(np.asarray(omega)), atol=1e-8)


def test_attitude_transform_closed_form_and_J_blocks():
    phi, theta = 0.3, -0.4
    T = np.asarray(sd.Tzyx(jnp.float64(phi), jnp.float64(theta)))
    # T^-1 in closed form: [[1, 0, -s_th], [0, c_phi, c_th s_phi], [0, -s_phi, c_th c_phi]]
    Tinv = np.array(
        [
            [1, 0, -np.sin(theta)],
            [0, np.cos(phi), np.cos(theta) * np.sin(phi)],
            [0, -np.sin(phi), np.cos(theta) * np.cos(phi)],
        ]
    )
    np.testing.assert_allclose(T @ Tinv, np.eye(3), atol=1e-14)
    eta = jnp.asarray([1.0, 2.0, 3.0, phi, theta, 0.7])
    J = np.asarray(sd.kinematics(eta))
    np.testing.assert_allclose(J[:3, :3], _rot_z(0.7) @ _rot_y(theta) @ _rot_x(phi), atol=1e-14)
    np.testing.assert_allclose(J[3:, 3:], T, atol=1e-14)
    np.testing.assert_array_equal(J[:3, 3:], 0.0)
    np.testing.assert_array_equal(J[3:, :3], 0.0)


def test_smtrx_and_hmtrx():
    a, b = RNG.normal(size=3), RNG.normal(size=3)
    np.testing.assert_allclose(sd.Smtrx(jnp.asarray(a)) @ b, np.cross(a, b), atol=1e-14)
    r = jnp.asarray(RNG.normal(size=3))
    np.testing.assert_allclose(sd.Hmtrx(r) @ sd.Hmtrx(-r), np.eye(6), atol=1e-14)


# ---------------------------------------------------------------------------------------------
# Coriolis and restoring
# ---------------------------------------------------------------------------------------------


def test_m2c_is_skew_symmetric_and_workless():
    for _ in range(5):
        M = jnp.asarray(_random_spd(6))
        nu = jnp.asarray(RNG.normal(size=6))
        C = np.asarray(sd.m2c(M, nu))
        np.testing.assert_allclose(C, -C.T, atol=1e-13)
        assert abs(float(nu @ C @ nu)) < 1e-12
        # linear in M: C_RB + C_A = C(M_RB + M_A)
        M2 = jnp.asarray(_random_spd(6))
        np.testing.assert_allclose(sd.m2c(M, nu) + sd.m2c(M2, nu), sd.m2c(M + M2, nu), atol=1e-12)
    M3 = jnp.asarray(_random_spd(3))
    nu3 = jnp.asarray(RNG.normal(size=3))
    C3 = np.asarray(sd.m2c(M3, nu3))
    np.testing.assert_allclose(C3, -C3.T, atol=1e-13)
    assert C3[0, 2] == pytest.approx(-float(M3[1, 1] * nu3[1] + M3[1, 2] * nu3[2]))


def test_rigid_body_coriolis_is_newton_euler_at_cg():
    """At the CG, C_RB(nu) nu = [m omega x v; omega x (I omega)] (Newton-Euler)."""
    m, I_g = 12.0, np.array([[1.0, 0.1, 0.0], [0.1, 2.0, -0.3], [0.0, -0.3, 3.0]])
    M = sd.rigid_body_mass_matrix(m, jnp.asarray(I_g), jnp.zeros(3))
    v, w = RNG.normal(size=3), RNG.normal(size=3)
    Cnu = np.asarray(sd.m2c(M, jnp.asarray(np.concatenate([v, w])))) @ np.concatenate([v, w])
    np.testing.assert_allclose(Cnu[:3], m * np.cross(w, v), atol=1e-12)
    np.testing.assert_allclose(Cnu[3:], np.cross(w, I_g @ w), atol=1e-12)


def test_gvect_neutral_pose_and_general_formula():
    W = B = jnp.float64(300.0)
    r = jnp.asarray([0.1, -0.2, 0.05])
    g0 = sd.gvect(W, B, jnp.float64(0.0), jnp.float64(0.0), r, r)
    np.testing.assert_array_equal(np.asarray(g0), 0.0)
    # neutral buoyancy with the CG right below the CB: upright is an equilibrium
    g_up = sd.gvect(W, B, 0.0 * W, 0.0 * W, jnp.asarray([0.0, 0.0, 0.02]), jnp.zeros(3))
    np.testing.assert_allclose(g_up, 0.0, atol=1e-15)
    # general case: -[f_g + f_b; r_g x f_g + r_b x f_b], f_g = R^T [0,0,W], f_b = -R^T [0,0,B]
    for _ in range(5):
        W, B = RNG.uniform(100, 200, size=2)
        r_g, r_b = RNG.normal(size=3) * 0.1, RNG.normal(size=3) * 0.1
        phi, theta, psi = RNG.uniform(-1.2, 1.2, size=3)
        R = _rot_z(psi) @ _rot_y(theta) @ _rot_x(phi)
        f_g, f_b = R.T @ [0, 0, W], -R.T @ [0, 0, B]
        expect = -np.concatenate([f_g + f_b, np.cross(r_g, f_g) + np.cross(r_b, f_b)])
        g = sd.gvect(
            jnp.float64(W), jnp.float64(B), jnp.float64(theta), jnp.float64(phi),
            jnp.asarray(r_g), jnp.asarray(r_b),
        )  # fmt: skip
        np.testing.assert_allclose(g, expect, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Integrated behaviour
# ---------------------------------------------------------------------------------------------


@functools.partial(jax.jit, static_argnames=("plant", "n"))
def _simulate(plant, x0, tau, args, dt, n):
    def f(t, x, a):
        return plant(t, x, tau, a), None

    def step(carry, _):
        t, x = carry
        x_next, _ = rk4(f, t, x, dt, args)
        return (t + dt, x_next), x_next

    _, xs = jax.lax.scan(step, (0.0 * dt, x0), None, length=n)
    return xs


def test_kinetic_energy_conserved_without_damping_restoring_thrust():
    p = _vehicle(damped=False, restoring=False)
    x0 = sd.sixdof_state([0.0, 0, 0, 0.1, -0.2, 0.3], [1.0, 0.3, -0.2, 0.5, -0.4, 0.6])
    tau = jnp.zeros(6)
    E0 = float(sd.kinetic_energy(p, x0.nu))
    xs = _simulate(sd.sixdof_plant, x0, tau, sd.sixdof_args(p), 0.005, 2000)
    E = jax.vmap(lambda nu: sd.kinetic_energy(p, nu))(xs.nu)
    assert np.max(np.abs(np.asarray(E) / E0 - 1.0)) < 1e-9
    # the motion is far from trivial (the energy moves between the degrees of freedom)
    assert float(jnp.max(jnp.abs(xs.nu - x0.nu))) > 0.1

    # with a constant current the relative kinetic energy 0.5 nu_r^T M nu_r is conserved
    v_c = jnp.asarray([0.4, -0.3, 0.1])
    args = sd.sixdof_args(p, WaterMotion(v_c, None))
    xs = _simulate(sd.sixdof_plant, x0, tau, args, 0.005, 2000)

    def E_rel(eta, nu):
        nu_c, _ = sd.current_in_body(eta, nu, v_c)
        return sd.kinetic_energy(p, nu - nu_c)

    Er0 = float(E_rel(x0.eta, x0.nu))
    Er = jax.vmap(E_rel)(xs.eta, xs.nu)
    assert np.max(np.abs(np.asarray(Er) / Er0 - 1.0)) < 1e-9


def test_vehicle_drifts_with_time_varying_current():
    """With nu_r = 0 and no restoring, a body carried by a uniform current moves with it."""
    p = _vehicle(damped=True, restoring=False)
    a, b = jnp.asarray([0.3, -0.2, 0.05]), jnp.asarray([0.01, 0.02, 0.0])

    def current(t):
        return a + b * t, b

    plant = sd.make_sixdof_plant(current)
    eta0 = jnp.asarray([1.0, 2.0, 3.0, 0.1, -0.2, 0.8])
    nu_c0, _ = sd.current_in_body(eta0, jnp.zeros(6), a)
    x0 = sd.sixdof_state(eta0, nu_c0)
    dt, n = 0.05, 200
    xs = _simulate(plant, x0, jnp.zeros(6), p, dt, n)
    T = dt * n
    np.testing.assert_allclose(xs.eta[-1, :3], eta0[:3] + a * T + 0.5 * b * T**2, atol=1e-10)
    np.testing.assert_allclose(xs.eta[-1, 3:], eta0[3:], atol=1e-12)


def test_restoring_equilibrium_and_damped_decay():
    """Neutrally buoyant, CG below CB, damped: a tilted vehicle returns upright and stops."""
    M_RB = sd.rigid_body_mass_matrix(
        30.0, jnp.diag(jnp.asarray([0.2, 4.0, 4.0])), jnp.asarray([0.0, 0, 0.02])
    )
    p = sd.sixdof_params(
        M_RB, np.eye(6), np.diag([5.0, 5, 5, 2, 10, 10]), 294.3, 294.3, [0, 0, 0.02], [0, 0, 0]
    )
    x0 = sd.sixdof_state([0, 0, 0, 0.3, -0.2, 0.0], np.zeros(6))
    xd = sd.sixdof_plant(0.0, sd.sixdof_state(), jnp.zeros(6), sd.sixdof_args(p))
    np.testing.assert_array_equal(np.asarray(xd.nu), 0.0)
    xs = _simulate(sd.sixdof_plant, x0, jnp.zeros(6), sd.sixdof_args(p), 0.02, 3000)
    np.testing.assert_allclose(xs.eta[-1, 3:5], 0.0, atol=1e-6)
    np.testing.assert_allclose(xs.nu[-1], 0.0, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------------


def test_validation_names_the_field():
    M_RB = np.diag([10.0, 10, 10, 1, 2, 2])
    with pytest.raises(ValueError, match="M_RB"):
        sd.sixdof_params(np.eye(5))
    with pytest.raises(ValueError, match="M_RB.*symmetric"):
        bad = M_RB.copy()
        bad[0, 4] = 1.0
        sd.sixdof_params(bad)
    with pytest.raises(ValueError, match="M_RB.*positive definite"):
        sd.sixdof_params(np.diag([10.0, 10, 10, 1, 2, -2]))
    with pytest.raises(ValueError, match="M_RB"):
        bad = M_RB.copy()
        bad[2, 2] = np.nan
        sd.sixdof_params(bad)
    with pytest.raises(ValueError, match="M_A"):
        sd.sixdof_params(M_RB, M_A=np.ones((6, 5)))
    with pytest.raises(ValueError, match=r"M_RB \+ M_A.*positive definite"):
        sd.sixdof_params(M_RB, M_A=-2.0 * np.eye(6))
    with pytest.raises(ValueError, match="D.*NaN"):
        sd.sixdof_params(M_RB, D=np.full((6, 6), np.nan))
    with pytest.raises(ValueError, match="D.*dissipative"):
        sd.sixdof_params(M_RB, D=-np.eye(6))
    with pytest.raises(ValueError, match="W"):
        sd.sixdof_params(M_RB, W=-1.0)
    with pytest.raises(ValueError, match="r_bg"):
        sd.sixdof_params(M_RB, r_bg=[0.0, 0.0])
    with pytest.raises(ValueError, match="r_bb"):
        sd.sixdof_params(M_RB, r_bb=[0.0, np.inf, 0.0])
    with pytest.raises(ValueError, match="eta"):
        sd.sixdof_state(eta=np.zeros(3))
    with pytest.raises(ValueError, match="nu"):
        sd.sixdof_state(nu=[0.0, 0, 0, 0, 0, np.nan])
    with pytest.raises(ValueError, match="velocity"):
        sd.sixdof_args(sd.sixdof_params(M_RB), WaterMotion(np.zeros(2), None))
    with pytest.raises(ValueError, match="vehicle"):
        sd.sixdof_args(M_RB)


# ---------------------------------------------------------------------------------------------
# dtypes and AD
# ---------------------------------------------------------------------------------------------


def test_float32_runs_and_agrees_with_float64():
    eta = [0.0, 0, 0, 0.1, -0.2, 0.3]
    nu = [1.0, 0.3, -0.2, 0.5, -0.4, 0.6]
    tau = [10.0, 1, -2, 0.1, 0.2, -0.3]
    out = {}
    for dt in (jnp.float32, jnp.float64):
        p = _vehicle(dtype=dt)
        args = sd.sixdof_args(p, WaterMotion([0.2, 0.1, 0.0], None))
        x0 = sd.sixdof_state(eta, nu, dtype=dt)
        xs = _simulate(sd.sixdof_plant, x0, jnp.asarray(tau, dt), args, jnp.asarray(0.01, dt), 100)
        for leaf in jax.tree_util.tree_leaves(xs):
            assert leaf.dtype == dt
            assert bool(jnp.all(jnp.isfinite(leaf)))
        out[dt] = xs
    for a, b in zip(
        jax.tree_util.tree_leaves(out[jnp.float32]),
        jax.tree_util.tree_leaves(out[jnp.float64]),
        strict=True,
    ):
        np.testing.assert_allclose(np.asarray(a, np.float64), b, rtol=1e-4, atol=1e-4)


def test_gradients_match_finite_differences():
    p = _vehicle()
    eta0 = jnp.asarray([0.0, 0, 0, 0.1, -0.2, 0.3])
    nu0 = jnp.asarray([1.0, 0.3, -0.2, 0.5, -0.4, 0.6])
    tau = jnp.asarray([10.0, 1, -2, 0.1, 0.2, -0.3])
    v_c = jnp.asarray([0.2, -0.1, 0.05])

    # the vector field, in both modes, against finite differences
    @jax.jit
    def field(eta, nu, tau, v_c):
        eta_dot, nu_dot = sd.vector_field(p, eta, nu, tau, WaterMotion(v_c, jnp.zeros(3)))
        return jnp.concatenate([eta_dot, nu_dot])

    check_grads(field, (eta0, nu0, tau, v_c), order=1, modes=["fwd", "rev"])

    # a trajectory loss (reverse mode through a scan) against central differences
    @jax.jit
    def loss(tau, d_scale, v_c):
        args = sd.SixDofArgs(p._replace(D=p.D * d_scale), WaterMotion(v_c, jnp.zeros(3)))

        def step(x, _):
            f = lambda t, y, a: (sd.sixdof_plant(t, y, tau, a), None)
            return euler(f, 0.0, x, 0.02, args)[0], None

        x, _ = jax.lax.scan(step, sd.SixDofState(eta0, nu0), None, length=50)
        return jnp.sum(x.eta**2) + sd.kinetic_energy(p, x.nu)

    d_scale = jnp.float64(1.0)
    g_tau, g_d, g_vc = jax.grad(loss, argnums=(0, 1, 2))(tau, d_scale, v_c)
    h = 1e-6
    fd = (loss(tau, d_scale + h, v_c) - loss(tau, d_scale - h, v_c)) / (2 * h)
    assert float(g_d) == pytest.approx(float(fd), rel=1e-6)
    for grad, arg in ((g_tau, 0), (g_vc, 2)):
        direction = jnp.asarray(RNG.normal(size=grad.shape))
        plus = [tau, d_scale, v_c]
        minus = [tau, d_scale, v_c]
        plus[arg] = plus[arg] + h * direction
        minus[arg] = minus[arg] - h * direction
        fd = (loss(*plus) - loss(*minus)) / (2 * h)
        assert float(grad @ direction) == pytest.approx(float(fd), rel=1e-6)
    # at rest (zero velocity, upright) the gradient is finite
    x_rest = sd.sixdof_state()
    gz = jax.jit(jax.grad(lambda nu: jnp.sum(field(x_rest.eta, nu, tau, jnp.zeros(3)))))(x_rest.nu)
    assert bool(jnp.all(jnp.isfinite(gz)))


def test_vmap_matches_loop():
    p = _vehicle()
    args = sd.sixdof_args(p)
    taus = jnp.asarray(RNG.normal(size=(4, 6)))
    x = sd.sixdof_state([0.0, 0, 0, 0.1, -0.2, 0.3], [1.0, 0.3, -0.2, 0.5, -0.4, 0.6])
    batched = jax.vmap(lambda tau: sd.sixdof_plant(0.0, x, tau, args).nu)(taus)
    for i in range(4):
        np.testing.assert_allclose(
            batched[i], sd.sixdof_plant(0.0, x, taus[i], args).nu, rtol=1e-12, atol=1e-12
        )
