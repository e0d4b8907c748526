"""``python -m probreg`` runs the command line (as the ``probreg`` script does)."""

import os
import sys
import threading

#: commands whose process ends as soon as their work is done (:func:`entry`): single-process
#: work whose files are all written and closed when :func:`probreg.cli.main` returns
FAST_EXIT_COMMANDS = frozenset({"run", "lift", "calibrate", "synth", "demo", "detect", "sensitivity", "import"})


def _command(argv):
    return next((a for a in argv if not a.startswith("-")), None)


def keep_dask_out(command):
    """Keep Dask out of the process of a :data:`FAST_EXIT_COMMANDS` command, unless it is loaded
    already: returns whether it was kept out.

    Where Dask is installed (``probreg[dask]``), xarray, under ArviZ, imports ``dask``,
    ``dask.array`` and ``distributed`` to ask whether arrays are chunked and which scheduler
    writes ``posterior.nc`` (0.5-0.9 s of one core per run; a run's arrays are never chunked).
    A ``None`` in ``sys.modules`` makes ``import dask`` fail at once, so xarray takes Dask as
    absent, as in an installation without it.  Only in the ``probreg`` script's own process,
    which ends with the command (:func:`entry`); ``batch`` and ``bench`` keep Dask.
    """
    if command not in FAST_EXIT_COMMANDS or "dask" in sys.modules:
        return False
    sys.modules["dask"] = None
    return True


def one_blas_thread(command):
    """Start the BLAS libraries (OpenBLAS under NumPy, SciPy and OpenCV) of a
    :data:`FAST_EXIT_COMMANDS` command with one thread each, unless the user chose
    (``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``) or NumPy is loaded already: returns whether it did.

    A run shares its work out over processes (:mod:`probreg.inference.parallel`), one per core,
    on small arrays: BLAS threads only compete with them, and a pool of threads, even idle under
    a runtime limit (:func:`probreg.pipeline.run_clip` sets one too), makes every forked worker
    dearer.  Read when OpenBLAS loads, so set before NumPy is imported; only in the ``probreg``
    script's own process (:func:`entry`), never on ``import probreg``.  On the benchmark suite's
    ``run_a`` (two cores, 4 runs interleaved with the version before, ``bench speed --baseline``)
    this and two smaller changes gave 0.55 s less wall time and 1.3 s less CPU (docs/method.md,
    "One BLAS thread").
    """
    if (command not in FAST_EXIT_COMMANDS or "numpy" in sys.modules
            or any(k in os.environ for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"))):
        return False
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    return True


def entry(argv=None):
    """The ``probreg`` script: :func:`probreg.cli.main`, then the process's exit.

    Tearing the interpreter down after a run (freeing every module and array) costs ~0.4 s, a
    twelfth of a typical run; after the commands of :data:`FAST_EXIT_COMMANDS` the process
    flushes its output and ends at once (``os._exit``) when nothing else is still running (no
    other thread but daemons such as tqdm's monitor, no child process).  ``batch`` and ``bench``
    (Dask clusters, subprocesses) always exit normally, and so does every command when
    ``PROBREG_NORMAL_EXIT`` is set.  Those commands also run without Dask (:func:`keep_dask_out`) and
    with one BLAS thread (:func:`one_blas_thread`).
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    command = _command(argv)
    one_blas_thread(command)
    keep_dask_out(command)
    from .cli import main

    code = main(argv)
    if (command in FAST_EXIT_COMMANDS and not os.environ.get("PROBREG_NORMAL_EXIT")
            and not _running_threads() and not _children()):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code or 0)
    sys.exit(code)


def _running_threads():
    return [t for t in threading.enumerate() if t is not threading.main_thread() and not t.daemon]


def _children():
    if "multiprocessing" not in sys.modules:
        return []
    import multiprocessing

    return multiprocessing.active_children()


if __name__ == "__main__":  # pragma: no cover
    entry()
