"""Forked work: results equal running here, failures reach the caller as themselves."""

import os

import numpy as np
import pytest

from probreg.inference.parallel import default_workers, fork_call, fork_map


def test_fork_call_returns_the_child_result_computed_from_inherited_data(monkeypatch):
    monkeypatch.setenv("PROBREG_WORKERS", "2")
    data = np.arange(10.0)
    result = fork_call(lambda: (os.getpid(), float(data.sum())))
    pid, total = result()
    assert total == 45.0
    assert pid != os.getpid()  # computed in another process


def test_fork_call_failure_is_raised_here_as_itself(monkeypatch):
    monkeypatch.setenv("PROBREG_WORKERS", "2")

    def work():
        raise KeyError("no such thing")

    result = fork_call(work)
    with pytest.raises(KeyError, match="no such thing"):
        result()


def test_one_worker_runs_the_work_here_when_asked(monkeypatch):
    monkeypatch.setenv("PROBREG_WORKERS", "1")
    assert default_workers() == 1
    result = fork_call(lambda: os.getpid())
    assert result() == os.getpid()


def test_fork_map_keeps_the_order_of_the_chunks(monkeypatch):
    chunks = [[1, 2], [3], [], [4, 5, 6]]
    assert fork_map(sum, chunks, workers=2) == [3, 3, 0, 15]
    done = []
    fork_map(sum, chunks, workers=1, done=done.append)
    assert done == chunks


def test_background_work_has_ended_when_its_block_ends_even_by_an_error(tmp_path):
    """``in_background``: the work (here writing a file after a pause) has ended when the block is left,
    whether the block ends normally or raises; the block's own error is the one that propagates."""
    import time

    from probreg.inference.parallel import in_background

    def slow_write(name):
        def work():
            time.sleep(0.3)
            (tmp_path / name).write_text("done")
        return work

    with in_background(slow_write("ok.txt")):
        pass
    assert (tmp_path / "ok.txt").read_text() == "done"
    with pytest.raises(KeyError, match="the block's"):
        with in_background(slow_write("after_error.txt")):
            raise KeyError("the block's")
    assert (tmp_path / "after_error.txt").read_text() == "done"


def test_pool_workers_leave_a_ctrl_c_to_their_parent(monkeypatch):
    """A terminal's Ctrl-C reaches the whole process group: the pool's workers ignore it (the
    parent stops the pool), so they do not each print 'Process ForkPoolWorker-N:'."""
    import signal

    monkeypatch.delenv("PROBREG_WORKERS", raising=False)
    from probreg.inference import parallel

    if not parallel._can_fork():
        pytest.skip("no fork on this platform")
    here = signal.getsignal(signal.SIGINT)
    out = parallel.fork_map(lambda chunk: signal.getsignal(signal.SIGINT) == signal.SIG_IGN, [[0], [1]], workers=2)
    assert out == [True, True] and signal.getsignal(signal.SIGINT) == here  # this process keeps its handler
    # and fork_call's process likewise (interrupted while it sent its result, it printed a traceback)
    assert parallel.fork_call(lambda: signal.getsignal(signal.SIGINT) == signal.SIG_IGN)() is True
