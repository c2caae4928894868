"""What an experiment is: [`Experiment`][vcjax.experiments.base.Experiment] (loop, scenario,
horizon, dt, typed options,
figures, optional extras) and the one jitted runner every experiment's rollouts go through.

An experiment is data: a frozen [`Experiment`][vcjax.experiments.base.Experiment] subclass instance
naming its runs
([`Experiment.variants`][vcjax.experiments.base.Experiment.variants]), the loop and the scenario of
each, its default horizon and step,
its default current (or none), its options (a frozen [`Options`][vcjax.experiments.base.Options]
dataclass whose fields
are typed; ``vcjax simulate NAME`` generates its flags from them,
[`flags`][vcjax.experiments.base.flags]), its metrics
(the loop's [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics] plus the experiment's own
extras) and its
figures. [`Experiment.run`][vcjax.experiments.base.Experiment.run] is the same for every experiment:
roll every variant out with
the one jitted runner, measure, write ``metrics.json`` and the figures.

The pieces, usable on their own (tests, notebooks, benchmarks)::

    from vcjax import experiments
    sim1 = experiments.get("sim1")
    setup = sim1.setup(horizon=20.0, current=(0.0, 0.3), timing="sampled")  # validated
    sc = sim1.scenario("vcm", setup)            # a loops.Scenario
    traj = sim1.simulate("vcm", setup, scenario=sc)   # jitted; gains: the loop's defaults
    m = sim1.metrics(sim1.outcome("vcm", setup, traj, scenario=sc), setup)
    result = sim1.run("out/sim1", setup=setup)  # what `vcjax simulate sim1` does
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from pathlib import Path
from typing import Any, ClassVar, Literal, NamedTuple

import jax

from vcjax import loops
from vcjax.rollout import RolloutConfig
from vcjax.runtime import compiler
from vcjax.runtime.outputs import write_json_atomic

__all__ = [
    "Experiment",
    "Options",
    "PathBound",
    "Setup",
    "Outcome",
    "option",
    "flags",
    "rollout",
]

#: The one jitted runner of every experiment:
#: [`vcjax.loops.simulate`][vcjax.loops.disturbances.simulate] with the loop and the
#: rollout configuration static (one compilation per loop and number of steps; gains, scenario
#: and ``dt`` traced).
rollout = compiler.jit(loops.simulate, static_argnames=("loop", "config"))


def option(default, help: str, metavar=None):
    """A field of an [`Options`][vcjax.experiments.base.Options] dataclass: its default, its
    ``--help`` line and (for an
    option taking several numbers) the names of its values."""
    return dataclasses.field(default=default, metadata={"help": help, "metavar": metavar})


@dataclasses.dataclass(frozen=True)
class Options:
    """Base of an experiment's typed options (a frozen dataclass; each field an
    [`option`][vcjax.experiments.base.option]). The field ``name`` is the flag ``--name``
    (underscores as dashes) of
    ``vcjax simulate`` for the experiments whose options have it, and of no other."""

    def __post_init__(self):
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):
            choices = typing.get_args(hints[f.name])
            value = getattr(self, f.name)
            if typing.get_origin(hints[f.name]) is Literal and value not in choices:
                raise ValueError(f"{f.name}: expected one of {choices}, got {value!r}")

    def check(self, dt: float, x64: bool = True) -> None:
        """Raise ``ValueError`` naming the flag for a value that cannot run at step ``dt``
        [s] (``x64``: the precision, which bounds seeds). Subclasses extend it."""

    def record(self) -> dict:
        """What ``run.json`` records of the options (the values that applied)."""
        return dataclasses.asdict(self)

    def replace(self, **changes) -> Options:
        """A copy with ``changes``."""
        return dataclasses.replace(self, **changes)


@dataclasses.dataclass(frozen=True)
class PathBound(Options):
    """The path-error bound of ``healthy`` (``--diverge-e M``)."""

    diverge_e: float | None = option(
        None,
        "a run more than M metres off the path is unhealthy (default: 25 % of u_d x horizon, "
        "at least 50 m)",
        "M",
    )

    def check(self, dt: float, x64: bool = True) -> None:
        super().check(dt, x64)
        b = self.diverge_e
        if b is not None and not (math.isfinite(b) and b > 0):
            raise ValueError(f"--diverge-e: expected a finite bound > 0 [m], got {b:g}")


def _flag_type(hint) -> dict:
    """argparse keywords of a field's type: ``Literal`` -> choices, ``tuple[float, ...]`` ->
    ``nargs``, ``float``/``int`` (``X | None``: the same)."""
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    if typing.get_origin(hint) in (typing.Union, types.UnionType) and len(args) == 1:
        hint = args[0]
    if typing.get_origin(hint) is Literal:
        return {"choices": list(typing.get_args(hint))}
    if typing.get_origin(hint) is tuple:
        items = typing.get_args(hint)
        return {"type": items[0], "nargs": len(items)}
    if hint in (int, float, str):
        return {"type": hint}
    raise TypeError(f"option type {hint!r}: no command-line form")


def flags(options: type[Options]) -> list[tuple[str, dict]]:
    """``[(flag, argparse keywords)]`` of an [`Options`][vcjax.experiments.base.Options] class, one
    per field: the flag is
    ``--`` + the field name with dashes, the keywords come from its type (``_flag_type``)
    and metadata; not given, an option is ``None`` (its default applies)."""
    hints = typing.get_type_hints(options)
    out = []
    for f in dataclasses.fields(options):
        kw = _flag_type(hints[f.name])
        meta = f.metadata
        default = "" if f.default is None else f" (default {f.default})"
        kw["help"] = (meta.get("help", "") + default).replace("%", "%%")  # argparse formats it
        if meta.get("metavar"):
            kw["metavar"] = meta["metavar"]
        out.append(("--" + f.name.replace("_", "-"), {"dest": f.name, "default": None, **kw}))
    return out


class Setup(NamedTuple):
    """What one run of an experiment takes besides the gains: ``horizon`` and ``dt`` [s],
    ``current`` ``(north, east)`` [m/s] (``None`` for an experiment without one), ``options``
    (the experiment's [`Options`][vcjax.experiments.base.Options])."""

    horizon: float
    dt: float
    current: tuple[float, float] | None
    options: Any

    @property
    def num_steps(self) -> int:
        return int(round(self.horizon / self.dt))


class Outcome(NamedTuple):
    """One variant's run: its loop, scenario, gains and (host) trajectory."""

    loop: loops.Loop
    scenario: loops.Scenario
    gains: Any
    traj: Any


@dataclasses.dataclass(frozen=True)
class Experiment:
    """One preset of ``vcjax simulate NAME``; subclasses fill in the methods marked so.

    Attributes:
        name: what ``vcjax simulate NAME`` calls it.
        summary: one line for ``--help``.
        horizon, dt: default simulated time and RK4 step [s].
        options: its [`Options`][vcjax.experiments.base.Options] class (``vcjax simulate NAME``'s
            own flags).
        current: default ocean current ``(north, east)`` [m/s]; ``None``: no ``--current``.
        gains: whether it takes ``--gains`` (a gains JSON of its loop, ``load_gains``).
        integrator, timing: of its rollouts ([`RolloutConfig`][vcjax.rollout.RolloutConfig]; a
            ``timing`` option, when the experiment has one, overrides ``timing``).
    """

    name: str
    summary: str
    horizon: float
    dt: float
    options: type[Options] = Options
    current: tuple[float, float] | None = None
    gains: bool = True
    integrator: str = "rk4"
    timing: str = "continuous"

    #: what ``metrics.json`` is written with (``newline=False``: no final newline)
    json_newline: ClassVar[bool] = True

    # ------------------------------------------------------------------ what a subclass says

    def variants(self, options) -> tuple[str, ...]:
        """The runs of one ``vcjax simulate NAME``, in order (subclass)."""
        raise NotImplementedError

    def loop(self, variant: str, options=None) -> loops.Loop:
        """The closed loop of ``variant`` (subclass)."""
        raise NotImplementedError

    def scenario(self, variant: str, setup: Setup | None = None) -> loops.Scenario:
        """The scenario of ``variant`` under ``setup`` (subclass)."""
        raise NotImplementedError

    def metrics(self, outcome: Outcome, setup: Setup) -> dict:
        """One run's metrics as Python values (subclass)."""
        raise NotImplementedError

    def figures(self, outcomes: dict, setup: Setup, out: Path) -> list[Path]:
        """Draw the figures of the runs into ``out``; the files (subclass)."""
        raise NotImplementedError

    def report(self, results: dict, setup: Setup) -> dict:
        """What ``metrics.json`` holds (default: the metrics per variant)."""
        return results

    def printed(self, results: dict) -> dict | None:
        """Flat metrics per run for the console's table (default: ``results``)."""
        return results

    def unhealthy(self, results: dict, outcomes: dict, setup: Setup) -> list[str]:
        """One line per unhealthy run (default: the runs whose ``healthy`` is false)."""
        return [
            f"{self.name} {v}: unhealthy (see metrics.json)"
            for v, m in results.items()
            if not m.get("healthy", True)
        ]

    def record(self, outcomes: dict, setup: Setup) -> dict:
        """Extra entries of ``run.json``'s ``config`` (default none)."""
        return {}

    def label(self, variant: str) -> str:
        """How the progress line names a run."""
        return variant

    # ------------------------------------------------------------------ the same for all

    def setup(self, horizon=None, dt=None, current=None, **options) -> Setup:
        """A [`Setup`][vcjax.experiments.base.Setup]: the defaults where ``None``; ``options`` by
        field name (a name the
        experiment's options do not have is a ``TypeError`` naming it)."""
        names = [f.name for f in dataclasses.fields(self.options)]
        for k in options:
            if k not in names:
                raise TypeError(f"{self.name}: no option {k!r} (its options: {names})")
        if current is not None and self.current is None:
            raise ValueError(f"current: {self.name} has no ocean current")
        cur = self.current if current is None else tuple(float(c) for c in current)
        return Setup(
            self.horizon if horizon is None else float(horizon),
            self.dt if dt is None else float(dt),
            cur,
            self.options(**options),
        )

    def default_gains(self, variant: str, options=None):
        """The gains of ``variant`` when none are given: its loop's defaults."""
        return self.loop(variant, options).default_gains()

    def load_gains(self, d: dict, options=None):
        """Gains from a gains-JSON object (what ``vcjax tune`` writes for the loop; missing
        entries: the defaults of the first variant), validated (``ValueError`` naming the
        entry)."""
        options = self.options() if options is None else options
        return self.loop(self.variants(options)[0], options).gains_from_json(d)

    def rollout_config(self, setup: Setup) -> RolloutConfig:
        timing = getattr(setup.options, "timing", self.timing)
        return RolloutConfig(num_steps=setup.num_steps, integrator=self.integrator, timing=timing)

    def simulate(self, variant: str, setup: Setup | None = None, gains=None, scenario=None):
        """Roll ``variant`` out (the jitted runner [`rollout`][vcjax.loops.disturbances.simulate]);
        returns the
        [`Trajectory`][vcjax.rollout.Trajectory] (on the device). ``gains``: default
        ``default_gains``; ``scenario``: default ``scenario``."""
        setup = self.setup() if setup is None else setup
        if not (setup.horizon > 0 and setup.dt > 0 and setup.horizon / setup.dt >= 1):
            raise ValueError(
                f"horizon and dt must be positive with horizon >= dt, got {setup.horizon}, "
                f"{setup.dt}"
            )
        loop = self.loop(variant, setup.options)
        gains = self.default_gains(variant, setup.options) if gains is None else gains
        sc = self.scenario(variant, setup) if scenario is None else scenario
        return rollout(loop, gains, sc, self.rollout_config(setup), setup.dt)

    def programs(self, setup: Setup, gains: dict, scenarios: dict) -> dict:
        """``{variant: call}``: each variant's rollout ``call(gains, scenario, dt)`` built with
        `vcjax.runtime.programs.build_all` (loaded from the
        program store, not traced, when an identical one was stored; the variants compiled
        concurrently), when the store is on (the command line's default); ``{}`` when it is off
        ([`simulate`][vcjax.experiments.base.Experiment.simulate]'s jitted runner then builds
        each).

        The key's static part is the variant's loop and rollout configuration (a changed
        option that changes the loop, the horizon or ``dt`` through the number of steps, or a
        user's law file: another program); gains, scenario and ``dt`` are traced inputs.
        """
        from vcjax.runtime import programs

        if programs.store_dir() is None or not scenarios:
            return {}
        if type(self).simulate is not Experiment.simulate:  # a runner of its own: used as is
            return {}
        if not (setup.horizon > 0 and setup.dt > 0 and setup.horizon / setup.dt >= 1):
            return {}  # simulate says what is wrong
        config = self.rollout_config(setup)
        jobs, names = [], list(scenarios)
        for v in names:
            loop = self.loop(v, setup.options)

            def program(g, sc, dt, _loop=loop):
                return loops.simulate(_loop, g, sc, config, dt)

            jobs.append(
                (
                    f"simulate:{self.name}:{v}",
                    program,
                    (loop, config),
                    (gains[v], scenarios[v], setup.dt),
                )
            )
        return {v: call for v, (call, _) in zip(names, programs.build_all(jobs), strict=True)}

    def outcome(self, variant, setup, traj, gains=None, scenario=None) -> Outcome:
        """The [`Outcome`][vcjax.experiments.base.Outcome] of a trajectory of ``variant`` (defaults
        as ``simulate``)."""
        gains = self.default_gains(variant, setup.options) if gains is None else gains
        sc = self.scenario(variant, setup) if scenario is None else scenario
        return Outcome(self.loop(variant, setup.options), sc, gains, traj)

    def run(self, out, gains=None, setup: Setup | None = None, progress=print) -> dict:
        """Run every variant, write ``metrics.json`` and the figures into ``out`` (created).

        Returns ``{"metrics", "files", "printed", "unhealthy", "config"}``: the metrics per
        variant, the files written, the console's table (or ``None``), one line per unhealthy
        run, extra entries of ``run.json``'s config.
        """
        setup = self.setup() if setup is None else setup
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        names = self.variants(setup.options)
        scenarios = {v: self.scenario(v, setup) for v in names}
        gains_of = {
            v: self.default_gains(v, setup.options) if gains is None else gains for v in names
        }
        stored = self.programs(setup, gains_of, scenarios)
        outcomes, results = {}, {}
        for i, v in enumerate(names):
            progress(
                f"[{i + 1}/{len(names)}] simulating {self.label(v)} "
                f"({setup.horizon:g} s, dt {setup.dt:g} s)"
            )
            sc, g = scenarios[v], gains_of[v]
            if v in stored:
                traj = jax.device_get(stored[v](g, sc, setup.dt))
            else:
                traj = jax.device_get(self.simulate(v, setup, g, sc))
            outcomes[v] = Outcome(self.loop(v, setup.options), sc, g, traj)
            results[v] = self.metrics(outcomes[v], setup)
        path = out / "metrics.json"
        write_json_atomic(path, self.report(results, setup), newline=self.json_newline)
        files = [path, *self.figures(outcomes, setup, out)]
        return {
            "metrics": results,
            "files": files,
            "printed": self.printed(results),
            "unhealthy": self.unhealthy(results, outcomes, setup),
            "config": self.record(outcomes, setup),
        }
