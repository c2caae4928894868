"""Simulation 2 (ODIN-class, VCM + depth loop + allocation): straight-line convergence, the
sideslip offset of an underactuated craft, the paper's helix run with its figures and metrics.

Bounds are derived, not fitted (see the docstrings); horizons are 150 s at dt = 0.1 s (RK4
results agree with dt = 0.05 s to 4 digits), one compiled loop per path kind.
"""

import math

import jax
import numpy as np
import pytest

from vcjax import experiments, loops, paths
from vcjax.rollout import RolloutConfig
from vcjax.vehicles import odin

SIM2 = experiments.get("sim2")

# a descending straight line 3 m east of the start, 2 m below it, heading north
LINE, LINE_COEFFS = paths.line(origin=(0.0, 3.0, -100.0), direction=(1.0, 0.0, 0.05))
HORIZON, DT = 150.0, 0.1


def _line_run(tau_dist):
    """Simulation 2's start (the experiment's scenario) on ``LINE`` instead of the helix."""
    loop = loops.make_loop("odin", "vcm", path=LINE)
    paper = SIM2.scenario("underactuated")
    sc = loops.make_scenario(
        loop,
        LINE_COEFFS,
        eta0=paper.eta0,
        nu0=paper.nu0,
        u_d=paper.u_d,
        plant=paper.plant,
        disturbance=np.concatenate([tau_dist, np.zeros(3)]),
        varpi0=0.0,
    )
    cfg = RolloutConfig(num_steps=int(round(HORIZON / DT)))
    return jax.device_get(experiments.rollout(loop, loop.default_gains(), sc, cfg, DT)), sc


def test_straight_line_underactuated_converges_without_disturbance():
    """Corollary 3: on a straight path without disturbance the underactuated craft converges
    to the path and v -> 0; depth follows z_p(w) (feed-forward through the particle rate)."""
    tr, _ = _line_run((0.0, 0.0, 0.0))
    assert np.all(tr.finite)
    k = int(120.0 / DT)
    dist = np.linalg.norm(tr.aux.p_err[k:], axis=1)
    assert dist.max() < 0.05
    assert np.abs(tr.aux.vcm.eps[k:, 1]).max() < 1e-3
    assert np.abs(tr.aux.depth_err[k:]).max() < 2e-3
    assert np.abs(tr.x.nu[k:, 1]).max() < 1e-3
    assert not np.any(tr.aux.alloc_saturated[k:])
    # the initial 8 m approach never asked for more than the thrusters give
    assert np.all(tr.aux.alloc_feasible)


def test_straight_line_sideslip_offset_under_sway_disturbance():
    """The paper's sideslip argument, quantitatively. With tau_v = 0 a constant sway force F is
    balanced by sway drag only: v (D_v + k U) = F. The craft then crabs; on a straight path
    e_dot = 0 needs the velocity over ground along the path, tan(gamma) = -v/u with
    gamma = psi_r + psi~ = atan(-e/Delta) + psi~, i.e. e = Delta tan(atan(v/u) + psi~) — about
    Delta v/u. The paper's designed e_ddot (edd="paper") leaves a steady heading offset: r_dot = 0
    needs p_G1 p_Phi3 psi~ = psi_r_ddot = kappa P_eps1 e, kappa = Delta / (Delta^2 + e^2)."""
    tr, sc = _line_run((0.0, 5.0, 0.0))
    u, v = float(tr.x.nu[-1, 0]), float(tr.x.nu[-1, 1])
    e = float(tr.aux.vcm.eps[-1, 1])
    psi_t = float(tr.aux.vcm.psi_tilde[-1])
    veh = sc.plant
    U = math.hypot(u, v)
    assert v == pytest.approx(5.0 / (float(veh.body.D[1, 1]) + float(veh.drag_coeff) * U), rel=0.01)
    g = SIM2.default_gains("underactuated").vcm
    Delta = float(g.Delta)
    assert e == pytest.approx(Delta * math.tan(math.atan(v / u) + psi_t), rel=0.01)
    assert e == pytest.approx(Delta * v / u, rel=0.12)
    kappa = Delta / (Delta**2 + e**2)
    P_eps1 = float(g.P_G[2] * g.P_Phi[4])
    assert psi_t == pytest.approx(kappa * P_eps1 * e / float(g.P_G[0] * g.P_Phi[2]), rel=0.1)


def test_helix_run_sim2_figures_metrics_and_error_bound(tmp_path):
    """The paper's scenario (underactuated, tau_dist = [0, 5, 0] N, helix), 150 s.

    Bound on the 3-D distance after 30 s (the first 20 %): the same sideslip argument, with the
    centripetal term: in a turn v (D_v + k U) = F + m11 u r, |r| <= u kappa_max,
    kappa_max = a / b^2 = 10/64 1/m, so v <= (5 + 174 * 0.5^2 * 0.156) / (8.7 + 68 * 0.55)
    = 0.25 m/s and |e| ~ Delta v / u <= 1.0 m; plus the heading offset above (~0.05 rad ->
    0.1 m) and small s and depth errors: ~1.15 m. The test allows 1.5 m (measured: 1.06 m).
    """
    setup = SIM2.setup(horizon=HORIZON, dt=DT)
    traj = jax.device_get(SIM2.simulate("underactuated", setup))
    outcome = SIM2.outcome("underactuated", setup, traj)
    m = SIM2.report({"underactuated": SIM2.metrics(outcome, setup)}, setup)
    assert m["actuation"] == "underactuated" and m["healthy"]
    for key in ("rms_dist_3d", "max_dist_3d", "rms_depth_err", "thruster_sat_fraction"):
        assert key in m and math.isfinite(m[key])
    assert m["max_dist_3d"] < 1.5
    assert 0.5 < m["rms_dist_3d"] < 1.2  # the sideslip offset is real: not zero either
    # the depth transient from 2 m off (PID, omega_n = 0.3 rad/s, zeta = 1, plus integral
    # overshoot: 0.47 m at 20 s, 0.14 m at 40 s) is still inside the 30 s..150 s window
    assert m["rms_depth_err"] < 0.1
    assert m["alloc_infeasible_fraction"] == 0.0
    assert 15.0 < m["mean_abs_sideslip_deg"] < 30.0
    files = SIM2.figures({"underactuated": outcome}, setup, tmp_path)
    for f in files:
        assert f.exists() and f.stat().st_size > 0
    assert {f.name for f in files} >= {"sim2_path_3d.png", "sim2_errors.png"}


def test_validation_names_the_field():
    with pytest.raises(ValueError, match="actuation"):
        SIM2.setup(actuation="sway")
    with pytest.raises(ValueError, match="actuation"):
        SIM2.loop("both")
    with pytest.raises(ValueError, match="depth"):
        loops.odin_gains(depth=(0.01, 0.1, 0.01))  # k_d k_p < k_i: unstable PID
    with pytest.raises(ValueError, match="attitude"):
        loops.odin_gains(attitude=(10.0, -1.0))
    loop = SIM2.loop("underactuated")
    with pytest.raises(ValueError, match="eta0"):
        loops.make_scenario(loop, eta0=(0.0, 0.0))
    with pytest.raises(ValueError, match="disturbance"):
        loops.make_scenario(loop, disturbance=(0.0, 5.0))
    with pytest.raises(ValueError, match="u_d"):
        loops.make_scenario(loop, u_d=0.0)


def test_design_model_is_derived_from_the_plant():
    sc = SIM2.scenario()
    dm = odin.design_model(sc.plant, sc.u_d)
    assert float(dm.m11) == pytest.approx(float(odin.mass_matrix(sc.plant)[0, 0]))


@pytest.mark.slow
def test_fully_actuated_helix_converges_to_the_path():
    """With sway thrust (v_d = 0) and integral action on both eps components, the disturbance
    is rejected and the craft converges to the helix (measured: 2.6 mm at 300 s)."""
    setup = SIM2.setup(horizon=300.0, dt=DT)
    tr = jax.device_get(SIM2.simulate("full", setup))
    m = SIM2.metrics(SIM2.outcome("full", setup, tr), setup)
    d = np.linalg.norm(tr.aux.p_err, axis=1)
    assert d[-1] < 0.01
    assert m["rms_dist_3d"] < 0.2
    assert m["rms_depth_err"] < 0.01
