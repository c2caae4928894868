"""Nothing deleted before it is safe (issue 31): every command reads and checks all of its
inputs before it touches ``--out``; ``--overwrite`` removes exactly the files an earlier run's
manifest lists, never an input of the command, and only once the checks have passed; a run
that ends early (a second Ctrl-C while figures are written) still leaves its ``run.json`` and
manifest; stale locks; the rank; the ``--max-steps`` advice; user code checked before any work.

Every case goes through the user's path (:func:`vcjax.cli.main`, or ``python -m vcjax.cli`` in
a subprocess) with ``tmp_path`` as ``--out`` and as the working directory. Where a case needs
the command to get past its checks, the run itself is replaced by a stub (the tests are about
what happens to the folder, not about the numbers), so the file runs in seconds.
"""

from __future__ import annotations

import dataclasses
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import jax.numpy as jnp
import pytest

from vcjax import cli, loops
from vcjax.runtime import outputs

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def _run(argv, capsys) -> tuple[int, str]:
    rc = cli.main([str(a) for a in argv])
    return rc, capsys.readouterr().err


def _tree(path: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()
    }


def _earlier_run(out: Path, *files: str, user: tuple[str, ...] = ()) -> dict[str, bytes]:
    """``out`` as an earlier vcjax run left it: ``files`` listed in its manifest, ``user``
    files beside them that vcjax did not write. Returns the tree."""
    out.mkdir(parents=True, exist_ok=True)
    for name in (*files, *user):
        (out / name).write_text(f"earlier {name}\n")
    outputs.write_json_atomic(out / outputs.MANIFEST, {"files": sorted(files)})
    return _tree(out)


def _config(tmp_path: Path, text: str, name: str = "c.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# ------------------------------------------------------------------ README: main job, then tests


def test_readme_missing_gains_after_the_main_job_names_the_gains_file(
    tmp_path, monkeypatch, capsys
):
    """The README's main job (``vcjax simulate sim1``) left ``out/sim1``; the missing gains
    file is reported as such (not "holds another vcjax run's files"), and the folder is left
    as it was."""
    monkeypatch.chdir(tmp_path)
    before = _earlier_run(tmp_path / "out" / "sim1", "run.json", "metrics.json", "paths.png")
    rc, err = _run(["simulate", "sim1", "--gains", tmp_path / "no.json"], capsys)
    assert rc == 2
    assert "no.json" in err and "No such file" in err
    assert "holds another vcjax run" not in err
    assert _tree(tmp_path / "out" / "sim1") == before
    assert not (tmp_path / "out" / "sim1" / outputs.LOCK).exists()


def test_a_refused_command_creates_no_out_folder(tmp_path, monkeypatch, capsys):
    """Without ``out/sim1`` the refused command leaves no empty folder behind (in a checkout
    that was an ``out/`` in the repository)."""
    monkeypatch.chdir(tmp_path)
    rc, err = _run(["simulate", "sim1", "--gains", "no.json"], capsys)
    assert rc == 2 and "No such file" in err
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------ checks before --overwrite


def _bad_inputs(command: str, tmp_path: Path) -> list:
    """A command line of ``command`` with one bad input (a typo, a broken gains file)."""
    if command == "sweep":
        return ["sweep", _config(tmp_path, "[sweep]\nnum_scenario = 2\n")]
    if command == "tune":
        return ["tune", _config(tmp_path, "[optimizer]\nstep = 2\n")]
    if command == "fit":
        return ["fit", _config(tmp_path, '[data]\nfile = ["log.csv"]\n')]
    if command == "simulate":
        (tmp_path / "gains.json").write_text("{not json")
        return ["simulate", "sim1", "--gains", tmp_path / "gains.json"]
    return ["demo", "--horizon", "nan"]


@pytest.mark.parametrize("command", ["sweep", "tune", "fit", "simulate", "demo"])
def test_a_bad_input_with_overwrite_leaves_the_earlier_results(command, tmp_path, capsys):
    out = tmp_path / "out"
    before = _earlier_run(out, "run.json", "summary.json", "fig.png", user=("notes.txt",))
    rc, err = _run([*_bad_inputs(command, tmp_path), "--out", out, "--overwrite"], capsys)
    assert rc == 2, err
    assert err.startswith(f"vcjax: {command}") and "Traceback" not in err
    assert _tree(out) == before  # nothing removed, nothing written
    assert not (out / outputs.LOCK).exists()


class _Stopped(ValueError):
    pass


def _stub(monkeypatch, module: str, name: str, seen: dict, files: tuple[str, ...] = ()):
    """Replace the run ``module.name`` by a stub that records which files exist when it starts
    and then fails (exit 2) -- after ``--out`` has been prepared."""

    def run(config, out, *args, **kwargs):
        out = Path(out)
        seen["at_start"] = sorted(p.name for p in out.iterdir())
        raise _Stopped("stub: stopped after the checks")

    monkeypatch.setattr(__import__(module, fromlist=[name]), name, run)


def _gains_json(path: Path) -> None:
    loop = loops.make_loop("infante", "vcm")
    path.write_text(json.dumps(loop.gains_to_json(loop.default_gains())))


def test_overwrite_keeps_the_gains_file_a_sweep_reads_from_its_own_out(
    tmp_path, monkeypatch, capsys
):
    out = tmp_path / "out"
    _earlier_run(out, "run.json", "summary.json", "gains.json", "fig.png")
    _gains_json(out / "gains.json")  # an earlier tune's gains, now the sweep's input
    cfg = _config(
        tmp_path,
        '[sweep]\nnum_scenarios = 2\nvariants = ["vcm"]\n'
        '[simulation]\nhorizon = 1.0\ngains = "out/gains.json"\n',
    )
    seen: dict = {}
    _stub(monkeypatch, "vcjax.sweep", "run_sweep_config", seen)
    rc, err = _run(["sweep", cfg, "--out", out, "--overwrite"], capsys)
    assert rc == 2 and "stub: stopped after the checks" in err
    assert seen["at_start"] == [outputs.LOCK, "gains.json"]  # the rest of the earlier run: gone
    assert (out / "gains.json").is_file()


def test_overwrite_keeps_the_gains_a_tune_refines_in_its_own_out(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    _earlier_run(out, "run.json", "summary.json", "history.json", "gains.json")
    _gains_json(out / "gains.json")
    text = (EXAMPLES / "tuning" / "quick.toml").read_text()
    text = text.replace('controller = "vcm_integral"', 'controller = "vcm"')
    text += '\n[problem]\ninitial_gains = "out/gains.json"\n'
    assert 'controller = "vcm"' in text
    cfg = _config(tmp_path, text)
    seen: dict = {}
    _stub(monkeypatch, "tuning.run", "run_tune_config", seen)  # where tuning's lazy name looks
    rc, err = _run(["tune", cfg, "--out", out, "--overwrite"], capsys)
    assert rc == 2 and "stub: stopped after the checks" in err, err
    assert seen["at_start"] == [outputs.LOCK, "gains.json"]
    assert (out / "gains.json").is_file()


def test_overwrite_keeps_a_users_metrics_json_not_in_the_manifest(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    _earlier_run(out, "run.json", "summary.json", "fig.png", user=("metrics.json",))
    seen: dict = {}
    _stub(monkeypatch, "vcjax.sweep", "run_sweep_config", seen)
    rc, err = _run(
        ["sweep", EXAMPLES / "sweeps" / "quick.toml", "--out", out, "--overwrite"], capsys
    )
    assert rc == 2 and "stub" in err
    assert seen["at_start"] == [outputs.LOCK, "metrics.json"]
    assert (out / "metrics.json").read_text() == "earlier metrics.json\n"


# ------------------------------------------------------------------ a run that ends early


def test_second_ctrl_c_while_figures_are_written_keeps_run_json_and_manifest(
    tmp_path, monkeypatch, capsys
):
    """The second Ctrl-C (a ``KeyboardInterrupt`` out of the figure writer) ends the run at
    once; ``run.json`` (marked) and the manifest are still written, so the next
    ``--overwrite`` removes the stray figure and keeps the user's file."""
    from vcjax.experiments import ARM

    out = tmp_path / "demo"
    out.mkdir()
    (out / "notes.txt").write_text("mine")

    def interrupted(self, out, gains=None, setup=None, progress=print):
        (Path(out) / "stray.png").write_text("half the figures")
        raise KeyboardInterrupt

    monkeypatch.setattr(type(ARM), "run", interrupted)
    rc, err = _run(["demo", "--out", out], capsys)
    assert rc == 130 and "interrupted" in err
    info = json.loads((out / "run.json").read_text())
    assert info["ended_early"] == "KeyboardInterrupt" and info["interrupted"] is True
    manifest = json.loads((out / outputs.MANIFEST).read_text())["files"]
    assert manifest == ["run.json", "stray.png"]
    assert not (out / outputs.LOCK).exists()

    def complete(self, out, gains=None, setup=None, progress=print):
        (Path(out) / "arm_demo.png").write_text("figure")
        return _ran([Path(out) / "arm_demo.png"])

    monkeypatch.setattr(type(ARM), "run", complete)
    rc, err = _run(["demo", "--out", out, "--overwrite"], capsys)
    assert rc == 0, err
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [outputs.MANIFEST, "arm_demo.png", "notes.txt", "run.json"]
    )
    assert json.loads((out / outputs.MANIFEST).read_text())["files"] == ["arm_demo.png", "run.json"]


# ------------------------------------------------------------------ locks


def _ran(files):
    """What ``Experiment.run`` returns, for a stand-in run that wrote ``files``."""
    return {"metrics": {}, "files": files, "printed": None, "unhealthy": [], "config": {}}


def _demo_stub(monkeypatch):
    from vcjax.experiments import ARM

    monkeypatch.setattr(type(ARM), "run", lambda self, out, *a, **k: _ran([]))


@pytest.mark.parametrize("content", ["", "{", "[1, 2]", '{"pid": "12"}', '{"pid": null}'])
def test_an_empty_or_unparsable_lock_is_stale(content, tmp_path, monkeypatch, capsys):
    _demo_stub(monkeypatch)
    out = tmp_path / "out"
    out.mkdir()
    (out / outputs.LOCK).write_text(content)
    rc, err = _run(["demo", "--out", out], capsys)
    assert rc == 0, err
    assert "in use by" not in err
    assert not (out / outputs.LOCK).exists()


@pytest.fixture
def other_program():
    """A live process on this host that is not vcjax."""
    p = subprocess.Popen(["sleep", "300"])
    try:
        yield p.pid
    finally:
        p.kill()
        p.wait()


@pytest.mark.parametrize("recorded_start", [None, "1"])
def test_a_lock_whose_pid_is_another_program_is_stale(
    recorded_start, other_program, tmp_path, monkeypatch, capsys
):
    """The PID of the lock is alive but is another program (a reused PID): without a recorded
    start time its command line shows no vcjax; with one, the start time differs."""
    _demo_stub(monkeypatch)
    out = tmp_path / "out"
    out.mkdir()
    lock = {"pid": other_program, "host": socket.gethostname(), "command": "sweep"}
    if recorded_start is not None:
        lock["start"] = recorded_start
    (out / outputs.LOCK).write_text(json.dumps(lock))
    rc, err = _run(["demo", "--out", out], capsys)
    assert rc == 0, err
    assert "in use by" not in err


def test_the_lock_file_is_created_whole(tmp_path):
    d = outputs.prepare_out(tmp_path / "out", False, "t")
    try:
        lock = json.loads((tmp_path / "out" / outputs.LOCK).read_text())
        assert lock["pid"] == os.getpid() and lock["command"] == "t"
        assert lock["start"] == outputs._start_time(os.getpid())
    finally:
        d.release()


# ------------------------------------------------------------------ the --max-steps advice


def test_the_step_limit_advice_names_only_an_option_the_command_has(tmp_path, capsys):
    """The advice "raise the limit with --max-steps" is given only where that option exists
    (demo once advised it without having it; it has it now, as every experiment does), and the
    option it names raises the limit."""
    from vcjax.cli import build_parser

    for argv in (["demo"], ["simulate", "sim1"]):
        rc, err = _run([*argv, "--horizon", "1e12", "--out", tmp_path / "o"], capsys)
        assert rc == 2 and "steps: more than" in err
        assert "raise the limit with --max-steps" in err
        help_text = build_parser().parse_known_args([*argv, "--out", "x"])[0]
        assert hasattr(help_text, "max_steps"), argv
    assert not (tmp_path / "o").exists()
    from vcjax.commands import CLIError, _time_grid

    with pytest.raises(CLIError) as err:
        _time_grid(1e12, 0.05, 10, limit_option=None)
    assert "--max-steps" not in str(err.value)


# ------------------------------------------------------------------ user code


@dataclasses.dataclass(frozen=True)
class _Wrap(loops.Law):
    """Infante's VCM law with one thing changed by ``bug``."""

    bug: str = ""

    @property
    def _base(self):
        return loops.loop_class("infante").laws["vcm"]

    def default_gains(self, loop):
        g = self._base.default_gains(loop)
        return g._asdict() if self.bug == "gains_dict" else g

    def gain_specs(self, loop):
        return self._base.gain_specs(loop)

    def params(self, loop, gains, sc, design):
        return self._base.params(loop, gains, sc, design)

    def initial_state(self, loop, sc):
        return self._base.initial_state(loop, sc)

    def step(self, loop, params, t, x, z):
        tau, z_dot, aux = self._base.step(loop, params, t, x, z)
        if self.bug == "tau2":
            tau = tau[:2]
        elif self.bug == "tau4":
            tau = jnp.concatenate([tau, tau[:1]])
        elif self.bug == "zdot":
            z_dot = jnp.zeros(7)
        return tau, z_dot, aux

    def particle(self, z):
        return self._base.particle(z)

    def heading_error(self, aux):
        return self._base.heading_error(aux)


@dataclasses.dataclass(frozen=True)
class _NoZ(_Wrap):
    def step(self, loop, params, t, x):  # forgot z
        return super().step(loop, params, t, x, None)


@dataclasses.dataclass(frozen=True)
class _OldParams(_Wrap):
    def params(self, loop, gains, sc, model, k_rudder):  # the former INFANTE signature
        return super().params(loop, gains, sc, loop.law_design(sc))


@pytest.mark.parametrize(
    "law, message",
    [
        (_NoZ(), r"step\(loop, params, t, x\) must take \(loop, params, t, meas, z\)"),
        (
            _OldParams(),
            r"params\(.*k_rudder\) must take \(loop, gains, sc, design\).*design\.model",
        ),
        (_Wrap("gains_dict"), "default_gains returned a dict; expected a NamedTuple"),
        (_Wrap("tau2"), r"force tau of shape \(2,\); the infante loop's law 'vcm' returns \(3,\)"),
        (_Wrap("tau4"), r"force tau of shape \(4,\)"),
        (_Wrap("zdot"), "z_dot"),
    ],
)
def test_register_law_traces_one_step_before_any_work(law, message):
    with pytest.raises(ValueError, match=message) as err:
        loops.register_law("infante", "unit_buggy", law)
    assert str(err.value).startswith("register_law: infante law 'unit_buggy'")
    assert "unit_buggy" not in loops.controllers("infante")  # refused: not registered


def test_register_law_accepts_a_law_that_traces():
    try:
        loops.register_law("infante", "unit_fine", _Wrap())
        assert "unit_fine" in loops.controllers("infante")
    finally:
        cls = loops.loop_class("infante")
        cls.laws = {k: v for k, v in cls.laws.items() if k != "unit_fine"}
        cls.controllers = tuple(c for c in cls.controllers if c != "unit_fine")


@pytest.mark.parametrize(
    "body, message",
    [
        ("import sys\nsys.exit(0)\n", "called sys.exit(0) while being imported"),
        ("import sys\nsys.exit('bye')\n", "called sys.exit('bye') while being imported"),
        ("raise KeyboardInterrupt\n", "raised KeyboardInterrupt while being imported"),
    ],
)
def test_a_user_module_that_exits_at_import_is_its_failure(body, message, tmp_path, capsys):
    (tmp_path / "mine.py").write_text(body)
    cfg = _config(tmp_path, '[scenario]\nmodule = "mine.py"\n')
    rc, err = _run(["sweep", cfg, "--out", tmp_path / "out"], capsys)
    assert rc == 2
    assert "[scenario] module:" in err and "mine.py" in err and message in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_module_dot_is_named_as_a_folder(tmp_path, capsys):
    cfg = _config(tmp_path, '[scenario]\nmodule = "."\n')
    rc, err = _run(["sweep", cfg, "--out", tmp_path / "out"], capsys)
    assert rc == 2
    assert "[scenario] module: '.' is a folder" in err and "expected a Python file" in err


# ------------------------------------------------------------------ platforms, netCDF


def test_cuda_asked_on_a_machine_without_it_is_one_line(tmp_path):
    import jax

    if any(d.platform == "gpu" for d in jax.devices()):
        pytest.skip("this machine has a GPU")
    env = {**os.environ, "JAX_PLATFORMS": "cuda", "PYTHONPATH": str(ROOT)}
    p = subprocess.run(
        [sys.executable, "-m", "vcjax.cli", "simulate", "sim1", "--horizon", "1", "--out", "o"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 2, p.stderr
    assert p.stderr.startswith("vcjax: simulate: JAX_PLATFORMS=cuda: JAX cannot start")
    assert len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr


def test_netcdf_of_a_remus100_sweep_opens_in_xarray_and_scipy(tmp_path, monkeypatch):
    """REMUS 100 samples no sensor noise: its (scenarios, 0) input must not become a
    zero-length dimension (netCDF 3 reads one as a second record dimension: unreadable)."""
    xr = pytest.importorskip("xarray")
    from scipy.io import netcdf_file

    monkeypatch.chdir(tmp_path)
    cfg = _config(
        tmp_path,
        '[scenario]\nvehicle = "remus100"\n[sweep]\nnum_scenarios = 2\nvariants = ["alos3d"]\n'
        "[simulation]\nhorizon = 0.2\ndt = 0.05\n[output]\nrecord_points = 2\nfigures = false\n",
    )
    out = tmp_path / "out"
    rc = cli.main(["sweep", str(cfg), "--out", str(out), "--netcdf"])
    assert rc == 0
    with netcdf_file(out / "results.nc", "r", mmap=False) as f:
        assert all(n > 0 for n in f.dimensions.values() if n is not None)
        assert f.variables["ss_abs_e"].shape == (1, 2)
    with xr.open_dataset(out / "results.nc", engine="scipy") as ds:
        assert ds.sizes["scenario"] == 2 and ds["ss_abs_e"].dims == ("variant", "scenario")
        assert "noise_std" in ds.attrs["empty_inputs"]


# ------------------------------------------------------------------ the checkout stays as it was


def test_a_test_run_that_writes_into_the_checkout_fails(tmp_path):
    """tests/conftest.py watches the checkout: a test that writes there (here into a stand-in
    checkout) fails the run, naming the file; caches (``__pycache__``) do not count."""
    repo = tmp_path / "repo"
    (repo / "__pycache__").mkdir(parents=True)
    (repo / "kept.txt").write_text("x")
    (tmp_path / "test_writes.py").write_text(
        "from pathlib import Path\n"
        f"REPO = Path({str(repo)!r})\n"
        "def test_writes():\n"
        "    (REPO / 'out').mkdir()\n"
        "    (REPO / 'out' / 'sim1.png').write_text('x')\n"
        "    (REPO / '__pycache__' / 'a.pyc').write_text('x')\n"
    )
    env = {
        **os.environ,
        "VCJAX_TEST_CHECKOUT": str(repo),
        "PYTHONPATH": os.pathsep.join([str(ROOT / "tests"), str(ROOT)]),
    }
    env.pop("PYTEST_XDIST_WORKER", None)
    own = tmp_path / "vcjax-test-jax-cache-inner"  # its own (it removes it at its end)
    own.mkdir()
    env["VCJAX_TEST_CACHE_DIR"] = str(own)
    p = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "conftest", "-p", "no:cacheprovider"]
        + ["-p", "no:xdist", str(tmp_path / "test_writes.py")],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 1, p.stdout + p.stderr
    assert "1 passed" in p.stdout
    assert "wrote into the checkout" in p.stdout and "+ out/sim1.png" in p.stdout
    assert "a.pyc" not in p.stdout and "kept.txt" not in p.stdout


def test_register_traces_every_law_of_a_new_vehicle():
    """A new vehicle (here INFANTE's loop under another name) with a law whose force has
    another shape than its other laws': refused naming the odd one out; a law whose z_dot
    does not match its state: refused naming it. Neither vehicle is registered."""
    base = loops.loop_class("infante")

    @dataclasses.dataclass(frozen=True)
    class Twin(base):
        vehicle = "unit_twin"
        laws = {"vcm": base.laws["vcm"], "ilos": base.laws["ilos"], "odd": _Wrap("tau2")}
        controllers = ("vcm", "ilos", "odd")

    with pytest.raises(ValueError, match=r"unit_twin: the force tau of law\(s\) \['odd'\]"):
        loops.register(Twin)

    @dataclasses.dataclass(frozen=True)
    class Drift(base):
        vehicle = "unit_drift_order"
        laws = {"vcm": base.laws["vcm"], "bad": _Wrap("zdot")}
        controllers = ("vcm", "bad")

    with pytest.raises(ValueError, match=r"register: unit_drift_order law 'bad' \(_Wrap\): z_dot"):
        loops.register(Drift)
    assert "unit_twin" not in loops.vehicles() and "unit_drift_order" not in loops.vehicles()


@pytest.mark.parametrize("flags", [["--max-memory-gb", "1e-7"], []])
def test_fit_checks_its_logs_and_size_before_overwrite(flags, tmp_path, capsys):
    """A log in degrees, or more work than the memory limit: refused with the earlier fit's
    files intact (the logs are read and the work sized before --out is touched)."""
    from test_bad_inputs_cli import _deg, _fit_case

    cfg = _fit_case(tmp_path, (lambda c: None) if flags else _deg("psi"))
    out = tmp_path / "out"
    before = _earlier_run(out, "run.json", "fit.json", "fit_prediction.png")
    rc, err = _run(["fit", cfg, "--out", out, "--overwrite", "--quiet", *flags], capsys)
    assert rc == 2 and err.startswith("vcjax: fit: "), err
    assert _tree(out) == before


@pytest.mark.parametrize("command", ["sweep", "tune"])
def test_a_broken_gains_file_named_by_the_config_is_refused_before_overwrite(
    command, tmp_path, capsys
):
    (tmp_path / "g.json").write_text('{"vcm": {"P_G": [1, 1, 1],}}')
    if command == "sweep":
        text = '[sweep]\nnum_scenarios = 2\nvariants = ["vcm"]\n[simulation]\ngains = "g.json"\n'
    else:
        text = (EXAMPLES / "tuning" / "quick.toml").read_text()
        text = text.replace('controller = "vcm_integral"', 'controller = "vcm"')
        text += '\n[problem]\ninitial_gains = "g.json"\n'
    cfg = _config(tmp_path, text)
    out = tmp_path / "out"
    before = _earlier_run(out, "run.json", "summary.json", "fig.png")
    rc, err = _run([command, cfg, "--out", out, "--overwrite"], capsys)
    assert rc == 2 and "g.json" in err and "Expecting" in err, err
    assert _tree(out) == before


def test_overwrite_keeps_the_fit_json_a_sweep_reads_from_its_own_out(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    _earlier_run(out, "run.json", "fit.json", "fit_prediction.png")
    (out / "fit.json").write_text(json.dumps({"estimates": {}}))  # the earlier fit's result
    cfg = _config(
        tmp_path,
        '[scenario]\nvehicle = "remus100"\nplant_params = "out/fit.json"\n'
        '[sweep]\nnum_scenarios = 2\nvariants = ["alos3d"]\n',
    )
    seen: dict = {}
    _stub(monkeypatch, "vcjax.sweep", "run_sweep_config", seen)
    rc, err = _run(["sweep", cfg, "--out", out, "--overwrite"], capsys)
    assert rc == 2 and "stub: stopped after the checks" in err, err
    assert seen["at_start"] == [outputs.LOCK, "fit.json"]
