"""The notebooks run top to bottom without errors (in this interpreter's environment)."""
from __future__ import annotations

import os

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOKS = ["01_quickstart.ipynb", "02_paper_figures.ipynb", "03_bands.ipynb", "04_grasp_planning.ipynb"]


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_runs(name, tmp_path, monkeypatch):
    # README, "Your JAX settings": the kernel's JAX raises on implicit rank promotion and
    # promotes dtypes strictly
    monkeypatch.setenv("JAX_NUMPY_RANK_PROMOTION", "raise")
    monkeypatch.setenv("JAX_NUMPY_DTYPE_PROMOTION", "strict")
    nb = nbformat.read(os.path.join(ROOT, "notebooks", name), as_version=4)
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code"), "commit notebooks without outputs"
    # kernel "python3" is launched with sys.executable (jupyter_client substitutes "python"),
    # so the kernel sees this virtual environment.
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()   # raises CellExecutionError on the first failing cell
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors
    images = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if "image/png" in o.get("data", {})]
    assert len(images) >= 4, "the figures should display"
    if name == "04_grasp_planning.ipynb":      # the map's and the search's progress reach the notebook
        stderr = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
                         if o.get("output_type") == "stream" and o.get("name") == "stderr")
        assert "\rgrasp map: " in stderr and "start 3/3: best " in stderr, stderr[-500:]
