"""``python -m probreg`` runs the command line (as the ``probreg`` script does)."""

import os
import sys
import threading

from .cli import main

#: commands whose process ends as soon as their work is done (:func:`entry`): single-process
#: work whose files are all written and closed when :func:`probreg.cli.main` returns
FAST_EXIT_COMMANDS = frozenset({"run", "lift", "calibrate", "synth", "demo", "detect", "sensitivity", "import"})


def _command(argv):
    return next((a for a in argv if not a.startswith("-")), None)


def entry(argv=None):
    """The ``probreg`` script: :func:`probreg.cli.main`, then the process's exit.

    Tearing the interpreter down after a run (freeing every module and array) costs ~0.4 s, a
    twelfth of a typical run; after the commands of :data:`FAST_EXIT_COMMANDS` the process
    flushes its output and ends at once (``os._exit``) when nothing else is still running (no
    other thread but daemons such as tqdm's monitor, no child process).  ``batch`` and ``bench``
    (Dask clusters, subprocesses) always exit normally, and so does every command when
    ``PROBREG_NORMAL_EXIT`` is set.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    code = main(argv)
    if (_command(argv) in FAST_EXIT_COMMANDS and not os.environ.get("PROBREG_NORMAL_EXIT")
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
