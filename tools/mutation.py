"""Mutation testing of the numerical core with cosmic-ray (not part of any test run).

Each mutant (one small change to one module: an operator, a comparison, a constant, a negation)
is written into a scratch copy of the git-tracked tree and judged by a fresh pytest process
running default (non-slow) tests on one worker, niced; a mutant the tests do not fail
*survives*. Fresh processes because JAX's compiled programs are cached per process (a forked
runner would reuse the unmutated program) and JAX does not survive ``fork``.

Operators: cosmic-ray's full set makes about 11 mutants per arithmetic operator, most of them
bit and shift operations that fail at once on floating-point arrays. The set kept here
(:data:`KEEP`) is the selective set of numerical code: ``+`` <-> ``-``/``*``, ``*`` <-> ``/``,
``+``, ``**``, ``/`` -> ``*``/``-``, ``**`` -> ``*``/``/``, logical ``|``/``&``/``^`` among
themselves, every relational operator for every other, ``is`` <-> ``is not``, dropped unary
minus / ``not`` / ``~``, added ``not``, ``True`` <-> ``False``, ``and`` <-> ``or``,
``break`` <-> ``continue``, loops run zero times, each number changed.

Tests per mutant, by coverage: once per target, its default tests run unmutated under
coverage.py with one context per test (``--cov-context=test``; JAX's in-memory caches cleared
after every test, so that each test traces, and is credited with, every line it runs), timing
each test. A mutant is then run against only the tests that execute its line, fastest first,
stopping at the first failure (``-x``); a mutant on a line no test executes survives without
running anything (``"uncovered"``). A line run at import (module-level code: constants, a
section's declared bounds, dataclass defaults, ``def`` headers) is credited to no test, and a
test may read what it declares as data without running a line of the file: its mutants run
every test of the target, the tests that run the file first. Lines a fixture's setup runs
are credited to every test of the fixture's test file (a fixture of module scope is set up once,
in the first test's context, for all of them). Programs a mutant leaves
unchanged come from JAX's persistent compilation cache in the scratch folder (a changed
program has another cache key).

Results are appended to ``<target>.jsonl`` in the scratch folder (``--work``) as each mutant
finishes; running again with the same ``--work`` resumes (finished mutants are not run again;
``--fresh`` starts over). ``--sample N`` runs a seeded random sample of N mutants per target.

Usage (cosmic-ray and coverage in any environment; the tests run with ``--python``)::

    pip install -e ".[mutation]"
    python tools/mutation.py --list                       # targets, files, mutants per file
    python tools/mutation.py metrics waves --work /tmp/mut  # every mutant of both targets
    python tools/mutation.py metrics --line 120 --work /tmp/mut --rerun  # mutants of one line again

Prints progress and, per target, mutants / run / killed / timed out / survived (uncovered
included) and each survivor's diff; ``mutation.json`` in ``--work`` holds the summary.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: name -> (source files or folders, the default tests that exercise them)
MODULES = {
    "metrics": (
        "vcjax/metrics.py",
        "tests/test_metrics.py tests/test_health.py tests/test_loops.py"
        " tests/test_physics_envelope.py tests/test_experiments.py",
    ),
    "waves": (
        "vcjax/environment/waves.py",
        "tests/test_waves.py tests/test_waves_loops.py tests/test_physics_envelope.py",
    ),
    "control": (
        "vcjax/control",
        "tests/test_baselines.py tests/test_baselines3d.py tests/test_vcm.py tests/test_vcm3d.py"
        " tests/test_underactuation.py tests/test_remus100_channels.py tests/test_guidance.py"
        " tests/test_loops_params.py tests/test_control_power.py tests/test_control3d_power.py",
    ),
    "identify": (
        "vcjax/identify",
        "tests/test_lm.py tests/test_identify.py tests/test_identify_checks.py"
        " tests/test_lm_power.py tests/test_identify_power.py tests/test_identify_power2.py"
        " tests/test_bad_inputs_cli.py::test_fit_refuses_logs_it_cannot_trust"
        " tests/test_identify_power3.py",
    ),
    "tuning": (
        "tuning",
        "tests/test_tuning.py tests/test_tuning_power.py tests/test_config_meaning.py"
        " tests/test_tuners_study.py tests/test_robust.py tests/test_tuning_power_optim.py"
        " tests/test_tuning_power_run.py tests/test_tuning_power_spec.py"
        " tests/test_tuning_power_report.py tests/test_tuning_power_linesearch.py"
        " tests/test_tuning_power_optim2.py"
        " tests/test_waves_loops.py::test_the_tuning_evaluation_reports_the_runs_above_the_surface",
    ),
    "params": (
        "tuning/params.py",
        "tests/test_tuning.py -k 'parametrisation or symmetry_break or gain_space'",
    ),
    "vcm3d": ("vcjax/control/vcm3d.py", "tests/test_vcm3d.py tests/test_remus100_channels.py"),
    "vcm": ("vcjax/control/vcm.py", "tests/test_vcm.py tests/test_underactuation.py"),
    "lm": (
        "vcjax/identify/lm.py",
        "tests/test_lm.py tests/test_identify_checks.py tests/test_identify.py"
        " -k 'not cli and not infante_rk4'",
    ),
    "checks": (
        "vcjax/identify/checks.py",
        "tests/test_identify_checks.py tests/test_identify.py tests/test_bad_inputs_cli.py"
        " tests/test_identify_power.py"
        " -k 'not infante_rk4 and (not bad_inputs_cli or fit_refuses)'",
    ),
    "remus100": (
        "vcjax/vehicles/remus100.py",
        "tests/test_remus100.py tests/test_remus100_design.py",
    ),
    "remus100_design": (
        "vcjax/vehicles/remus100_design.py",
        "tests/test_remus100_design.py tests/test_remus100_channels.py",
    ),
    "sixdof": ("vcjax/vehicles/sixdof.py", "tests/test_sixdof.py"),
}

#: cosmic-ray operators kept (regular expressions on the operator name)
KEEP = [
    r"core/ReplaceBinaryOperator_Add_(Sub|Mul)$",
    r"core/ReplaceBinaryOperator_Sub_(Add|Mul)$",
    r"core/ReplaceBinaryOperator_Mul_(Div|Add|Pow)$",
    r"core/ReplaceBinaryOperator_Div_(Mul|Sub)$",
    r"core/ReplaceBinaryOperator_Pow_(Mul|Div)$",
    r"core/ReplaceBinaryOperator_(BitOr|BitAnd)_(BitOr|BitAnd|BitXor)$",
    r"core/ReplaceBinaryOperator_(FloorDiv|Mod)_(Div|Mul)$",
    r"core/ReplaceComparisonOperator_(Eq|NotEq|Lt|LtE|Gt|GtE)_(Eq|NotEq|Lt|LtE|Gt|GtE)$",
    r"core/ReplaceComparisonOperator_(Is|IsNot)_(Is|IsNot)$",
    r"core/ReplaceUnaryOperator_USub_UAdd$",
    r"core/ReplaceUnaryOperator_Delete_(Not|Invert)$",
    r"core/(AddNot|ReplaceTrueWithFalse|ReplaceFalseWithTrue|ReplaceAndWithOr|ReplaceOrWithAnd)$",
    r"core/(ReplaceBreakWithContinue|ReplaceContinueWithBreak|ZeroIterationForLoop)$",
    r"core/NumberReplacer$",
]
_KEEP = re.compile("|".join(f"(?:{k})" for k in KEEP))


_PHASE = re.compile(r"\|(setup|run|teardown)$")


# --- pytest plugin (``-p mutation``): per-test times and outcomes; JAX caches cleared per test ---


def pytest_runtest_logreport(report):
    out = os.environ.get("MUTATION_TIMES")
    if out:
        rec = _TIMES.setdefault(report.nodeid, [0.0, "passed"])
        rec[0] += report.duration
        if report.failed or (report.when == "call" and not report.passed):
            rec[1] = report.outcome


def pytest_runtest_teardown(item):
    if os.environ.get("MUTATION_CLEAR_JAX"):  # the next test traces (and is credited) again
        import jax

        jax.clear_caches()


def pytest_sessionfinish(session):
    out = os.environ.get("MUTATION_TIMES")
    if out:
        Path(out).write_text(json.dumps(_TIMES, indent=0))


_TIMES: dict = {}


# --- the driver ---


def target_files(name: str) -> list[str]:
    """The ``.py`` files of a target (a file, or every file of a folder), relative to the root."""
    path = ROOT / MODULES[name][0]
    files = [path] if path.is_file() else sorted(path.rglob("*.py"))
    return [str(f.relative_to(ROOT)) for f in files]


def mutants(file: str, code: str) -> list[dict]:
    """The kept mutants of one file, in line order (cosmic-ray's operators and occurrences)."""
    from cosmic_ray.ast import ast_nodes, get_ast
    from cosmic_ray.commands.init import _operators

    tree = get_ast(code)
    out = []
    for op_name, _args, op in _operators({}):
        if not _KEEP.match(op_name):
            continue
        positions = (p for node in ast_nodes(tree) for p in op.mutation_positions(node))
        for occ, (start, _end) in enumerate(positions):
            out.append(
                {
                    "id": f"{file}:{start[0]}:{start[1]}:{op_name.split('/')[-1]}:{occ}",
                    "file": file,
                    "line": start[0],
                    "operator": op_name,
                    "occurrence": occ,
                }
            )
    return sorted(out, key=lambda m: (m["line"], m["id"]))


def mutate(code: str, m: dict) -> str | None:
    from cosmic_ray.mutating import mutate_code
    from cosmic_ray.plugins import get_operator

    return mutate_code(code, get_operator(m["operator"])(), m["occurrence"])


def _diff(code: str, mutated: str, file: str) -> list[str]:
    import difflib

    d = difflib.unified_diff(code.splitlines(), mutated.splitlines(), file, file, n=0, lineterm="")
    return [x for x in d if x[:1] in "+-" and x[:3] not in ("+++", "---")]


def _spans(code: str):
    """Per statement: (first, last line of its own text, enclosing def or None, at module level)."""
    import ast

    out = []

    def walk(node, func, top):
        for child in ast.iter_child_nodes(node):
            if not isinstance(child, ast.stmt):
                continue
            body = [c for c in ast.iter_child_nodes(child) if isinstance(c, ast.stmt)]
            last = (body[0].lineno - 1) if body else child.end_lineno
            first = min([child.lineno] + [d.lineno for d in getattr(child, "decorator_list", [])])
            out.append((first, max(first, last), child, func, top))
            is_def = isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            walk(child, child if is_def else func, top and not is_def)

    walk(ast.parse(code), None, True)
    return out


def select_tests(
    code: str, line: int, by_line: dict[int, set], times: dict[str, float] | None = None
) -> tuple[list[str], str]:
    """The tests that run a mutant's line, fastest first (``times``: seconds per test of the
    target): those credited with its statement; for a ``def``'s header (defaults, decorators)
    those that run its body. A line run at import (module-level code, a class body, a table
    built by a function when the module loads) is credited to no test (coverage's context
    ``""``), and its value is data that a test may read without running a line of the file
    (a bound a config check takes from a section's declaration): such a mutant runs every test
    of the target, those that run the file first."""
    t = (times or {}).get

    def whole(first: set) -> list[str]:
        rest = set(times or ()) - first
        return sorted(first, key=lambda n: (t(n, 0.0), n)) + sorted(
            rest, key=lambda n: (t(n, 0.0), n)
        )

    spans = [s for s in _spans(code) if s[0] <= line <= s[1]]
    if not spans:
        return [], "uncovered"
    first, last, node, func, top = max(spans, key=lambda s: s[0])
    tests = set().union(*(by_line.get(n, set()) for n in range(first, last + 1)))
    if "" in tests:  # run at import (context ""): a value any test of the target may use
        return whole(set().union(*by_line.values()) - {""}), "import"
    if tests:
        return sorted(tests, key=lambda n: (t(n, 0.0), n)), "line"
    if hasattr(node, "body") and not top or hasattr(node, "decorator_list"):
        end = node.end_lineno
        tests = set().union(*(by_line.get(n, set()) for n in range(first, end + 1))) - {""}
        if tests:
            return sorted(tests, key=lambda n: (t(n, 0.0), n)), "body"
    if top:
        return whole(set().union(*by_line.values()) - {""}), "module"
    return [], "uncovered"


def _env(work: Path, tree: Path, **extra) -> dict:
    env = dict(os.environ)
    path = [str(tree), str(tree / "tools")] + [p for p in env.get("PYTHONPATH", "").split(":") if p]
    env.update(
        PYTHONPATH=":".join(path),
        VCJAX_TEST_CACHE_DIR=str(work / "jaxcache"),  # programs a mutant leaves unchanged
        PYTHONPYCACHEPREFIX=str(work / "pyc"),
        **extra,
    )
    return env


def _pytest(python: str, args: list[str], env: dict, tree: Path, timeout: float | None):
    cmd = ["nice", "-n", "15", python, "-m", "pytest", "-q", "-n", "0", "-p", "no:cacheprovider"]
    proc = subprocess.Popen(
        cmd + args,
        cwd=tree,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    try:
        out, _ = proc.communicate(timeout=timeout)
        return proc.returncode, out
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return None, "timeout"


def collect_coverage(name: str, work: Path, tree: Path, python: str) -> tuple[dict, dict]:
    """Per file, line -> the tests that ran it; per test, seconds (unmutated, cached in work)."""
    import coverage

    data, times = work / f"{name}.coverage", work / f"{name}.times.json"
    files = target_files(name)
    if not (data.exists() and times.exists()):
        src = sorted({str(Path(f).parent) for f in files})
        print(f"{name}: collecting per-test coverage of {MODULES[name][1]}", flush=True)
        env = _env(work, tree, COVERAGE_FILE=str(data), MUTATION_TIMES=str(times))
        env["MUTATION_CLEAR_JAX"] = "1"
        args = ["-p", "pytest_cov", "-p", "mutation", "--cov-context=test", "--cov-report="]
        args += [f"--cov={s}" for s in src] + shlex.split(MODULES[name][1])
        rc, out = _pytest(python, args, env, tree, None)
        if rc not in (0, 1):
            data.unlink(missing_ok=True)
            sys.exit(f"mutation: the unmutated tests of {name} did not run:\n{out[-3000:]}")
        print(out.strip().splitlines()[-1], flush=True)
    t = json.loads(times.read_text())
    passed = {k: v[0] for k, v in t.items() if v[1] == "passed"}
    cov = coverage.CoverageData(basename=str(data))
    cov.read()
    by_file = {}
    for f in files:
        lines = cov.contexts_by_lineno(str((tree / f).resolve())) or {}
        by_file[f] = {n: set().union(*(credited(c, passed) for c in cs)) for n, cs in lines.items()}
    return by_file, passed


def credited(context: str, passed) -> set:
    """The tests a coverage context credits with its lines: the context's own test (when it
    passed unmutated); for a fixture's setup, every passed test of the same test file. A fixture
    of module (or wider) scope is set up once, in the context of the first test that asks for
    it, yet every later test that uses it reads what it computed (a fit, a tune run once for the
    whole file): a mutant of those lines must run them too. ``""`` (run at import) stays as it
    is (:func:`select_tests`)."""
    if context == "":
        return {""}
    test = _PHASE.sub("", context)
    if context.endswith("|setup"):
        module = test.split("::")[0]
        return {n for n in passed if n.split("::")[0] == module}
    return {test} if test in passed else set()


#: third-party modules the mutant server imports once, before it forks a pytest per mutant
PRELOAD = (
    "numpy", "scipy", "scipy.linalg", "scipy.optimize", "scipy.stats", "jax", "jax.numpy",
    "jax.scipy", "jax.experimental", "optax", "matplotlib", "matplotlib.pyplot", "pytest",
    "_pytest", "xdist", "tomllib", "hypothesis",
)  # fmt: skip


def serve() -> int:
    """The mutant server (``--serve``, started by :class:`Server`): imports the third-party
    modules once (two thirds of a short test's CPU time), then for each request line (JSON:
    pytest arguments, seconds, log file) forks a child that runs pytest and answers its exit
    status (null: timed out, killed). Neither vcjax nor tuning is ever imported here: each child
    imports them, mutated, from the tree; JAX's backend starts in the child (safe to fork
    before it)."""
    import importlib

    os.environ.setdefault("MPLBACKEND", "Agg")
    for mod in PRELOAD:
        try:
            importlib.import_module(mod)
        except Exception:  # noqa: BLE001 - an optional module
            pass
    assert not any(m.split(".")[0] in ("vcjax", "tuning") for m in sys.modules)
    import pytest

    for line in sys.stdin:
        req = json.loads(line)
        pid = os.fork()
        if pid == 0:  # the child: its own session (killed as a group), output to the log
            os.setsid()
            fd = os.open(req["log"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            rc = 3
            try:
                rc = int(pytest.main(req["args"]))
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(rc)
        deadline, rc = time.time() + req["timeout"], None
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                rc = os.waitstatus_to_exitcode(status)
                break
            if time.time() > deadline:
                os.killpg(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                break
            time.sleep(0.05)
        try:  # whatever the tests started in the child's session
            os.killpg(pid, signal.SIGKILL)
        except OSError:
            pass
        print(json.dumps({"rc": rc}), flush=True)
    return 0


class Server:
    """A niced ``--serve`` process in the tree; :meth:`run` runs one pytest in a fresh fork."""

    def __init__(self, python: str, work: Path, tree: Path):
        self.cmd = ["nice", "-n", "15", python, str(Path(__file__).resolve()), "--serve"]
        self.env = _env(work, tree, PYTHONDONTWRITEBYTECODE="1")
        self.tree, self.log, self.proc = tree, work / "last.log", None

    def close(self) -> None:
        if self.proc is not None:
            self.proc.stdin.close()  # the server ends at the end of its input
            self.proc.wait()
            self.proc = None

    def run(self, args: list[str], timeout: float) -> tuple[int | None, str]:
        if self.proc is None or self.proc.poll() is not None:
            self.proc = subprocess.Popen(
                self.cmd, cwd=self.tree, env=self.env, stdin=subprocess.PIPE,
                stdout=subprocess.PIPE, text=True,
            )  # fmt: skip
        args = ["-q", "-n", "0", "-p", "no:cacheprovider", *args]
        req = {"args": args, "timeout": timeout, "log": str(self.log)}
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        rc = json.loads(self.proc.stdout.readline())["rc"]
        return rc, self.log.read_text(errors="replace") if self.log.exists() else ""


def in_annotation(code: str, m: dict) -> bool:
    """Whether a mutant changes only an annotation of a module that never evaluates them
    (``from __future__ import annotations``): not code, nothing to test."""
    import ast

    tree = ast.parse(code)
    if not any(
        isinstance(n, ast.ImportFrom)
        and n.module == "__future__"
        and n.names[0].name == "annotations"
        for n in tree.body
    ):
        return False
    line, col = int(m["id"].split(":")[1]), int(m["id"].split(":")[2])
    for node in ast.walk(tree):
        anns = []
        if isinstance(node, ast.arg | ast.AnnAssign):
            anns = [node.annotation]
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            anns = [node.returns]
        for a in anns:
            if a is not None and (a.lineno, a.col_offset) <= (line, col) < (
                a.end_lineno,
                a.end_col_offset,
            ):
                return True
    return False


def run_module(name, work: Path, python: str, a) -> dict:
    tree = work / "tree"
    out = work / f"{name}.jsonl"
    done = {}
    if out.exists() and not a.fresh:
        for line in out.read_text().splitlines():
            r = json.loads(line)
            if r["outcome"] != "error":  # an error (e.g. the run stopped) runs again
                done[r["id"]] = r
    if a.tests:
        by_file, times = None, {}
    else:
        by_file, times = collect_coverage(name, work, tree, python)
    todo = []
    for f in target_files(name):
        code = (tree / f).read_text()
        ms = mutants(f, code)
        if a.line:
            ms = [m for m in ms if m["line"] in a.line]
        if a.only:
            ms = [m for m in ms if re.search(a.only, m["id"])]
        todo += [(m, code) for m in ms]
    if a.sample:
        random.Random(a.seed).shuffle(todo)
        todo = sorted(todo[: a.sample], key=lambda mc: (mc[0]["file"], mc[0]["line"]))
    results = [done[m["id"]] for m, _ in todo if m["id"] in done and not a.rerun]
    server = Server(python, work, tree)
    if times:  # the server itself: the fastest tests pass on the unmutated tree
        fastest = sorted(times, key=times.get)[:3]
        rc, output = server.run(fastest, a.timeout)
        if rc != 0:
            sys.exit(
                f"mutation: unmutated, {fastest} did not pass in the server:\n{output[-3000:]}"
            )
    with out.open("a") as log:
        for i, (m, code) in enumerate(todo, 1):
            if m["id"] in done and not a.rerun:
                continue
            path, t0 = tree / m["file"], time.time()
            mutated = mutate(code, m)
            if mutated is None:
                continue
            if a.tests:
                tests, why = shlex.split(a.tests), "given"
            else:
                tests, why = select_tests(code, m["line"], by_file[m["file"]], times)
            r = {**m, "diff": _diff(code, mutated, m["file"]), "tests": len(tests), "by": why}
            if in_annotation(code, m):
                r["outcome"] = "annotation"
            elif not tests:
                r["outcome"] = "uncovered"
            else:
                stat = path.stat()
                path.write_text(mutated)
                try:
                    limit = a.timeout + 5 * sum(times.get(t, 0.0) for t in tests)
                    rc, output = server.run(["-x", *tests], limit)
                finally:
                    path.write_text(code)
                    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))  # its .pyc again
                outcome = {None: "timeout", 0: "survived", 1: "killed", 2: "incompetent"}
                r["outcome"] = outcome.get(rc, "error")
                broken = ("ERROR collecting", "ImportError while loading conftest")
                if rc in (3, 4) and any(b in output for b in broken):
                    r["outcome"] = "incompetent"  # the mutant breaks the import
                if r["outcome"] == "error":
                    r["output"] = output[-2000:]
            r["seconds"] = round(time.time() - t0, 1)
            log.write(json.dumps(r) + "\n")
            log.flush()
            results.append(r)
            print(
                f"[{name} {i}/{len(todo)}] {m['file']}:{m['line']} "
                f"{m['operator'].split('/')[-1]}: {r['outcome']} "
                f"({len(tests)} tests by {why}, {r['seconds']} s)",
                flush=True,
            )
    server.close()
    return summarise(name, results)


def summarise(name: str, results: list[dict]) -> dict:
    counts = dict.fromkeys(
        ("killed", "timeout", "incompetent", "survived", "uncovered", "annotation", "error"), 0
    )
    for r in results:
        counts[r["outcome"]] += 1
    run = len(results) - counts["error"] - counts["annotation"]
    killed = counts["killed"] + counts["timeout"] + counts["incompetent"]
    return {
        "module": MODULES[name][0],
        "tests": MODULES[name][1],
        "mutants": len(results),
        **counts,
        "killed_fraction": killed / run if run else None,
        "survivors": [
            {"id": r["id"], "outcome": r["outcome"], "diff": r["diff"]}
            for r in results
            if r["outcome"] in ("survived", "uncovered")
        ],
    }


def _copy_tree(dest: Path) -> None:
    files = subprocess.run(
        ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    for f in files:
        if (ROOT / f).is_file():
            (dest / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / f, dest / f)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("names", nargs="*", help=f"targets (default: all of {list(MODULES)})")
    ap.add_argument("--sample", type=int, default=0, help="mutants run per target (0: all)")
    ap.add_argument("--seed", type=int, default=24)
    ap.add_argument(
        "--timeout", type=float, default=240.0, help="seconds per mutant, plus 5x its tests' time"
    )
    ap.add_argument("--python", default=sys.executable, help="interpreter that runs the tests")
    ap.add_argument("--work", type=Path, default=None, help="scratch folder (default: temporary)")
    ap.add_argument("--fresh", action="store_true", help="forget the results in --work")
    ap.add_argument("--line", type=int, action="append", help="only the mutants of this line")
    ap.add_argument("--only", help="only the mutants whose id matches this regular expression")
    ap.add_argument("--rerun", action="store_true", help="run finished mutants again")
    ap.add_argument("--tests", help="run these tests for every mutant instead of selecting")
    ap.add_argument("--list", action="store_true", help="list the targets and count mutants")
    ap.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.serve:
        return serve()
    unknown = [n for n in a.names if n not in MODULES]
    if unknown:
        ap.error(f"unknown targets {unknown}; choose from {list(MODULES)}")
    if a.list:
        for n in a.names or list(MODULES):
            files = target_files(n)
            counts = [len(mutants(f, (ROOT / f).read_text())) for f in files]
            print(f"{n:16s} {sum(counts):5d} mutants  tests: {MODULES[n][1]}")
            for f, c in zip(files, counts, strict=True):
                print(f"    {f:40s} {c:5d}")
        return 0
    work = (a.work or Path(tempfile.mkdtemp(prefix="vcjax-mutation-"))).resolve()
    if not (work / "tree").exists():
        (work / "tree").mkdir(parents=True)
        _copy_tree(work / "tree")
    summary = work / "mutation.json"
    results = json.loads(summary.read_text()) if summary.exists() else {}
    for name in a.names or list(MODULES):
        res = run_module(name, work, a.python, a)
        if not (a.line or a.only or a.tests):
            results[name] = res
        frac = res["killed_fraction"]
        print(
            f"{name}: {res['mutants']} mutants: killed {res['killed']}, failed to import "
            f"{res['incompetent']}, timed out {res['timeout']}, survived {res['survived']}, "
            f"uncovered {res['uncovered']}, in annotations {res['annotation']}, "
            f"errors {res['error']}" + ("" if frac is None else f" ({100 * frac:.1f} % killed)")
        )
        for s in res["survivors"]:
            print(f"  {s['outcome']}:", s["id"], *s["diff"], sep="\n    ")
        summary.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
