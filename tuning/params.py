"""Unconstrained parametrisation of any loop's gains (docs/guides/tuning.md).

The optimisers work on a flat vector ``theta`` (n,) of unconstrained reals.
[`GainSpace`][tuning.params.GainSpace]
(static) says which of a loop's gain groups
([`vcjax.loops.Loop.gain_specs`][vcjax.loops.loop.Loop.gain_specs]) are tuned and
maps ``theta`` to valid gains:

* a positive gain (``GainSpec.bound is None``; e.g. ``P_G`` (3,), ``P_Phi`` (5,), ``Delta``,
  ``sigma``, a depth PID's gains): ``gain = exp(theta)`` (log parametrisation: positive,
  scale-free, so one step size suits gains of very different size);
* a gain with an upper bound that depends on the others (``GainSpec.bound``; e.g. the VCM
  integral gains ``P_int`` (2,) below the Routh–Hurwitz bound of the ``eps`` error dynamics
  ``(P_Geps + P_Phieps) P_Geps P_Phieps``): ``gain = FRAC_MAX * sigmoid(theta) * bound``, so
  every ``theta`` gives a stable loop whatever the other gains are. Bounded groups are decoded
  after the positive ones (their bound uses the decoded values).

Gains that are not tuned keep the values of the ``base`` gains passed to
[`GainSpace.decode`][tuning.params.GainSpace.decode].
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import loops, paths
from vcjax.loops.pm import rh_bound

__all__ = ["FRAC_MAX", "GainSpace", "rh_bound", "default_loop"]

#: largest fraction of a bound a bounded gain may reach
FRAC_MAX = 0.95
_FRAC_CLIP = 1e-6  # bounded gains of exactly 0 are encoded as this fraction of FRAC_MAX


def default_loop() -> loops.Loop:
    """Simulation 1's loop with ``vcm_integral`` (what tuning meant before any ``[scenario]``)."""
    return loops.make_loop("infante", "vcm_integral", path=paths.LINE)


@dataclasses.dataclass(frozen=True)
class GainSpace:
    """Which gains of a loop are tuned, and how (static, hashable).

    Attributes:
        loop: the [`Loop`][vcjax.loops.loop.Loop] (default: Simulation 1's, ``vcm_integral``).
        tune: names of the tuned groups, a subset of ``loop.gain_specs()`` names, kept in that
            order (``None``: all of them).
    """

    loop: loops.Loop = dataclasses.field(default_factory=default_loop)
    tune: tuple[str, ...] | None = None

    def __post_init__(self):
        if not isinstance(self.loop, loops.Loop):
            raise ValueError(f"loop: expected a vcjax.loops.Loop, got {type(self.loop).__name__}")
        names = [s.name for s in self.loop.gain_specs()]
        tune = tuple(names if self.tune is None else self.tune)
        unknown = [t for t in tune if t not in names]
        if unknown:
            raise ValueError(
                f"tune: unknown gains {unknown} for {self.loop.describe()}; choose from {names}"
            )
        if len(set(tune)) != len(tune):
            raise ValueError(f"tune: duplicate names in {list(tune)}")
        if not tune:
            raise ValueError("tune: nothing to tune")
        object.__setattr__(self, "tune", tuple(n for n in names if n in tune))

    @property
    def specs(self) -> tuple:
        """The tuned [`GainSpec`][vcjax.loops.types.GainSpec] groups, in ``theta`` order."""
        by_name = {s.name: s for s in self.loop.gain_specs()}
        return tuple(by_name[n] for n in self.tune)

    @property
    def size(self) -> int:
        """Length n of ``theta``."""
        return sum(s.size for s in self.specs)

    def labels(self) -> list[str]:
        """(n,) names of the entries of ``theta`` (e.g. ``"P_Phi[2]"``, ``"Delta"``)."""
        out = []
        for s in self.specs:
            out += [s.name] if s.size == 1 else [f"{s.name}[{i}]" for i in range(s.size)]
        return out

    def _segments(self, theta):
        i = 0
        for s in self.specs:
            yield s, theta[i : i + s.size]
            i += s.size

    def decode(self, theta, base):
        """Map ``theta`` (n,) to the loop's gains (valid for every finite ``theta``).

        Works on traced arrays (differentiable); ``base`` supplies the gains not tuned.
        """
        theta = jnp.asarray(theta)
        gains = base
        bounded = []
        for s, seg in self._segments(theta):
            if s.bound is None:
                gains = s.set(gains, jnp.exp(seg))
            else:
                bounded.append((s, seg))
        for s, seg in bounded:
            gains = s.set(gains, FRAC_MAX * jax.nn.sigmoid(seg) * s.bound(gains))
        return gains

    def check_gains(self, gains, where: str = "gains"):
        """``gains`` if it has the structure of the loop's whole gains
        (``loop.default_gains()``), else a ``ValueError`` naming both: a part of the gains
        (e.g. Simulation 1's ``gains.vcm``) is refused before any field lookup fails."""
        want = jax.tree_util.tree_structure(self.loop.default_gains())
        got = jax.tree_util.tree_structure(gains)
        if got != want:
            raise ValueError(
                f"{where}: expected the whole gains of {self.loop.describe()} "
                f"({type(self.loop.default_gains()).__name__}), got {type(gains).__name__}"
            )
        return gains

    def encode(self, gains) -> jax.Array:
        """Inverse of ``decode`` on the tuned gains (``theta`` (n,), float).

        Bounded gains at (or beyond) the ends of ``[0, FRAC_MAX * bound]`` are clipped to a
        fraction ``1e-6`` inside; positive gains of 0 to ``log(1e-12)``.
        """
        self.check_gains(gains)
        parts = []
        for s in self.specs:
            g = jnp.asarray(s.get(gains))
            if s.bound is not None:
                f = g / (FRAC_MAX * s.bound(gains))
                f = jnp.clip(f, _FRAC_CLIP, 1.0 - _FRAC_CLIP)
                parts.append(jnp.log(f) - jnp.log1p(-f))
            else:
                parts.append(jnp.log(jnp.maximum(g, 1e-12)))
        return jnp.concatenate(parts)

    def symmetry_break(self, gains, eps: float = 0.1) -> np.ndarray:
        """(n,) offset of ``theta`` that splits equal Baumgarte pairs (``loop.symmetric_pairs``).

        The closed loop depends on each pair ``(p_G, p_Phi)`` of a holonomic row only through
        ``p_G + p_Phi`` and ``p_G p_Phi`` (35), so the loss is symmetric under swapping them and
        a start with ``p_G = p_Phi`` (the defaults) is a critical point along
        ``log(p_G / p_Phi)``: gradient descent would never separate them. The offset multiplies
        ``p_G`` by ``exp(eps)`` and divides ``p_Phi`` by it (product unchanged, sum up by
        ``O(eps^2)``). Zero where the pair is already unequal or not both tuned (log groups).
        """
        self.check_gains(gains)
        off = np.zeros(self.size)
        start, specs = {}, {}
        i = 0
        for s in self.specs:
            start[s.name], specs[s.name] = i, s
            i += s.size
        for a, ia, b, ib in self.loop.symmetric_pairs():
            if a not in start or b not in start:
                continue
            if specs[a].bound is not None or specs[b].bound is not None:
                continue
            va = np.asarray(specs[a].get(gains))[ia]
            vb = np.asarray(specs[b].get(gains))[ib]
            if np.isclose(va, vb):
                off[start[a] + ia] = eps
                off[start[b] + ib] = -eps
        return off

    def start(self, gains, eps: float = 0.1) -> jax.Array:
        """(n,) ``theta`` every tuner starts from: ``encode(gains)`` plus
        ``symmetry_break`` (what ``vcjax tune`` and the tuner studies share)."""
        return self.encode(gains) + jnp.asarray(self.symmetry_break(gains, eps))

    def describe(self, theta, base) -> dict:
        """Plain-JSON dict of the tuned groups' decoded values (for histories and reports)."""
        return self.values(self.decode(jnp.asarray(np.asarray(theta)), base))

    def values(self, g) -> dict:
        """Plain-JSON dict of the tuned groups' values in the gains ``g``."""
        out = {}
        for s in self.specs:
            v = np.asarray(s.get(g))
            out[s.name] = float(v[0]) if s.size == 1 else v.tolist()
        return out
