"""What the water and the world do to a vehicle: one seam.

* [`vcjax.environment.current`][vcjax.environment.current],
[`vcjax.environment.waves`][vcjax.environment.waves]: the physics (currents,
  Gauss–Markov processes; sea states and Airy kinematics).
* [`Component`][vcjax.environment.component.Component]
([`vcjax.environment.component`][vcjax.environment.component]): one disturbance — its TOML section
  and schema, ``sample(key, section) -> params`` (traced), an optional process
  (``init``/``advance``) and its contribution (water velocity + material acceleration at a NED
  point, a body force, measurement noise); [`register`][vcjax.environment.component.register] makes
  one known by its
  section, [`lookup`][vcjax.environment.component.lookup] finds it.
* The built-in components: [`ConstantCurrent`][vcjax.environment.flow.ConstantCurrent]
``[current]``, [`GaussMarkov`][vcjax.environment.flow.GaussMarkov]
  ``[gauss_markov]``, [`Waves`][vcjax.environment.sea.Waves] ``[waves]``,
  [`SensorNoise`][vcjax.environment.noise.SensorNoise] ``[sensor_noise]``,
  [`ConstantForce`][vcjax.environment.force.ConstantForce] ``[force]``.
* [`WaterMotion`][vcjax.environment.component.WaterMotion]: the water at a vehicle (velocity and
  material acceleration, (3,) NED each), the one door of every plant in ``vcjax.vehicles``.
* [`Environment`][vcjax.environment.component.Environment]: the components of one run with their
sampled parameters (a pytree:
  the components are its static structure); [`sample`][vcjax.environment.component.sample] draws one
  from TOML sections. A
  loop declares what it feels (``vcjax.loops.Loop.feels``) and refuses the rest by name.
"""

from vcjax.environment import current, waves
from vcjax.environment.component import (
    KINDS,
    REGISTRY,
    Component,
    Environment,
    Key,
    WaterMotion,
    add_section,
    check_for_loop,
    check_section,
    components,
    draw,
    draw_unit,
    freeze,
    lookup,
    register,
    sample,
    unregister,
    water_motion,
)
from vcjax.environment.flow import ConstantCurrent, CurrentParams, GaussMarkov, GaussMarkovParams
from vcjax.environment.force import ConstantForce, ForceParams
from vcjax.environment.noise import NoiseParams, SensorNoise
from vcjax.environment.sea import SeaParams, Waves

register(ConstantCurrent())
register(GaussMarkov())
register(Waves())
register(SensorNoise())
register(ConstantForce())

__all__ = [
    "KINDS",
    "REGISTRY",
    "add_section",
    "unregister",
    "Component",
    "ConstantCurrent",
    "ConstantForce",
    "CurrentParams",
    "Environment",
    "ForceParams",
    "GaussMarkov",
    "GaussMarkovParams",
    "Key",
    "NoiseParams",
    "SeaParams",
    "SensorNoise",
    "WaterMotion",
    "Waves",
    "check_section",
    "components",
    "current",
    "draw",
    "draw_unit",
    "check_for_loop",
    "freeze",
    "lookup",
    "register",
    "sample",
    "water_motion",
    "waves",
]
