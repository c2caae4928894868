"""The sensor-noise component (``[sensor_noise]``): white Gaussian noise on what the controller
measures, drawn per step from ``fold_in(key, k)`` and held over the step."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax.environment.component import Component, Key

__all__ = ["SensorNoise", "NoiseParams"]


class NoiseParams(NamedTuple):
    """std: (n,) standard deviation of each measured entry (SI units); key: PRNG key."""

    std: Any
    key: Any


@dataclasses.dataclass(frozen=True)
class SensorNoise(Component):
    """Noise over a loop's sensor channels (``channels``: ``((name, entries), ...)``, e.g.
    ``tuple(loop.noise_channels.items())``); a channel ending in ``_deg`` is given in degrees
    (deg/s) and applied in radians."""

    channels: tuple[tuple[str, int], ...] = ()

    section = "sensor_noise"
    kind = "noise"
    process = True

    def bind(self, loop):
        return dataclasses.replace(self, channels=tuple(loop.noise_channels.items()))

    @property
    def schema(self):
        return {n: Key(0.0, f"standard deviation ({m} entries)", lo=0.0) for n, m in self.channels}

    def sample(self, key, section):
        parts = []
        for name, m in self.channels:
            v = section[name]
            parts.append(jnp.full((m,), math.radians(v) if name.endswith("_deg") else v))
        std = jnp.concatenate(parts) if parts else jnp.zeros(0)
        return NoiseParams(std, key)

    def advance(self, params, state, k, t, dt):
        std = params.std
        n = std * jax.random.normal(jax.random.fold_in(params.key, k), std.shape, std.dtype)
        return state, n

    def noise(self, params, held):
        return held
