"""The example notebook ``examples/tuning.ipynb`` runs top to bottom.

nbformat/nbclient/ipykernel are not dependencies: the code cells are read with the standard
library's ``json`` and executed in order in one namespace (matplotlib on the Agg backend), which
is what a kernel would do for this notebook (it uses no magics or display hooks).
"""

import json
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "tuning.ipynb"


def _code_cells(path):
    nb = json.loads(path.read_text())
    assert nb["nbformat"] == 4
    return ["".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "code"]


def test_tuning_notebook_executes(monkeypatch, tmp_path):
    cells = _code_cells(NOTEBOOK)
    assert cells and not any(
        line.lstrip().startswith(("%", "!")) for c in cells for line in c.splitlines()
    )
    monkeypatch.chdir(tmp_path)  # anything the notebook writes lands here
    ns = {"__name__": "__main__"}
    for i, src in enumerate(cells):
        exec(compile(src, f"{NOTEBOOK.name}[cell {i}]", "exec"), ns)  # noqa: S102
    result = ns["result"]
    assert result.n_bad == 0 and result.loss < result.history[0]["loss"]
    assert plt.get_fignums()  # the plotting cell drew something
    plt.close("all")


REMUS_NOTEBOOK = NOTEBOOK.parent / "remus100_3d.ipynb"


@pytest.mark.slow
def test_remus100_notebook_executes_at_small_size(monkeypatch, tmp_path):
    cells = _code_cells(REMUS_NOTEBOOK)
    monkeypatch.setenv("VCJAX_NOTEBOOK_SMALL", "1")
    monkeypatch.chdir(tmp_path)
    ns = {"__name__": "__main__"}
    for i, src in enumerate(cells):
        exec(compile(src, f"{REMUS_NOTEBOOK.name}[cell {i}]", "exec"), ns)  # noqa: S102
    for rms, ok in ns["sweeps"].values():
        assert bool(ok.all()) and rms.shape == (4,)
    assert plt.get_fignums()
    plt.close("all")


@pytest.mark.parametrize("path", [NOTEBOOK, REMUS_NOTEBOOK], ids=lambda p: p.name)
def test_notebooks_are_committed_executed_with_their_figures(path):
    """The documentation shows the notebooks as committed (it does not execute them): each is
    committed run top to bottom in one kernel, with its outputs and at least one figure, and
    forces no backend (a figure must show in Jupyter)."""
    nb = json.loads(path.read_text())
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert [c["execution_count"] for c in code] == list(range(1, len(code) + 1))
    images = [o for c in code for o in c["outputs"] if "image/png" in o.get("data", {})]
    assert images, f"{path.name}: no figure in the committed outputs"
    assert not any(o.get("output_type") == "error" for c in code for o in c["outputs"])
    assert not any("matplotlib.use(" in "".join(c["source"]) for c in code)
