"""The waves component (``[waves]``): a random sea per run (``
sea_state``, physics in [`vcjax.environment.waves`][vcjax.environment.waves]) whose orbital motion
the vehicle feels
at its own position."""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax.environment import waves
from vcjax.environment.component import Component, Key, draw

__all__ = ["Waves", "SeaParams"]


class SeaParams(NamedTuple):
    """sea: [`Sea`][vcjax.environment.waves.Sea] ((N,) arrays); origin_depth: () depth of the
    NED origin below the mean free surface [m] (the sea is felt at ``origin_depth + z``)."""

    sea: Any
    origin_depth: Any


@dataclasses.dataclass(frozen=True)
class Waves(Component):
    """Linear (Airy) waves in deep water: ``hs``, ``tp``, ``direction_deg``, ``origin_depth``
    drawn per run (numbers or ``[lo, hi]`` ranges); ``spectrum``, ``components`` and whether
    ``spreading`` is zero are static (they change the program)."""

    section = "waves"
    kind = "waves"
    schema = {
        "spectrum": Key("jonswap", "wave spectrum", choices=waves.SPECTRA),
        "hs": Key(None, "significant wave height [m]", lo=0.0),
        "tp": Key(None, "peak period [s]", lo=0.0, strict_lo=True),
        "direction_deg": Key(0.0, "direction the waves travel towards [deg from north]"),
        "gamma": Key(3.3, "JONSWAP peak enhancement (1: Pierson-Moskowitz)", lo=1.0),
        "spreading": Key(0.0, "directional spreading exponent s of cos^2s (0: long-crested)", 0),
        "components": Key(64.0, "regular components of each sea", lo=1.0),
        "origin_depth": Key(0.0, "depth of the NED origin below the mean free surface [m]"),
    }

    def check(self, raw):
        out = super().check(raw)
        n = out["components"]
        if isinstance(n, tuple) or n != int(n):
            raise ValueError(f"[waves] components: expected an integer, got {n!r}")
        out["components"] = int(n)
        return out

    def sample(self, key, section):
        k_par, k_sea = jax.random.split(key)
        names = ("hs", "tp", "direction_deg", "origin_depth")
        ks = jax.random.split(k_par, len(names))
        hs, tp, direction_deg, depth = (draw(ks[i], section[n]) for i, n in enumerate(names))
        sea = waves.sea_state(
            k_sea,
            hs,
            tp,
            jnp.deg2rad(direction_deg),
            spectrum=section["spectrum"],
            gamma=section["gamma"],
            spreading=section["spreading"],
            components=section["components"],
            dtype=hs.dtype,
        )
        return SeaParams(sea, depth)

    def water(self, params, held, t, p_ned, current):
        p = jnp.asarray(p_ned).at[2].add(params.origin_depth)
        return waves.orbital_kinematics(params.sea, t, p, current)
