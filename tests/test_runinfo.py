"""``run.json``: every output folder records how to reproduce the run that wrote it."""

import dataclasses
import json
import math
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

import vcjax
from vcjax import cli
from vcjax.runtime.runinfo import git_commit, run_info, to_jsonable

KEYS = {"command", "argv", "vcjax", "versions", "x64", "devices", "processes", "config", "seeds"}


@dataclasses.dataclass(frozen=True)
class _Spec:
    n: int
    path: Path
    limits: tuple


class _Pair(NamedTuple):
    a: object
    b: object


def test_config_values_become_plain_json():
    spec = _Spec(3, Path("a/b.toml"), (1.0, math.inf))
    got = to_jsonable({"spec": spec, "x": np.arange(3), "p": _Pair(np.float32(0.5), None)})
    assert got == {
        "spec": {"n": 3, "path": "a/b.toml", "limits": [1.0, "inf"]},
        "x": [0, 1, 2],
        "p": {"a": 0.5, "b": None},
    }
    assert json.loads(json.dumps(got)) == got  # strict JSON (no NaN/Infinity tokens)


def test_run_info_names_versions_devices_and_commit():
    info = run_info("sweep", config={"k": 1}, seeds={"sweep": 3}, wall_s=1.5, argv=["x"])
    assert KEYS <= set(info)
    assert info["vcjax"]["version"] == vcjax.__version__
    assert info["versions"]["jax"] == jax.__version__
    assert info["devices"]["count"] == jax.device_count()
    assert info["processes"] == {"count": 1, "index": 0}
    assert info["seeds"] == {"sweep": 3} and info["config"] == {"k": 1}
    assert info["x64"] is True  # tests run in float64
    git = git_commit()
    if git is not None:  # a git checkout: the commit is recorded, 40 hex digits
        assert info["vcjax"]["git"] == git and len(git["commit"]) == 40


def test_demo_writes_run_json(tmp_path):
    out = tmp_path / "demo"
    assert cli.main(["demo", "--out", str(out), "--horizon", "0.5"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert KEYS <= set(run)
    assert run["command"] == "demo" and run["config"]["horizon"] == 0.5
    assert run["wall_s"]["total"] > 0


def test_git_commit_only_of_a_checkouts_root(tmp_path):
    """An installed vcjax inside some other repository (a venv in a user's project) must not
    record that repository's commit: only the root of the checkout counts."""
    import subprocess

    git = ["git", "-c", "user.email=t@t", "-c", "user.name=t", "-C", str(tmp_path)]
    subprocess.run([*git, "init", "-q"], check=True)
    (tmp_path / "f").write_text("x")
    subprocess.run([*git, "add", "f"], check=True)
    subprocess.run([*git, "commit", "-qm", "c"], check=True)
    sub = tmp_path / "site-packages"
    sub.mkdir()
    root = git_commit(tmp_path)
    assert root is not None and len(root["commit"]) == 40 and root["dirty"] is False
    assert git_commit(sub) is None
