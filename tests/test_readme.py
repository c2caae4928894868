"""The README's Python examples run as written, and its quick-start commands match `.ci/run`."""

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def _python_blocks():
    return re.findall(r"```python\n(.*?)```", README, flags=re.S)


def test_python_examples_run():
    blocks = _python_blocks()
    assert len(blocks) >= 2
    namespaces = []
    for code in blocks:
        ns: dict = {}
        exec(compile(code, "README.md", "exec"), ns)
        namespaces.append(ns)
    # the engine example: Φ has decayed and W kept full rank
    traj = namespaces[0]["traj"]
    assert np.max(np.abs(np.asarray(traj.aux.Phi[-1]))) < 1e-3
    assert int(traj.aux.rank[-1]) == 2


def test_quick_start_test_command_is_what_ci_runs():
    blocks = re.findall(r"```bash\n(.*?)```", README, flags=re.S)
    test_cmd = [ln for ln in blocks[1].splitlines() if ln and not ln.startswith("#")][0]
    ci = (ROOT / ".ci" / "run").read_text()
    assert test_cmd in ci
    install = [ln for ln in blocks[0].splitlines() if ln and not ln.startswith("#")][0]
    assert install.split(" && ")[:2] == [
        "python3 -m venv .venv",
        '.venv/bin/pip install -e ".[test]"',
    ]
