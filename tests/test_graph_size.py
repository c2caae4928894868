"""Graph size as a test: every registered loop's forward and gradient program stays within its
StableHLO line budget (issue 30).

The line count of the lowered program (``jax.jit(f).lower(...).as_text()``) is deterministic,
unlike compile seconds (those live in ``benchmarks/perf/compile_times.py``, which builds the very
programs counted here with the same helpers, ``tests/reference/programs.py``), and XLA's compile time follows it. Lowering only, nothing is
compiled. The horizon is 2 steps: a rollout is one ``lax.scan`` whose body does not depend on its
length (checked: 5 and 250 steps give the same counts for every loop, and
``test_the_count_does_not_depend_on_the_horizon`` keeps checking it on one loop).

Budgets: the counts of float64 programs under jax 0.10.2 plus about 10 %, rounded up to 100
lines (REMUS 100 ``vcm3d``: 6,898 / 24,304 lines, the issue's budget 8 k / 30 k). A change that
grows a program past its budget has to say why here; one that shrinks it should tighten it.

The gradient is the library's default reverse pass: per-step checkpointed
(``RolloutConfig.checkpoint``, default True since the budgets of the stored tape, in the
comments). It holds each step twice, once forward and once recomputed in the backward scan, so
it has 10-26 % more lines than the stored tape, and compiles faster (REMUS 100 ``vcm3d_ilos``:
about 15 % less XLA compile time, ``benchmarks/perf/compile_times.py``): what it no longer
holds is the tape's residuals, each of them a buffer XLA schedules through the backward scan.
On 6-DOF plants it checkpoints RK4's four stages instead (``rk4(..., remat=True)``; the step
too with a sampled law), for the same reason and more so: the stage loop stacked the vector
field's thousand or so intermediates; ``vcm3d_ilos``'s gradient builds in about two thirds of
the time (its lines: 29,922 to 25,389).

Lines are a budget, not a clock: XLA's compile follows the program it optimises, and buffers
stacked through a loop (dynamic slices in and out, one per residual) cost it far more than their
lines. Checkpointing the stages inside the checkpointed step added 12 % lines to
``vcm3d_ilos``'s gradient (33,623) and still took a quarter off its build.
"""

import pytest

from tests.reference.programs import build_times, loop_programs

#: "vehicle/controller": (forward, gradient) budgets in StableHLO lines; measured counts in
#: the comments (float64, jax 0.10.2, ``python -m benchmarks.perf.compile_times --no-compile``)
BUDGETS = {
    "arm/vcm": (2400, 11200),  # 2177 / 10118 (stored tape: 8041)
    "infante/vcm": (1300, 4200),  # 1124 / 3806 (stored tape: 3361)
    "infante/vcm_integral": (1300, 4400),  # 1139 / 3926 (stored tape: 3478)
    "infante/vcm_ilos": (1300, 4600),  # 1161 / 4112 (stored tape: 3703)
    "infante/ilos": (1100, 3700),  # 990 / 3325 (stored tape: 2946)
    "infante/los_pid": (1200, 3800),  # 1010 / 3437 (stored tape: 3030)
    "infante/alos": (1100, 3700),  # 990 / 3319 (stored tape: 2932)
    # 6-DOF: stages checkpointed (the step too where stated); "step": the step checkpointed
    "odin/vcm": (4400, 12500),  # 3961 / 11353 (step: 13416; stored tape: 11461)
    "odin/vcm_full": (4400, 12400),  # 3932 / 11260 (step: 13330; stored tape: 11403)
    "remus100/vcm3d_ilos": (7900, 28000),  # 7156 / 25389 (step: 29922; stored tape: 25755)
    "remus100/vcm3d": (7600, 26800),  # 6898 / 24304 (step: 28525; tape: 24304); issue: 30 k
    "remus100/decoupled": (6300, 13100),  # 5646 / 11881 (step: 14574; stored tape: 13626)
    "remus100/alos3d": (3400, 8900),  # 3076 / 8073 (step: 9814; stored tape: 9172)
    "remus100/pvs_pid": (3400, 8700),  # 3042 / 7889 (step: 9597; stored tape: 8940)
}
STEPS = 2
#: the JAX release the budgets were measured with (a JAX release changes the lowering: jax
#: 0.5.1 writes 1.3-1.6x the lines of 0.10.2 for the same loops)
BUDGET_JAX = (0, 10)


def _jax_version() -> tuple[int, ...]:
    import jax

    return tuple(int(p) for p in jax.__version__.split(".")[:2])


def _lines(vehicle, controller, steps=STEPS, kinds=("forward", "gradient")):
    fwd, grad, gains, sc = loop_programs(vehicle, controller, steps, "continuous")
    progs = {"forward": fwd, "gradient": grad}
    return [build_times(progs[k], gains, sc, compile=False)["hlo_lines"] for k in kinds]


#: vcjax's own vehicles (examples and tests register more: the puck, the skiff, laws of theirs)
BUILTIN = ("infante", "odin", "remus100", "arm")


def test_every_registered_loop_has_a_budget():
    from vcjax import loops

    every = {f"{v}/{c}" for v in BUILTIN for c in loops.controllers(v)}
    every = {n for n in every if n.split("/")[1] in _builtin_controllers(n.split("/")[0])}
    assert every == set(BUDGETS), "add the new loop's budget (or drop the removed one's)"


def _builtin_controllers(vehicle: str) -> set[str]:
    """The controllers vcjax itself gives ``vehicle`` (laws registered by an example or a test,
    e.g. the how-to's ``los_pd``, are not vcjax's)."""
    from vcjax import loops

    cls = loops.loop_class(vehicle)
    return {
        c
        for c in loops.controllers(vehicle)
        if c not in cls.laws or type(cls.laws[c]).__module__.startswith("vcjax.")
    }


#: the default run checks these (the largest programs of each vehicle and every INFANTE law);
#: the rest are slow (time)
SLOW_BUDGETS = {"remus100/vcm3d_ilos", "remus100/decoupled", "remus100/pvs_pid"}


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(n, marks=pytest.mark.slow(reason="time")) if n in SLOW_BUDGETS else n
        for n in sorted(BUDGETS)
    ],
)
def test_forward_and_gradient_within_budget(name):
    if _jax_version() < BUDGET_JAX:
        pytest.skip(f"budgets measured with jax {BUDGET_JAX}: older JAX lowers more lines")
    vehicle, controller = name.split("/")
    forward, gradient = _lines(vehicle, controller)
    budget_f, budget_g = BUDGETS[name]
    assert forward <= budget_f, f"{name} forward: {forward} StableHLO lines > {budget_f}"
    assert gradient <= budget_g, f"{name} gradient: {gradient} StableHLO lines > {budget_g}"
    # the reverse pass is a second scan over stored residuals: always the larger program
    assert gradient > forward


def test_the_count_does_not_depend_on_the_horizon():
    """What lets the budgets be checked on a 2-step rollout: the scan body is the program."""
    assert _lines("infante", "vcm_integral", 2) == _lines("infante", "vcm_integral", 40)


def test_a_sampled_6dof_loop_runs_rk4_stages_as_a_loop():
    """With a sampled controller, RK4's four plant evaluations of a 6-DOF vehicle are one
    loop (``RolloutConfig.stages = "auto"``): REMUS 100 ``vcm3d``'s forward program is 6,846
    lines, 9,523 with the stages unrolled (float64, jax 0.10.2), so the budget below fails if
    the loop is lost (the rule itself: ``tests/test_integrators.py``)."""
    if _jax_version() < BUDGET_JAX:
        pytest.skip(f"budgets measured with jax {BUDGET_JAX}: older JAX lowers more lines")
    fwd, _, gains, sc = loop_programs("remus100", "vcm3d", STEPS, "sampled")
    lines = build_times(fwd, gains, sc, compile=False)["hlo_lines"]
    assert lines <= 7600, f"remus100/vcm3d sampled forward: {lines} StableHLO lines > 7600"
