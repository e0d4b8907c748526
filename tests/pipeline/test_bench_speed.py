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
