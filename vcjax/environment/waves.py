"""Ocean waves: spectra, random sea states and linear (Airy) wave kinematics in deep water.

Frames, units and signs
-----------------------
Inertial frame NED: ``north``, ``east`` [m] horizontal, ``depth`` [m] positive **down** below the
mean free surface. The elevation ``zeta`` [m] is positive **up**. A wave *direction* ``beta``
[rad] is the direction the waves travel **towards**, clockwise from north (the convention of
[`vcjax.environment.current`][vcjax.environment.current]: a swell with ``beta = pi/2`` runs towards
east).
Frequencies ``omega`` [rad/s], periods [s], wavenumbers ``k`` [rad/m]; one-sided spectra
``S(omega)`` [m^2 s/rad].

A sea is a sum of ``N`` regular components (linear superposition)::

    zeta(t, n, e) = sum_i a_i cos(theta_i),
    theta_i = k_i (n cos(beta_i) + e sin(beta_i)) - omega_i t + phi_i,
    k_i = omega_i^2 / g                                       (deep water, g = 9.81 m/s^2).

Airy kinematics (velocity potential ``(g a / omega) e^{-k d} sin(theta)``), with
``c_i = a_i omega_i e^{-k_i d} cos(theta_i)`` and ``s_i = a_i omega_i e^{-k_i d} sin(theta_i)``::

    u_NED      = sum_i [ c_i cos(beta_i),  c_i sin(beta_i),  -s_i ]          (velocity)
    du_NED/dt  = sum_i omega_i [ s_i cos(beta_i), s_i sin(beta_i), c_i ]    (local derivative)

Under a crest (``theta = 0``) the water moves with the wave (horizontal velocity ``a omega
e^{-kd}`` along ``beta``) and its vertical velocity is zero; a quarter wavelength ahead of the
crest (``theta = pi/2``) the surface rises, so the down-velocity is ``-a omega e^{-kd}`` (up);
under the crest the water accelerates downwards (``+a omega^2 e^{-kd}`` down). The velocity is
irrotational and divergence-free; the attenuation ``e^{-k d}`` is deep-water linear theory
(valid for depth of water > about half a wavelength). Above the mean free surface (``depth < 0``,
e.g. a vehicle at the surface inside a crest) the kinematics are those at ``depth = 0`` (constant
extrapolation instead of the exponential growth of the linear formulae).

Spectra
-------
Pierson–Moskowitz (ITTC/modified, in ``Hs`` and ``Tp``; ``omega_p = 2 pi / Tp``)::

    S_PM(omega) = 5/16 Hs^2 omega_p^4 omega^-5 exp(-5/4 (omega_p / omega)^4),

whose zeroth moment is exactly ``Hs^2 / 16`` and whose peak is at ``omega_p``. JONSWAP::

    S_J(omega) = S_PM(omega) gamma^r / I(gamma),  r = exp(-(omega - omega_p)^2 / (2 sigma^2
    omega_p^2)),  sigma = 0.07 (omega <= omega_p), 0.09 (omega > omega_p),

normalised **exactly**: ``I(gamma) = (16 / Hs^2) int S_PM gamma^r d omega`` (it depends on
``gamma`` only) is computed by a fixed composite Gauss–Legendre rule in ``u = (omega_p /
omega)^4`` (where the PM part is ``5/4 exp(-5/4 u)``), accurate to ~1e-12 relative and
differentiable in ``gamma``. So ``m0 = Hs^2 / 16`` for every ``gamma``; DNV's closed-form factor
``1 - 0.287 ln(gamma)`` differs from ``1 / I(gamma)`` by 0.2 % at ``gamma = 3.3`` and 1.8 %
at ``gamma = 7``.

Random sea states ([`sea_state`][vcjax.environment.waves.sea_state])
-------------------------------------
Frequency grid: ``N`` equal bins covering ``[0.6, 4.0] omega_p`` (``BAND``). Below
``0.6 omega_p`` a PM spectrum holds ``exp(-5/4 / 0.6^4) = 6e-5`` of its energy, above
``4 omega_p`` about ``5/4 / 4^4 = 0.5 %`` (JONSWAP with ``gamma = 3.3``: 0.3 %), i.e. the
realised ``Hs`` is at most 0.25 % low, from the high frequencies that ``e^{-k d}`` removes
within a metre or two of depth anyway. One frequency is drawn uniformly inside each bin and one
phase uniformly in ``[0, 2 pi)`` (so the sea never repeats: no common period), and the amplitude
is ``a_i = sqrt(2 S(omega_i) d_omega)``. Then ``E[sum a_i^2 / 2] = int_band S d omega`` exactly
(unbiased) and likewise for every moment (e.g. the velocity variance at depth). A single draw
scatters about it: with 64 components a JONSWAP (``gamma = 3.3``) sea's own variance
``sum a_i^2 / 2`` has a 3 % standard deviation (1.5 % in its Hs), from the few bins that
resolve the peak; more ``components`` narrow it.

Directional spreading: with ``spreading = s > 0`` each component gets its own direction drawn
from the ``cos^{2s}`` distribution ``D(beta) = Gamma(s + 1) / (sqrt(pi) Gamma(s + 1/2))
cos^{2s}(beta - beta_0)``, ``|beta - beta_0| <= pi/2`` (DNV-RP-C205's ``cos^n`` with ``n = 2s``),
by ``beta = beta_0 + arcsin(2 B - 1)``, ``B ~ Beta(s + 1/2, s + 1/2)`` (exact: ``sin(beta -
beta_0)`` has density ``(1 - x^2)^{s - 1/2}``). One direction per frequency keeps ``N``
components (no ``N x M`` grid) and gives the directional spectrum ``S(omega) D(beta)`` in
expectation; a discretised ``N x M`` grid would, with deterministic phases per frequency,
also be possible, but costs ``M`` times more per evaluation. ``spreading = 0`` (long-crested):
every component travels towards ``beta_0``. The frequencies and phases drawn from a key do not
depend on ``spreading`` (only the directions do).

The draws use ``jax.random`` only: the same key gives the same sea inside or outside ``jit`` and
``vmap``. ``hs``, ``tp``, ``direction`` and ``gamma`` may be traced (one sea per scenario under
``vmap``); ``spectrum``, ``components`` and whether ``spreading`` is zero are static. ``hs = 0``
gives a calm sea (every amplitude exactly 0, so every kinematic quantity exactly 0).

Water kinematics for a body (the plant-side seam)
-------------------------------------------------
[`water_kinematics`][vcjax.environment.waves.water_kinematics] gives the water's velocity ``v_w``
(3,) = current + orbital velocity at
the vehicle's NED position and its **material** acceleration ``a_w = du/dt + (v_w . grad) u`` (the
acceleration of the water particle there, which is what the pressure gradient of the undisturbed
flow, i.e. the Froude–Krylov force, and the added-mass force see). In body axes (``R`` body ->
NED, ``omega_b = nu[3:]``), ``nu_w = [R^T v_w; 0]``, ``nu_w_dot = [R^T a_w - omega_b x R^T v_w;
0]``, ``nu_r = nu - nu_w``, the rigid body obeys::

    M_RB nu_dot + C_RB(nu) nu + M_A nu_r_dot + C_A(nu_r) nu_r + D(nu_r) nu_r + g(eta)
        = tau + tau_FK,
    tau_FK = [m_d R^T a_w;  m_d r_bb x R^T a_w]
    ([`froude_krylov`][vcjax.environment.waves.froude_krylov]),

with ``m_d = rho V`` the displaced mass and ``r_bb`` the centre of buoyancy (the long-wave
approximation: the water's acceleration is uniform over the hull; Fossen 2021, Ch. 10, with
the current made unsteady). The translational wave force on a body held still is then
``(m_d I + M_A[:3, :3]) R^T a_w``. The drag sees ``nu_r``. Written the way vcjax's plants
already take a current (``M nu_r_dot + C(nu_r) nu_r + D nu_r + g = tau``, ``nu_dot = nu_r_dot +
nu_c_dot`` with ``v_c = v_w``, ``v_c_dot = a_w``), the same physics needs the extra body force
[`current_door_correction`][vcjax.environment.waves.current_door_correction] ``= tau_FK - M_RB
[R^T a_w; 0]``, which is exactly zero for a
neutrally buoyant body whose CG is at its CB (``m = m_d``, ``r_bg = r_bb``). A neutrally buoyant
body with its actuators off then moves with the water particles (``tests/test_waves.py``).

The water depends on the vehicle's position, so it is evaluated inside the plant's vector field
(every integrator stage), not once per control step like a uniform current::

    def plant_in_waves(t, x, u, args):             # x.eta (6,), args.water: the plant's door
        water = water_kinematics(sea, t, x.eta[:3], current)   # WaterMotion(v_w, a_w)
        dx = plant(t, x, u, args._replace(water=water))
        a_w = water.acceleration
        R = Rzyx(*x.eta[3:])
        tau_fk = current_door_correction(R, a_w, M_RB, m_d, r_bb)   # (6,) body force
        return dx._replace(nu=dx.nu + M^-1 tau_fk)   # or add tau_fk to the plant's force sum

Every plant takes the water through one door,
[`WaterMotion`][vcjax.environment.component.WaterMotion] (velocity and material acceleration,
(3,) NED each): [`vector_field`][vcjax.vehicles.sixdof.vector_field] takes it as it is;
[`vcjax.vehicles.remus100`][vcjax.vehicles.remus100] rotates the share named uniform
(``Remus100Args.uniform``, the current) as PVS does, by the yaw angle only, and the rest in
full. For REMUS 100 (``W = B``, CB at
the origin, CG 2 cm below) the correction is the pendulum moment ``-m r_bg x R^T a_w``.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax._checks import check_array, check_positive, float_dtype, is_concrete
from vcjax.environment.component import WaterMotion

__all__ = [
    "GRAVITY",
    "BAND",
    "SPECTRA",
    "jonswap",
    "jonswap_normalisation",
    "pierson_moskowitz",
    "Sea",
    "sea_state",
    "calm_sea",
    "elevation",
    "orbital_velocity",
    "orbital_acceleration",
    "orbital_velocity_gradient",
    "orbital_kinematics",
    "water_kinematics",
    "froude_krylov",
    "current_door_correction",
    "BREAKING_STEEPNESS",
    "LINEAR_STEEPNESS",
    "peak_wavelength",
    "check_point",
    "check_origin_depth",
    "envelope_warnings",
]

#: Gravity of the deep-water dispersion relation ``k = omega^2 / g`` [m/s^2].
GRAVITY = 9.81

#: Frequency band of [`sea_state`][vcjax.environment.waves.sea_state] as multiples of the peak
#: frequency ``omega_p``.
BAND = (0.6, 4.0)

#: Spectrum names accepted by [`sea_state`][vcjax.environment.waves.sea_state].
SPECTRA = ("jonswap", "pm")

#: Stokes' limiting steepness ``H / lambda`` of a regular deep-water wave (it breaks beyond).
BREAKING_STEEPNESS = 1.0 / 7.0
#: Sea-state steepness ``Hs / lambda_p`` above which linear (Airy) theory is warned about: half
#: the breaking limit (DNV-RP-C205 takes ``Hs / lambda_p <= 1/15`` for its design sea states;
#: steeper seas are strongly non-linear and partly breaking).
LINEAR_STEEPNESS = 1.0 / 14.0


# --------------------------------------------------------------------------------------------
# Validity envelope (eager checks, plain Python: before anything is traced)
# --------------------------------------------------------------------------------------------


def peak_wavelength(tp: float) -> float:
    """Deep-water wavelength of the peak period ``lambda_p = g tp^2 / (2 pi)`` [m]."""
    return GRAVITY * float(tp) ** 2 / (2.0 * math.pi)


def check_point(name: str, p) -> None:
    """``p`` must be one (3,) NED point ``(north, east, depth)`` (the shape is static, so this
    also holds inside ``jit``; a (2,) or (4,) point would otherwise be clamped by the indexing).
    Raises ``ValueError`` naming ``name``."""
    shape = jnp.shape(p)
    if shape != (3,):
        raise ValueError(
            f"{name}: expected a (3,) NED point (north, east, depth) [m], got shape {shape}"
        )


def check_origin_depth(origin_depth, name: str = "origin_depth") -> None:
    """The NED origin must lie at or below the mean free surface: ``origin_depth >= 0`` [m]
    (every entry of a range). The vehicle feels the sea at depth ``origin_depth + z``; an origin
    above the sea puts a survey in the air, where the (deep-water, submerged) kinematics of this
    module do not apply (they are held at their surface value). ``ValueError`` naming ``name``."""
    a = np.asarray(origin_depth, dtype=np.float64).reshape(-1)
    if np.any(a < 0):
        raise ValueError(
            f"{name}: {float(a.min()):g} m puts the NED origin above the mean free surface "
            "(depth is positive down); a survey under waves needs origin_depth >= 0"
        )


def _steep_share(hs, tp) -> str | None:
    """For ``(lo, hi)`` ranges drawn uniformly and independently (as a sweep draws them): the
    share of sea states steeper than ``LINEAR_STEEPNESS`` (midpoint rule, 400 x 400)."""
    h, t = np.asarray(hs, np.float64).reshape(-1), np.asarray(tp, np.float64).reshape(-1)
    if h.size == 1 and t.size == 1 or (np.ptp(h) == 0 and np.ptp(t) == 0):
        return None
    q = (np.arange(400) + 0.5) / 400
    hh = h.min() + np.ptp(h) * q
    tt = t.min() + np.ptp(t) * q
    steep = hh[:, None] / (GRAVITY * tt[None, :] ** 2 / (2.0 * math.pi))
    pct = float(f"{100.0 * float(np.mean(steep > LINEAR_STEEPNESS)):.2g}")  # 2 digits, no 1e+02
    return f"{pct:g} % of its sea states are past 1/14"


def envelope_warnings(hs, tp, origin_depth=None, components: int | None = None) -> list[str]:
    """One line per way a sea state leaves the validity of linear deep-water wave theory.

    ``hs``, ``tp``, ``origin_depth``: numbers or ``(lo, hi)`` ranges [m, s, m] (the steepest
    case is checked: the largest ``hs`` with the shortest ``tp``).

    * steepness ``Hs / lambda_p`` (``lambda_p = g tp^2 / 2 pi``) above ``LINEAR_STEEPNESS``:
      beyond linear theory (and, above ``BREAKING_STEEPNESS``, beyond breaking);
    * ``origin_depth`` shallower than ``Hs / 2`` (a significant crest): the vehicle sits in the
      crests' zone, where the linear kinematics are extrapolated (held at their surface value
      above the mean level).

    Deep water (water depth > ``lambda_p / 2``) is assumed throughout: vcjax has no seabed.
    """
    hs_hi = float(np.max(np.asarray(hs, dtype=np.float64)))
    tp_lo = float(np.min(np.asarray(tp, dtype=np.float64)))
    out = []
    if hs_hi > 0 and tp_lo > 0:
        lam = peak_wavelength(tp_lo)
        steep = hs_hi / lam
        if steep > LINEAR_STEEPNESS:
            if steep > BREAKING_STEEPNESS:
                tail = f"{steep / BREAKING_STEEPNESS:.2g}x steeper than breaking (1/7)"
            else:
                tail = "past the 1/14 limit of linear theory (breaking: 1/7)"
            share = _steep_share(hs, tp)
            which = "" if share is None else f"the steepest sea of the ranges ({share}): "
            out.append(
                f"waves: {which}hs {hs_hi:g} m with tp {tp_lo:g} s (wavelength {lam:.3g} m) has "
                f"steepness Hs/lambda_p = {steep:.3g}, {tail}: linear (Airy) kinematics are "
                "outside their validity there"
            )
    if origin_depth is not None and hs_hi > 0:
        d_lo = float(np.min(np.asarray(origin_depth, dtype=np.float64)))
        if d_lo < 0.5 * hs_hi:
            out.append(
                f"waves: origin_depth {d_lo:g} m is less than hs / 2 = {0.5 * hs_hi:g} m (the "
                "height of a significant crest): the vehicle runs among the crests, where linear "
                "kinematics are only extrapolated (held at their mean-surface value above it) "
                "and a real vehicle would broach"
            )
    return out


# --------------------------------------------------------------------------------------------
# Spectra
# --------------------------------------------------------------------------------------------


def _gauss_legendre_panels(edges, order):
    x, w = np.polynomial.legendre.leggauss(order)
    nodes, weights = [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        nodes.append(0.5 * (hi - lo) * x + 0.5 * (hi + lo))
        weights.append(0.5 * (hi - lo) * w)
    return np.concatenate(nodes), np.concatenate(weights)


# Quadrature in u = (omega_p / omega)^4 on [0, 40] (the PM weight exp(-5/4 u) is 2e-22 at 40):
# panels refined around the peak u = 1 (a kink of sigma there, so it is a panel edge).
_U_EDGES = (0.0, 0.3, 0.5, 0.7, 0.85, 1.0, 1.15, 1.3, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 6.0, 10.0)
_U_NODES, _U_WEIGHTS = _gauss_legendre_panels(_U_EDGES + (20.0, 40.0), 12)


def _peak_exponent(x):
    """``r(x)`` of JONSWAP's peak enhancement at ``x = omega / omega_p``."""
    sigma = jnp.where(x <= 1.0, 0.07, 0.09)
    return jnp.exp(-((x - 1.0) ** 2) / (2.0 * sigma * sigma))


def jonswap_normalisation(gamma):
    """() ``I(gamma) = (16 / Hs^2) int S_PM(omega) gamma^r(omega) d omega`` (dimensionless).

    ``1 / I(gamma)`` is the exact JONSWAP normalising factor (``I(1) = 1``); computed by a fixed
    192-node composite Gauss–Legendre rule (jittable and differentiable in ``gamma``; dtype of
    ``gamma``, default float for a Python number).
    """
    gamma = jnp.asarray(gamma)
    if not jnp.issubdtype(gamma.dtype, jnp.floating):
        gamma = gamma.astype(float_dtype())
    u = jnp.asarray(_U_NODES, dtype=gamma.dtype)
    w = jnp.asarray(_U_WEIGHTS, dtype=gamma.dtype)
    x = u ** (-0.25)
    f = 1.25 * jnp.exp(-1.25 * u + _peak_exponent(x) * jnp.log(gamma))
    return jnp.sum(w * f)


def _pm_unit(omega, tp):
    """``S_PM(omega)`` for ``Hs = 1`` [m^2 s/rad]; exactly 0 at ``omega <= 0.05 omega_p``."""
    wp = 2.0 * math.pi / tp
    x = omega / wp
    ok = x > 0.05
    xs = jnp.where(ok, x, 1.0)
    xi4 = xs**-4
    return jnp.where(ok, (5.0 / 16.0) / wp * xi4 / xs * jnp.exp(-1.25 * xi4), 0.0)


def _check_spectrum(hs, tp, gamma=None) -> None:
    """Eager checks of a spectrum's parameters (shapes always; values when concrete)."""
    for name, x in (("hs", hs), ("tp", tp), ("gamma", gamma)):
        if x is not None and jnp.shape(x) != ():
            raise ValueError(f"{name}: expected a scalar, got shape {jnp.shape(x)}")
    check_positive("hs", hs, (), strict=False)
    check_positive("tp", tp, ())
    if gamma is not None:
        a = check_array("gamma", gamma, ())
        if a is not None and not float(a) >= 1.0:
            raise ValueError(f"gamma: expected a peak enhancement >= 1, got {float(a)}")


def pierson_moskowitz(omega, hs, tp):
    """One-sided Pierson–Moskowitz spectrum ``S(omega)`` [m^2 s/rad] (module docstring).

    Args:
        omega: frequencies [rad/s] (any shape; 0 and negative give 0);
        hs: () significant wave height [m] (``m0 = Hs^2 / 16``); tp: () peak period [s].
    """
    _check_spectrum(hs, tp)
    return hs * hs * _pm_unit(omega, tp)


def jonswap(omega, hs, tp, gamma=3.3):
    """One-sided JONSWAP spectrum ``S(omega)`` [m^2 s/rad], exactly normalised (``m0 = Hs^2 / 16``).

    Args:
        omega: frequencies [rad/s] (any shape); hs: () significant wave height [m];
        tp: () peak period [s]; gamma: () peak enhancement (>= 1; 1 gives Pierson–Moskowitz).

    The normalisation ``1 / I(gamma)`` is computed by quadrature
    ([`jonswap_normalisation`][vcjax.environment.waves.jonswap_normalisation]),
    not by DNV's approximation ``1 - 0.287 ln(gamma)``.
    """
    _check_spectrum(hs, tp, gamma)
    omega = jnp.asarray(omega)
    gamma = jnp.asarray(gamma, dtype=omega.dtype) if _is_py(gamma) else jnp.asarray(gamma)
    wp = 2.0 * math.pi / tp
    enh = jnp.exp(_peak_exponent(omega / wp) * jnp.log(gamma))
    return hs * hs * _pm_unit(omega, tp) * enh / jonswap_normalisation(gamma)


def _is_py(x):
    return isinstance(x, (int, float))


# --------------------------------------------------------------------------------------------
# Sea states
# --------------------------------------------------------------------------------------------


class Sea(NamedTuple):
    """A realised sea: ``N`` regular deep-water components (a pytree of (N,) arrays).

    Attributes:
        omega: (N,) frequencies [rad/s].
        amplitude: (N,) amplitudes ``a_i`` [m] (>= 0).
        wavenumber: (N,) ``k_i = omega_i^2 / g`` [rad/m].
        phase: (N,) phases ``phi_i`` [rad].
        direction: (N,) directions of travel ``beta_i`` [rad, clockwise from north].
    """

    omega: Any
    amplitude: Any
    wavenumber: Any
    phase: Any
    direction: Any


def calm_sea(components: int = 1, dtype=None) -> Sea:
    """A [`Sea`][vcjax.environment.waves.Sea] of ``components`` zero-amplitude components (unit
    frequency): no waves.

    Every kinematic function returns exact zeros for it (a placeholder for "no waves" that
    keeps shapes static when some scenarios of a batch have waves and others not).
    """
    dtype = float_dtype(dtype)
    one = jnp.ones(components, dtype=dtype)
    zero = jnp.zeros(components, dtype=dtype)
    return Sea(one, zero, one / GRAVITY, zero, zero)


def _sea_dtype(dtype, *xs):
    if dtype is not None:
        return float_dtype(dtype)
    for x in xs:
        x_dtype = getattr(x, "dtype", None)
        if x_dtype is not None and jnp.issubdtype(x_dtype, jnp.floating):
            return jnp.dtype(x_dtype)
    return float_dtype()


def _check_static(spectrum, components, spreading, gamma, hs, tp, direction):
    if spectrum not in SPECTRA:
        raise ValueError(f"spectrum: expected one of {SPECTRA}, got {spectrum!r}")
    if isinstance(components, bool) or not isinstance(components, (int, np.integer)):
        raise ValueError(f"components: expected a positive integer, got {components!r}")
    if components < 1:
        raise ValueError(f"components: expected a positive integer, got {components}")
    check_positive("hs", hs, (), strict=False)
    check_positive("tp", tp, ())
    check_array("direction", direction, ())
    check_positive("spreading", spreading, (), strict=False)
    a = check_array("gamma", gamma, ())
    if a is not None and not float(a) >= 1.0:
        raise ValueError(f"gamma: expected a peak enhancement >= 1, got {float(a)}")


def sea_state(
    key,
    hs,
    tp,
    direction,
    *,
    spectrum: str = "jonswap",
    gamma=3.3,
    spreading=0.0,
    components: int = 64,
    dtype=None,
) -> Sea:
    """Draw a random sea (module docstring: grid, amplitudes, spreading).

    Args:
        key: a ``jax.random`` key (the sea is a pure function of it and the parameters).
        hs: () significant wave height [m] (>= 0; 0 gives a calm sea); tp: () peak period [s].
        direction: () mean direction the waves travel towards [rad, clockwise from north].
        spectrum: ``"jonswap"`` or ``"pm"`` (static). gamma: () JONSWAP peak enhancement (>= 1).
        spreading: () ``s`` of the ``cos^{2s}`` spreading; 0 = long-crested. Whether it is zero is
            decided in Python when it is concrete; a traced ``spreading`` must be > 0.
        components: ``N`` (static). dtype: float dtype (default: that of ``hs``/``tp``/
            ``direction`` when one is a float array, else JAX's default float).

    Returns:
        [`Sea`][vcjax.environment.waves.Sea] with (N,) arrays of ``dtype``.

    Raises:
        ValueError: naming the argument (unknown spectrum, ``hs < 0``, ``tp <= 0``,
            ``gamma < 1``, ``spreading < 0``, non-integer ``components``); concrete values only.
    """
    _check_static(spectrum, components, spreading, gamma, hs, tp, direction)
    dtype = _sea_dtype(dtype, hs, tp, direction)
    hs = jnp.asarray(hs, dtype=dtype)
    tp = jnp.asarray(tp, dtype=dtype)
    direction = jnp.asarray(direction, dtype=dtype)
    long_crested = is_concrete(spreading) and float(np.asarray(spreading)) == 0.0
    k_freq, k_phase, k_dir = jax.random.split(key, 3)

    wp = 2.0 * math.pi / tp
    lo, hi = wp * BAND[0], wp * BAND[1]
    d_omega = (hi - lo) / components
    u = jax.random.uniform(k_freq, (components,), dtype=dtype)
    omega = lo + (jnp.arange(components, dtype=dtype) + u) * d_omega
    if spectrum == "pm":
        s_unit = pierson_moskowitz(omega, 1.0, tp)
    else:
        s_unit = jonswap(omega, 1.0, tp, jnp.asarray(gamma, dtype=dtype))
    e2 = 2.0 * s_unit * d_omega
    pos = e2 > 0
    amplitude = hs * jnp.where(pos, jnp.sqrt(jnp.where(pos, e2, 1.0)), 0.0)
    phase = jax.random.uniform(k_phase, (components,), dtype=dtype, maxval=2.0 * math.pi)
    if long_crested:
        beta = jnp.broadcast_to(direction, (components,))
    else:
        s = jnp.asarray(spreading, dtype=dtype)
        b = jax.random.beta(k_dir, s + 0.5, s + 0.5, (components,), dtype=dtype)
        beta = direction + jnp.arcsin(jnp.clip(2.0 * b - 1.0, -1.0, 1.0))
    return Sea(omega, amplitude, omega * omega / GRAVITY, phase, beta)


# --------------------------------------------------------------------------------------------
# Kinematics
# --------------------------------------------------------------------------------------------


# 2 pi = _TWO_PI_HI + _TWO_PI_LO: the high part has 8 significant bits, so n * _TWO_PI_HI is
# exact for |n| < 2^16 in float32 (far beyond in float64); the low part is 2 pi - 6.28125.
_TWO_PI_HI = 6.28125
_TWO_PI_LO = 0.0019353071795864769253


@jax.custom_jvp
def _sincos(theta):
    """``(cos(theta), sin(theta))`` by one shared reduction and two short polynomials.

    ``r = theta - 2 pi n`` (``n = round(theta / 2 pi)``, two-part constant), ``h = r / 2`` in
    ``[-pi/2, pi/2]``, Taylor series of ``sin h`` and ``cos h`` (to ``h^13``/``h^12`` in float32,
    ``h^23``/``h^22`` in float64; truncation below the dtype's epsilon), then ``cos r = 1 - 2
    sin^2 h`` and ``sin r = 2 sin h cos h``. Branch-free multiply-adds: about 5x cheaper than
    ``jnp.cos`` plus ``jnp.sin`` on XLA:CPU, for 6e-7 (float32) and 1e-15 (float64) absolute
    error (``tests/test_waves.py``); its derivative is ``(-sin, cos)`` (a custom JVP).
    """
    dtype = theta.dtype
    n = jnp.round(theta * (1.0 / (2.0 * math.pi)))
    h = 0.5 * ((theta - n * _TWO_PI_HI) - n * _TWO_PI_LO)
    h2 = h * h
    terms = 11 if jnp.finfo(dtype).bits > 32 else 6
    s = jnp.full_like(h, (-1) ** terms / math.factorial(2 * terms + 1))
    c = jnp.full_like(h, (-1) ** terms / math.factorial(2 * terms))
    for j in range(terms - 1, -1, -1):
        s = s * h2 + (-1) ** j / math.factorial(2 * j + 1)
        c = c * h2 + (-1) ** j / math.factorial(2 * j)
    s = s * h
    return 1.0 - 2.0 * s * s, 2.0 * s * c


@_sincos.defjvp
def _sincos_jvp(primals, tangents):
    # d(cos, sin) = (-sin, cos) d theta from the primal outputs: the derivative of the functions
    # themselves, not of the polynomials (no second polynomial in gradient graphs).
    cos, sin = _sincos(primals[0])
    dtheta = tangents[0]
    return (cos, sin), (-sin * dtheta, cos * dtheta)


def _phase(sea: Sea, t, north, east):
    cb, sb = jnp.cos(sea.direction), jnp.sin(sea.direction)
    theta = sea.wavenumber * (north * cb + east * sb) - sea.omega * t + sea.phase
    return theta, cb, sb


def _components(sea: Sea, t, p, name: str = "p"):
    """Per-component ``c_i, s_i`` (module docstring), ``cos/sin(beta_i)`` and ``depth > 0``."""
    check_point(name, p)
    p = jnp.asarray(p)
    theta, cb, sb = _phase(sea, t, p[0], p[1])
    below = p[2] > 0
    depth = jnp.where(below, p[2], 0.0)
    amp = sea.amplitude * sea.omega * jnp.exp(-sea.wavenumber * depth)
    cos, sin = _sincos(theta)
    return amp * cos, amp * sin, cb, sb, below


def elevation(sea: Sea, t, north, east):
    """() free-surface elevation ``zeta`` [m, positive up] at time ``t`` [s], (north, east) [m]."""
    theta, _, _ = _phase(sea, t, north, east)
    return jnp.sum(sea.amplitude * _sincos(theta)[0])


def orbital_velocity(sea: Sea, t, p):
    """(3,) NED orbital velocity of the water [m/s] at ``p = (north, east, depth)`` [m], time ``t``.

    Linear Airy theory, attenuated ``e^{-k depth}`` (module docstring for the signs).
    """
    c, s, cb, sb, _ = _components(sea, t, p)
    return jnp.stack([jnp.sum(c * cb), jnp.sum(c * sb), -jnp.sum(s)])


def orbital_acceleration(sea: Sea, t, p):
    """(3,) local time derivative ``du/dt`` [m/s^2] of
    [`orbital_velocity`][vcjax.environment.waves.orbital_velocity] at fixed ``p``."""
    c, s, cb, sb, _ = _components(sea, t, p)
    ws, wc = sea.omega * s, sea.omega * c
    return jnp.stack([jnp.sum(ws * cb), jnp.sum(ws * sb), jnp.sum(wc)])


def _gradient(c, s, cb, sb, below, k):
    kc, ks = k * c, k * s
    g_nn = -jnp.sum(ks * cb * cb)
    g_ne = -jnp.sum(ks * cb * sb)
    g_ee = -jnp.sum(ks * sb * sb)
    g_dn = -jnp.sum(kc * cb)
    g_de = -jnp.sum(kc * sb)
    g_dd = jnp.sum(ks)
    z = jnp.zeros_like(g_dd)
    # columns d/d(depth) vanish above the mean surface (constant extrapolation there)
    g_nd, g_ed, g_dd = (jnp.where(below, v, z) for v in (g_dn, g_de, g_dd))
    rows = ([g_nn, g_ne, g_nd], [g_ne, g_ee, g_ed], [g_dn, g_de, g_dd])
    return jnp.stack([jnp.stack(r) for r in rows])


def orbital_velocity_gradient(sea: Sea, t, p):
    """(3, 3) ``G[i, j] = d u_i / d p_j`` [1/s] of
    [`orbital_velocity`][vcjax.environment.waves.orbital_velocity] (NED, ``p_j`` in
    (north, east, depth)); symmetric (irrotational) and trace-free (incompressible) below the
    mean surface."""
    c, s, cb, sb, below = _components(sea, t, p)
    return _gradient(c, s, cb, sb, below, sea.wavenumber)


def orbital_kinematics(sea: Sea, t, p_ned, current=None):
    """The waves' share of [`water_kinematics`][vcjax.environment.waves.water_kinematics]: the
    orbital velocity and its material
    acceleration in a uniform current (for a plant that takes the current through a door of its
    own and the waves on top of it, e.g. [`vcjax.vehicles.remus100`][vcjax.vehicles.remus100]).

    Args:
        sea: [`Sea`][vcjax.environment.waves.Sea]; t: () time [s]; p_ned: (3,) ``(north, east,
            depth)`` [m];
        current: (3,) uniform current in NED [m/s] (default 0).

    Returns:
        ``(u (3,), a (3,))``: ``u`` = [`orbital_velocity`][vcjax.environment.waves.orbital_velocity]
        [m/s] and ``a = du/dt + G (current +
        u)`` [m/s^2], so that ``water_kinematics(sea, t, p, current, current_dot) == (current + u,
        current_dot + a)``. Both exactly 0 for a calm sea.

    ``G v`` is summed per component with ``du/dt`` (not as the matrix of
    [`orbital_velocity_gradient`][vcjax.environment.waves.orbital_velocity_gradient] times ``v``):
    with ``w_i = cos(beta_i) v_n + sin(beta_i)
    v_e``, ``q_i = omega_i - k_i w_i`` and ``r_i = k_i v_d`` (0 above the mean surface),
    ``a = sum_i [cos(beta_i) A_i, sin(beta_i) A_i, c_i q_i + r_i s_i]``, ``A_i = s_i q_i - r_i
    c_i`` (a quarter fewer operations per component).
    """
    c, s, cb, sb, below = _components(sea, t, p_ned, "p_ned")
    if current is not None and jnp.shape(current) != (3,):
        raise ValueError(
            f"current: expected a (3,) NED velocity [m/s], got shape {jnp.shape(current)}"
        )
    u = jnp.stack([jnp.sum(c * cb), jnp.sum(c * sb), -jnp.sum(s)])
    v = u if current is None else u + current
    k = sea.wavenumber
    q = sea.omega - k * (cb * v[0] + sb * v[1])
    r = k * jnp.where(below, v[2], jnp.zeros_like(v[2]))
    A = s * q - r * c
    return u, jnp.stack([jnp.sum(cb * A), jnp.sum(sb * A), jnp.sum(c * q + r * s)])


def water_kinematics(sea: Sea, t, p_ned, current=None, current_dot=None):
    """Water velocity and material acceleration at a vehicle's NED position (the plant's seam).

    Args:
        sea: [`Sea`][vcjax.environment.waves.Sea]; t: () time [s]; p_ned: (3,) ``(north, east,
            depth)`` [m];
        current: (3,) uniform current in NED [m/s] (default 0);
        current_dot: (3,) its time derivative [m/s^2] (default 0).

    Returns:
        [`WaterMotion`][vcjax.environment.component.WaterMotion] ``(v_w (3,), a_w (3,))``:
        ``v_w = current + u(t, p)`` [m/s] and
        ``a_w = current_dot + du/dt + G v_w`` [m/s^2] (``G`` =
        [`orbital_velocity_gradient`][vcjax.environment.waves.orbital_velocity_gradient]),
        the acceleration of the water particle at ``p`` (the convective term makes a body that
        follows the particle feel exactly the particle's acceleration; the current, being uniform,
        only advects the waves). Pass it to a plant as its water (its one door).
    """
    if current_dot is not None and jnp.shape(current_dot) != (3,):
        raise ValueError(
            "current_dot: expected a (3,) NED acceleration [m/s^2], got shape "
            f"{jnp.shape(current_dot)}"
        )
    u, a = orbital_kinematics(sea, t, p_ned, current)
    v = u if current is None else u + current
    if current_dot is not None:
        a = a + current_dot
    return WaterMotion(v, a)


# --------------------------------------------------------------------------------------------
# Loads on a body
# --------------------------------------------------------------------------------------------


def froude_krylov(R, a_water, m_displaced, r_bb):
    """(6,) Froude–Krylov load about the body origin ``[m_d R^T a_w; m_d r_bb x R^T a_w]``.

    The force of the undisturbed flow's pressure gradient on the displaced water (long-wave
    approximation: ``a_w`` uniform over the hull), acting at the centre of buoyancy.

    Args:
        R: (3, 3) body -> NED rotation; a_water: (3,) water acceleration in NED [m/s^2]
            ([`water_kinematics`][vcjax.environment.waves.water_kinematics]); m_displaced: ()
            displaced mass ``rho V`` [kg] (``B / g``);
        r_bb: (3,) centre of buoyancy w.r.t. the body origin, body frame [m].
    """
    ab = R.T @ a_water
    f = m_displaced * ab
    return jnp.concatenate([f, jnp.cross(r_bb, f)])


def current_door_correction(R, a_water, M_RB, m_displaced, r_bb):
    """(6,) body force to add to ``tau`` of a plant that takes the water as its current.

    Plants of the form ``M nu_r_dot + C(nu_r) nu_r + ... = tau``, ``nu_dot = nu_r_dot +
    nu_c_dot`` given ``v_c = v_w`` and ``v_c_dot = a_w``
    ([`water_kinematics`][vcjax.environment.waves.water_kinematics]) apply the
    water's acceleration to the rigid body's mass, ``M_RB [R^T a_w; 0]``; the Froude–Krylov load
    is [`froude_krylov`][vcjax.environment.waves.froude_krylov]. Their difference
    ``froude_krylov(...) - M_RB [R^T a_w; 0]`` is
    returned: exactly zero when the body is neutrally buoyant with CG = CB.

    Args:
        R: (3, 3) body -> NED rotation; a_water: (3,) NED [m/s^2]; M_RB: (6, 6) rigid-body mass
        matrix about the body origin; m_displaced: () [kg]; r_bb: (3,) body frame [m].
    """
    ab = R.T @ a_water
    return froude_krylov(R, a_water, m_displaced, r_bb) - M_RB[:, :3] @ ab
