"""The package's layout: stages layered one way (import-linter), small modules, few top-level modules."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "probreg"


def test_import_contracts_hold():
    """`lint-imports` checks the contracts of pyproject.toml: layered stages, no simulator in the
    estimation stages, no cycles inside a stage."""
    pytest.importorskip("importlinter")  # a test extra; installed by `make test`
    out = subprocess.run([sys.executable, "-c", "from importlinter.cli import lint_imports_command; "
                          "lint_imports_command()"], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "0 broken" in out.stdout
    assert "the pipeline's stages are layered KEPT" in out.stdout


def test_a_layer_violation_is_caught(tmp_path):
    """The contract is not vacuous: a lower stage importing a higher one breaks it."""
    pytest.importorskip("importlinter")
    import shutil

    shutil.copytree(PKG, tmp_path / "probreg", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    bad = tmp_path / "probreg" / "geometry" / "camera.py"
    bad.write_text(bad.read_text() + "\nfrom ..inference import ClipModel  # noqa\n")
    out = subprocess.run([sys.executable, "-c", "import sys; sys.path.insert(0, '.'); "
                          "from importlinter.cli import lint_imports_command; lint_imports_command()"],
                         cwd=tmp_path, capture_output=True, text=True)
    assert out.returncode != 0
    assert "probreg.geometry.camera -> probreg.inference" in out.stdout


def test_no_module_is_too_large_to_hold_in_ones_head():
    sizes = {p.relative_to(ROOT).as_posix(): len(p.read_text().splitlines()) for p in PKG.rglob("*.py")}
    assert sizes, "no modules found"
    assert {k: v for k, v in sizes.items() if v > 650} == {}


def test_few_top_level_modules_beside_the_stage_subpackages():
    top = sorted(p.name for p in PKG.glob("*.py"))
    assert len(top) <= 8, top
    stages = {"geometry", "lanes", "calibration", "filtering", "lifting", "inference", "analysis",
              "report", "detect", "io", "sim", "bench"}
    assert stages <= {p.name for p in PKG.iterdir() if (p / "__init__.py").exists()}


def test_every_stage_says_what_it_does_and_exports_its_names():
    import importlib

    for init in PKG.glob("*/__init__.py"):
        mod = importlib.import_module(f"probreg.{init.parent.name}")
        assert mod.__doc__ and len(mod.__doc__.split()) >= 12, init
        assert hasattr(mod, "__all__") and mod.__all__, init
        for name in mod.__all__:
            assert hasattr(mod, name), (init, name)


def test_help_imports_no_heavy_module():
    """`probreg --help` starts fast: no matplotlib, ArviZ, OpenCV, SciPy, Dask or OpenSim behind it."""
    code = ("import sys, contextlib, io\nfrom probreg.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n        main(['--help'])\n    except SystemExit:\n        pass\n"
            "heavy = {'matplotlib', 'arviz', 'cv2', 'scipy', 'dask', 'distributed', 'opensim', 'emcee', 'xarray'}\n"
            "print(sorted(heavy & {m.split('.')[0] for m in sys.modules}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
