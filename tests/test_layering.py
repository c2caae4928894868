"""The data flow of the package: a module imports only from modules earlier in the
flow. Checked statically from the source (no imports executed)."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "vcjax"

#: layers in data-flow order; a module may import from its own layer or an earlier one.
#: ``config`` sits just above ``loops``: the ``[scenario]`` section reads the loop registry and
#: the loop classes' dataclass fields (its options), so ``loops`` never imports it. ``runtime``
#: (devices, caches, outputs, interrupts, progress: plumbing that knows no physics) is at the
#: bottom. Figures (``plots``) read results of loops and sweeps and run nothing; the experiments
#: (presets of ``vcjax simulate``) sit on top, below only the CLI. The worst-case search
#: (``search``, ``vcjax falsify``) runs sweeps' rollouts and draws its own figures.
LAYERS = [
    {"_checks", "runtime", "linalg", "integrators"},
    {"mechanics", "paths"},
    {"environment"},
    {"vehicles", "guidance", "allocation", "rollout"},
    {"control"},
    {"loops"},
    {"config"},
    {"metrics"},
    {"sweep"},
    {"plots"},
    {"search"},
    {"experiments", "identify"},
    {"cli", "commands", "plugins"},
]
#: the only modules of vcjax that may import vcjax.experiments (besides itself)
EXPERIMENT_IMPORTERS = {"cli", "commands"}
LAYER_OF = {name: i for i, names in enumerate(LAYERS) for name in names}


def _top(modname: str) -> str | None:
    parts = modname.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "vcjax" else None


def _imports(path: Path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            if node.module == "vcjax":
                yield from (a.name for a in node.names)
            elif _top(node.module):
                yield _top(node.module)
        elif isinstance(node, ast.Import):
            yield from filter(None, (_top(a.name) for a in node.names))


def test_every_module_is_in_a_layer():
    names = {
        p.stem if p.is_file() else p.name
        for p in ROOT.iterdir()
        if p.name != "__pycache__" and (p.is_dir() or p.suffix == ".py")  # not py.typed
    }
    names -= {"__init__"}
    assert names <= set(LAYER_OF), f"add to LAYERS: {sorted(names - set(LAYER_OF))}"


def test_imports_follow_the_data_flow():
    bad = []
    for path in ROOT.rglob("*.py"):
        rel = path.relative_to(ROOT)
        if rel.name == "__init__.py" and len(rel.parts) == 1:
            continue  # the package re-exports
        own = rel.parts[0].removesuffix(".py")
        for dep in _imports(path):
            if dep != own and LAYER_OF[dep] > LAYER_OF[own]:
                bad.append(f"{rel} imports vcjax.{dep}")
    assert not bad, bad


TUNING = Path(__file__).resolve().parents[1] / "tuning"
#: what the tuner may not import: the experiments and the CLI sit above it
ABOVE_TUNING = {
    "sim1",
    "sim2",
    "demos",
    "sim_remus100",
    "experiments",
    "cli",
    "commands",
    "plugins",
}
#: the tuner's command (``vcjax tune``) plugs into the CLI through its seam, vcjax.plugins
PLUGIN_MODULES = {"command.py": {"plugins"}}


def _imports_tuning(path: Path) -> bool:
    """Whether a module imports ``tuning``: an import statement, or a string name handed to
    ``importlib.import_module`` / ``__import__`` (a plugin seam is entry points, not names)."""
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.Call):
            f = node.func
            fname = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if fname in ("import_module", "__import__") and node.args:
                arg = node.args[0]
                names = [arg.value] if isinstance(arg, ast.Constant) else ["<computed>"]
        if any(n == "tuning" or n.startswith("tuning.") or n == "<computed>" for n in names):
            return True
    return False


def test_tuning_imports_the_layer_never_an_experiment_and_vcjax_never_imports_tuning():
    bad = []
    for path in TUNING.rglob("*.py"):
        allowed = PLUGIN_MODULES.get(path.name, set())
        for dep in _imports(path):
            if dep in ABOVE_TUNING - allowed:
                bad.append(f"tuning/{path.name} imports vcjax.{dep}")
    for path in ROOT.rglob("*.py"):  # the CLI too: `vcjax tune` is found by its entry point
        if _imports_tuning(path):
            bad.append(f"vcjax/{path.relative_to(ROOT)} imports tuning")
    assert not bad, bad


def test_the_tune_command_is_an_entry_point_of_the_command_seam():
    """``vcjax tune`` reaches the CLI through ``[project.entry-points."vcjax.commands"]``
    (vcjax.plugins); the object it names is a Command of that name, cheap to import."""
    import tomllib

    from vcjax.plugins import GROUP, Command

    project = tomllib.loads((ROOT.parent / "pyproject.toml").read_text())["project"]
    assert project["entry-points"][GROUP] == {"tune": "tuning.command:COMMAND"}
    assert project["entry-points"]["vcjax.metrics"] == {
        "loss": "tuning.robust:TuningLossMetric.of_table"
    }
    from tuning.command import COMMAND

    assert isinstance(COMMAND, Command) and COMMAND.name == "tune" and COMMAND.distributed


def test_sweep_never_imports_an_experiment():
    bad = [
        f"{p.relative_to(ROOT)} imports vcjax.{dep}"
        for p in (ROOT / "sweep").rglob("*.py")
        for dep in _imports(p)
        if dep in ("sim1", "sim2", "demos", "sim_remus100", "experiments", "plots")
    ]
    assert not bad, bad


def test_nothing_but_the_cli_imports_an_experiment():
    bad = [
        f"{p.relative_to(ROOT)} imports vcjax.experiments"
        for p in ROOT.rglob("*.py")
        if p.relative_to(ROOT).parts[0].removesuffix(".py")
        not in EXPERIMENT_IMPORTERS | {"experiments"}
        for dep in _imports(p)
        if dep == "experiments"
    ]
    assert not bad, bad


def test_no_private_figure_helpers_across_modules():
    """Figures use the public helpers of vcjax.plots (pyplot, save), no private names."""
    bad = []
    for path in [*ROOT.rglob("*.py"), *TUNING.rglob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("vcjax.plots"):
                bad += [
                    f"{path.name}: {node.module}.{a.name}" for a in node.names if a.name[0] == "_"
                ]
    assert not bad, bad


# ------------------------------------------------------------------ the import graph


def _module_name(path: Path, base: Path) -> str:
    parts = list(path.relative_to(base).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    """``{module: modules of vcjax and tuning it imports}``, every import counted (those inside
    functions too: an import deferred to call time is still a dependency)."""
    base = ROOT.parent
    files = {_module_name(p, base): p for pkg in (ROOT, TUNING) for p in pkg.rglob("*.py")}
    graph = {}
    for name, path in files.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                mod = node.module or ""
                if node.level:  # relative: resolved against the package
                    head = package.split(".")[: len(package.split(".")) - node.level + 1]
                    mod = ".".join(head + ([mod] if mod else []))
                for a in node.names:  # "from pkg import submodule" depends on the submodule
                    deps.add(f"{mod}.{a.name}" if f"{mod}.{a.name}" in files else mod)
            elif isinstance(node, ast.Import):
                deps.update(a.name for a in node.names)
        graph[name] = {d for d in deps if d in files and d != name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as ``[a, b, ..., a]``, or None (depth-first search)."""
    done, on_path = set(), []

    def visit(v):
        if v in on_path:
            return [*on_path[on_path.index(v) :], v]
        if v in done:
            return None
        on_path.append(v)
        for w in sorted(graph.get(v, ())):
            if cycle := visit(w):
                return cycle
        on_path.pop()
        done.add(v)
        return None

    for v in sorted(graph):
        if cycle := visit(v):
            return cycle
    return None


def test_the_import_graph_has_no_cycles():
    graph = import_graph()
    assert {"vcjax.loops.registry", "vcjax.commands", "tuning.spec"} <= set(graph)
    assert "vcjax.loops.registry" in graph["vcjax.loops"]  # the graph sees the imports
    assert find_cycle(graph) is None, " -> ".join(find_cycle(graph))
    # and the check finds one when there is one
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]


def test_no_package_level_cycle():
    """Collapsed to packages, the graph runs one way: tuning imports vcjax, vcjax imports
    nothing of tuning (no module exempted, deferred imports counted)."""
    packages: dict[str, set[str]] = {}
    for mod, deps in import_graph().items():
        packages.setdefault(mod.split(".")[0], set()).update(d.split(".")[0] for d in deps)
    packages = {p: deps - {p} for p, deps in packages.items()}
    assert packages == {"vcjax": set(), "tuning": {"vcjax"}}, packages
    assert find_cycle(packages) is None


# ------------------------------------------------------------------ tests and benchmarks


def _imported_names(path: Path) -> list[str]:
    """The modules a file imports: import statements, string names handed to
    ``import_module``/``__import__``, and the imports of code held in strings (a snippet run in
    a subprocess)."""
    tree = ast.parse(path.read_text())
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.append(node.module)
        elif isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.Call) and node.args:
            f = node.func
            fname = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            arg = node.args[0]
            if fname in ("import_module", "__import__") and isinstance(arg, ast.Constant):
                names.append(str(arg.value))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            names += re.findall(r"^\s*(?:from|import) +([\w.]+)", node.value, re.M)
    return names


def test_tests_and_benchmarks_import_one_way():
    """Benchmarks may import the tests' shared oracles and helpers (``tests.reference``); the
    tests never import ``benchmarks`` (they run it as users do: ``python -m benchmarks``)."""
    repo = ROOT.parent
    bad = []
    for path in sorted((repo / "tests").rglob("*.py")):
        for name in _imported_names(path):
            if name == "benchmarks" or name.startswith("benchmarks."):
                bad.append(f"{path.relative_to(repo)} imports {name}")
    for path in sorted((repo / "benchmarks").rglob("*.py")):
        for name in _imported_names(path):
            if name.split(".")[0] == "tests" and not name.startswith("tests.reference"):
                bad.append(f"{path.relative_to(repo)} imports {name} (only tests.reference)")
    assert not bad, bad
