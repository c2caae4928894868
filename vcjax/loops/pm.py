"""Pieces shared by the loops whose law is the planar VCM law
([`vcjax.control.vcm`][vcjax.control.vcm]):
the Routh–Hurwitz bound of its integral gains and the tunable groups of its
[`PMGains`][vcjax.control.vcm.PMGains], wherever they sit in a vehicle's gains."""

from __future__ import annotations

from vcjax.loops.params import gain_spec, get_param

__all__ = ["rh_bound", "pm_gain_specs", "PM_PAIRS"]

#: the Baumgarte pairs of the planar VCM law (see ``Loop.symmetric_pairs``)
PM_PAIRS = (("P_G", 1, "P_Phi", 3), ("P_G", 2, "P_Phi", 4))


def rh_bound(P_G, P_Phi):
    """(2,) Routh–Hurwitz bound ``(P_Geps + P_Phieps) P_Geps P_Phieps`` on ``P_int`` (41)."""
    pg, pphi = P_G[1:], P_Phi[3:]
    return (pg + pphi) * pg * pphi


def pm_gain_specs(field: str, integral: bool, ilos: bool) -> tuple:
    """The tunable groups of the [`PMGains`][vcjax.control.vcm.PMGains] at gains field ``field``:
    ``P_int`` only with integral action, ``sigma_i`` only with the integral-LOS angle."""

    def int_bound(gains):
        pm = get_param(gains, field)
        return rh_bound(pm.P_G, pm.P_Phi)

    f = f"{field}."
    specs = [
        gain_spec("P_G", f + "P_G", 3),
        gain_spec("P_Phi", f + "P_Phi", 5),
        gain_spec("Delta", f + "Delta"),
        gain_spec("sigma", f + "sigma"),
    ]
    specs += [gain_spec("P_int", f + "P_int", 2, bound=int_bound)] if integral else []
    specs += [gain_spec("sigma_i", f + "sigma_i")] if ilos else []
    return tuple(specs)
