"""The shape of the code above the simulator floors (issue 29): no function of the config, sweep,
tuning, fit, experiment or search modules longer than 80 lines or taking more than 8 parameters
(a settings object replaces a long parameter list), and ``tuning`` built on the public faces of
its dependencies only. Checked statically from the source (nothing imported)."""

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the packages whose functions are held to the limits
CHECKED = ("vcjax/config", "vcjax/sweep", "tuning", "vcjax/identify", "vcjax/experiments")
CHECKED += ("vcjax/search",)
MAX_LINES = 80  # end_lineno - lineno + 1 of the def (decorators not counted)
MAX_PARAMS = 8  # every parameter (positional, keyword-only, *args, **kwargs) but self / cls


@functools.cache
def _functions() -> tuple:
    """``(file, def node)`` of every function (methods and nested ones too) of ``CHECKED``."""
    out = []
    for folder in CHECKED:
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            for node in ast.walk(ast.parse(path.read_text(), rel)):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    out.append((rel, node))
    return tuple(out)


def _params(fn) -> int:
    a = fn.args
    names = [p.arg for p in a.posonlyargs + a.args + a.kwonlyargs]
    names += [p.arg for p in (a.vararg, a.kwarg) if p is not None]
    return len([n for n in names if n not in ("self", "cls")])


def test_no_long_function_and_no_long_parameter_list():
    seen = []
    for rel, fn in _functions():
        lines, params = fn.end_lineno - fn.lineno + 1, _params(fn)
        if lines > MAX_LINES or params > MAX_PARAMS:
            seen.append(f"{rel}:{fn.lineno} {fn.name}: {lines} lines, {params} parameters")
    assert not seen, (
        f"over {MAX_LINES} lines or {MAX_PARAMS} parameters (split it; group settings into an "
        "options object):\n" + "\n".join(seen)
    )


def _private(module: str) -> bool:
    """A module path with a leading-underscore part (``optax._src.linesearch``,
    ``vcjax._checks``), dunder names (``__future__``) aside."""
    return any(p.startswith("_") and not p.startswith("__") for p in module.split("."))


def test_tuning_imports_no_private_module():
    """``tuning`` uses the public faces of optax, jax and vcjax: no ``_src`` module, no
    leading-underscore module or name of another package (deferred imports included; its own
    modules may share private helpers)."""
    bad = []
    for path in sorted((ROOT / "tuning").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for node in ast.walk(ast.parse(path.read_text(), rel)):
            if isinstance(node, ast.Import):
                mods = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                if node.module.split(".")[0] == "tuning":
                    continue
                mods = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif (
                isinstance(node, ast.Call)
                and getattr(node.func, "attr", getattr(node.func, "id", None))
                in ("import_module", "__import__")
                and node.args
                and isinstance(node.args[0], ast.Constant)
            ):
                mods = [str(node.args[0].value)]
            else:
                continue
            bad += [f"{rel}:{node.lineno} {m}" for m in mods if _private(m)]
    assert not bad, "tuning imports private modules:\n" + "\n".join(bad)


def test_the_checks_see_what_they_look_for():
    """The checks above find long functions, long parameter lists and private imports."""
    fn = ast.parse("def f(a, b, *c, d, **e):\n    pass\n").body[0]
    assert _params(fn) == 5
    method = ast.parse("def f(self, a):\n    pass\n").body[0]
    assert _params(method) == 1
    assert _private("optax._src.linesearch") and _private("vcjax._checks")
    assert not _private("__future__") and not _private("optax.tree")
    assert len(_functions()) > 200  # the folders were found
