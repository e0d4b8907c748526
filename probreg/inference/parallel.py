"""Work on forked processes: a map over chunks and a single call in the background.

Both fall back to running here when the platform cannot fork, when only one worker is wanted
(``PROBREG_WORKERS=1``, as ``probreg batch`` sets for its single-core workers) or when no process
may be started (a sandbox, a daemonic process); the results are the same either way.  Forked
processes inherit the caller's data, so only arguments and results are pickled, and they run
with one BLAS thread each (they already use every core).
"""

from __future__ import annotations

import contextlib
import os

__all__ = ["default_workers", "fork_map", "fork_call", "in_background", "stop_flag", "warm_imports"]

#: the function forked workers run on their chunk (set only while a pool runs)
_FORKED = None


def default_workers():
    """Processes for the per-frame and per-draw work: ``PROBREG_WORKERS`` when set, else the
    machine's cores, at most 4."""
    env = os.environ.get("PROBREG_WORKERS", "").strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    return min(os.cpu_count() or 1, 4)


def _can_fork():
    import multiprocessing as mp

    return "fork" in mp.get_all_start_methods()


def _ignore_interrupt():
    """A forked process leaves a Ctrl-C to its parent, which stops the pool (the ``with`` block
    terminates it) or ends with it (:func:`fork_call`'s daemonic process): without this every pool
    worker printed its own ``Process ForkPoolWorker-N``, and a :func:`fork_call` process
    interrupted while it sent its result a traceback."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _forked_chunk(indices):
    from threadpoolctl import threadpool_limits

    # the workers already use every core: BLAS threads inside them only compete (4x slower)
    with threadpool_limits(limits=1):
        return _FORKED(indices)


def fork_map(func, chunks, workers=None, done=None):
    """``[func(chunk) for chunk in chunks]``, on ``workers`` forked processes (default: one per
    chunk) when there are several and the platform forks, else here.  ``done(chunk)`` is called
    as each chunk finishes.

    >>> fork_map(sum, [[1, 2], [3], []], workers=1)
    [3, 3, 0]
    """
    import multiprocessing as mp

    global _FORKED
    workers = len(chunks) if workers is None else min(int(workers), len(chunks))
    if workers > 1 and _can_fork():
        _FORKED = func
        try:
            with mp.get_context("fork").Pool(workers, initializer=_ignore_interrupt) as pool:
                out = []
                for chunk, res in zip(chunks, pool.imap(_forked_chunk, chunks)):
                    out.append(res)
                    if done is not None:
                        done(chunk)
                return out
        except OSError:  # no processes allowed here (sandbox, limits)
            pass
        finally:
            _FORKED = None
    out = []
    for c in chunks:
        out.append(func(c))
        if done is not None:
            done(c)
    return out


def fork_call(work):
    """Start ``work()`` in a forked process and return a function that waits for its result.

    Meant for work that can overlap the caller's own (on two cores it then costs no wall
    time).  With one worker, without ``fork`` or where no process may be started, ``work``
    runs when the result is asked for; if the process fails or dies, ``work`` runs again
    here, so its own exceptions reach the caller as they would without a process.  Fork only
    while no other thread of this process is importing or holding locks.

    >>> result = fork_call(lambda: 6 * 7)
    >>> result()
    42
    """
    import multiprocessing as mp

    if default_workers() < 2 or not _can_fork():
        return work
    ctx = mp.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)

    def child():
        from threadpoolctl import threadpool_limits

        _ignore_interrupt()  # a Ctrl-C is the parent's to handle; this process ends with it (a daemon)
        try:
            with threadpool_limits(limits=1):
                out = ("ok", work())
        except BaseException as exc:  # any failure must reach the parent, not hang it
            out = ("failed", f"{type(exc).__name__}: {exc}")
        try:
            send.send(out)
        except Exception as exc:  # noqa: BLE001 -- e.g. an unpicklable result
            send.send(("failed", f"{type(exc).__name__}: {exc}"))
        finally:
            send.close()

    try:
        proc = ctx.Process(target=child, daemon=True)
        proc.start()
    except (OSError, AssertionError):  # no processes allowed here (sandbox; a daemonic process's child)
        send.close()
        receive.close()
        return work
    send.close()

    def result():
        try:
            status, value = receive.recv()
        except EOFError:  # the process died (killed, out of memory)
            status, value = "failed", "process died"
        finally:
            receive.close()
        proc.join()
        return value if status == "ok" else work()

    return result


@contextlib.contextmanager
def in_background(work):
    """``work()`` on a forked process (:func:`fork_call`) while the ``with`` block runs, waited for
    when the block ends, also when it raises: work that writes into a folder the block's failure
    removes (an unfinished result folder) has ended before the folder goes.  A failure of ``work``
    raises after a block that succeeded; after a failing block, the block's error is the one raised.

    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     with in_background(lambda: open(f"{d}/a.txt", "w").write("from the fork")):
    ...         _ = open(f"{d}/b.txt", "w").write("here")
    ...     print(open(f"{d}/a.txt").read())
    from the fork
    """
    result = fork_call(work)
    try:
        yield
    except BaseException:
        with contextlib.suppress(Exception):
            result()
        raise
    result()


def stop_flag():
    """A flag (``set()``, ``is_set()``) that a process forked after it is made sees when the caller
    sets it, e.g. to tell :func:`fork_call` work to finish early; where processes cannot share
    one, a flag of this process (work that runs here sees it).

    >>> import time
    >>> flag = stop_flag()
    >>> def wait_for_it(limit_s=20.0):   # in the forked process: sees the flag set out here
    ...     t0 = time.monotonic()
    ...     while not flag.is_set() and time.monotonic() - t0 < limit_s:
    ...         time.sleep(0.005)
    ...     return flag.is_set()
    >>> result = fork_call(wait_for_it)
    >>> flag.set(); result()
    True
    """
    import multiprocessing as mp
    import threading

    try:
        return mp.get_context("fork").Event() if _can_fork() else threading.Event()
    except OSError:  # no shared semaphores on this system
        return threading.Event()


def warm_imports():
    """Import what the rest of a run needs (scipy.signal, ArviZ, h5netcdf, matplotlib: ~2.5 s) in
    a thread while the lanes are found; join it before any fork (an import lock could hang it)."""
    import threading

    def work():
        import importlib

        for name in ("scipy.signal", "h5netcdf", "arviz", "matplotlib.figure", "matplotlib.backends.backend_agg"):
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001 -- only a head start: the real import reports it
                pass

    thread = threading.Thread(target=work, name="probreg-imports", daemon=True)
    thread.start()
    return thread
