"""Every notebook executes (nbclient, a real kernel) on a small built-in clip and shows its figures."""

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

NOTEBOOKS = sorted((Path(__file__).resolve().parents[2] / "notebooks").glob("*.ipynb"))


def _images(cell):
    return sum("image/png" in o.get("data", {}) for o in cell.get("outputs", []))


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes_and_shows_figures(path, tmp_path, monkeypatch):
    monkeypatch.setenv("PROBREG_NOTEBOOK_FAST", "1")  # the kernel inherits it: small clips, short sampling
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    nb = nbformat.read(str(path), as_version=4)
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()  # raises CellExecutionError on any error
    errors = [o for c in nb.cells for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors
    assert sum(_images(c) for c in nb.cells if c.cell_type == "code") >= 1, "no figure shown"
    if path.stem.startswith("02"):
        # the bands: the cell that reads angles.csv and draws them shows a figure
        bands = [c for c in nb.cells if c.cell_type == "code" and "fill_between" in c.source]
        assert bands and _images(bands[0]) >= 1
        assert (tmp_path / "nb_result" / "gait_cycle.csv").exists()


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_is_valid_nbformat_with_cell_ids(path):
    """Cells without an id are a MissingIDFieldWarning now and a hard error in nbformat's next
    versions; every cell has a unique one and the notebook validates without warnings."""
    import json
    import warnings

    doc = json.loads(path.read_text(encoding="utf-8"))
    ids = [c.get("id") for c in doc["cells"]]
    assert all(ids) and len(set(ids)) == len(ids)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        nbformat.validate(nbformat.reads(path.read_text(encoding="utf-8"), as_version=4))
