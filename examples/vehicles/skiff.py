"""A marine vehicle of your own: a small fully actuated surface craft (55 kg, two azimuth
thrusters) in the horizontal plane, written the way Fossen writes a 3-DOF craft — rigid-body
and added mass, Coriolis and centripetal forces, linear and quadratic drag on the velocity
relative to the water (so the current reaches it), body-frame thrust limits — held on a path by
the paper's VCM law through the generic engine: the point 1 m ahead of its centre follows the
path, and the hull trails behind it like a towed boat. Registered as vehicle "skiff" (the last
line). Configs load this file with ``[scenario] module = "../vehicles/skiff.py"`` (relative to
the config file); Python imports it.

    vcjax sweep examples/sweeps/own_vehicle.toml --out out/sweep-own-vehicle
    vcjax tune examples/tuning/own_vehicle.toml --out out/tune-own-vehicle
"""

import dataclasses
from typing import Any, ClassVar, NamedTuple

import jax.numpy as jnp

from vcjax import loops, paths
from vcjax.linalg import saturate, smooth_saturate


class SkiffParams(NamedTuple):
    m: Any  # () mass [kg]
    Iz: Any  # () yaw moment of inertia [kg m^2]
    a_u: Any  # () surge added mass, -X_udot [kg]
    a_v: Any  # () sway added mass, -Y_vdot [kg]
    a_r: Any  # () yaw added inertia, -N_rdot [kg m^2]
    X_u: Any  # () linear surge drag [kg/s]
    Y_v: Any  # () linear sway drag [kg/s]
    N_r: Any  # () linear yaw drag [kg m^2/s]
    X_uu: Any  # () quadratic surge drag [kg/m]
    Y_vv: Any  # () quadratic sway drag [kg/m]
    N_rr: Any  # () quadratic yaw drag [kg m^2]
    L: Any  # () distance of the point that follows the path ahead of the centre [m]
    tau_max: Any  # (3,) thrust limits: surge [N], sway [N], yaw [N m], in the body frame


def rotation(psi):
    """T(psi): body velocities (u, v, r) -> NED rates (x_dot, y_dot, psi_dot)."""
    c, s, o, i = jnp.cos(psi), jnp.sin(psi), jnp.zeros_like(psi), jnp.ones_like(psi)
    return jnp.stack([jnp.stack([c, -s, o]), jnp.stack([s, c, o]), jnp.stack([o, o, i])])


@dataclasses.dataclass(frozen=True)
class SkiffLoop(loops.EngineLoop):
    """q = (x north, y east, psi) [m, m, rad]; the engine's generalised forces are NED forces
    and the yaw moment, tau_ned = T(psi) tau_body."""

    vehicle: ClassVar[str] = "skiff"
    initial_keys: ClassVar[dict[str, float]] = {
        "x": 0.0,
        "y": 0.0,
        "heading_deg": 0.0,
        "speed": 0.0,  # surge speed over ground at the start [m/s]
    }
    default_speed: ClassVar[float] = 1.0  # m/s along the path

    @classmethod
    def default_path(cls):
        return paths.line(origin=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0))  # due north

    def default_params(self, dtype=None):
        f = lambda x: jnp.asarray(x, dtype)
        return SkiffParams(
            m=f(55.0), Iz=f(15.0), a_u=f(5.0), a_v=f(40.0), a_r=f(8.0),
            X_u=f(20.0), Y_v=f(60.0), N_r=f(15.0), X_uu=f(10.0), Y_vv=f(80.0), N_rr=f(10.0),
            L=f(1.0), tau_max=f([100.0, 60.0, 40.0]),
        )  # fmt: skip

    def mass_matrix(self, q, p):  # M(q) = T M_body T^T
        T = rotation(q[2])
        return T @ jnp.diag(jnp.stack([p.m + p.a_u, p.m + p.a_v, p.Iz + p.a_r])) @ T.T

    def bias_force(self, q, qd, p):  # n(q, qd): qd is the velocity relative to the water here
        T = rotation(q[2])
        u, v, r = T.T @ qd
        m11, m22 = p.m + p.a_u, p.m + p.a_v
        # body frame: C(nu) nu - M T^T T_dot nu (the NED coordinates' own term) + D(nu) nu
        coriolis = jnp.stack([(m11 - m22) * v * r, (m11 - m22) * u * r, (m22 - m11) * u * v])
        drag = jnp.stack(
            [(p.X_u + p.X_uu * jnp.abs(u)) * u, (p.Y_v + p.Y_vv * jnp.abs(v)) * v,
             (p.N_r + p.N_rr * jnp.abs(r)) * r]
        )  # fmt: skip
        return T @ (coriolis + drag)

    def point(self, q, p):  # what follows the path: the point L ahead of the centre
        return q[:2] + p.L * jnp.stack([jnp.cos(q[2]), jnp.sin(q[2])])

    def water_velocity(self, q, current, p):  # the water moves the hull, it does not turn it
        return jnp.stack([current[0], current[1], jnp.zeros_like(current[0])])

    def plant(self, t, x, u, args):  # the engine's plant, with the thrust limits in the body frame
        p, (q, qd) = args.params, x
        T = rotation(q[2])
        sat = smooth_saturate if self.smooth else saturate  # smooth while tuning, if asked
        tau = T @ sat(T.T @ u, p.tau_max) + args.disturbance
        qd_r = qd - self.water_velocity(q, args.water.velocity, p)  # relative to the water
        return qd, jnp.linalg.solve(self.mass_matrix(q, p), tau - self.bias_force(q, qd_r, p))

    def signals(self, traj, sc):  # commands as the thrusters see them
        n = traj.u.shape[0]
        Ts = jnp.vectorize(rotation, signature="()->(3,3)")(traj.x[0][:n, 2])
        u_body = jnp.einsum("kji,kj->ki", Ts, traj.u)  # T^T u at every step
        tau_max = sc.plant.tau_max
        s = super().signals(traj, sc)
        return s._replace(
            cmd_ratio=u_body / tau_max,
            sat=jnp.any(jnp.abs(u_body) > tau_max, axis=1),
            act={"thrust": jnp.max(jnp.abs(u_body[:, :2]), axis=1)},  # [N]
        )

    def initial_from(self, v):  # [initial] keys -> (q0, qd0); heading already in radians
        q0 = jnp.stack([v["x"], v["y"], v["heading_deg"]])
        return q0, rotation(q0[2]) @ jnp.stack([v["speed"], 0.0 * v["speed"], 0.0 * v["speed"]])


loops.register(SkiffLoop)  # the one registry line
