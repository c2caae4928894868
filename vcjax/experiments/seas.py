"""The sea of ``vcjax simulate NAME --waves HS TP DIR_DEG``, shared by the experiments whose loops
feel waves (``remus100``, ``sim2``): the options
([`WaveOptions`][vcjax.experiments.seas.WaveOptions]), one long-crested JONSWAP
sea drawn from ``PRNGKey(--wave-seed)`` and the record of it that goes into ``metrics.json``."""

from __future__ import annotations

import dataclasses
import math

import jax
import numpy as np

from vcjax.environment import waves as wv
from vcjax.experiments.base import Options, option
from vcjax.runtime import sizing

__all__ = ["WaveOptions", "option_sea", "option_sea_record", "SPECTRUM", "GAMMA", "COMPONENTS"]

#: the option's sea: spectrum, peak enhancement and number of components
SPECTRUM = "jonswap"
GAMMA = 3.3
COMPONENTS = 64


@dataclasses.dataclass(frozen=True)
class WaveOptions(Options):
    """``--waves HS TP DIR_DEG`` and ``--wave-seed N``: every run in one random sea
    ([`option_sea`][vcjax.experiments.seas.option_sea])."""

    waves: tuple[float, float, float] | None = option(
        None,
        "a random JONSWAP sea (64 components, long-crested): significant height HS [m], peak "
        "period TP [s], direction the waves travel towards DIR_DEG [deg, clockwise from north]",
        ("HS", "TP", "DIR_DEG"),
    )
    wave_seed: int | None = option(
        None, "with --waves: seed of the sea's frequencies and phases (default 0)", "N"
    )

    @property
    def seed(self) -> int:
        """The sea's seed (``--wave-seed``, default 0)."""
        return 0 if self.wave_seed is None else int(self.wave_seed)

    def record(self) -> dict:
        return {**super().record(), "wave_seed": self.seed}

    def check(self, dt: float, x64: bool = True) -> None:
        super().check(dt, x64)
        if self.wave_seed is not None:
            if self.waves is None:
                raise ValueError("--wave-seed needs --waves HS TP DIR_DEG")
            sizing.check_seed("--wave-seed", self.wave_seed, x64)
        if self.waves is None:
            return
        hs, tp, _ = self.waves
        if not all(math.isfinite(v) for v in self.waves):
            raise ValueError(f"--waves: contains NaN or inf, got {list(self.waves)}")
        if hs < 0:
            raise ValueError(f"--waves: HS must be >= 0 [m], got {hs:g}")
        if tp < 40.0 * dt:
            raise ValueError(
                f"--waves: TP must be >= 40 dt = {40.0 * dt:g} s (the shortest component, "
                f"TP / 4, needs 10 steps), got {tp:g}"
            )


def option_sea(waves, seed: int = 0) -> wv.Sea:
    """The sea of ``--waves HS TP DIR_DEG`` (``waves``: those three numbers, the direction in
    degrees towards which the waves travel): [`sea_state`][vcjax.environment.waves.sea_state] with
    ``SPECTRUM``, ``GAMMA`` and ``COMPONENTS``, long-crested, from
    ``PRNGKey(seed)``."""
    hs, tp, direction_deg = (float(v) for v in waves)
    key = jax.random.PRNGKey(seed)
    return wv.sea_state(
        key,
        hs,
        tp,
        np.radians(direction_deg),
        spectrum=SPECTRUM,
        gamma=GAMMA,
        components=COMPONENTS,
    )


def option_sea_record(waves, seed: int, origin_depth: float) -> dict:
    """What ``metrics.json`` records of the sea of [`option_sea`][vcjax.experiments.seas.option_sea]
    (``origin_depth``: the
    NED origin's depth below the mean free surface [m])."""
    hs, tp, direction = (float(x) for x in waves)
    return {
        "hs": hs,
        "tp": tp,
        "direction_deg": direction,
        "seed": int(seed),
        "spectrum": SPECTRUM,
        "gamma": GAMMA,
        "components": COMPONENTS,
        "origin_depth": float(origin_depth),
    }
