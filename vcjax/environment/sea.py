"""The waves component (``[waves]``): a random sea per run (``
sea_state``, physics in [`vcjax.environment.waves`][vcjax.environment.waves]) whose orbital motion
the vehicle feels
at its own position."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax._checks import ConfigError
from vcjax.environment import waves
from vcjax.environment.component import Component, Key, draw_unit, written

__all__ = ["Waves", "SeaParams", "SAMPLED", "MIN_SPREADING", "check_waves"]


class SeaParams(NamedTuple):
    """The sampled sea of one run.

    Attributes:
        sea: [`Sea`][vcjax.environment.waves.Sea] ((N,) arrays).
        origin_depth: () depth of the NED origin below the mean free surface [m] (the sea is
            felt at ``origin_depth + z``).
        hs, tp, direction_deg: () the drawn significant height [m], peak period [s] and
            direction [deg, towards, clockwise from north] (``None`` where not drawn).
    """

    sea: Any
    origin_depth: Any
    hs: Any = None
    tp: Any = None
    direction_deg: Any = None


#: the keys of ``[waves]`` drawn per run, in the order of their uniform numbers
SAMPLED = ("hs", "tp", "direction_deg", "origin_depth")
#: the smallest positive ``spreading``: ``s -> 0+`` tends to a uniform spread over the whole
#: +-90 deg half-plane (the widest), while ``s = 0`` is long-crested (one direction), so a tiny
#: positive ``s`` would silently mean the opposite of what 0 means
MIN_SPREADING = 1.0


def check_waves(section: Mapping, given: Mapping) -> None:
    """Keys that do not apply to the others' values are refused: ``gamma`` is JONSWAP's; a
    positive ``spreading`` is at least ``MIN_SPREADING``; the NED origin lies below the mean
    surface (``origin_depth >= 0``). ``given``: the keys the table wrote
    ([`written`][vcjax.environment.component.written])."""
    if section["spectrum"] == "pm" and "gamma" in given:
        raise ConfigError(
            "[waves] gamma: the peak enhancement of the JONSWAP spectrum; spectrum = 'pm' "
            "(Pierson-Moskowitz) has none and would ignore it"
        )
    if 0.0 < section["spreading"] < MIN_SPREADING:
        raise ConfigError(
            f"[waves] spreading: 0 is long-crested (one direction) and s >= {MIN_SPREADING:g} "
            f"spreads as cos^2s (1 the widest); got {section['spreading']:g}, which would "
            "spread the components over the whole +-90 deg half-plane"
        )
    try:
        waves.check_origin_depth(section["origin_depth"], "[waves] origin_depth")
    except ValueError as err:
        raise ConfigError(str(err)) from None


@dataclasses.dataclass(frozen=True)
class Waves(Component):
    """Linear (Airy) waves in deep water: ``hs``, ``tp``, ``direction_deg``, ``origin_depth``
    drawn per run (numbers or ``[lo, hi]`` ranges); ``spectrum``, ``components`` and whether
    ``spreading`` is zero are static (they change the program)."""

    section = "waves"
    kind = "waves"
    #: THE declaration of ``[waves]`` (`vcjax.config.schema.Waves`
    #: is built from it)
    schema = {
        "spectrum": Key(
            "jonswap", "wave spectrum (pm: Pierson-Moskowitz)", choices=waves.SPECTRA, kind="str"
        ),
        "hs": Key(None, "significant wave height (required)", lo=0.0, unit="m"),
        "tp": Key(None, "peak period (required)", lo=0.0, strict_lo=True, unit="s"),
        "direction_deg": Key(
            0.0, "direction the waves travel towards, clockwise from north", unit="deg"
        ),
        "gamma": Key(3.3, "JONSWAP peak enhancement (1: Pierson-Moskowitz)", lo=1.0, kind="float"),
        "spreading": Key(
            0.0,
            "s of the cos^2s directional spreading: 0 = long-crested (every component towards "
            "direction_deg), else s >= 1 (1: cos^2, the widest; larger s: narrower)",
            lo=0.0,
            kind="float",
        ),
        "components": Key(64, "regular components of each sea", lo=1, kind="int"),
        "origin_depth": Key(
            0.0,
            "depth of the NED origin below the mean free surface: the vehicle feels the sea at "
            "depth origin_depth + z (the same mission at another depth)",
            unit="m",
        ),
    }

    def check(self, raw):
        out = super().check(raw)
        check_waves(out, written(raw, self.schema))
        return out

    def sample(self, key, section, dtype=None):
        """The sea of one run: ``hs``, ``tp``, ``direction_deg`` and ``origin_depth`` from four
        uniform numbers of ``split(key)[0]``, the sea's frequencies, phases and directions from
        ``split(key)[1]`` ([`sea_state`][vcjax.environment.waves.sea_state]); ``dtype``: float
        dtype (default: JAX's default float)."""
        k_par, k_sea = jax.random.split(key)
        dtype = jnp.asarray(0.0).dtype if dtype is None else jnp.dtype(dtype)
        u = jax.random.uniform(k_par, (4,), dtype)
        hs, tp, direction_deg, depth = (
            draw_unit(u[i], section[n], dtype) for i, n in enumerate(SAMPLED)
        )
        sea = waves.sea_state(
            k_sea,
            hs,
            tp,
            direction_deg * (math.pi / 180.0),
            spectrum=section["spectrum"],
            gamma=section["gamma"],
            spreading=section["spreading"],
            components=section["components"],
            dtype=hs.dtype,
        )
        return SeaParams(sea, depth, hs, tp, direction_deg)

    def water(self, params, held, t, p_ned, current):
        p = jnp.asarray(p_ned).at[2].add(params.origin_depth)
        return waves.orbital_kinematics(params.sea, t, p, current)
