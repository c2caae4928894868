"""The data flow of the package (STYLE.md): a module imports only from modules earlier in the
flow. Checked statically from the source (no imports executed)."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "vcjax"

#: layers in data-flow order; a module may import from its own layer or an earlier one
LAYERS = [
    {"_checks", "linalg", "integrators", "progress", "distributed", "runinfo"},
    {"mechanics", "systems", "paths", "currents"},
    {"vehicles", "guidance", "allocation", "rollout"},
    {"control"},
    {"plots", "plots_sim2", "sweep_plots"},
    {"sim1", "sim2", "demos"},
    {"sweep"},
    {"cli"},
]
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
    names = {p.stem if p.is_file() else p.name for p in ROOT.iterdir() if p.name != "__pycache__"}
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
