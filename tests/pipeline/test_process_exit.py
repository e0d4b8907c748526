"""The ``probreg`` script ends its process at once after single-process commands
(:func:`probreg.__main__.entry`): what it printed and wrote must be whole, its exit code kept."""

import json
import os
import subprocess
import sys

import numpy as np

from probreg.__main__ import FAST_EXIT_COMMANDS, _command


def _probreg(*args, env=None):
    import os

    return subprocess.run([sys.executable, "-m", "probreg", *args], capture_output=True, text=True,
                          env={**os.environ, **(env or {})}, check=False)


def test_commands_with_clusters_or_subprocesses_exit_normally():
    assert _command(["--debug", "run", "clip", "--out", "x"]) == "run"
    assert _command(["--version"]) is None
    assert {"batch", "bench"}.isdisjoint(FAST_EXIT_COMMANDS)


def test_a_fast_exit_keeps_the_output_whole_and_the_exit_code(tmp_path):
    fast = _probreg("synth", "--preset", "run", "--seed", "3", "--frames", "40", "--no-images",
                    "--out", str(tmp_path / "fast"))
    normal = _probreg("synth", "--preset", "run", "--seed", "3", "--frames", "40", "--no-images",
                      "--out", str(tmp_path / "normal"), env={"PROBREG_NORMAL_EXIT": "1"})
    assert fast.returncode == normal.returncode == 0
    # piped (block-buffered) output reaches the reader whole
    assert fast.stdout.strip() and (fast.stdout.replace(str(tmp_path / "fast"), "OUT")
                                    == normal.stdout.replace(str(tmp_path / "normal"), "OUT"))
    for name in ("clip.json", "keypoints2d.json"):
        assert (tmp_path / "fast" / name).read_bytes() == (tmp_path / "normal" / name).read_bytes()
    assert len(json.loads((tmp_path / "fast" / "keypoints2d.json").read_text())["frames"]) == 40
    assert np.array_equal(np.load(tmp_path / "fast" / "groundtruth" / "joints3d.npy"),
                          np.load(tmp_path / "normal" / "groundtruth" / "joints3d.npy"))
    # an error keeps its code and its message
    bad = _probreg("run", str(tmp_path / "missing"), "--out", str(tmp_path / "out"))
    assert bad.returncode == 2 and "clip folder not found" in bad.stderr


def test_the_fast_exit_skips_the_teardown_and_the_normal_one_does_not(tmp_path):
    import os

    code = ("import atexit, sys, threading, time\natexit.register(lambda: print('teardown ran'))\n"
            "daemon = sys.argv[2] == 'True'\n"
            "threading.Thread(target=time.sleep, args=(4,), daemon=daemon).start()\n"
            "from probreg.__main__ import entry\n"
            "entry(['synth', '--preset', 'run', '--frames', '20', '--no-images', '--out', sys.argv[1]])\n")
    # a daemon thread (e.g. tqdm's monitor) does not hold the exit up; a live non-daemon one does
    for env, daemon, ran in (({}, True, False), ({"PROBREG_NORMAL_EXIT": "1"}, True, True), ({}, False, True)):
        out = subprocess.run([sys.executable, "-c", code, str(tmp_path / f"{daemon}{ran}"), str(daemon)],
                             capture_output=True, text=True, env={**os.environ, **env}, check=False)
        assert out.returncode == 0, out.stderr
        assert ("teardown ran" in out.stdout) == ran
        assert "wrote 20 frames" in out.stdout


def test_single_process_commands_write_the_posterior_without_dask(tmp_path):
    """xarray (under ArviZ) imports Dask when it is installed; ``probreg run`` keeps it out of its
    process (:func:`probreg.__main__.keep_dask_out`), and ``posterior.nc`` is written all the same."""
    import arviz as az

    code = ("import sys\nfrom probreg.__main__ import keep_dask_out\nkept = keep_dask_out(sys.argv[1])\n"
            "import arviz as az, numpy as np\n"
            "az.from_dict(posterior={'h': np.arange(10.0).reshape(2, 5)}).to_netcdf(sys.argv[2])\n"
            "print(kept, sys.modules.get('dask', 'absent') is None, 'distributed' in sys.modules)\n")
    for command, kept in (("run", "True True False"), ("batch", "False False")):
        out = subprocess.run([sys.executable, "-c", code, command, str(tmp_path / f"{command}.nc")],
                             capture_output=True, text=True, check=False)
        assert out.returncode == 0, out.stderr
        assert out.stdout.startswith(kept)
        post = az.from_netcdf(tmp_path / f"{command}.nc").posterior
        assert np.array_equal(post["h"].values, np.arange(10.0).reshape(2, 5))


def test_dask_is_kept_out_only_of_a_fresh_single_process_command(monkeypatch):
    import types

    from probreg.__main__ import keep_dask_out

    loaded = types.ModuleType("dask")
    monkeypatch.setitem(sys.modules, "dask", loaded)  # a notebook or a Dask worker has it loaded
    assert keep_dask_out("run") is False and sys.modules["dask"] is loaded
    monkeypatch.delitem(sys.modules, "dask")
    assert keep_dask_out("batch") is False and "dask" not in sys.modules
    assert keep_dask_out("run") is True and sys.modules["dask"] is None
    monkeypatch.delitem(sys.modules, "dask")  # the test process keeps its Dask


def test_single_process_commands_start_blas_with_one_thread():
    """``probreg run`` sets one BLAS thread before NumPy loads (:func:`probreg.__main__.one_blas_thread`):
    ``import probreg`` loads no NumPy, the limit reaches every OpenBLAS NumPy and SciPy load, and a
    user's own setting, ``batch``/``bench``, or a process with NumPy already loaded are left alone."""
    code = ("import os, sys\nimport probreg\nfrom probreg.__main__ import one_blas_thread\n"
            "before = 'numpy' in sys.modules\nset_ = one_blas_thread(sys.argv[1])\n"
            "import numpy, scipy.linalg\nfrom threadpoolctl import threadpool_info\n"
            "n = sorted({d['num_threads'] for d in threadpool_info() if d['internal_api'] == 'openblas'})\n"
            "print(before, set_, os.environ.get('OPENBLAS_NUM_THREADS'), n)\n")
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}

    def run(command, **extra):
        out = subprocess.run([sys.executable, "-c", code, command], capture_output=True, text=True, check=False,
                             env={**env, **extra})
        assert out.returncode == 0, out.stderr
        return out.stdout.strip()

    assert run("run") == "False True 1 [1]"
    assert run("run", OPENBLAS_NUM_THREADS="2") == "False False 2 [2]"  # the user's choice stands
    assert run("bench").startswith("False False None")  # OpenBLAS's own default (one per core)
