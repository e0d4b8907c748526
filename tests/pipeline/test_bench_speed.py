"""The speed benchmark's CPU accounting: the CPU time it reports for a command holds the work of
the processes that command forks (the run's workers), not only its own."""

import sys

from probreg.bench.speed import _wall


def test_cpu_of_a_command_includes_its_forked_workers():
    # the command's own process idles; a forked worker burns at least 0.3 s of CPU (measured by
    # the worker itself, so the bound holds however loaded the machine is)
    burn = ("import multiprocessing as mp, time\n"
            "def work(_):\n"
            "    t = time.process_time()\n"
            "    while time.process_time() - t < 0.3:\n"
            "        pass\n"
            "    return 1\n"
            "if __name__ == '__main__':\n"
            "    with mp.get_context('fork').Pool(1) as pool:\n"
            "        assert pool.map(work, [0]) == [1]\n")
    cpu = []
    _, code = _wall([sys.executable, "-c", burn], cpu=cpu)
    assert code == 0 and len(cpu) == 1
    assert cpu[0] >= 0.3
    # and nothing is counted when no list is given
    assert _wall([sys.executable, "-c", "pass"])[1] == 0


def test_paired_runs_alternate_and_count_each_commands_cpu(tmp_path, monkeypatch):
    import pytest

    from probreg.bench.speed import HERE, _paired, source_tree

    monkeypatch.chdir(HERE)
    log = tmp_path / "order.txt"
    step = "import sys, time\nopen(sys.argv[1], 'a').write(sys.argv[2])\nt = time.process_time()\n" \
           "while time.process_time() - t < float(sys.argv[3]):\n    pass\nsys.exit(int(sys.argv[4]))\n"
    commands = {"a": ([sys.executable, "-c", step, str(log), "a", "0.0", "0"], source_tree(".")),
                "b": ([sys.executable, "-c", step, str(log), "b", "0.3", "3"], source_tree("."))}
    res = _paired(commands, 2)
    assert log.read_text() == "abab"  # baseline first in every pair
    assert res["b"][2] == [3, 3] and res["a"][2] == [0, 0]
    assert min(res["b"][1]) >= 0.3 and all(w > 0 for w in res["a"][0] + res["b"][0])
    with pytest.raises(ValueError, match="no probreg/__init__.py"):
        source_tree(tmp_path)
    (tmp_path / "probreg").mkdir()
    (tmp_path / "probreg" / "__init__.py").write_text("")
    assert source_tree(tmp_path) == tmp_path.resolve()


def test_paired_runs_import_the_trees_they_are_given_wherever_the_bench_runs(tmp_path, monkeypatch):
    """``bench speed --baseline``: each side imports ``probreg`` from its own tree, also when the bench
    is started from inside another checkout (``python -m`` and ``-c`` put the working folder first on
    the path: the baseline ran the working folder's code, and the comparison measured a tree
    against itself)."""
    from probreg.bench.speed import _paired, source_tree

    def tree(name):
        (tmp_path / name / "probreg").mkdir(parents=True)
        (tmp_path / name / "probreg" / "__init__.py").write_text(f"NAME = {name!r}\n")
        return source_tree(tmp_path / name)

    baseline, here, elsewhere = tree("baseline"), tree("here"), tree("elsewhere")
    monkeypatch.chdir(elsewhere)  # the bench started from a third checkout
    log = tmp_path / "imported.txt"
    said = ("import sys, probreg\nopen(sys.argv[1], 'a').write(probreg.NAME + ' ')\n")
    _paired({"baseline": ([sys.executable, "-c", said, str(log)], baseline),
             "this tree": ([sys.executable, "-c", said, str(log)], here)}, 2)
    assert log.read_text().split() == ["baseline", "here", "baseline", "here"]


def test_frames_read_like_the_run_go_through_the_runs_reader(small_clip, monkeypatch):
    """``bench speed`` reports the CPU time of reading the frames the way the lane step does (the
    prefetching reader of ``io.frames``, its decode thread included): every frame is decoded once,
    and the CPU comes back as (user, system)."""
    import cv2
    import numpy as np

    from probreg.bench.speed import _per_frame, _read_like_the_run
    from probreg.io import load_clip

    n = load_clip(small_clip).n_frames
    real, calls = cv2.imread, []

    def counting(path, *args):
        calls.append(str(path))
        return real(path, *args)

    monkeypatch.setattr(cv2, "imread", counting)
    cpu = _read_like_the_run(small_clip)
    # each frame decoded by the run's reader once (loading the clip reads the first one's size too)
    assert len(set(calls)) == n and len(calls) <= n + 1
    assert sorted(set(calls)) == sorted(str(p) for p in load_clip(small_clip).frame_paths)
    assert np.shape(cpu) == (2,) and np.all(np.asarray(cpu) >= 0) and cpu[0] > 0
    assert _per_frame((0.5, 0.25), 100) == "5.0 ms user + 2.5 ms system per frame"
