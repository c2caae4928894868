"""REMUS 100 (Fossen's PythonVehicleSimulator model) validated against PVS's own trajectory.

The reference ``tests/data/remus100_pvs_reference.csv`` was produced by PythonVehicleSimulator
(commit c717e073, ``remus100('depthHeadingAutopilot', z_d=30, psi_d=50 deg, n_d=1525 rpm,
V_c=0.5 m/s, beta_c=170 deg)``, 3000 steps of 0.02 s). Row k holds the state *before* step k and
the command used in step k. Replaying the commands through :func:`pvs_step` must reproduce it.

Run ``python tests/test_remus100.py`` to print the maximum deviations.
"""

import functools
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

from vcjax.environment import WaterMotion, water_motion
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import remus100 as rm

CSV = Path(__file__).parent / "data" / "remus100_pvs_reference.csv"
DT = 0.02
POSE = ["x", "y", "z", "phi", "theta", "psi"]
VEL = ["u", "v", "w", "p", "q", "r"]
ACT = ["delta_r", "delta_s", "n_rpm"]
CMD = ["delta_r_cmd", "delta_s_cmd", "n_cmd_rpm"]


@functools.cache
def reference():
    """The CSV as a dict of float64 columns (provenance line skipped, header used)."""
    with open(CSV) as f:
        provenance = f.readline()
    assert provenance.startswith("# REMUS 100, PythonVehicleSimulator")
    data = np.genfromtxt(CSV, delimiter=",", skip_header=1, names=True, dtype=np.float64)
    return {name: data[name] for name in data.dtype.names}


def _cols(names):
    ref = reference()
    return np.stack([ref[n] for n in names], axis=1)


def _pvs_args(dtype=jnp.float64):
    return rm.remus100_args(rm.remus100_params(dtype=dtype), V_c=0.5, beta_c=math.radians(170.0))


def _x0_from_csv():
    return rm.remus100_state(_cols(POSE)[0], _cols(VEL)[0], _cols(ACT)[0])


#: One compiled scan of 3000 PVS steps, reused by every test below (same shapes, same dtype).
_jit_replay = jax.jit(rm.pvs_rollout)


def _replay(*a):
    rep = _jit_replay(*a)
    assert bool(np.all(np.asarray(rep.ok)))
    return rep.x


def deviations(xs) -> dict:
    """Max |model - reference| over all 3001 rows: position [m], angles [deg] (psi wrapped),
    body velocities [m/s, rad/s], actuator states [rad, rad, rpm]."""
    eta, nu, act = (np.asarray(a) for a in (xs.eta, xs.nu, xs.act))
    d_pos = np.abs(eta[:, :3] - _cols(POSE)[:, :3])
    d_ang = eta[:, 3:] - _cols(POSE)[:, 3:]
    d_ang[:, 2] = (d_ang[:, 2] + np.pi) % (2 * np.pi) - np.pi
    d_nu = np.abs(nu - _cols(VEL))
    d_act = np.abs(act - _cols(ACT))
    return {
        "position_m": float(np.max(np.linalg.norm(eta[:, :3] - _cols(POSE)[:, :3], axis=1))),
        "position_xyz_m": d_pos.max(axis=0).tolist(),
        "angles_deg": np.degrees(np.abs(d_ang).max(axis=0)).tolist(),
        "lin_vel_mps": d_nu[:, :3].max(axis=0).tolist(),
        "ang_vel_radps": d_nu[:, 3:].max(axis=0).tolist(),
        "delta_r_rad": float(d_act[:, 0].max()),
        "delta_s_rad": float(d_act[:, 1].max()),
        "n_rpm": float(d_act[:, 2].max()),
    }


@functools.cache
def pvs_replay_deviations() -> dict:
    """Replay the CSV's commands through ``pvs_step`` (one ``lax.scan``, float64)."""
    cmds = jnp.asarray(_cols(CMD)[:-1])  # the last row's command is never applied
    xs = _replay(_x0_from_csv(), cmds, _pvs_args(), DT)
    return deviations(xs)


@functools.partial(jax.jit, static_argnames=("n",))
def _rk4_rollout(x0, cmds, args, dt, n):
    """The continuous plant through vcjax.rollout (rk4, command held over each step)."""

    def table(t, x, z, tab):  # sampled controller: the recorded command of step k
        k = jnp.round(t / dt).astype(jnp.int32)
        return tab[k], z, None

    cfg = RolloutConfig(num_steps=n, integrator="rk4", timing="sampled")
    return rollout(rm.remus100_plant, table, cfg, args, cmds, x0, jnp.zeros(0), dt).x


_one_step = jax.jit(rm.pvs_step)


@jax.jit
def _fields(x, cmd, args):
    """Both vector fields and one PVS step (dt = 0.02), compiled once per dtype."""
    dt = jnp.asarray(DT, x.nu.dtype)
    return (
        rm.remus100_plant(0.0, x, cmd, args),
        rm.remus100_plant_smooth(0.0, x, cmd, args),
        rm.pvs_step(x, cmd, args, dt),
    )


# ---------------------------------------------------------------------------------------------
# Acceptance: PVS's own step reproduces PVS's trajectory
# ---------------------------------------------------------------------------------------------


def test_pvs_step_reproduces_reference_trajectory():
    dev = pvs_replay_deviations()
    msg = f"max deviations vs PVS reference: {dev}"
    print(msg)
    # acceptance thresholds of the task
    assert dev["position_m"] < 0.05, msg
    assert max(dev["angles_deg"]) < 0.5, msg
    # what is actually achieved: the CSV's 10 significant digits (x ~ 100 m -> ~1e-8 m)
    assert dev["position_m"] < 1e-6, msg
    assert max(dev["angles_deg"]) < 1e-6, msg
    assert max(dev["lin_vel_mps"]) < 1e-8, msg
    assert max(dev["ang_vel_radps"]) < 1e-9, msg
    assert dev["delta_r_rad"] < 1e-9 and dev["delta_s_rad"] < 1e-9, msg
    assert dev["n_rpm"] < 1e-5, msg


def test_float32_replay():
    """The same replay in float32 (measured: 0.3 mm, 1.3e-4 deg, 0.003 rpm)."""
    f32 = jnp.float32
    x0 = rm.remus100_state(_cols(POSE)[0], _cols(VEL)[0], _cols(ACT)[0], dtype=f32)
    xs = _replay(x0, jnp.asarray(_cols(CMD)[:-1], f32), _pvs_args(f32), jnp.asarray(DT, f32))
    assert xs.eta.dtype == f32
    dev = deviations(jax.tree_util.tree_map(lambda a: np.asarray(a, np.float64), xs))
    assert dev["position_m"] < 5e-3 and max(dev["angles_deg"]) < 5e-3, dev
    assert dev["n_rpm"] < 0.05, dev


def test_first_step_by_hand():
    """Step 0 from rest: only the actuators and the propeller-free forces act."""
    x0, args = _x0_from_csv(), _pvs_args()
    u0 = jnp.asarray(_cols(CMD)[0])
    x1 = _one_step(x0, u0, args, jnp.float64(DT))
    # act[1] = 0 + dt (cmd - 0) / T: 0.02 / 0.1 x cmd and 0.02 / 1.0 x 1525 rpm
    np.testing.assert_allclose(x1.act, [0.0, 0.2 * float(u0[1]), 30.5], rtol=1e-15)
    # at rest with the act state zero, the first nu comes from the current alone (nu_r != 0)
    np.testing.assert_allclose(x1.nu, _cols(VEL)[1], rtol=1e-9, atol=1e-15)


# ---------------------------------------------------------------------------------------------
# The continuous-time plant, integrated with RK4
# ---------------------------------------------------------------------------------------------


def test_continuous_plant_rk4_close_to_reference():
    """RK4 on the vector field vs PVS's forward Euler at the same dt.

    The difference is PVS's own discretisation error, not a model difference: it equals the
    Richardson estimate ``2 (x_{dt/2} - x_dt)`` of the Euler scheme's error (measured: 0.0457 m
    for RK4 vs 0.0458 m estimated; velocities, angles and actuators agree just as closely).
    The tolerances are about twice that error.
    """
    cmds = _cols(CMD)[:-1]
    args = _pvs_args()
    xs = _rk4_rollout(_x0_from_csv(), jnp.asarray(cmds), args, jnp.float64(DT), n=len(cmds))
    dev = deviations(xs)
    msg = f"rk4 plant vs PVS reference: {dev}"
    print(msg)
    assert dev["position_m"] < 0.1, msg
    assert max(dev["angles_deg"]) < 0.1, msg
    assert max(dev["lin_vel_mps"]) < 0.02, msg
    assert max(dev["ang_vel_radps"]) < 2e-3, msg
    assert dev["delta_r_rad"] < 2e-4 and dev["delta_s_rad"] < 6e-3, msg
    assert dev["n_rpm"] < 12.0, msg

    # Euler's own error: the same scheme at dt/2 (commands held for two half steps)
    half = jax.jit(rm.pvs_rollout)(
        _x0_from_csv(), jnp.asarray(np.repeat(cmds, 2, axis=0)), args, DT / 2
    ).x
    full = _replay(_x0_from_csv(), jnp.asarray(cmds), args, DT)
    est = 2.0 * np.linalg.norm(np.asarray(half.eta[::2, :3] - full.eta[:, :3]), axis=1).max()
    assert 0.5 * est < dev["position_m"] < 1.5 * est, (est, msg)


# ---------------------------------------------------------------------------------------------
# Steady state, numbers, conventions
# ---------------------------------------------------------------------------------------------


def _steady_surge_speed_independent(n_rpm=1525.0):
    """Solve the pure-surge balance with the vehicle data (docs/reference/vehicles.md)'s formulas, typed in here.

    (1 - t) X_prop(u) = 0.5 rho S CD_0 u^2 + exp(-3u) M11 / T_surge u, with
    X_prop = rho D^4 (KT_0 n^2 + (KT_max - KT_0) / Ja_max (0.944 u / D) n), n in rps.
    """
    rho, L, diam = 1026.0, 1.6, 0.19
    S = 0.7 * L * diam
    CD_0 = 0.42 * math.pi * (diam / 2) ** 2 / S
    M11 = 31.86829  # the vehicle data (docs/reference/vehicles.md): m + m k1
    n, Dp = n_rpm / 60.0, 0.14

    def thrust(u):
        return rho * Dp**4 * (0.4566 * n * n + (0.1798 - 0.4566) / 0.6632 * (0.944 * u / Dp) * n)

    def balance(u):
        return 0.9 * thrust(u) - 0.5 * rho * S * CD_0 * u * u - M11 / 20.0 * math.exp(-3 * u) * u

    u = brentq(balance, 0.1, 5.0, xtol=1e-14)
    K = rho * Dp**5 * (0.0700 * n * n + (0.0312 - 0.0700) / 0.6632 * (0.944 * u / Dp) * n)
    return u, K


def test_steady_surge_speed_at_1525_rpm():
    u_star, K_prop = _steady_surge_speed_independent()
    assert u_star == pytest.approx(
        2.55, abs=0.01
    )  # the vehicle data (docs/reference/vehicles.md) [DER]: 2.55 m/s
    # 60 s of calm water from rest at 1525 rpm (same compiled scan as the acceptance test)
    calm = rm.remus100_args(rm.remus100_params())
    cmds = jnp.tile(jnp.asarray([0.0, 0.0, 1525.0]), (3000, 1))
    xs = _replay(rm.remus100_state(), cmds, calm, DT)
    x_end = jax.tree_util.tree_map(lambda a: np.asarray(a[-1]), xs)
    assert x_end.nu[0] == pytest.approx(u_star, abs=1e-6)
    np.testing.assert_allclose(x_end.nu[2:], 0.0, atol=1e-8)
    # The roll transient of the propeller spin-up (K_prop, coupled through M[1, 3] = -m z_g)
    # leaves a tiny sway speed that decays only through the faded linear and the quadratic
    # cross-flow drag (time constant of minutes at this size), hence the looser bound.
    assert abs(x_end.nu[1]) < 1e-3
    # the propeller's roll moment K_prop / 10 is balanced by the restoring moment z_g W sin(phi)
    W = 4 / 3 * math.pi * 1026.0 * 0.8 * 0.095**2 * 9.81
    assert x_end.eta[3] == pytest.approx(math.asin(0.1 * K_prop / (0.02 * W)), abs=1e-6)
    assert abs(x_end.eta[4]) < 1e-6
    print("steady state:", u_star, x_end.eta, x_end.nu)
    np.testing.assert_allclose(x_end.act, [0.0, 0.0, 1525.0], atol=1e-9)


def test_parameters_match_vehicles_md():
    p = rm.remus100_params()
    b = p.body
    M = np.asarray(b.M_RB + b.M_A)
    np.testing.assert_allclose(b.M_RB[0, 0], 31.029384, rtol=1e-6)
    np.testing.assert_allclose(
        np.diag(M), [31.86829, 60.46702, 60.46702, 0.15803, 7.46639, 7.45398], rtol=2e-5
    )
    np.testing.assert_allclose(
        [M[0, 4], M[4, 0], M[1, 3], M[3, 1]], [0.62059, 0.62059, -0.62059, -0.62059], rtol=2e-5
    )
    np.testing.assert_allclose(
        np.diag(np.asarray(b.D)), [1.59341, 3.02335, 3.02335, 0.58852, 10.78727, 7.45398], rtol=2e-5
    )
    np.testing.assert_allclose(
        np.diag(np.asarray(b.M_A)),
        [0.83891, 29.43764, 29.43764, 0.03360, 3.42621, 3.42621],
        rtol=2e-4,
    )
    assert float(p.CD_0) == pytest.approx(0.055960, rel=1e-4)
    assert rm.hoerner(0.19, 0.19) == pytest.approx(1.19773, rel=1e-5)
    # equivalent pure-sway / pure-yaw cross-flow coefficients (the vehicle data (docs/reference/vehicles.md): -196.13, -28.93)
    z = jnp.zeros(6)
    Y = rm.crossflow_drag(p, z.at[1].set(1.0))[1]
    N = rm.crossflow_drag(p, z.at[5].set(1.0))[5]
    assert float(Y) == pytest.approx(-196.13, rel=1e-4)
    assert float(N) == pytest.approx(-28.93, rel=1e-3)
    # rudder / stern-plane gains at U = 1 m/s (the vehicle data (docs/reference/vehicles.md): -3.4115, +2.7292, -4.7760, -3.8208)
    tau = rm.control_forces(p, z, z.at[0].set(1.0), jnp.asarray([1.0, 0.0, 0.0]))
    assert float(tau[1]) == pytest.approx(-3.4115, rel=1e-4)
    assert float(tau[5]) == pytest.approx(2.7292, rel=1e-4)
    tau = rm.control_forces(p, z, z.at[0].set(1.0), jnp.asarray([0.0, 1.0, 0.0]))
    assert float(tau[2]) == pytest.approx(-4.7760, rel=1e-4)
    assert float(tau[4]) == pytest.approx(-3.8208, rel=1e-4)
    # bollard thrust at 1525 rpm: 116.3 N; at 2.5 m/s: 45.8 N
    assert float(rm.propeller(p, 1525.0, 0.0)[0]) == pytest.approx(116.3, abs=0.1)
    assert float(rm.propeller(p, 1525.0, 2.5)[0]) == pytest.approx(45.8, abs=0.1)


def test_coriolis_zeroed_entries_and_skew_symmetry():
    p = rm.remus100_params()
    nu_r = jnp.asarray([1.5, 0.2, -0.1, 0.3, -0.2, 0.4])
    C = np.asarray(rm.coriolis(p, nu_r))
    np.testing.assert_allclose(C, -C.T, atol=1e-13)
    from vcjax.vehicles.sixdof import m2c

    C_A_full = np.asarray(m2c(p.body.M_A, nu_r))
    C_RB = np.asarray(m2c(p.body.M_RB, nu_r))
    for i, j in rm.CA_ZEROED:
        assert C[i, j] == pytest.approx(C_RB[i, j], abs=1e-15)
        assert C_A_full[i, j] != 0.0  # PVS really removes something here


def test_current_conventions():
    p = rm.remus100_params()
    beta = math.radians(170.0)
    a1 = rm.remus100_args(p, V_c=0.5, beta_c=beta)
    a2 = rm.remus100_args(p, water=water_motion([0.5 * math.cos(beta), 0.5 * math.sin(beta), 0]))
    np.testing.assert_allclose(a1.water.velocity, a2.water.velocity, atol=1e-16)
    w_c, w_c_dot = a1.water.velocity[:2], a1.water.acceleration[:2]
    psi, r = 0.7, 0.05
    eta = jnp.zeros(6).at[5].set(psi)
    nu = jnp.zeros(6).at[5].set(r)
    nu_c, nu_c_dot = rm.current_in_body(eta, nu, w_c, w_c_dot)
    u_c, v_c = 0.5 * math.cos(beta - psi), 0.5 * math.sin(beta - psi)  # PVS's formula
    np.testing.assert_allclose(nu_c, [u_c, v_c, 0, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(nu_c_dot, [r * v_c, -r * u_c, 0, 0, 0, 0], atol=1e-15)
    # PVS rotates by yaw only: roll and pitch do not change nu_c
    nu_c2, _ = rm.current_in_body(eta.at[3].set(0.3).at[4].set(-0.2), nu, w_c)
    np.testing.assert_allclose(nu_c2, nu_c, atol=1e-15)


def test_actuator_saturation_as_pvs():
    p = rm.remus100_params()
    args = rm.remus100_args(p)
    lim = np.asarray(p.act_max)
    x = rm.remus100_state(nu=[1.0, 0, 0, 0, 0, 0], act=[0.5, -0.5, 2000.0])
    cmd = jnp.asarray([0.4, -0.1, 1800.0])
    x1 = _one_step(x, cmd, args, jnp.float64(DT))
    sat = np.array([lim[0], -lim[1], lim[2]])
    np.testing.assert_allclose(
        x1.act, sat + DT * (np.asarray(cmd) - sat) / np.asarray(p.T_act), rtol=1e-15
    )
    # the forces see the clipped state: same nu as a state sitting exactly at the limits
    x1b = _one_step(x._replace(act=jnp.asarray(sat)), cmd, args, jnp.float64(DT))
    np.testing.assert_array_equal(np.asarray(x1.nu), np.asarray(x1b.nu))
    # continuous plant: no windup at a limit, free to move back inside
    xs = x._replace(act=jnp.asarray(sat))
    d_out = _fields(xs, cmd, args)[0].act
    np.testing.assert_allclose(d_out, [0.0, (-0.1 + lim[1]) / 0.1, 0.0], atol=1e-15)
    d_in = _fields(xs, jnp.asarray([0.0, 0.0, 1000.0]), args)[0].act
    np.testing.assert_allclose(d_in, [-lim[0] / 0.1, lim[1] / 0.1, (1000.0 - lim[2]) / 1.0])


def test_validation_names_the_field():
    with pytest.raises(ValueError, match="r_bg"):
        rm.remus100_params(r_bg=[0.0, 0.02])
    with pytest.raises(ValueError, match="r_bg.*below"):
        rm.remus100_params(r_bg=[0.0, 0.0, -0.01])
    with pytest.raises(ValueError, match="rho"):
        rm.remus100_params(rho=float("nan"))
    with pytest.raises(ValueError, match="T_n"):
        rm.remus100_params(T_n=0.0)
    with pytest.raises(ValueError, match="delta_max_deg"):
        rm.remus100_params(delta_max_deg=95.0)
    with pytest.raises(ValueError, match="act"):
        rm.remus100_state(act=[0.0, 0.0])
    with pytest.raises(ValueError, match="eta"):
        rm.remus100_state(eta=[0.0] * 5 + [float("inf")])
    with pytest.raises(ValueError, match="velocity"):
        rm.remus100_args(rm.remus100_params(), water=WaterMotion([0.1, 0.2], None))
    with pytest.raises(ValueError, match="vehicle"):
        rm.remus100_args(None)


def test_float32_and_gradients_at_rest():
    for dt in (jnp.float32, jnp.float64):
        args = _pvs_args(dt)
        x = rm.remus100_state(dtype=dt)
        cmd = jnp.asarray([0.05, -0.05, 1000.0], dtype=dt)
        out = _fields(x, cmd, args)
        for leaf in jax.tree_util.tree_leaves(out):
            assert leaf.dtype == dt and bool(jnp.all(jnp.isfinite(leaf)))
    # from rest in calm water (U = U_r = 0, alpha undefined) the gradients are finite
    calm = rm.remus100_args(rm.remus100_params())

    def loss(state, cmd):
        f = rm.remus100_plant(0.0, state, cmd, calm)
        return sum(jnp.sum(leaf**2) for leaf in jax.tree_util.tree_leaves(f))

    g = jax.jit(jax.grad(loss, argnums=(0, 1)))(rm.remus100_state(), jnp.asarray([0.0, 0.0, 0.0]))
    for leaf in jax.tree_util.tree_leaves(g):
        assert bool(jnp.all(jnp.isfinite(leaf)))
    # smooth-saturation variant: same field for small commands inside the limits
    x = rm.remus100_state(nu=[1.0, 0.1, 0.0, 0, 0, 0.05], act=[0.01, -0.02, 800.0])
    c = jnp.asarray([0.0, 0.0, 800.0])
    hard, smooth, _ = _fields(x, c, calm)
    np.testing.assert_allclose(smooth.nu, hard.nu, rtol=1e-12)
    lim, T = np.asarray(calm.vehicle.act_max), np.asarray(calm.vehicle.T_act)
    np.testing.assert_allclose(smooth.act, (lim * np.tanh(np.asarray(c) / lim) - x.act) / T)


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_numpy_dtype_promotion", "strict")
    for k, v in pvs_replay_deviations().items():
        print(f"{k:>15}: {v}")
