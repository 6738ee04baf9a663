"""The notebooks run top to bottom (small size: ABSORBER_JAX_QUICK=1)."""

import os
import pathlib

import nbformat
import pytest
from nbclient import NotebookClient

NB_DIR = pathlib.Path(__file__).resolve().parents[2] / "notebooks"
NOTEBOOKS = sorted(NB_DIR.glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_executes(path, tmp_path):
    os.environ["ABSORBER_JAX_QUICK"] = "1"
    nb = nbformat.read(path, as_version=4)
    # every cell runs even after a failing one, so that all errors are reported together
    NotebookClient(nb, timeout=900, kernel_name="python3", allow_errors=True,
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    errors = [f"{o.get('ename')}: {o.get('evalue')}" for c in nb.cells if c.cell_type == "code"
              for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors, errors
    assert any(c.get("outputs") for c in nb.cells if c.cell_type == "code")   # it ran
