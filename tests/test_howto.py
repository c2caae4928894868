"""The how-to examples run as the guides say: a law of your own (``examples/laws/los_pd.py``)
swept beside a built-in law and tuned, and a marine vehicle of your own
(``examples/vehicles/skiff.py``) swept in currents and tuned, through the command line a user
types (the configs under ``examples/sweeps/`` and ``examples/tuning/``), and through Python."""

import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import cli, loops
from vcjax.config.scenario import import_module_file
from vcjax.rollout import RolloutConfig
from vcjax.sweep.run import variant_gains

ROOT = Path(__file__).resolve().parents[1]


def test_own_law_swept_beside_a_builtin_law(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "sweep"
    assert cli.main(["sweep", str(ROOT / "examples/sweeps/own_law.toml"), "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert set(s["variants"]) == {"los_pd", "vcm_integral"}
    # each law ran with its own gains type (the LOS-PD law's are not the VCM's), and both keep
    # the craft on the line in these currents
    for v in ("los_pd", "vcm_integral"):
        assert s["variants"][v]["n_diverged"] == 0
        assert s["variants"][v]["metrics"]["ss_abs_e"]["p95"] < 5.0


@pytest.mark.slow  # 9 s; test_new_law tunes the same law
def test_own_law_tuned_from_its_config(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "tune"
    assert cli.main(["tune", str(ROOT / "examples/tuning/own_law.toml"), "--out", str(out)]) == 0
    gains = json.loads((out / "gains.json").read_text())
    assert {"Delta", "sigma", "k_u", "k_p", "k_d"} <= set(
        json.dumps(gains).replace('"', " ").split()
    )
    s = json.loads((out / "summary.json").read_text())
    assert np.isfinite(s["heldout_loss_after"]) and s["heldout_loss_after"] > 0


def test_own_law_in_python(monkeypatch):
    """The guide's Python block, run as written from the repository root."""
    import re

    page = (ROOT / "docs/guides/own-law.md").read_text()
    code = re.findall(r"^```py\n(.*?)^```$", page, flags=re.S | re.M)[-1]
    monkeypatch.chdir(ROOT)
    ns: dict = {}
    exec(compile(code, "own-law.md", "exec"), ns)
    e = np.asarray(ns["e"])
    # the craft starts 10 m off the line x = 10 m and the law brings it closer
    assert abs(e[0]) > 9.0 and abs(e[-1]) < 0.5 * abs(e[0])
    assert ns["loop"].controller == "los_pd"


def test_variant_gains_refuses_gains_of_another_law():
    import_module_file(ROOT / "examples/laws/los_pd.py")
    ls = {v: loops.make_loop("infante", v) for v in ("los_pd", "vcm_integral")}
    vcm = ls["vcm_integral"].default_gains()
    g = variant_gains(ls, vcm)
    assert g["vcm_integral"] is vcm and type(g["los_pd"]).__name__ == "LosPDGains"
    with pytest.raises(ValueError, match="los_pd"):
        variant_gains(ls, {"los_pd": vcm})
    with pytest.raises(ValueError, match="no variant"):
        variant_gains(ls, {"nope": vcm})
    los = ls["los_pd"].default_gains()._replace(Delta=jnp.asarray(3.0))
    assert float(variant_gains(ls, los)["los_pd"].Delta) == 3.0


def test_the_guide_shows_the_example_as_it_is():
    page = (ROOT / "docs/guides/own-law.md").read_text()
    law = (ROOT / "examples/laws/los_pd.py").read_text().rstrip()
    assert f"```py\n{law}\n```" in page
    toml = (ROOT / "examples/sweeps/own_law.toml").read_text().split("\n\n", 1)[1].rstrip()
    assert toml in page


def test_the_disturbance_guide_shows_the_example_component_as_it_is():
    import re

    page = (ROOT / "docs/guides/disturbances.md").read_text()
    shown = re.findall(r"^```python\n(.*?)^```", page, flags=re.S | re.M)[0]
    assert shown.strip() in (ROOT / "examples/environment/tidal.py").read_text()


# ------------------------------------------------------------------ a marine vehicle of your own

SKIFF = ROOT / "examples/vehicles/skiff.py"


def test_own_vehicle_swept_in_currents(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "sweep"
    cfg = ROOT / "examples/sweeps/own_vehicle.toml"
    assert cli.main(["sweep", str(cfg), "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert set(s["variants"]) == {"vcm"}
    m = s["variants"]["vcm"]
    # every run reaches the line from up to 10 m off and stays within a few decimetres of it
    # in currents up to 0.5 m/s (the law has no integral action: a small offset remains)
    assert m["n_diverged"] == 0 and m["metrics"]["ss_abs_e"]["p95"] < 0.5
    # the numbers the guide quotes
    np.testing.assert_allclose(
        [m["metrics"]["ss_abs_e"][k] for k in ("p50", "p95")], [0.05, 0.12], atol=0.005
    )


@pytest.mark.slow  # 18 s; the sweep test runs the vehicle through the CLI
def test_own_vehicle_tuned_from_its_config(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "tune"
    cfg = ROOT / "examples/tuning/own_vehicle.toml"
    assert cli.main(["tune", str(cfg), "--out", str(out)]) == 0
    gains = json.loads((out / "gains.json").read_text())
    assert {"P_G", "P_Phi", "sigma"} <= set(gains) and gains.get("vehicle", "skiff") == "skiff"
    s = json.loads((out / "summary.json").read_text())
    assert np.isfinite(s["heldout_loss_after"]) and s["heldout_loss_after"] > 0
    # the numbers the guide quotes: loss, and the terms for commands beyond the limits, effort
    # and path error, before and after
    b, a = s["heldout_terms_before"], s["heldout_terms_after"]
    got = [s["heldout_loss_before"], s["heldout_loss_after"], b["sat_excess"], a["sat_excess"]]
    got += [b["effort"], a["effort"], b["eps"], a["eps"]]
    page = [2.08, 0.525, 1.22, 0.001, 2.03, 0.17, 0.27, 0.43]
    np.testing.assert_allclose(got, page, rtol=0.02, atol=5e-4)


def test_own_vehicle_in_python(monkeypatch):
    """The guide's Python block, run as written from the repository root."""
    import re

    page = (ROOT / "docs/guides/own-vehicle.md").read_text()
    code = re.findall(r"^```py\n(.*?)^```$", page, flags=re.S | re.M)[-1]
    monkeypatch.chdir(ROOT)
    ns: dict = {}
    exec(compile(code, "own-vehicle.md", "exec"), ns)
    e = np.asarray(ns["e"])
    # the bow point starts 5.5 m off the line y = 0 and the law brings it onto the line
    assert abs(e[0]) > 5.0 and abs(e[-1]) < 0.3
    assert ns["loop"].vehicle == "skiff"


def test_own_vehicle_drifts_with_the_current_as_the_drag_ode_says():
    """Thrusters off (zero thrust limits), at rest, heading north in a 0.4 m/s current flowing
    north: only the surge equation acts, (m - X_udot) u_r' = -(X_u + X_uu |u_r|) u_r on the
    velocity relative to the water u_r = u - V_c, u_r(0) = -V_c. Its closed form (w = -u_r):
    w(t) = a w0 E / (a + b w0 (1 - E)), E = exp(-a t / m'), and the distance drifted is
    V_c t - (m'/b) ln(1 + b w0 (1 - E) / a); sway and yaw stay zero."""
    import_module_file(SKIFF)
    loop = loops.make_loop("skiff", "vcm")
    p = loop.default_params()
    off = p._replace(tau_max=jnp.zeros(3))
    V_c = 0.4
    sc = loops.make_scenario(loop, current=(V_c, 0.0), plant=off, design=p)
    dt, n = 0.01, 3000
    traj = loops.simulate(loop, loop.default_gains(), sc, RolloutConfig(num_steps=n), dt)
    t = dt * np.arange(n + 1)
    m1, a, b, w0 = float(p.m + p.a_u), float(p.X_u), float(p.X_uu), V_c
    E = np.exp(-a * t / m1)
    w = a * w0 * E / (a + b * w0 * (1 - E))
    x = V_c * t - (m1 / b) * np.log1p(b * w0 * (1 - E) / a)
    q, qd = (np.asarray(traj.x[0]), np.asarray(traj.x[1]))
    np.testing.assert_allclose(qd[:, 0], V_c - w, atol=1e-8)
    np.testing.assert_allclose(q[:, 0], x, atol=1e-8)
    np.testing.assert_allclose(q[:, 1:], 0.0, atol=1e-12)
    np.testing.assert_allclose(qd[:, 1:], 0.0, atol=1e-12)
    assert V_c - qd[-1, 0] < 1e-3  # it ends moving with the water


def test_the_vehicle_guide_shows_the_example_as_it_is():
    page = (ROOT / "docs/guides/own-vehicle.md").read_text()
    src = SKIFF.read_text().rstrip()
    assert f"```py\n{src}\n```" in page
    for cfg in ("sweeps", "tuning"):
        toml = (ROOT / f"examples/{cfg}/own_vehicle.toml").read_text().split("\n\n", 1)[1]
        assert toml.rstrip() in page, cfg
