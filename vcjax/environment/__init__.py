"""What the water and the world do to a vehicle: one seam.

* :mod:`vcjax.environment.current`, :mod:`vcjax.environment.waves`: the physics (currents,
  Gauss–Markov processes; sea states and Airy kinematics).
* :class:`Component` (:mod:`vcjax.environment.component`): one disturbance — its TOML section
  and schema, ``sample(key, section) -> params`` (traced), an optional process
  (``init``/``advance``) and its contribution (water velocity + material acceleration at a NED
  point, a body force, measurement noise); :func:`register` makes one known by its
  section, :func:`lookup` finds it.
* The built-in components: :class:`ConstantCurrent` ``[current]``, :class:`GaussMarkov`
  ``[gauss_markov]``, :class:`Waves` ``[waves]``, :class:`SensorNoise` ``[sensor_noise]``,
  :class:`ConstantForce` ``[force]``.
* :class:`Environment`: the components of one run with their sampled parameters (a pytree:
  the components are its static structure); :func:`sample` draws one from TOML sections. A
  loop declares what it feels (:attr:`vcjax.loops.Loop.feels`) and refuses the rest by name.
"""

from vcjax.environment import current, waves
from vcjax.environment.component import (
    KINDS,
    Component,
    Environment,
    Key,
    check_section,
    components,
    draw,
    freeze,
    lookup,
    register,
    sample,
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
    "Waves",
    "check_section",
    "components",
    "current",
    "draw",
    "freeze",
    "lookup",
    "register",
    "sample",
    "waves",
]
