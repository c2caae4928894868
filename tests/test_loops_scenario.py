"""Scenarios by hand and from files (vcjax.loops.scenario): what make_scenario builds (units,
padding, the nearest start parameter, dtypes), every input it refuses with the field named,
parameter files and overrides, and which loops take which current. Eager."""

import json
import math

import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import loops, paths


def infante(controller="vcm"):
    return loops.make_loop("infante", controller)


def test_initial_keys_in_their_units_and_defaults_for_the_rest():
    loop = infante()
    sc = loops.make_scenario(loop, initial={"y": 3.0, "heading_deg": 45.0})
    # x = 0 (default), y = 3; heading 45 deg in radians; speed 2 m/s (default) as surge
    np.testing.assert_allclose(sc.eta0, [0.0, 3.0, math.pi / 4], rtol=1e-15)
    np.testing.assert_array_equal(sc.nu0, [2.0, 0.0, 0.0])
    # the particle starts at the point of Simulation 1's line x = 10 nearest to (0, 3): w = 3
    assert float(sc.varpi0) == 3.0
    # a planar current (2,) is the (3,) NED current with zero vertical component
    np.testing.assert_array_equal(sc.current, [0.0, 0.0, 0.0])
    assert float(sc.u_d) == loop.default_speed and sc.plant is sc.design
    np.testing.assert_array_equal(sc.disturbance, np.zeros(3))


def test_exact_start_current_speed_and_particle():
    loop = loops.make_loop("odin", "vcm")
    eta0 = [1.0, 2.0, -100.0, 0.0, 0.0, 0.3]
    sc = loops.make_scenario(
        loop, eta0=eta0, nu0=np.zeros(6), current=(0.1, -0.2), u_d=0.7, varpi0=4.0
    )
    np.testing.assert_array_equal(sc.eta0, eta0)
    np.testing.assert_array_equal(sc.current, [0.1, -0.2, 0.0])
    assert float(sc.u_d) == 0.7 and float(sc.varpi0) == 4.0
    # only eta0: nu0 from the initial keys' defaults (speed along surge)
    sc = loops.make_scenario(loop, eta0=eta0)
    assert sc.nu0.shape == (6,) and float(sc.nu0[0]) == loop.initial_keys["speed"]


def test_a_circle_start_parameter_and_float32_arrays():
    loop = loops.make_loop("infante", "vcm", path=paths.CIRCLE)
    _, coeffs = paths.circle(center=(0.0, 0.0), radius=40.0)
    sc = loops.make_scenario(
        loop, coeffs, initial={"x": 0.0, "y": 50.0}, dtype=jnp.float32
    )  # 10 m outside the circle, a quarter turn from its start
    assert sc.eta0.dtype == jnp.float32 and sc.path.radius.dtype == jnp.float32
    assert sc.plant.mass.dtype == jnp.float32 and sc.current.dtype == jnp.float32
    p = np.asarray(paths.path_point(loop.path, sc.path, sc.varpi0))
    np.testing.assert_allclose(p[:2], [0.0, 40.0], atol=1e-3)  # nearest point of the circle


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"initial": {"z": 1.0}}, r"initial: unknown keys \['z'\]; expected \['x', 'y'"),
        ({"initial": {"x": float("nan")}}, r"initial: x: not finite"),
        ({"initial": {"x": 1.0}, "eta0": [0, 0, 0]}, r"initial: give the initial keys or eta0"),
        ({"eta0": [0.0, 0.0]}, r"eta0: expected a finite array of shape \(3,\)"),
        ({"nu0": [2.0, 0.0, float("inf")]}, r"nu0: expected a finite array of shape \(3,\)"),
        ({"current": (0.0, 0.5, 0.0, 1.0)}, r"current: expected a finite \(2,\) or \(3,\)"),
        ({"current": (float("nan"), 0.5)}, r"current: expected a finite"),
        ({"u_d": 0.0}, r"u_d: expected a finite value > 0, got 0.0"),
        ({"u_d": float("nan")}, r"u_d: expected a finite value > 0"),
        ({"disturbance": [1.0, 2.0]}, r"disturbance: expected a finite \(3,\) force"),
        ({"disturbance": [0.0, 5.0, 0.0]}, r"the infante plant takes no disturbance force"),
    ],
)
def test_make_scenario_names_what_it_refuses(kwargs, message):
    with pytest.raises(ValueError, match=message):
        loops.make_scenario(infante(), **kwargs)


def test_parameters_of_the_wrong_vehicle_or_out_of_range_are_refused():
    loop = infante()
    odin = loops.make_loop("odin", "vcm").default_params()
    with pytest.raises(ValueError, match="plant: expected InfanteParams, got OdinParams"):
        loops.make_scenario(loop, plant=odin)
    bad = loop.default_params()._replace(mass=jnp.asarray(-1.0))
    with pytest.raises(ValueError, match=r"design\.mass: every entry must be > 0"):
        loops.make_scenario(loop, design=bad)
    sc = loops.make_scenario(loop, design=loop.default_params()._replace(mass=jnp.asarray(4000.0)))
    assert float(sc.design.mass) == 4000.0 and float(sc.plant.mass) != 4000.0


def test_which_loops_take_which_current():
    arm = loops.make_loop("arm", "vcm")
    with pytest.raises(ValueError, match="current: the arm loop takes no current; set"):
        loops.make_scenario(arm, current=(0.1, 0.0))
    assert loops.make_scenario(arm).current.shape == (3,)  # zero current: fine
    loops.check_disturbances(infante(), True, True)  # INFANTE takes both

    class SteadyOnly(loops.Loop):  # a plant that reads a constant current only
        vehicle = "steady"
        feels = {"current": True}

    loops.check_disturbances(SteadyOnly, True, False)
    with pytest.raises(
        ValueError, match=r"steady loop cannot take a time-varying \(Gauss-Markov\)"
    ):
        loops.check_disturbances(SteadyOnly, True, True)
    with pytest.raises(ValueError, match=r"time-varying.*\(it takes no current at all\)"):
        loops.check_disturbances(type(arm), False, True)
    loops.check_disturbances(type(arm), False, False)


def test_read_param_file_takes_a_flat_map_or_a_fit_output(tmp_path):
    loop = infante()
    flat = tmp_path / "flat.json"
    flat.write_text(json.dumps({"mass": 3000.0, "X_uu": -40.0}))
    assert loops.read_param_file(flat, loop) == {"mass": 3000.0, "X_uu": -40.0}
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"estimates": {"N_ur": -1.5}, "std": {"N_ur": 0.1}}))
    assert loops.read_param_file(fit, loop) == {"N_ur": -1.5}


@pytest.mark.parametrize(
    "text, message",
    [
        (None, r"params: cannot read .*missing.json"),
        ("{not json", r"params: .*bad.json: not valid JSON"),
        ("[1, 2]", r"params: .*bad.json: expected an object of parameter values"),
        ('{"mass": 1.0, "hull": 2.0}', r"unknown infante parameters \['hull'\]; valid: \["),
    ],
)
def test_read_param_file_names_the_file_and_the_problem(tmp_path, text, message):
    f = tmp_path / ("missing.json" if text is None else "bad.json")
    if text is not None:
        f.write_text(text)
    with pytest.raises(ValueError, match=message):
        loops.read_param_file(f, infante())


def test_apply_params_checks_shapes_and_keeps_dtypes():
    p = loops.make_loop("odin", "vcm").default_params()
    q = loops.apply_params(p, {"drag_coeff": 50, "body.W": 1800.0})
    assert float(q.drag_coeff) == 50.0 and q.drag_coeff.dtype == p.drag_coeff.dtype
    assert float(q.body.W) == 1800.0 and float(p.body.W) != 1800.0
    with pytest.raises(ValueError, match=r"params: drag_coeff: expected a finite value of shape"):
        loops.apply_params(p, {"drag_coeff": [1.0, 2.0]})
    with pytest.raises(ValueError, match=r"plant_params: body.W: expected a finite value"):
        loops.apply_params(p, {"body.W": float("nan")}, where="plant_params")
