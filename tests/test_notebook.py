"""The differentiable-simulation notebook runs top to bottom, and its checks hold: the
sensitivity map equals central finite differences, one MPC decision beats no shedding, and
the fault-reactance gradient equals its central difference."""
import re
from pathlib import Path

import nbformat
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "differentiable_simulation.ipynb"


def test_differentiable_simulation_notebook_runs():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(NOTEBOOK.parents[1])}}).execute()
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code"
                   for o in c.outputs)
    # float32 gradients against differences with h = 1e-3: agreement to 1e-2 relative
    assert float(re.search(r"largest relative difference: (\S+)", text)[1]) < 1e-2
    none, mpc = map(float, re.search(r"no shedding (\S+), MPC plan (\S+)", text).groups())
    assert mpc > none
    grad, central = map(float, re.search(r"dV/dX_fault = (\S+) \(central difference (\S+)\)",
                                         text).groups())
    assert abs(grad - central) <= 0.02 * abs(central)
