"""REMUS 100 under the 3-D VCM law, one error channel at a time (loops layer, PVS plant).

A straight level line (azimuth 30 deg, depth 10 m) and four starts on it: nominal (on the path,
aligned, at the desired speed), a pure sideways (cross-track) offset, a pure depth offset and a
pure speed error. Each excited channel must be driven back while the others stay where the
nominal run leaves them, each checked by its own assertion. The gains differ between the
horizontal and the vertical channel (heading poles 1.2 and 2.0 rad/s, pitch 0.4 and 0.6 rad/s,
look-ahead 6 m and 10 m), so a row, index or sign swapped between the channels changes what is
measured; the ILOS and integral gains are zero, so the law is the paper's LOS-angle law and the
attitude errors follow their designed two-pole response (the heading and pitch rows hold
exactly on the design model, ``tests/test_vcm3d.py``).

References that do not come from the code under test:

* the start: ``psi~(0) = atan(e0 / Delta_h)`` and ``theta~(0) = -atan(h0 / Delta_v)`` (the
  approach angles (24) at the offset, with ``psi = psi_p`` and ``theta = theta_p``);
* the attitude error of the excited channel: ``(s + p_G)(s + p_Phi) x = 0`` from ``x(0)`` with
  ``x'(0) = 0`` (the vehicle starts aligned and the offset does not yet change), i.e.
  ``x(t) = x0 (p_Phi exp(-p_G t) - p_G exp(-p_Phi t)) / (p_Phi - p_G)``. The PVS plant is not
  the design model: the propeller starts at 1000 rpm, above its steady 893 rpm at 1.5 m/s, and
  the surge transient this causes tilts the pitch by up to 0.008 rad in every run (through the
  surge-pitch added mass and the lagging propeller). That transient is the nominal run's, so
  the comparison is made on the difference to the nominal run (measured: 3.6 % of ``psi~(0)``
  for the heading, 2.6 % of ``theta~(0)`` for the pitch; swapping the heading and pitch gains
  gives 35 % and 26 %).
* the free desired sway and heave ``v_d``, ``w_d`` (underactuation): they move with the sway
  and heave the plant really has (measured correlation 0.96 and 0.86), each in its own channel;
* the position errors: a contraction by a stated factor within the 30 s horizon, without
  growing past the start (the vehicle's sideslip and angle of attack make the LOS rate
  ``U / Delta`` only an upper bound on the rate).

The exact least-squares dynamics of the linear rows (``u, v, w, s, e, h``) per channel are
tested on the design model in ``tests/test_vcm3d.py``; on the underactuated vehicle the sway
and heave rows are absorbed by the free ``v_d``, ``w_d`` and the cross-track and depth rows by
the fins, so only the attitude rows and the look-ahead set the channels' rates here.
"""

import functools

import jax
import numpy as np
import pytest

from vcjax import loops, paths
from vcjax.control.vcm3d import vcm3d_gains
from vcjax.rollout import RolloutConfig

AZ = 0.5  # path azimuth [rad]
DEPTH = 10.0  # path depth [m]
LINE, LINE_C = paths.line(origin=(0.0, 0.0, DEPTH), direction=(np.cos(AZ), np.sin(AZ), 0.0))
#: path frame at the start: along-track, cross-track (to starboard of the path), down
T_HAT = np.array([np.cos(AZ), np.sin(AZ), 0.0])
N_HAT = np.array([-np.sin(AZ), np.cos(AZ), 0.0])
START = 20.0 * T_HAT + np.array([0.0, 0.0, DEPTH])
U_D = 1.5
DT, STEPS = 0.1, 300  # 30 s
LOOP = loops.make_loop("remus100", "vcm3d_ilos", path=LINE)

P_G = np.array([1.2, 0.4, 0.3, 0.35, 0.15])  # psi, theta, s, e, h
P_PHI = np.array([0.5, 0.3, 0.6, 2.0, 0.6, 0.4, 0.45, 0.25])  # u, v, w, psi, theta, s, e, h
DELTA = np.array([6.0, 10.0])  # horizontal, vertical
E0, H0, U0 = 0.5, 2.0, 1.2  # sideways offset [m], depth offset [m], initial speed [m/s]


@functools.cache
def _simulate():
    conf = RolloutConfig(num_steps=STEPS)
    return jax.jit(lambda gains, sc: loops.simulate(LOOP, gains, sc, conf, DT))


def _gains():
    g = vcm3d_gains(
        P_G=P_G, P_Phi=P_PHI, Delta=DELTA, sigma=0.3, k_int=(0.0, 0.0, 0.0), sigma_i=(0.0, 0.0)
    )
    return LOOP.default_gains()._replace(vcm3d=g)


@functools.cache
def run(case: str) -> dict:
    """Time histories of one start (one compiled program for all four)."""
    offset, speed = {
        "nominal": (np.zeros(3), U_D),
        "sideways": (E0 * N_HAT, U_D),
        "depth": (np.array([0.0, 0.0, H0]), U_D),
        "speed": (np.zeros(3), U0),
    }[case]
    p0 = START + offset
    initial = dict(x=p0[0], y=p0[1], z=p0[2], heading_deg=np.degrees(AZ), speed=speed)
    sc = loops.make_scenario(LOOP, LINE_C, initial=initial, u_d=U_D)
    tr = _simulate()(_gains(), sc)
    assert bool(np.all(np.asarray(tr.finite)))
    sig = LOOP.signals(tr, sc)
    return {
        "t": np.asarray(tr.t[:-1]),
        "s": np.asarray(sig.eps[:, 0]),
        "e": np.asarray(sig.eps[:, 1]),
        "h": np.asarray(sig.depth_err),
        "u": np.asarray(sig.u_err),
        "psi": np.asarray(sig.psi_err),
        "theta": np.asarray(tr.x.eta[:-1, 4] - tr.aux.theta_d),
        "sat": bool(np.any(np.asarray(sig.sat))),
        "v": np.asarray(tr.x.nu[:-1, 1]),
        "w": np.asarray(tr.x.nu[:-1, 2]),
        "v_d": np.asarray(tr.z.v_d[:-1]),
        "w_d": np.asarray(tr.z.w_d[:-1]),
    }


def two_pole(x0, p_G, p_Phi, t):
    """``(s + p_G)(s + p_Phi) x = 0``, ``x(0) = x0``, ``x'(0) = 0``."""
    return x0 * (p_Phi * np.exp(-p_G * t) - p_G * np.exp(-p_Phi * t)) / (p_Phi - p_G)


def _max(x):
    return float(np.max(np.abs(x)))


def test_nominal_start_stays_on_the_path():
    """On the path, aligned, at speed: only the propeller's spin-down transient, and nothing
    in the horizontal plane (the vehicle is symmetric about its vertical plane)."""
    r = run("nominal")
    assert _max(r["e"]) < 1e-3 and _max(r["psi"]) < 1e-4
    assert _max(r["h"]) < 0.06 and _max(r["theta"]) < 0.012
    assert _max(r["s"]) < 0.2 and _max(r["u"]) < 0.1
    assert not r["sat"]


def test_sideways_offset_is_driven_back_by_the_heading_channel():
    r, nom = run("sideways"), run("nominal")
    t, e, psi = r["t"], r["e"], r["psi"]
    # geometry of the start: the offset is cross-track, and the approach angle is Delta_h's
    assert e[0] == pytest.approx(E0, abs=1e-12)
    assert r["s"][0] == pytest.approx(0.0, abs=1e-12) and r["h"][0] == pytest.approx(0.0, abs=1e-12)
    assert psi[0] == pytest.approx(np.arctan(E0 / DELTA[0]), abs=1e-12)
    # the heading error follows its designed two-pole response (p_G,psi, p_Phi,psi)
    dev = psi - nom["psi"] - two_pole(psi[0], P_G[0], P_PHI[3], t)
    assert _max(dev) < 0.1 * psi[0], _max(dev) / psi[0]
    # the cross-track error is driven back: the rudder's own force first pushes the vehicle
    # out (non-minimum phase: 0.8 mm for 0.5 s), then the error falls monotonically until it
    # crosses the path; the overshoot is damped out
    assert np.max(e) <= E0 + 0.005
    assert np.all(np.diff(e[(t >= 1.0) & (t <= 15.0)]) < 0.0)
    assert abs(e[t == 10.0][0]) < 0.3 * E0
    assert _max(e[t >= 15.0]) < 0.2 * E0
    assert abs(e[-1]) < 0.15 * E0
    # the vertical channel is left alone: depth and pitch as in the nominal run
    assert _max(r["h"] - nom["h"]) < 0.02 * E0
    assert _max(r["theta"] - nom["theta"]) < 2e-3
    assert _max(r["s"] - nom["s"]) < 0.02
    # the free desired sway v_d (solved so that the rudder's force comes with its moment)
    # moves with the sway the vehicle really has; the desired heave stays put
    assert _max(r["v_d"]) > 0.05 and np.corrcoef(r["v_d"], r["v"])[0, 1] > 0.8
    assert _max(r["w_d"] - nom["w_d"]) < 0.005
    assert not r["sat"]


def test_depth_offset_is_driven_back_by_the_pitch_channel():
    r, nom = run("depth"), run("nominal")
    t, h, theta = r["t"], r["h"], r["theta"]
    # below the path: h > 0, and the approach angle pitches the nose up (theta_d > 0)
    assert h[0] == pytest.approx(H0, abs=1e-12)
    assert r["e"][0] == pytest.approx(0.0, abs=1e-12) and r["s"][0] == pytest.approx(0.0, abs=1e-12)
    assert theta[0] == pytest.approx(-np.arctan(H0 / DELTA[1]), abs=1e-12)
    # the pitch error follows its designed two-pole response (p_G,theta, p_Phi,theta)
    dev = theta - nom["theta"] - two_pole(theta[0], P_G[1], P_PHI[4], t)
    assert _max(dev) < 0.1 * abs(theta[0]), _max(dev) / abs(theta[0])
    # the depth error decreases (after the stern planes' own force has pushed the vehicle
    # down by 0.3 mm, the vertical non-minimum phase), monotonically, without overshoot
    assert np.max(h) <= H0 + 0.005
    assert np.all(np.diff(h[t >= 1.0]) < 0.0)
    assert h[t == 10.0][0] < 0.6 * H0
    assert 0.0 < h[-1] < 0.05 * H0
    # the horizontal channel is left alone: cross-track and heading as in the nominal run
    assert _max(r["e"] - nom["e"]) < 0.005 * H0
    assert _max(r["psi"] - nom["psi"]) < 1e-3
    assert _max(r["s"] - nom["s"]) < 0.05
    # the free desired heave w_d moves with the heave the vehicle really has; v_d stays put
    assert _max(r["w_d"]) > 0.03 and np.corrcoef(r["w_d"], r["w"])[0, 1] > 0.7
    assert _max(r["v_d"] - nom["v_d"]) < 0.005
    assert not r["sat"]


def test_speed_error_is_driven_back_by_the_surge_channel():
    r, nom = run("speed"), run("nominal")
    t, u, s = r["t"], r["u"], r["s"]
    assert u[0] == pytest.approx(U0 - U_D, abs=1e-12)
    # the speed error shrinks monotonically to zero, the along-track lag it built is recovered
    assert np.all(np.diff(u) >= 0.0) and np.all(u <= 0.0)
    assert abs(u[t == 10.0][0]) < 0.02 * abs(u[0])
    assert abs(u[-1]) < 1e-3 * abs(u[0])
    assert np.min(s) < -0.1  # the particle ran ahead of the slow vehicle ...
    assert abs(s[-1]) < 0.01 * abs(np.min(s))  # ... and the vehicle caught up
    # neither the horizontal nor the vertical channel moves
    assert _max(r["e"] - nom["e"]) < 1e-3 and _max(r["psi"] - nom["psi"]) < 1e-4
    assert _max(r["h"] - nom["h"]) < 0.05 and _max(r["theta"] - nom["theta"]) < 0.01
