"""The loop registry and the Loop / Law base classes (vcjax.loops.registry, .loop, .law): what
registration refuses and says, what a registered law adds, the base classes' defaults. Eager,
no rollouts."""

import dataclasses
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest
from planar_loops import PlanarPointMass

from vcjax import loops, paths
from vcjax.loops.law import missing_methods, required
from vcjax.loops.loop import REQUIRED


@dataclasses.dataclass(frozen=True)
class SledLoop(PlanarPointMass, loops.EngineLoop):
    """A planar point mass on ice, held on a path by the generic engine (this file's vehicle)."""

    vehicle: ClassVar[str] = "unit_sled"
    initial_keys: ClassVar[dict[str, float]] = {"x": 1.0, "y": 0.5, "vx": 0.0, "vy": 0.0}
    noise_channels: ClassVar[dict[str, int]] = {"position_std": 2, "velocity_std": 2}
    # a class of its own: laws registered here never reach EngineLoop's other subclasses
    laws: ClassVar[dict] = {"vcm": loops.EngineLaw()}
    defaults: ClassVar[tuple] = (3.0, 0.2, (5.0, 5.0))

    @classmethod
    def default_path(cls):
        return paths.line(origin=(0.0, 0.0), direction=(1.0, 0.0))


loops.register(SledLoop)


@dataclasses.dataclass(frozen=True)
class SelfMade(SledLoop):
    """A loop that implements its one controller in its own methods (no laws)."""

    vehicle: ClassVar[str] = "unit_selfmade"
    laws: ClassVar[dict] = {}
    controllers: ClassVar[tuple] = ("mine",)

    def default_gains(self):
        return loops.engine_gains()

    def gain_specs(self):
        return ()


loops.register(SelfMade, check=False)  # implements no step: only what registration records


@dataclasses.dataclass(frozen=True)
class HoldLaw(loops.Law):
    """A law that pushes with a constant force (enough to be registered and called)."""

    force: float = 1.0

    def default_gains(self, loop):
        return loops.engine_gains()

    def gain_specs(self, loop):
        return (loops.gain_spec("sigma"),)

    def params(self, loop, gains, sc, design):
        return gains

    def initial_state(self, loop, sc):
        return jnp.atleast_1d(sc.varpi0)

    def step(self, loop, params, t, meas, z):
        return jnp.full(2, self.force), jnp.zeros_like(z), None


def test_register_refuses_what_is_not_a_named_loop_class():
    for bad in (42, dict, SledLoop(controller="vcm", path=SledLoop.default_path()[0])):
        with pytest.raises(ValueError, match="register: expected a Loop subclass"):
            loops.register(bad)

    @dataclasses.dataclass(frozen=True)
    class Nameless(SledLoop):
        vehicle: ClassVar[str] = ""

    with pytest.raises(ValueError, match="with a vehicle name"):
        loops.register(Nameless)


def test_register_refuses_no_controllers_and_laws_that_are_not_laws():
    @dataclasses.dataclass(frozen=True)
    class Lawless(SledLoop):
        vehicle: ClassVar[str] = "unit_lawless"
        laws: ClassVar[dict] = {}
        controllers: ClassVar[tuple] = ()

    with pytest.raises(ValueError, match="Lawless lists no controllers"):
        loops.register(Lawless)

    @dataclasses.dataclass(frozen=True)
    class Strange(SledLoop):
        vehicle: ClassVar[str] = "unit_strange"
        laws: ClassVar[dict] = {"vcm": object()}

    with pytest.raises(ValueError, match=r"unit_strange law 'vcm': expected a Law"):
        loops.register(Strange)
    assert "unit_lawless" not in loops.vehicles() and "unit_strange" not in loops.vehicles()


def test_the_registry_looks_up_by_name_and_lists_what_it_knows():
    assert "unit_sled" in loops.vehicles() and list(loops.vehicles()) == sorted(loops.vehicles())
    assert loops.loop_class("unit_sled") is SledLoop
    assert loops.controllers("unit_sled")[0] == "vcm"
    path, coeffs = loops.default_path("unit_sled")
    assert path is paths.LINE
    np.testing.assert_array_equal(coeffs.direction, [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"vehicle: expected one of \[.*'unit_sled'"):
        loops.loop_class("unit_sledge")
    loop = loops.make_loop("unit_sled", "vcm", smooth=True)
    assert isinstance(loop, SledLoop) and loop.smooth and loop.path is paths.LINE
    assert loop == loops.make_loop("unit_sled", "vcm", smooth=True)  # static: equal, hashable
    assert hash(loop) == hash(loops.make_loop("unit_sled", "vcm", smooth=True))
    assert loop.describe() == "unit_sled / vcm on a line"
    with pytest.raises(ValueError, match=r"unit_sled loop options: .*unexpected keyword"):
        loops.make_loop("unit_sled", "vcm", edd="paper")


def test_a_loop_checks_its_controller_and_path_kind():
    with pytest.raises(ValueError, match=r"controller: vehicle 'unit_sled' supports \['vcm'"):
        SledLoop(controller="pid", path=paths.LINE)
    with pytest.raises(ValueError, match="path: expected a vcjax.paths.Path, got str"):
        SledLoop(controller="vcm", path="line")


def test_register_law_adds_a_controller_and_refuses_what_it_cannot_take():
    law = loops.register_law("unit_sled", "hold", HoldLaw(force=2.0))
    assert isinstance(law, HoldLaw) and loops.controllers("unit_sled")[-1] == "hold"
    loop = loops.make_loop("unit_sled", "hold")
    assert loop.law is law and [g.name for g in loop.gain_specs()] == ["sigma"]
    # the law's defaults: no symmetric pairs, the particle is the state's first entry
    assert loop.symmetric_pairs() == ()
    with pytest.raises(ValueError, match="already has a controller 'hold'"):
        loops.register_law("unit_sled", "hold", HoldLaw())
    assert loops.register_law("unit_sled", "hold", HoldLaw(3.0), replace=True).force == 3.0
    assert loops.controllers("unit_sled").count("hold") == 1
    with pytest.raises(ValueError, match=r"vehicle: expected one of"):
        loops.register_law("no_such_vehicle", "hold", HoldLaw())
    with pytest.raises(ValueError, match="register_law: controller: expected a name"):
        loops.register_law("unit_sled", "", HoldLaw())
    with pytest.raises(ValueError, match=r"unit_sled law 'x': expected a Law, got 3"):
        loops.register_law("unit_sled", "x", 3)


def test_register_law_refuses_a_loop_that_implements_its_controllers_itself():
    with pytest.raises(ValueError, match="the unit_selfmade loop implements its controllers"):
        loops.register_law("unit_selfmade", "hold", HoldLaw())
    loop = loops.make_loop("unit_selfmade", "mine")
    assert loop.law is None and loop.symmetric_pairs() == ()
    g = loop.gains_from_json({"sigma": 2.5})  # the one reader, no law's checks
    assert float(g.sigma) == 2.5 and float(g.P_G[0]) == float(loops.engine_gains().P_G[0])


def test_required_methods_are_the_ones_marked():
    assert set(REQUIRED) == {
        "default_path",
        "position",
        "default_params",
        "plant",
        "control",
        "plant_args",
        "ctrl_params",
        "initial_state",
        "signals",
        "initial_from",
    }
    assert missing_methods(loops.Law) == [
        "default_gains",
        "gain_specs",
        "initial_state",
        "params",
        "step",
    ]
    assert missing_methods(HoldLaw) == []

    class Base:
        @required
        def must(self):
            raise NotImplementedError

    class Child(Base):
        def must(self):
            return 1

    assert missing_methods(Base) == ["must"] and missing_methods(Child) == []


def test_base_loop_defaults_say_what_is_not_modelled():
    loop = loops.make_loop("unit_sled", "vcm")
    assert loop.param_names() == ("m", "b", "tau_max")
    assert loop.default_model_fields() == loop.param_names()
    np.testing.assert_array_equal(
        loop.noise_std({"position_std": 0.5, "velocity_std": 0.1}), [0.5, 0.5, 0.1, 0.1]
    )
    np.testing.assert_array_equal(loop.noise_std({}), np.zeros(4))
    with pytest.raises(ValueError, match="plant: expected PointMassParams, got tuple"):
        loop.validate_params((3.0, 0.2, (5.0, 5.0)))
    with pytest.raises(NotImplementedError, match="no sensor-noise model"):
        loops.Loop.measure(loop, None, None)
    with pytest.raises(NotImplementedError, match="no time-varying current"):
        loops.Loop.with_current(loop, None, None, None)
    with pytest.raises(NotImplementedError, match="no law and no override"):
        loops.Loop.default_gains(loops.make_loop("unit_selfmade", "mine"))
