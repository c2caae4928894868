"""One water door for every plant: each registered vehicle's loop hands its plant the water as one
[`WaterMotion`][vcjax.environment.component.WaterMotion] (velocity and material acceleration,
(3,) NED each), the horizontal water moves every plant that feels a current, and the vertical
water moves exactly the plants whose model can feel it (ODIN's 6-DOF body; REMUS 100's share of
the water that is not its uniform current) — the others document that they cannot."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import loops
from vcjax.config.scenario import import_module_file
from vcjax.environment import WaterMotion, water_motion
from vcjax.vehicles import remus100

ROOT = Path(__file__).resolve().parents[1]
import_module_file(ROOT / "examples" / "loops" / "puck.py")
import_module_file(ROOT / "examples" / "vehicles" / "skiff.py")

#: vehicle -> does its plant feel the water's vertical velocity (its module says why not)
VERTICAL = {
    "infante": False,  # a horizontal-plane model
    "remus100": False,  # PVS's uniform current is horizontal (the waves' share is felt: below)
    "odin": True,  # a 6-DOF body in 3-D water
    "arm": False,  # an arm in air feels no water at all
    "puck": False,  # a planar point: the water's first two components
    "skiff": False,  # a planar hull: the water's first two components
}


#: the plant's command size (zeros: the door, not the controller, is under test)
COMMANDS = {"infante": 2, "remus100": 3, "odin": 8, "arm": 2, "puck": 2, "skiff": 3}


@pytest.mark.parametrize("vehicle", sorted(VERTICAL))
def test_every_plant_takes_the_water_through_one_3d_door(vehicle):
    assert vehicle in loops.vehicles()
    cls = loops.loop_class(vehicle)
    loop = loops.make_loop(vehicle, cls.default_controller)
    sc = loops.make_scenario(loop)
    x0, _ = loop.initial_state(sc)
    u = jnp.zeros(COMMANDS[vehicle], sc.u_d.dtype)
    args = loop.plant_args(sc, sc.current, jnp.zeros(3))
    assert isinstance(args.water, WaterMotion)
    assert args.water.velocity.shape == (3,)
    assert args.water.acceleration is None or args.water.acceleration.shape == (3,)

    def x_dot(v):  # one evaluation each: eager costs less than compiling
        dx = loop.plant(0.0, x0, u, loop.plant_args(sc, jnp.asarray(v), jnp.zeros(3)))
        return jnp.concatenate([jnp.ravel(a) for a in jax.tree_util.tree_leaves(dx)])

    still, across, down = (x_dot(v) for v in ([0.0, 0, 0], [0.3, -0.2, 0.0], [0.0, 0.0, 0.3]))
    assert bool(jnp.all(jnp.isfinite(across))) and bool(jnp.all(jnp.isfinite(down)))
    assert bool(jnp.any(across != still)) == cls.can_feel("current")
    assert bool(jnp.any(down != still)) == VERTICAL[vehicle]
    if not VERTICAL[vehicle]:
        np.testing.assert_array_equal(down, still)


@pytest.mark.slow  # compiles the REMUS 100 plant (~5 s); the door's shape is checked above
def test_remus100_feels_the_vertical_water_that_is_not_its_current():
    """PVS's door (``uniform``: the current, yaw-only, horizontal) leaves a vertical current
    out; the rest of the water (a wave's orbital motion) goes through the full rotation, all
    three components."""
    p = remus100.remus100_params()
    x = remus100.remus100_state([0.0, 0.0, 5.0, 0.1, -0.05, 0.3], [1.5, 0, 0, 0, 0, 0.02])
    u = jnp.asarray([0.05, -0.03, 1000.0])
    current = jnp.asarray([0.2, 0.1, 0.0])
    up = jnp.asarray([0.2, 0.1, -0.3])
    zero = jnp.zeros(3)

    @jax.jit
    @jax.vmap
    def nu_dot(v, v_uniform):
        water, uniform = WaterMotion(v, zero), WaterMotion(v_uniform, zero)
        return remus100.remus100_plant(0.0, x, u, remus100.Remus100Args(p, water, None, uniform)).nu

    calm, blind, felt = nu_dot(jnp.stack([current, up, up]), jnp.stack([current, up, current]))
    np.testing.assert_array_equal(blind, calm)  # all of it uniform: the vertical is not felt
    assert float(jnp.max(jnp.abs(felt - calm))) > 1e-3  # the rest: felt
    alone = remus100.remus100_plant(0.0, x, u, remus100.remus100_args(p, water=water_motion(up)))
    np.testing.assert_allclose(alone.nu, calm, rtol=1e-14, atol=1e-14)  # no uniform: all of it


def test_the_old_door_names_are_gone_or_deprecated():
    """The per-plant doors (``V_c``, ``v_c``, ``v_w``) are gone from the plants' arguments; the
    engine's ``args.current`` (the own-vehicle guide's spelling) still reads, with a warning."""
    from vcjax.vehicles import infante, odin, sixdof

    for kind in (infante.PlantArgs, remus100.Remus100Args, odin.OdinArgs, sixdof.SixDofArgs):
        assert "water" in kind._fields
        assert not {"V_c", "V_c_dot", "v_c", "v_c_dot", "v_w", "v_w_dot"} & set(kind._fields)
    loop = loops.make_loop("puck", "vcm")
    sc = loops.make_scenario(loop, current=(0.1, 0.2, 0.0))
    args = loop.plant_args(sc, sc.current, jnp.zeros(3))
    with pytest.warns(DeprecationWarning, match="water.velocity"):
        np.testing.assert_array_equal(args.current, sc.current)
