"""The walkthrough notebook runs top to bottom in its fast setting and ends with a recommended design."""

import sys
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

REPO = Path(__file__).resolve().parents[1]
NOTEBOOK = REPO / "notebooks" / "walkthrough.ipynb"
CELL_TIMEOUT_S = 600  # a guard against a hung kernel: the fit cell fits two materials (about 300 s cold)
PREFIX_MARKER = "KERNEL_PREFIX="


def _text(cell) -> str:
    """Everything a code cell printed or displayed as text."""
    parts = []
    for out in cell.get("outputs", []):
        if out.get("output_type") == "stream":
            parts.append(out.get("text", ""))
        elif "data" in out:
            parts.append(out["data"].get("text/plain", ""))
            parts.append(out["data"].get("text/markdown", ""))
    return "".join(parts)


def test_committed_notebook_has_no_outputs():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    assert nb.metadata["kernelspec"]["name"] == "python3"
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert not cell.outputs and cell.execution_count is None


@pytest.mark.slow
@pytest.mark.xdist_group("short_tp_fits")
def test_walkthrough_runs_in_its_fast_setting(tmp_path, monkeypatch):
    monkeypatch.setenv("PEANO_BAYES_NOTEBOOK_FAST", "1")
    monkeypatch.setenv("TMPDIR", str(tmp_path))  # the notebook's results folder (tempfile.mkdtemp)
    nb = nbformat.read(NOTEBOOK, as_version=4)
    # One extra cell (in memory only) reports which Python environment the kernel runs in.
    nb.cells.append(nbformat.v4.new_code_cell(f"import sys\nprint('{PREFIX_MARKER}' + sys.prefix)"))
    client = nbclient.NotebookClient(
        nb,
        kernel_name="python3",  # jupyter_client starts it with this interpreter (sys.executable)
        timeout=CELL_TIMEOUT_S,
        resources={"metadata": {"path": str(NOTEBOOK.parent)}},
    )
    client.execute()  # raises CellExecutionError, naming the cell, on any error

    texts = [_text(cell) for cell in nb.cells if cell.cell_type == "code"]
    everything = "\n".join(texts)
    assert "Traceback" not in everything
    assert f"{PREFIX_MARKER}{sys.prefix}" in texts[-1], "the kernel runs another Python environment than pytest"
    assert "fast setting: True" in texts[0]
    # fitted and written for two materials, into the temporary folder
    assert sorted(p.parent.name for p in tmp_path.rglob("posterior.nc")) == ["P", "TP"]
    # the convergence cell never calls short chains converged
    assert "verdict: converged" not in everything
    convergence = next(t for t in texts if "max R-hat" in t and "verdict" in t)
    assert "fast setting" in convergence
    # figures were shown in the notebook
    assert any("image/png" in out.get("data", {}) for cell in nb.cells for out in cell.get("outputs", []))
    # the recommendation cell printed the top design and its one-sentence explanation
    recommendation = next(t for t in texts if "TOP DESIGN:" in t)
    assert "meets every requirement with probability" in recommendation
