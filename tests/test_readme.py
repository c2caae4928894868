"""The README's Python examples run as written, and its quick-start commands match `.ci/run`."""

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def _python_blocks():
    return re.findall(r"```python\n(.*?)```", README, flags=re.S)


def _run_blocks():
    namespaces = []
    for code in _python_blocks():
        ns: dict = {}
        exec(compile(code, "README.md", "exec"), ns)
        namespaces.append(ns)
    return namespaces


def test_python_examples_run_and_their_claims_hold():
    """Every Python block runs, and what its comments claim is checked against something
    independent of the code that produced it."""
    blocks = _python_blocks()
    assert len(blocks) == 5, "a README block was added or removed: check its claim here"
    engine, sweep_xr, puck, path, remus = _run_blocks()

    # 1. the engine: "Φ decays as exp(−P_Φ t)" -- against the analytic solution of (14),
    #    and "rank 2" (W = [[∂K/∂q̇], [∂Ġ/∂q̇]] of two independent constraints)
    traj = engine["traj"]
    t = np.asarray(traj.t[:-1])
    Phi = np.asarray(traj.aux.Phi)
    P_Phi = np.asarray(engine["gains"].P_Phi)
    expected = Phi[0] * np.exp(-P_Phi * t[:, None])
    np.testing.assert_allclose(Phi, expected, atol=1e-7 * np.max(np.abs(Phi[0])))
    assert np.max(np.abs(Phi[-1])) < 1e-3
    assert np.all(np.asarray(traj.aux.rank) == 2) and bool(traj.healthy)

    # 2. xarray: the medians per current-speed bin equal those computed with plain NumPy from
    #    the labelled arrays' raw values (each scenario's own sampled speed), and units are kept
    ds = sweep_xr["ds"]
    assert dict(ds["iae_e"].sizes) == {"variant": 2, "scenario": 8}
    speed = np.asarray(ds["current_speed"].values)
    iae = np.asarray(ds["iae_e"].sel(variant="alos").values)
    by_bin = np.asarray(sweep_xr["by_speed"].sel(variant="alos").values)
    for k, (lo, hi) in enumerate([(0.0, 0.5), (0.5, 1.0)]):
        sel = (speed > lo) & (speed <= hi)
        if sel.any():
            assert by_bin[k] == np.median(iae[sel])
    assert ds["iae_e"].attrs["units"] == "m s"

    # 3. your own loop: the README's puck is examples/loops/puck.py as written there, it is in
    #    the registry, and its engine holds the puck on the 0.5 m circle (independent check:
    #    the puck's distance from the centre, not the controller's own error signal)
    ex = (ROOT / "examples" / "loops" / "puck.py").read_text()
    assert blocks[2].strip() in ex
    import jax

    from vcjax import loops
    from vcjax.rollout import RolloutConfig

    loop = loops.make_loop("puck", "vcm")
    sc = loops.make_scenario(loop)
    tr = jax.jit(lambda g: loops.simulate(loop, g, sc, RolloutConfig(num_steps=400), 0.02))(
        loop.default_gains()
    )
    pos = np.asarray(loop.signals(tr, sc).pos)
    assert abs(np.hypot(pos[0, 0], pos[0, 1]) - 0.5) > 0.05  # it starts off the circle
    assert abs(np.hypot(pos[-1, 0], pos[-1, 1]) - 0.5) < 1e-3

    # 4. paths: a spline "through waypoints, parametrised by cumulative chord length" -- the
    #    frame at each knot is the waypoint, and psi_p is the direction of a finite difference
    pts = np.array([[0, 0], [20, 5], [35, 30], [20, 55]], float)
    knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    from vcjax.paths import path_frame

    for w, pt in zip(knots, pts, strict=True):
        f = path_frame(path["path"], path["coeffs"], w)
        np.testing.assert_allclose(np.asarray(f.p_bar), pt, atol=1e-9)
    h = 1e-5
    a, b = (np.asarray(path_frame(path["path"], path["coeffs"], 12.0 + d).p_bar) for d in (-h, h))
    psi_fd = np.arctan2(b[1] - a[1], b[0] - a[0])
    assert abs(float(path["frame"].psi_p) - psi_fd) < 1e-6

    # 5. REMUS 100 replay: "every command finite, every state finite", (501, 6) poses, and the
    #    actuator states follow PVS's Euler lag exactly: a_k = a_cmd (1 - (1 - dt/T)^k) from 0
    #    (fins T = 0.1 s, propeller T = 1 s; commands inside the limits)
    rep = remus["rep"]
    assert bool(rep.ok.all()) and rep.x.eta.shape == (501, 6)
    assert np.all(np.isfinite(np.asarray(rep.x.nu)))
    cmd = np.array([np.radians(5.0), np.radians(-5.0), 1525.0])
    T = np.array([0.1, 0.1, 1.0])
    expected = cmd * (1.0 - (1.0 - 0.02 / T) ** 500)
    np.testing.assert_allclose(np.asarray(rep.x.act[-1]), expected, rtol=1e-9)


def test_quick_start_test_command_is_what_ci_runs():
    blocks = re.findall(r"```bash\n(.*?)```", README, flags=re.S)
    test_cmd = [ln for ln in blocks[1].splitlines() if ln and not ln.startswith("#")][0]
    ci = (ROOT / ".ci" / "run").read_text()
    assert test_cmd in ci
    install = [ln for ln in blocks[0].splitlines() if ln and not ln.startswith("#")][0]
    assert install.split(" && ")[:2] == [
        "python3 -m venv .venv",
        '.venv/bin/pip install -e ".[test]"',
    ]
