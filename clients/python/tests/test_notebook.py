"""The example notebook (examples/paper_table1.ipynb) runs top to bottom against the test server,
as a reader would run it, and shows what it promises: the paper's rows with the published values
beside ours, and the recommendation."""

from __future__ import annotations

import os
from pathlib import Path

import nbformat
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "paper_table1.ipynb"


def test_the_example_notebook_runs(server, monkeypatch) -> None:
    monkeypatch.setenv("OPTIMIS_URL", server.url)
    monkeypatch.setenv("OPTIMIS_TOKEN", server.token)
    # Short, so that the suite stays quick; the paper's figures need ~10⁴ iterations to settle.
    monkeypatch.setenv("OPTIMIS_ITERATIONS", "1000")
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    # The kernel inherits this process's environment (the variables above).
    NotebookClient(notebook, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOK.parent)}}).execute()

    def text(cell) -> str:
        parts = []
        for output in cell.get("outputs", []):
            parts.append(output.get("text", ""))
            parts.append(output.get("data", {}).get("text/plain", ""))
        return "".join(parts)

    code = [cell for cell in notebook.cells if cell.cell_type == "code"]
    assert "succeeded, 1000 iterations" in text(code[1])
    table = text(code[2])
    # The paper's five rows, each with its published RMS beside ours (Table 1: switch 61%).
    for strategy in ("plane1", "plane2", "plane3", "switch", "optimal"):
        assert strategy in table, table
    assert "61" in table, table
    assert "RMS" in text(code[3]) and "switch:" in text(code[3])
    assert "w1_stderr" in text(code[4])
    assert os.environ["OPTIMIS_ITERATIONS"] == "1000"
