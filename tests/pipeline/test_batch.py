"""`probreg batch` on Dask: manifest, fault isolation, resume after a kill, determinism, a separate scheduler."""

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from probreg.batch import MANIFEST_COLUMNS, read_manifest
from probreg.cli import main
from probreg.io import ClipFormatError

FAST = "20,600,12"  # walkers, max_steps, draws: a short run per clip


def _manifest(path, rows, header="clip,walkers,max_steps,draws"):
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def _summary(out):
    with open(out / "summary.csv", newline="") as fh:
        return list(csv.DictReader(fh))


# ----------------------------------------------------------------------------- the manifest
def test_manifest_paths_are_relative_to_it_and_options_override(tmp_path):
    (tmp_path / "season").mkdir()
    m = tmp_path / "season" / "m.csv"
    m.write_text("clip,stature_m,camera_side,seed,shot,slow_motion\nheat1,1.62,far,,,4\n/abs/heat2.mp4,,,7,1,\n"
                 "heat1,,,,,\n")
    e = read_manifest(m, {"seed": 0})
    assert e[0].clip == (tmp_path / "season" / "heat1").resolve() and e[0].options["stature"] == 1.62
    assert e[0].options["camera_side"] == "far" and e[0].options["seed"] == 0
    assert e[1].options["shot"] == "1" and e[0].options["shot"] == "longest"  # the default
    assert e[0].options["slow_motion"] == 4.0 and e[1].options["slow_motion"] == 1.0  # a replay; real time
    assert e[1].clip == Path("/abs/heat2.mp4") and e[1].name == "heat2" and e[1].options["seed"] == 7
    assert [x.name for x in e] == ["heat1", "heat2", "heat1-2"]  # one result folder per entry
    assert {"stature_m", "camera_side", "model"} <= set(MANIFEST_COLUMNS)


def test_every_entry_gets_its_own_result_folder(tmp_path):
    """Suffixed names never meet a clip of that name, nor differ from another only in case (one
    folder where the file system ignores case); before 0.2.0.dev35 the clips x, x and x-2 all but
    one wrote DIR/x-2 and lost a summary row."""
    m = tmp_path / "m.csv"
    m.write_text("clip,name\na/x,\nb/x,\nx-2,\nHeat,\nheat,\nc/y,x\n")
    names = [e.name for e in read_manifest(m)]
    assert names == ["x", "x-2", "x-2-2", "Heat", "heat-2", "x-3"]
    assert len({n.casefold() for n in names}) == len(names)


@pytest.mark.parametrize("text, needle", [
    ("video\nx\n", "needs a 'clip' column"),
    ("clip,colour\nx,red\n", "unknown column(s) colour"),
    ("clip,walkers\nx,many\n", "line 2, column 'walkers'"),
    ("clip,camera_side\nx,left\n", "not auto, main or far"),
    ("clip,shot\nx,first\n", "column 'shot': 'first' is not longest, all or a number"),
    ("clip,slow_motion\nx,0\n", "column 'slow_motion': '0' is not a positive factor"),
    ("clip,seed\nx,-3\n", "column 'seed': '-3' is not a whole number >= 0"),
    ("clip,min_score\nx,30\n", "column 'min_score': '30' is not a confidence in [0, 1]"),
    ("clip\n\n,\n", "empty 'clip'"),
    ("clip,name\nx,../elsewhere\n", "column 'name': '../elsewhere' is not a folder name inside the output folder"),
    ("clip,name\nx,.\n", "column 'name': '.' is not a folder name"),
    ("clip,name\nx,Summary.csv\n", "column 'name': 'Summary.csv' is not a folder name"),
])
def test_bad_manifests_name_line_and_column(tmp_path, text, needle, capsys):
    m = tmp_path / "m.csv"
    m.write_text(text)
    with pytest.raises(ClipFormatError) as exc:
        read_manifest(m)
    assert needle in str(exc.value)
    assert main(["batch", str(m), "--out", str(tmp_path / "o")]) == 2
    assert needle in capsys.readouterr().err


def test_batch_flags_reach_every_entry(tmp_path, monkeypatch, capsys):
    """Options given on the command line are the entries' defaults, none silently dropped."""
    import probreg.batch as batch

    seen = {}

    def fake_run_batch(manifest, out, base, **kw):
        seen.update(base)
        raise KeyboardInterrupt  # stop before any work

    monkeypatch.setattr(batch, "run_batch", fake_run_batch)
    m = tmp_path / "m.csv"
    m.write_text("clip\nx\n")
    assert main(["batch", str(m), "--out", str(tmp_path / "o"), "--shot", "1", "--height-allowance", "0.01",
                 "--camera-side", "far", "--slow-motion", "3"]) == 130
    assert seen["shot"] == "1" and seen["height_allowance"] == 0.01 and seen["camera_side"] == "far"
    assert seen["slow_motion"] == 3.0
    # a Ctrl-C: the batch says what it keeps (finished clips) and how to go on, not "nothing was written"
    assert "interrupted; the clips that finished are kept; the same command again runs the rest" in \
        capsys.readouterr().err


def test_the_resume_hash_holds_the_software_and_names_what_changed(tmp_path):
    """A result made with other software (an upgraded numpy, OpenCV, probreg, ...) is not skipped on
    a rerun: its numbers could differ (0.2.0.dev38: OpenCV 5 moved a camera height by 1.5 points)."""
    from probreg.batch import _finished, entry_hash
    from probreg.io import software_versions
    from probreg.io.output import MARKER

    m = tmp_path / "m.csv"
    m.write_text("clip\nheat1\n")
    entry = read_manifest(m)[0]
    now = software_versions()
    older = {**now, "numpy": "1.26.4", "opencv": "4.9.0"}
    assert entry_hash(entry) == entry_hash(entry, now)  # read from the installation when not given
    assert entry_hash(entry, older) != entry_hash(entry, now)
    assert entry_hash(entry, {**now, "probreg": "0.0.1"}) != entry_hash(entry, now)
    # a finished result of the older software: rerun, and the versions that changed are named
    target = tmp_path / "out" / "heat1"
    target.mkdir(parents=True)
    (target / MARKER).write_text("{}")
    (target / "run.json").write_text("{}")
    (target / "batch.json").write_text(json.dumps({"hash": entry_hash(entry, older), "software": older}))
    changed = set()
    assert not _finished(entry, tmp_path / "out", entry_hash(entry, now), changed)
    assert changed == {f"numpy 1.26.4 -> {now['numpy']}", f"opencv 4.9.0 -> {now['opencv']}"}
    (target / "batch.json").write_text(json.dumps({"hash": entry_hash(entry, now), "software": now}))
    changed.clear()
    assert _finished(entry, tmp_path / "out", entry_hash(entry, now), changed) and not changed


def test_workers_with_other_software_are_refused_by_name():
    from probreg.batch import BatchSetupError, check_workers_software
    from probreg.io import software_versions

    now = software_versions()

    class FakeClient:  # Client.run: {worker address: the function's result there}
        def __init__(self, found):
            self.found = found

        def run(self, fn):
            assert fn is software_versions
            return self.found

    check_workers_software(FakeClient({"tcp://a:1": dict(now), "tcp://b:2": dict(now)}), now)  # all alike
    with pytest.raises(BatchSetupError) as exc:
        check_workers_software(FakeClient({"tcp://a:1": dict(now), "tcp://b:2": {**now, "scipy": "1.11.0"}}), now)
    assert f"tcp://b:2: scipy {now['scipy']} -> 1.11.0" in str(exc.value) and "tcp://a:1" not in str(exc.value)


def test_a_worker_that_joined_with_other_software_fails_its_clip_by_name(tmp_path):
    """Workers checked at the start cannot cover one that joins later (an adaptive cluster): each
    task compares its worker's versions with the batch's and fails its clip, naming them."""
    from probreg.batch import entry_hash, run_entry
    from probreg.io import software_versions

    (tmp_path / "m.csv").write_text("clip\nheat1\n")
    entry = read_manifest(tmp_path / "m.csv")[0]
    batch_software = {**software_versions(), "emcee": "2.2.1"}
    row = run_entry(entry, tmp_path / "out", entry_hash(entry, batch_software), batch_software)
    assert row["status"] == "failed" and f"emcee 2.2.1 -> {software_versions()['emcee']}" in row["error"]
    assert not (tmp_path / "out").exists()  # nothing written for it


# ----------------------------------------------------------------------------- on a LocalCluster
pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def season(small_clip, tmp_path_factory):
    root = tmp_path_factory.mktemp("season")
    for name in ("heat1", "heat2"):
        shutil.copytree(small_clip, root / name)
    (root / "broken").mkdir()
    (root / "broken" / "clip.json").write_text("{ not json")
    return root


@pytest.mark.slow
def test_batch_isolates_a_broken_clip_resumes_and_equals_single_runs(season, tmp_path, capsys, monkeypatch):
    m = _manifest(season / "m.csv", [f"heat1,{FAST}", "broken,,,", f"heat2,{FAST}"])
    out = tmp_path / "batch"
    assert main(["batch", str(m), "--out", str(out), "--workers", "2", "--quiet"]) == 3  # one failed
    rows = _summary(out)
    assert [r["name"] for r in rows] == ["heat1", "broken", "heat2"]
    assert rows[1]["status"] == "failed" and "clip.json" in rows[1]["error"]
    for r in (rows[0], rows[2]):
        assert r["status"] in ("ok", "flagged") and r["error"] == "" and float(r["knee_band_width_deg"]) > 0
        assert r["verdict"] in ("ok", "unreliable") and float(r["wall_s"]) > 0
        assert r["gait_verdict"] in ("ok", "unreliable")
        assert r["cuts"] == "" and r["frames_estimated"] == "0-40"  # no cut: the whole clip
    # the same clip, the same options: batch equals a single `probreg run` byte for byte
    single = tmp_path / "single"
    main(["run", str(season / "heat1"), "--out", str(single), "--walkers", "20", "--max-steps", "600",
          "--draws", "12", "--quiet"])
    assert (single / "angles.csv").read_bytes() == (out / "heat1" / "angles.csv").read_bytes()
    # a rerun skips what is done and leaves it byte-identical; the broken clip is tried again
    before = {p: p.read_bytes() for p in (out / "heat1").iterdir()}
    mtimes = {p: p.stat().st_mtime_ns for p in before}
    assert main(["batch", str(m), "--out", str(out), "--workers", "1", "--quiet"]) == 3
    assert {p: p.read_bytes() for p in (out / "heat1").iterdir()} == before
    assert {p: p.stat().st_mtime_ns for p in before} == mtimes
    rows2 = _summary(out)
    assert [r["name"] for r in rows2] == ["heat1", "broken", "heat2"]  # no duplicate rows
    assert rows2[0]["skipped"] == "yes" and rows2[1]["status"] == "failed"
    # changed options make a clip run again
    _manifest(m, [f"heat1,{FAST}", "broken,,,", "heat2,20,600,10"])
    assert main(["batch", str(m), "--out", str(out), "--workers", "2", "--quiet"]) == 3
    rows3 = _summary(out)
    assert rows3[0]["skipped"] == "yes" and rows3[2]["skipped"] == "no"
    # a batch whose software differs from its workers' refuses to start and touches nothing
    import probreg.batch as batch

    before = {p: p.read_bytes() for p in (out / "heat1").iterdir()}
    real = batch.software_versions
    monkeypatch.setattr(batch, "software_versions", lambda: {**real(), "numpy": "0.0.0"})
    assert main(["batch", str(m), "--out", str(out), "--workers", "1", "--quiet"]) == 2
    assert "numpy 0.0.0 -> " in capsys.readouterr().err
    assert {p: p.read_bytes() for p in (out / "heat1").iterdir()} == before


@pytest.mark.slow
def test_a_batch_killed_midway_completes_on_rerun(season, tmp_path):
    m = _manifest(season / "m2.csv", [f"heat1,{FAST}", f"heat2,{FAST}"])
    out = tmp_path / "batch"
    cmd = [sys.executable, "-m", "probreg", "batch", str(m), "--out", str(out), "--workers", "1", "--quiet"]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while time.time() - t0 < 300 and not (out / "heat1" / ".probreg").exists() and proc.poll() is None:
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)  # the whole batch, workers included, mid-way
    proc.wait()
    assert (out / "heat1" / ".probreg").exists(), "the first clip did not finish before the kill"
    first = (out / "heat1" / "angles.csv").read_bytes()
    assert main(["batch", str(m), "--out", str(out), "--workers", "1", "--quiet"]) in (0, 3)
    rows = _summary(out)
    assert [r["name"] for r in rows] == ["heat1", "heat2"] and rows[0]["skipped"] == "yes"
    assert all(r["status"] in ("ok", "flagged") for r in rows)
    assert (out / "heat1" / "angles.csv").read_bytes() == first
    assert not list(out.glob(".heat*.tmp-*"))  # no half results left behind


@pytest.mark.slow
def test_batch_on_a_separately_started_scheduler(season, tmp_path):
    if shutil.which("dask", path=str(Path(sys.executable).parent)) is None:
        pytest.skip("the dask command line is not installed")
    dask_cli = str(Path(sys.executable).parent / "dask")
    sched_file = tmp_path / "scheduler.json"
    sched = subprocess.Popen([dask_cli, "scheduler", "--port", "0", "--dashboard-address", ":0",
                              "--scheduler-file", str(sched_file)], stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, start_new_session=True)
    worker = None
    try:
        t0 = time.time()
        while not sched_file.exists() and time.time() - t0 < 60:
            time.sleep(0.2)
        address = json.loads(sched_file.read_text())["address"]
        worker = subprocess.Popen([dask_cli, "worker", address, "--nthreads", "1", "--nworkers", "1"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        m = _manifest(season / "m3.csv", [f"heat2,{FAST}"])
        out = tmp_path / "batch"
        assert main(["batch", str(m), "--out", str(out), "--scheduler", address, "--quiet"]) in (0, 3)
        rows = _summary(out)
        assert len(rows) == 1 and rows[0]["status"] in ("ok", "flagged") and (out / "heat2" / "angles.csv").exists()
    finally:
        for p in (worker, sched):
            if p is not None:
                os.killpg(p.pid, signal.SIGTERM)
                p.wait(timeout=30)
