"""The sea of ``vcjax simulate NAME --waves HS TP DIR_DEG``, shared by the experiments that take
waves (``remus100``, ``sim2``): one long-crested JONSWAP sea drawn from ``PRNGKey(seed)`` and
the record of it that goes into ``metrics.json``."""

from __future__ import annotations

import jax
import numpy as np

from vcjax.environment import waves as wv

#: the option's sea: spectrum, peak enhancement and number of components
SPECTRUM = "jonswap"
GAMMA = 3.3
COMPONENTS = 64


def option_sea(waves, seed: int = 0) -> wv.Sea:
    """The sea of ``--waves HS TP DIR_DEG`` (``waves``: those three numbers, the direction in
    degrees towards which the waves travel): :func:`vcjax.environment.waves.sea_state` with
    :data:`SPECTRUM`, :data:`GAMMA` and :data:`COMPONENTS`, long-crested, from
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
    """What ``metrics.json`` records of the sea of :func:`option_sea` (``origin_depth``: the
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
