"""Unconstrained parametrisation of the VCM gains (SPEC §6).

The optimisers work on a flat vector ``theta`` (n,) of unconstrained reals. :class:`GainSpace`
(static) says which gains are tuned and maps ``theta`` to valid :class:`~vcjax.control.vcm.PMGains`:

* ``P_G`` (3,), ``P_Phi`` (5,), ``Delta`` (), ``sigma`` (): ``gain = exp(theta)`` (log
  parametrisation: positive, scale-free, so one step size suits gains of very different size);
* ``P_int`` (2,) (integral action (41)): a fraction of the Routh–Hurwitz bound of the ``eps``
  error dynamics, ``P_int = FRAC_MAX * sigmoid(theta) * (P_Geps + P_Phieps) P_Geps P_Phieps``, so
  every ``theta`` gives a stable (41) whatever the other gains are.

Gains that are not tuned keep the values of the ``base`` gains passed to :meth:`GainSpace.decode`.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from vcjax.control.vcm import PMGains

__all__ = ["GAIN_NAMES", "FRAC_MAX", "GainSpace", "rh_bound"]

#: tunable gain groups and their sizes
GAIN_NAMES = {"P_G": 3, "P_Phi": 5, "Delta": 1, "sigma": 1, "P_int": 2, "sigma_i": 1}
#: largest fraction of the Routh–Hurwitz bound the integral gains may reach
FRAC_MAX = 0.95
_FRAC_CLIP = 1e-6  # integral gains of exactly 0 are encoded as this fraction of FRAC_MAX


def rh_bound(P_G, P_Phi):
    """(2,) Routh–Hurwitz bound ``(P_Geps + P_Phieps) P_Geps P_Phieps`` on ``P_int`` (41)."""
    pg, pphi = P_G[1:], P_Phi[3:]
    return (pg + pphi) * pg * pphi


@dataclasses.dataclass(frozen=True)
class GainSpace:
    """Which VCM gains are tuned, and how (static, hashable).

    Attributes:
        variant: ``"vcm_integral"`` (default), ``"vcm"`` or ``"vcm_ilos"``. ``sigma_i`` is tuned
            only for ``"vcm_ilos"``. For ``"vcm"`` the integral gains
            are never tuned (the law ignores them).
        tune: names of the tuned groups, a subset of :data:`GAIN_NAMES`, kept in that order.
    """

    variant: str = "vcm_integral"
    tune: tuple[str, ...] = ("P_G", "P_Phi", "Delta", "sigma", "P_int")

    def __post_init__(self):
        if self.variant not in ("vcm", "vcm_integral", "vcm_ilos"):
            raise ValueError(
                f"variant: expected 'vcm', 'vcm_integral' or 'vcm_ilos', got {self.variant!r}"
            )
        tune = tuple(self.tune)
        unknown = [t for t in tune if t not in GAIN_NAMES]
        if unknown:
            raise ValueError(f"tune: unknown gains {unknown}; choose from {list(GAIN_NAMES)}")
        if len(set(tune)) != len(tune):
            raise ValueError(f"tune: duplicate names in {list(tune)}")
        tune = tuple(n for n in GAIN_NAMES if n in tune)
        if self.variant == "vcm":
            tune = tuple(n for n in tune if n != "P_int")
        if self.variant != "vcm_ilos":  # only the ILOS approach angle uses sigma_i
            tune = tuple(n for n in tune if n != "sigma_i")
        if not tune:
            raise ValueError("tune: nothing to tune")
        object.__setattr__(self, "tune", tune)

    @property
    def size(self) -> int:
        """Length n of ``theta``."""
        return sum(GAIN_NAMES[n] for n in self.tune)

    def labels(self) -> list[str]:
        """(n,) names of the entries of ``theta`` (e.g. ``"P_Phi[2]"``, ``"Delta"``)."""
        out = []
        for n in self.tune:
            k = GAIN_NAMES[n]
            out += [n] if k == 1 else [f"{n}[{i}]" for i in range(k)]
        return out

    def decode(self, theta, base: PMGains) -> PMGains:
        """Map ``theta`` (n,) to :class:`PMGains` (valid for every finite ``theta``).

        Works on traced arrays (differentiable); ``base`` supplies the gains not tuned.
        """
        theta = jnp.asarray(theta)
        vals = dict(base._asdict())
        i = 0
        frac = None
        for n in self.tune:
            k = GAIN_NAMES[n]
            seg = theta[i : i + k]
            i += k
            if n == "P_int":
                frac = FRAC_MAX * jax.nn.sigmoid(seg)
            else:
                vals[n] = jnp.exp(seg) if k > 1 else jnp.exp(seg[0])
        if frac is not None:
            vals["P_int"] = frac * rh_bound(vals["P_G"], vals["P_Phi"])
        return PMGains(**vals)

    def encode(self, gains: PMGains) -> jax.Array:
        """Inverse of :meth:`decode` on the tuned gains (``theta`` (n,), float).

        Integral gains at (or beyond) the ends of ``[0, FRAC_MAX * bound]`` are clipped to a
        fraction ``1e-6`` inside.
        """
        parts = []
        for n in self.tune:
            g = jnp.atleast_1d(jnp.asarray(getattr(gains, n)))
            if n == "P_int":
                f = g / (FRAC_MAX * rh_bound(gains.P_G, gains.P_Phi))
                f = jnp.clip(f, _FRAC_CLIP, 1.0 - _FRAC_CLIP)
                parts.append(jnp.log(f) - jnp.log1p(-f))
            else:
                parts.append(jnp.log(jnp.maximum(g, 1e-12)))  # sigma_i may be 0
        return jnp.concatenate(parts)

    def symmetry_break(self, gains: PMGains, eps: float = 0.1) -> np.ndarray:
        """(n,) offset of ``theta`` that splits equal ``(p_G, p_Phi)`` pairs of the ``eps`` rows.

        The closed loop depends on each pair only through ``P_eps2 = p_G + p_Phi`` and
        ``P_eps1 = p_G p_Phi`` (35), so the loss is symmetric under swapping them and a start
        with ``p_G = p_Phi`` (the defaults) is a critical point along ``log(p_G / p_Phi)``:
        gradient descent would never separate them. The offset multiplies ``p_G`` by
        ``exp(eps)`` and divides ``p_Phi`` by it (``P_eps1`` unchanged, ``P_eps2`` up by
        ``O(eps^2)``). Zero where the pair is already unequal or not both tuned.
        """
        off = np.zeros(self.size)
        if not ("P_G" in self.tune and "P_Phi" in self.tune):
            return off
        start = {}
        i = 0
        for n in self.tune:
            start[n] = i
            i += GAIN_NAMES[n]
        pg, pphi = np.asarray(gains.P_G), np.asarray(gains.P_Phi)
        for row in (1, 2):  # s, e rows: P_G[1:] pairs with P_Phi[3:]
            if np.isclose(pg[row], pphi[row + 2]):
                off[start["P_G"] + row] = eps
                off[start["P_Phi"] + row + 2] = -eps
        return off

    def describe(self, theta, base: PMGains) -> dict:
        """Plain-JSON dict of the decoded gains (for histories and reports)."""
        g = self.decode(jnp.asarray(np.asarray(theta)), base)
        return {k: np.asarray(v).tolist() for k, v in g._asdict().items()}
