"""Mutation testing of the numerical core with cosmic-ray (not part of any test run).

Each mutant (one small change to one module: an operator, a comparison, a constant, a negation)
is written into a scratch copy of the git-tracked tree and judged by a fresh pytest process
running the module's default (non-slow) tests on one worker, niced; a mutant the tests do not
fail *survives*. Fresh processes because JAX's compiled programs are cached per process (a
forked runner would reuse the unmutated program) and JAX does not survive ``fork``.

Operators: cosmic-ray's full set makes about 11 mutants per arithmetic operator, most of them
bit and shift operations that fail at once on floating-point arrays. The set kept here
(:data:`KEEP`) is the selective set of numerical code: ``+`` <-> ``-``/``*``, ``*`` <-> ``/``,
``+``, ``**``, ``/`` -> ``*``/``-``, ``**`` -> ``*``/``/``, logical ``|``/``&``/``^`` among
themselves, every relational operator for every other, ``is`` <-> ``is not``, dropped unary
minus / ``not`` / ``~``, added ``not``, ``True`` <-> ``False``, ``and`` <-> ``or``,
``break`` <-> ``continue``, loops run zero times, each number changed. A seeded random sample
of ``--sample`` mutants per module is run (the whole set takes hours on two cores).

Usage (cosmic-ray in any environment; the tests run with ``--python``)::

    pip install -e ".[mutation]"          # or cosmic-ray in a separate environment
    python tools/mutation.py metrics params --sample 40
    python tools/mutation.py --list

Programs a mutant leaves unchanged come from JAX's persistent compilation cache in the scratch
folder (a changed program has another cache key). Prints, per module, mutants generated /
selected / run / killed / survived / timed out and each survivor's diff, and writes
``mutation.json`` in the scratch folder (``--work``).
"""

from __future__ import annotations

import argparse
import json
import random
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: name -> (module, the default tests that exercise it)
MODULES = {
    "metrics": ("vcjax/metrics.py", "tests/test_metrics.py tests/test_health.py"),
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


def _cosmic_ray() -> str:
    exe = shutil.which("cosmic-ray") or str(Path(sys.executable).with_name("cosmic-ray"))
    if not Path(exe).exists():
        sys.exit("mutation: cosmic-ray not found (pip install cosmic-ray)")
    return exe


def _copy_tree(dest: Path) -> None:
    files = subprocess.run(
        ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    for f in files:
        if (ROOT / f).is_file() and not f.startswith(("docs/", "examples/")):
            (dest / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / f, dest / f)


def run_module(name, work: Path, python: str, sample: int, seed: int, timeout: float) -> dict:
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import WorkerOutcome, WorkResult

    module, tests = MODULES[name]
    cache = shlex.quote(str(work / "jaxcache"))  # programs a mutant leaves unchanged
    cmd = (
        f"env PYTHONPATH=. JAX_COMPILATION_CACHE_DIR={cache} "
        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS=0.5 "
        f"nice -n 19 {shlex.quote(python)} -m pytest -x -q -n 0 -p no:cacheprovider {tests}"
    )
    cfg, sess = work / f"{name}.toml", work / f"{name}.sqlite"
    cfg.write_text(
        f'[cosmic-ray]\nmodule-path = "{module}"\ntimeout = {timeout}\nexcluded-modules = []\n'
        f'test-command = {json.dumps(cmd)}\n[cosmic-ray.distributor]\nname = "local"\n'
    )
    sess.unlink(missing_ok=True)
    tree = work / "tree"
    subprocess.run([_cosmic_ray(), "init", str(cfg), str(sess)], cwd=tree, check=True)
    with use_db(str(sess), WorkDB.Mode.open) as db:
        items = list(db.pending_work_items)
        kept = [w for w in items if _KEEP.match(w.mutations[0].operator_name)]
        random.Random(seed).shuffle(kept)
        chosen = {w.job_id for w in kept[:sample]}
        for w in items:
            if w.job_id not in chosen:
                db.set_result(w.job_id, WorkResult(worker_outcome=WorkerOutcome.SKIPPED))
    subprocess.run([_cosmic_ray(), "exec", str(cfg), str(sess)], cwd=tree, check=True)
    dump = subprocess.run(
        [_cosmic_ray(), "dump", str(sess)], capture_output=True, text=True, check=True
    ).stdout
    counts = dict.fromkeys(("killed", "survived", "timeout", "incompetent", "error"), 0)
    survivors = []
    for line in dump.splitlines():
        w, r = json.loads(line)
        if r is None or r["worker_outcome"] == "skipped":
            continue
        m = w["mutations"][0]
        where = f"{m['module_path']}:{m['start_pos'][0]} {m['operator_name']}"
        if r["worker_outcome"] != "normal":
            counts["error"] += 1
        elif r["test_outcome"] == "survived":
            counts["survived"] += 1
            lines = (r["diff"] or "").splitlines()
            diff = [x for x in lines if x[:1] in "+-" and x[:3] not in ("+++", "---")]
            survivors.append({"where": where, "diff": diff})
        elif r["output"] == "timeout":
            counts["timeout"] += 1
        else:
            counts[r["test_outcome"]] += 1
    run = sum(counts.values())
    killed = counts["killed"] + counts["timeout"] + counts["incompetent"]
    return {
        "module": module,
        "tests": tests,
        "generated": len(items),
        "selected": len(kept),
        "run": run,
        **counts,
        "killed_fraction": killed / run if run else None,
        "survivors": survivors,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("names", nargs="*", help=f"modules (default: all of {list(MODULES)})")
    ap.add_argument("--sample", type=int, default=30, help="mutants run per module")
    ap.add_argument("--seed", type=int, default=24)
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per mutant")
    ap.add_argument("--python", default=sys.executable, help="interpreter that runs the tests")
    ap.add_argument("--work", type=Path, default=None, help="scratch folder (default: temporary)")
    ap.add_argument("--list", action="store_true", help="list the modules and their tests")
    a = ap.parse_args(argv)
    if a.list:
        for n, (m, t) in MODULES.items():
            print(f"{n:16s} {m:36s} {t}")
        return 0
    unknown = [n for n in a.names if n not in MODULES]
    if unknown:
        ap.error(f"unknown modules {unknown}; choose from {list(MODULES)}")
    work = a.work or Path(tempfile.mkdtemp(prefix="vcjax-mutation-"))
    (work / "tree").mkdir(parents=True, exist_ok=True)
    _copy_tree(work / "tree")
    results = {}
    for name in a.names or list(MODULES):
        res = results[name] = run_module(name, work, a.python, a.sample, a.seed, a.timeout)
        frac = res["killed_fraction"]
        print(
            f"{name}: generated {res['generated']}, selected {res['selected']}, run {res['run']}: "
            f"killed {res['killed']}, timed out {res['timeout']}, survived {res['survived']}"
            + ("" if frac is None else f" ({100 * frac:.1f} % killed)")
        )
        for s in res["survivors"]:
            print("  survived:", s["where"], *s["diff"], sep="\n    ")
        (work / "mutation.json").write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
