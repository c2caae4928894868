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


def test_a_fixtures_setup_is_credited_to_every_test_of_its_file():
    """A line run while a fixture is set up (coverage's ``|setup`` phase: a module-scoped
    fixture is set up once, in the first test's context) is credited to every passed test of
    that test file, not only the first; a line of a test's own run to that test (when it
    passed unmutated); import-time lines stay ``""``."""
    mt = _tool()
    passed = {
        "tests/a.py::t1": 1.0,
        "tests/a.py::t2": 0.5,
        "tests/a.py::C::t3": 0.2,
        "tests/b.py::t4": 1.0,
    }
    assert mt.credited("tests/a.py::t1|setup", passed) == {
        "tests/a.py::t1",
        "tests/a.py::t2",
        "tests/a.py::C::t3",
    }
    assert mt.credited("tests/a.py::t2|run", passed) == {"tests/a.py::t2"}
    assert mt.credited("tests/a.py::t2|teardown", passed) == {"tests/a.py::t2"}
    assert mt.credited("tests/b.py::failed|run", passed) == set()  # failed unmutated
    assert mt.credited("", passed) == {""}
