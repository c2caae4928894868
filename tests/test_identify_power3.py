"""Tests written for the survivors of the mutation run of ``vcjax/identify/fit.py`` from line 288
on (the second stage's weights, the uncertainty, the trust, the free-run RMS) and of
``vcjax/identify/figures.py`` (issue 31, item 8; docs/development/testing.md, "Mutation
testing"). NumPy only: the fit's pieces are called with stand-ins for the shooting problem and
the Levenberg-Marquardt solver, and the expected values are computed here independently (a
full-matrix inverse instead of the Schur complement, written-out formulas)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from test_identify import _dense  # the whole sparse Jacobian as one dense matrix

from vcjax.identify import fit

# ------------------------------------------------------------------ the two stages' weights


def _staged(monkeypatch, sig, reason="ftol"):
    """``fit._two_stages`` with a stand-in solver that records the weights each stage's residual
    function is built with; the shots' residual noise per channel is ``sig``."""
    seen = []

    def lm(linearize, residual, z, s, max_iters, callback):
        seen.append(residual(z, s))  # the stand-in problem returns its weights
        k = len(seen)
        r = np.full(3, float(k))
        return SimpleNamespace(
            z=z + 1.0, s=s, r=r, cost_history=[10.0 * k, k], iterations=k, reason=reason
        )

    monkeypatch.setattr(fit, "levenberg_marquardt", lm)
    spread = np.array([2.0, 4.0])
    seg = SimpleNamespace(y=np.zeros((1, 3, 2)))
    noise_args = []

    def noise(r, w):
        noise_args.append((r.copy(), np.array(w)))
        return np.asarray(sig, dtype=float)

    sh = SimpleNamespace(seg=seg, spread=spread, noise=noise)
    prob = SimpleNamespace(residuals=lambda z, s, seg, w: np.array(w, dtype=float))
    out = fit._two_stages(prob, sh, np.zeros(2), 7, None)
    return out, seen, noise_args


def test_the_second_stage_weighs_each_channel_by_one_over_its_noise(monkeypatch):
    """Kills: stage 2 skipped or run with the spread weights (``stage == 1`` mutated), the
    noise taken from other residuals or weights, the weights not ``1 / noise``, the noise floor
    (1e-12 spread) moved to where it acts on a real noise."""
    (res, w, history, iters), seen, noise_args = _staged(monkeypatch, [0.5, 1e-13])
    np.testing.assert_array_equal(seen[0], [0.5, 0.25])  # stage 1: 1 / spread
    r1, w1 = noise_args[0]
    np.testing.assert_array_equal(r1, np.full(3, 1.0))  # stage 1's residuals, its weights
    np.testing.assert_array_equal(w1, [0.5, 0.25])
    # the second channel's noise is below the floor 1e-12 * spread = 4e-12: floored
    np.testing.assert_allclose(seen[1], [1 / 0.5, 1 / 4e-12], rtol=1e-15)
    np.testing.assert_array_equal(w, seen[1])
    assert len(noise_args) == 1  # no third stage
    assert iters == [1, 2] and history == [10.0, 1, 20.0, 2]
    np.testing.assert_array_equal(res.r, np.full(3, 2.0))


def test_a_fit_to_round_off_stops_after_the_first_stage(monkeypatch):
    """Kills: the round-off test (every channel's noise below 1e-7 of its spread) inverted,
    made "any channel", or its threshold moved."""
    spread = np.array([2.0, 4.0])
    (_, w, _, iters), seen, _ = _staged(monkeypatch, 0.99e-7 * spread)
    assert iters == [1] and len(seen) == 1
    np.testing.assert_array_equal(w, [0.5, 0.25])
    # one channel at the threshold (not below it): the second stage runs
    (_, w, _, iters), seen, _ = _staged(monkeypatch, [0.5e-7 * 2.0, 1e-7 * 4.0])
    assert iters == [1, 2]
    np.testing.assert_allclose(w, [1 / 1e-7, 1 / 4e-7], rtol=1e-15)


def test_an_interrupted_first_stage_ends_the_fit(monkeypatch):
    (_, w, _, iters), seen, noise_args = _staged(monkeypatch, [0.5, 0.5], reason="interrupted")
    assert iters == [1] and noise_args == []
    np.testing.assert_array_equal(w, [0.5, 0.25])


# ------------------------------------------------------------------ the uncertainty


def _blocks(seed=0, J=3, m=5, p=2, n=2):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(J, m, p)), rng.normal(size=(J, m, n)), rng.normal(size=(J, m))


def _full_covariance(Jz, Js):
    """The (p, p) block of ``inv(J^T J)`` of the whole sparse Jacobian (numpy, no Schur)."""
    full = _dense(Jz, Js)
    p = Jz.shape[2]
    return np.linalg.inv(full.T @ full)[:p, :p]


def test_the_standard_deviations_and_correlation_are_the_delta_method_by_hand():
    """Kills: the residual variance's degrees of freedom (m - n_par) or square changed, the
    information's normalisation, its inverse or the scaling Jacobian applied wrongly, the
    correlation not normalised by the standard deviations."""
    Jz, Js, r = _blocks()
    g = np.array([0.7, -2.5])
    sh = SimpleNamespace(m=15.0, n_par=8)
    res = SimpleNamespace(r=r, Jz=Jz, Js=Js, z=np.array([0.1, 0.2]))
    prob = SimpleNamespace(scale_jacobian=lambda z: g)
    sd, corr, info_n = fit._uncertainty(prob, sh, res)
    sigma2 = np.sum(r**2) / (15.0 - 8)
    cov = sigma2 * _full_covariance(Jz, Js) * np.outer(g, g)
    np.testing.assert_allclose(sd, np.sqrt(np.diag(cov)), rtol=1e-9)
    np.testing.assert_allclose(
        corr, cov / np.outer(np.sqrt(np.diag(cov)), np.sqrt(np.diag(cov))), rtol=1e-9
    )
    np.testing.assert_allclose(np.diag(corr), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.diag(info_n), 1.0, rtol=1e-12)
    info = np.linalg.inv(_full_covariance(Jz, Js))
    d = np.sqrt(np.diag(info))
    np.testing.assert_allclose(info_n, info / np.outer(d, d), rtol=1e-9, atol=1e-12)


def test_a_parameter_the_scaling_maps_to_nothing_has_zero_std_and_zero_correlation():
    """Kills: the zero standard deviations not replaced before dividing (0 / 0: NaN in the
    correlation), replaced on the wrong side of 0."""
    Jz, Js, r = _blocks(1)
    sh = SimpleNamespace(m=15.0, n_par=8)
    res = SimpleNamespace(r=r, Jz=Jz, Js=Js, z=np.zeros(2))
    prob = SimpleNamespace(scale_jacobian=lambda z: np.array([3.0, 0.0]))
    sd, corr, _ = fit._uncertainty(prob, sh, res)
    sigma2 = np.sum(r**2) / 7.0
    assert sd[1] == 0.0
    np.testing.assert_allclose(
        sd[0], 3.0 * np.sqrt(sigma2 * _full_covariance(Jz, Js)[0, 0]), rtol=1e-9
    )
    np.testing.assert_allclose(corr, [[1.0, 0.0], [0.0, 0.0]], rtol=1e-12, atol=0.0)


# ------------------------------------------------------------------ excitation and trust


class _Prob:
    """A stand-in shooting problem: ``linearize`` records its arguments and returns fixed
    blocks; ``values`` maps ``z`` to ``nominal * exp(z)``; the scaling Jacobian is 1."""

    def __init__(self, Jz, Js, r, names=("a", "b")):
        self.blocks, self.all_names, self.calls = (r, Jz, Js), list(names), []
        self.nominal = {n: float(i + 1) for i, n in enumerate(names)}

    def linearize(self, z, s, seg, w):
        self.calls.append((np.array(z), np.array(s), seg, np.array(w)))
        return self.blocks

    def scale_jacobian(self, z):
        return np.ones(len(self.all_names))

    def values(self, z):
        return {
            n: self.nominal[n] * float(np.exp(v)) for n, v in zip(self.all_names, z, strict=True)
        }


def test_the_excitation_is_judged_at_the_start_with_the_spread_weights():
    """Kills: the start's segments taken from another sample than the first, the weights
    other than ``1 / spread``, the sensitivities from another information (``sqrt(I_ii / m)``,
    ``I`` by hand: the inverse of the full covariance), the conditioning warning dropped."""
    Jz, Js, r = _blocks(2)
    y = np.arange(24.0).reshape(3, 4, 2)
    sh = SimpleNamespace(seg=SimpleNamespace(y=y), spread=np.array([2.0, 8.0]), m=15.0)
    prob = _Prob(Jz, Js, r)
    z0 = np.array([0.3, -0.1])
    sens, warn = fit._excitation(prob, sh, z0)
    ((z, s, seg, w),) = prob.calls
    np.testing.assert_array_equal(z, z0)
    np.testing.assert_array_equal(s, y[:, 0, :])
    assert seg is sh.seg
    np.testing.assert_array_equal(w, [0.5, 0.125])
    info = np.linalg.inv(_full_covariance(Jz, Js))
    np.testing.assert_allclose(sens, np.sqrt(np.diag(info) / 15.0), rtol=1e-9)
    assert warn is None
    Jz[..., 1] = Jz[..., 0] * (1.0 + 1e-9)  # two parameters the logs cannot separate
    _, warn = fit._excitation(_Prob(Jz, Js, r), sh, z0)
    assert warn.startswith("before fitting: the information matrix at the initial estimate")


def test_trust_judges_identifiability_only_from_a_finite_correlation():
    """Kills: the identifiability warnings drawn from a non-finite correlation (``and`` ->
    ``or``, the test negated), the standard deviations not keyed by name, the trust warnings
    (plausible range, zero or NaN standard error) not judged against the nominal values."""
    Jz, Js, r = _blocks(3, p=3)
    Jz[..., 2] = Jz[..., 0] + Jz[..., 1]  # a null direction: the information is singular
    res = SimpleNamespace(r=r, Jz=Jz, Js=Js, z=np.array([0.0, np.log(200.0), 0.0]))
    sh = SimpleNamespace(m=15.0, n_par=9)
    prob = _Prob(Jz, Js, r, names=("a", "b", "c"))
    std, corr, warns, untrusted = fit._trust(prob, sh, res, ())
    assert list(std) == ["a", "b", "c"] and all(v > 0 for v in std.values())
    assert warns and all("not separately identifiable" in w for w in warns)
    assert any(w.startswith("b: estimate 400 is 200 x its nominal value 2") for w in untrusted)
    # the same with residuals that are not finite: no correlation, no identifiability claims
    res.r = np.full_like(r, np.nan)
    std, corr, warns, untrusted = fit._trust(prob, sh, res, ())
    assert not np.all(np.isfinite(corr)) and warns == []
    assert untrusted[0].startswith("a: standard error nan: zero or non-finite")


def test_the_information_is_normalised_whatever_its_scale_and_an_unexcited_one_stays_finite():
    """Kills: the floor of the information's diagonal (1e-300) moved to 1 (weak information,
    diagonal below 1, then not normalised to a unit diagonal) or below 0 (a parameter with no
    information at all: 0 / 0 in the normalised information instead of a zero row and an
    infinite standard deviation, which the trust warnings name)."""
    Jz, Js, r = _blocks(4)
    sh = SimpleNamespace(m=15.0, n_par=8)
    prob = SimpleNamespace(scale_jacobian=lambda z: np.ones(2))
    weak = SimpleNamespace(r=r, Jz=1e-3 * Jz, Js=Js, z=np.zeros(2))
    sd, _, info_n = fit._uncertainty(prob, sh, weak)
    np.testing.assert_allclose(np.diag(info_n), 1.0, rtol=1e-12)
    sigma2 = np.sum(r**2) / 7.0
    want = np.sqrt(sigma2 * np.diag(_full_covariance(1e-3 * Jz, Js)))
    np.testing.assert_allclose(sd, want, rtol=1e-6)
    Jz[..., 1] = 0.0  # the logs say nothing about the second parameter
    with np.errstate(over="ignore", invalid="ignore"):  # its variance overflows to inf
        sd, _, info_n = fit._uncertainty(
            prob, sh, SimpleNamespace(r=r, Jz=Jz, Js=Js, z=np.zeros(2))
        )
    assert np.all(np.isfinite(info_n)) and info_n[1, 1] == 0.0 and info_n[0, 0] == 1.0
    assert np.isfinite(sd[0]) and sd[1] == np.inf


# ------------------------------------------------------------------ figures (matplotlib only)


@pytest.fixture
def saved(monkeypatch):
    """The figures' ``savefig_atomic``, recording the figure instead of writing it."""
    from vcjax.runtime import outputs

    out = []
    monkeypatch.setattr(outputs, "savefig_atomic", lambda fig, path, **kw: out.append(fig))
    return out


def _result(model):
    return SimpleNamespace(
        problem=SimpleNamespace(model=model, step_name="euler"), warnings=[], converged=True,
        cost_history=[4.0, 2.0, 1.0], stage_iterations=[2], iterations=2, wall_time_s=0.5,
    )  # fmt: skip


def test_a_two_channel_prediction_figure_labels_both_bottoms_and_shares_time(saved, tmp_path):
    """Kills: the time axis not shared, and the bottom row's first axis miscounted when a
    model has fewer channels than the three columns (``max(n - 3, 0)``: both of two channels
    get the time label); the axes laid out beyond the figure's edges (``rect``)."""
    from vcjax.identify.figures import prediction_figure

    model = SimpleNamespace(state_columns=("a", "b"), units=("m", "rad"), vehicle="toy")
    t, x = np.arange(3.0), np.ones((3, 2))
    log = SimpleNamespace(name="toy.csv", t=t, x=x)
    prediction_figure(_result(model), log, x, x, tmp_path / "p.png")
    (fig,) = saved
    axes = fig.axes
    assert [a.get_visible() for a in axes] == [True, True, False]
    assert [a.get_xlabel() for a in axes[:2]] == ["t [s]", "t [s]"]
    assert axes[0].get_shared_x_axes().joined(axes[0], axes[1])
    before = [a.get_position().bounds for a in axes[:2]]
    assert all(
        0.0 <= x0 and x0 + w <= 1.0 and 0.0 <= y0 and y0 + h <= 1.0 for x0, y0, w, h in before
    )


def test_a_figure_without_warnings_is_laid_out_over_the_whole_height(saved, tmp_path):
    """Kills: the height reserved for no warnings not 0 (the layout then squeezed into
    nothing, or stretched below the figure): the cost figure's layout is matplotlib's own."""
    from vcjax.identify.figures import cost_history_figure
    from vcjax.identify.models import get_fit_model

    cost_history_figure(_result(get_fit_model("infante")), tmp_path / "c.png")
    (fig,) = saved
    (ax,) = fig.axes
    before = ax.get_position().bounds
    assert fig.texts == [] and 0.0 <= before[1] < 0.15 and before[1] + before[3] <= 1.0
    fig.tight_layout()
    np.testing.assert_allclose(ax.get_position().bounds, before, atol=1e-3)  # applied


@pytest.mark.parametrize("n, height", [(1, 0.065), (2, 0.09), (6, 0.19), (7, 0.19)])
def test_the_warnings_take_four_hundredths_and_a_fortieth_a_line_up_to_six(n, height):
    """Kills: the height reserved for the warnings' text other than ``0.04 + 0.025`` per line
    shown (at most 6); a line's width other than 150 characters (a line of 151 is
    shortened, at a word)."""
    from matplotlib.figure import Figure

    from vcjax.identify import figures

    warns = ["a" * 70 + " " + "b" * 71] + [f"w{i}" for i in range(n - 1)]  # the first: 151
    fig = Figure()
    assert figures._warnings_text(fig, SimpleNamespace(warnings=warns, converged=True)) == (
        pytest.approx(height, abs=1e-15)
    )
    (text,) = fig.texts
    assert text.get_text().split("\n")[0] == "warning: " + "a" * 70 + " ..."


# ------------------------------------------------------------------ fit_logs' signature


def test_fit_logs_takes_its_arguments_by_name_and_the_callback_only_by_name():
    """Kills: ``*`` in ``fit_logs``' signature made ``/`` (the model, logs, parameter names
    and settings positional-only, the callback positional): by name they are accepted (the
    empty logs refused first), a fifth positional argument is refused."""
    from vcjax.identify.models import get_fit_model

    model = get_fit_model("infante")
    with pytest.raises(ValueError, match="files: no logs given"):
        fit.fit_logs(model=model, logs=[], params=["cf_coeff"], options=None)
    with pytest.raises(TypeError, match="positional argument"):
        fit.fit_logs(model, [], ["cf_coeff"], None, lambda *a: None)
