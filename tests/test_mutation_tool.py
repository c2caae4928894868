"""``tools/mutation.py``'s choice of tests per mutant (docs/development/testing.md, "Mutation
testing"): pure ``ast`` bookkeeping on a made-up file and made-up coverage."""

from __future__ import annotations

import importlib.util
from pathlib import Path

SRC = """\
LIMIT = 3.0


def f(x, scale=2.0):
    return x * scale * LIMIT
"""


def _tool():
    path = Path(__file__).resolve().parents[1] / "tools" / "mutation.py"
    spec = importlib.util.spec_from_file_location("_mutation_tool", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_a_line_run_at_import_runs_every_test_of_the_target_those_of_its_file_first():
    """A module-level constant (and a ``def`` header: its defaults) runs at import, credited
    to no test (context ""): every test of the target, the file's fastest first, then the
    others fastest first (one that only reads the declaration as data included); a line in a
    body: the tests that ran it."""
    mt = _tool()
    by_line = {1: {""}, 4: {""}, 5: {"t_f", "t_g"}}
    times = {"t_f": 2.0, "t_g": 1.0, "t_data": 0.5, "t_other": 3.0}
    assert mt.select_tests(SRC, 1, by_line, times) == (
        ["t_g", "t_f", "t_data", "t_other"],
        "import",
    )
    assert mt.select_tests(SRC, 4, by_line, times)[0] == ["t_g", "t_f", "t_data", "t_other"]
    assert mt.select_tests(SRC, 5, by_line, times) == (["t_g", "t_f"], "line")
    assert mt.select_tests(SRC, 2, by_line, times) == ([], "uncovered")  # a blank line
