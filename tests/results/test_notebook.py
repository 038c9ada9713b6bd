"""Plots show where the user is (issue 29, item 1): a notebook executed headless
(nbclient, a real ipykernel with its default inline backend, no DISPLAY) shows the
result's plot as an image, the user's own figure after it, and the result's HTML display
with units."""

import os

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

CELLS = [
    "import hapstab\n"
    "loop = hapstab.HapticLoop(hapstab.Device(0.3, 0.5), hapstab.SpringDamper(200, 0.5),\n"
    "                          hapstab.mass_spring_damper(0.5, 5, 500), 1e-3, 20)\n"
    "res = hapstab.stability(loop)",
    "res.plot();",                                          # the result's figure
    "import matplotlib.pyplot as plt\n"
    "plt.figure(); plt.plot([0, 1], [1, 0]); plt.title('mine');",   # the user's own, after
    "res",                                                  # its HTML display
    "import matplotlib; print(matplotlib.get_backend())",
]


def _outputs(cell, kind):
    return [o for o in cell.outputs if kind in o.get("data", {})]


def test_notebook_shows_the_plots_and_units(tmp_path):
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in CELLS])
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY",
                                                            "MPLBACKEND")}
    client = nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    old = dict(os.environ)
    os.environ.clear()
    os.environ.update(env)          # the kernel inherits it: no display anywhere
    try:
        client.execute()
    finally:
        os.environ.clear()
        os.environ.update(old)
    cells = nb.cells
    assert _outputs(cells[1], "image/png"), cells[1].outputs      # the result's plot
    assert _outputs(cells[2], "image/png"), cells[2].outputs      # and the user's after it
    html = _outputs(cells[3], "text/html")[0]["data"]["text/html"]
    assert "Hz" in html and " s<" in html and "{re" not in html
    assert "agg" not in cells[4].outputs[0]["text"].lower()     # nobody switched it
