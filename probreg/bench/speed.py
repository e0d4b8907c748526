"""Where the time of ``probreg run`` goes, measured the way a user meets it.

A typical clip (the benchmark suite's ``run_a``: 250 frames, 1920x1080 JPEG, 50 fps; generated
when ``--suite-dir`` is not given) runs through the command line, ``probreg run CLIP --out OUT``,
in a fresh process, twice (the best wall time counts; both are listed).  The breakdown:

* start-up: a fresh ``python -m probreg --help`` (interpreter and probreg's imports) and
  ``import probreg.pipeline`` with everything the run imports (numpy, scipy, OpenCV, emcee, ...);
* decode: reading every frame with OpenCV alone, one image after the other, and as the run reads
  them (``probreg.io.frames.iter_frames``: decoded on a thread a few frames ahead), each with its
  CPU time split into user and system time;
* lanes (decode included), precompute (the family grid and the reference height), sampling
  (emcee) and propagation (re-lifting every kept draw), from ``run.json``;
* the rest: writing the result files, ``posterior.nc`` and the report.

The bootstrap's re-noised keypoints are shared by two draws (``--draws-per-noise-copy 2``, the
default): the clip also runs with a copy per draw (``1``, as before), at two seeds each, and the
mean widths of the knee, hip and elbow bands of ``angles.csv`` are compared (the seeds' spread is
the Monte Carlo noise the change must stay within).

The CPU time of the run's processes (user + system, the forked workers included: they are
waited for) is read for each run: on two cores, the wall time cannot fall below half of it.

Then how many posterior draws the bands need: the knee bands of the run's 60 draws recomputed
from subsets of 15, 30 and 45 draws (the draws' own joints from ``joints3d.npz``), with their
mean width and how far their edges move from the 60-draw band.

The machine's own speed drifts (a shared virtual machine ran the same code 1.5x slower one hour
than another), so the bench times a fixed single-core reference workload (pure Python, a matrix
product, decoding the clip's first frame) at its start and at its end: reports of different
hours compare through it.  With ``--baseline DIR`` (a source tree of another revision, e.g. a
``git worktree``) the clip also runs alternately with that tree's ``probreg`` and with this one,
``--repeats`` pairs (default 3): the change measured within the same minutes.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .common import BenchReport, md_table


def _children_cpu():
    """CPU seconds (user + system) of this process's finished, waited-for descendants."""
    u = resource.getrusage(resource.RUSAGE_CHILDREN)
    return u.ru_utime + u.ru_stime


#: this bench's own source tree (the checkout its ``probreg`` comes from)
HERE = Path(__file__).resolve().parents[2]


def _self_cpu():
    """``(user, system)`` CPU seconds of this process so far, all its threads."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime, r.ru_stime


def _per_frame(cpu, n):
    """``"A ms user + B ms system per frame"`` of ``(user, system)`` seconds over ``n`` frames.

    >>> _per_frame((0.5, 0.25), 100)
    '5.0 ms user + 2.5 ms system per frame'
    """
    return f"{1000 * cpu[0] / n:.1f} ms user + {1000 * cpu[1] / n:.1f} ms system per frame"


def _read_like_the_run(clip_dir):
    """``(user, system)`` CPU seconds of reading every frame of a clip folder through
    :func:`probreg.io.frames.iter_frames`, the reader of the run's lane step."""
    from ..io import load_clip
    from ..io.frames import iter_frames

    clip = load_clip(clip_dir)
    cpu0 = _self_cpu()
    for _ in iter_frames(clip):
        pass
    return np.subtract(_self_cpu(), cpu0)


def tree_env(tree, base=None):
    """The environment that makes ``python -m probreg`` (or ``-c``) import ``probreg`` from ``tree``:
    ``tree`` first on ``PYTHONPATH`` and ``PYTHONSAFEPATH`` set, so that Python does not put the
    working folder (which may be another checkout) ahead of it (``-m`` and ``-c`` prepend it).

    >>> env = tree_env("/src/a", {"PYTHONPATH": "/x"})
    >>> env["PYTHONPATH"].split(os.pathsep), env["PYTHONSAFEPATH"]
    (['/src/a', '/x'], '1')
    """
    env = dict(os.environ if base is None else base)
    env["PYTHONPATH"] = os.pathsep.join([str(tree)] + [p for p in [env.get("PYTHONPATH")] if p])
    env["PYTHONSAFEPATH"] = "1"
    return env


def _wall(cmd, cpu=None, tree=HERE):
    """Wall time and exit code of ``cmd`` run with the ``probreg`` of source tree ``tree`` (default
    this bench's own; :func:`tree_env`), from a neutral working folder; its CPU seconds (all its
    processes) go to ``cpu``."""
    c0, t0 = _children_cpu(), time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=tree_env(tree), cwd=tempfile.gettempdir())
    wall = time.perf_counter() - t0
    if cpu is not None:
        cpu.append(_children_cpu() - c0)
    return wall, proc.returncode


def _reference_s(jpeg_path, repeats=3):
    """Best-of-``repeats`` seconds of a fixed single-core workload: a pure-Python loop, 20 products
    of a 300x300 matrix (one BLAS thread) and 20 decodes of the JPEG ``jpeg_path``.

    >>> import cv2, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = cv2.imwrite(f"{d}/f.jpg", np.zeros((64, 64, 3), np.uint8))
    ...     t = _reference_s(f"{d}/f.jpg", repeats=1)
    >>> 0 < t < 60
    True
    """
    import cv2
    from threadpoolctl import threadpool_limits

    data = np.fromfile(str(jpeg_path), np.uint8)
    a = np.random.default_rng(0).random((300, 300))
    best = float("inf")
    with threadpool_limits(limits=1):
        for _ in range(repeats):
            t0 = time.perf_counter()
            sum(i * i for i in range(1_000_000))
            for _ in range(20):
                a @ a
                cv2.imdecode(data, cv2.IMREAD_COLOR)
            best = min(best, time.perf_counter() - t0)
    return best


def source_tree(path):
    """``path`` as a source tree holding the ``probreg`` package (for ``--baseline``).

    Raises
    ------
    ValueError
        When ``path`` has no ``probreg/__init__.py``.
    """
    path = Path(path).resolve()
    if not (path / "probreg" / "__init__.py").is_file():
        raise ValueError(f"--baseline {path}: no probreg/__init__.py there (give a checkout of probreg, "
                         "e.g. 'git worktree add DIR REV')")
    return path


def _paired(commands, pairs):
    """Each of ``commands`` ({label: (argv, source tree)}) run ``pairs`` times, alternating in that order:
    ``{label: (walls, cpus, exit codes)}``."""
    out = {k: ([], [], []) for k in commands}
    for _ in range(int(pairs)):
        for label, (cmd, tree) in commands.items():
            walls, cpus, codes = out[label]
            wall, code = _wall(cmd, cpu=cpus, tree=tree)
            walls.append(wall)
            codes.append(code)
    return out


def _baseline_section(py, clip, tmp, baseline, pairs):
    """The clip run alternately with the ``baseline`` tree and with this one: a table and numbers."""
    commands = {}
    for label, tree in (("baseline", baseline), ("this tree", HERE)):
        out = Path(tmp) / f"paired_{label.replace(' ', '_')}"
        argv = [py, "-m", "probreg", "run", str(clip), "--out", str(out), "--seed", "0", "--quiet", "--overwrite"]
        commands[label] = (argv, tree)
    res = _paired(commands, pairs)
    rows = [[label, ", ".join(f"{w:.2f}" for w in walls), float(np.mean(walls)), float(np.mean(cpus)),
             ", ".join(map(str, sorted(set(codes))))] for label, (walls, cpus, codes) in res.items()]
    diff = [np.subtract(res["this tree"][k], res["baseline"][k]) for k in (0, 1)]  # wall, CPU; pair by pair
    mean_sd = [(float(np.mean(d)), float(np.std(d, ddof=1)) if len(d) > 1 else float("nan")) for d in diff]
    table = md_table(["code", "CLI wall s, in run order", "mean wall s", "mean CPU s", "exit"], rows)
    text = (f"{table}\nThis tree minus the baseline, pair by pair: wall {mean_sd[0][0]:+.2f} s (sd {mean_sd[0][1]:.2f}), "
            f"CPU {mean_sd[1][0]:+.2f} s (sd {mean_sd[1][1]:.2f}) over {len(diff[0])} pairs.\n")
    return text, {"baseline_walls": res["baseline"][0], "baseline_cpus": res["baseline"][1],
                  "paired_walls": res["this tree"][0], "paired_cpus": res["this tree"][1]}


def _typical_clip(args, tmp):
    given = getattr(args, "suite_dir", None)
    if given and (Path(given) / "run_a" / "clip.json").exists():
        return Path(given) / "run_a"
    from ..sim import SUITES, config_from_preset, synthesize, write_clip

    name, preset, seed = next(c for c in SUITES["bench"] if c[0] == "run_a")
    clip = synthesize(config_from_preset(preset, seed), seed=seed, preset=preset)
    return write_clip(clip, Path(tmp) / name, images=True)


def _band_stability(result):
    from ..geometry import joint_angles

    samples = np.load(result / "joints3d.npz")["samples"].astype(float)  # (S, F, 17, 3)
    S = len(samples)
    knee = np.concatenate([joint_angles(samples)["knee_l"], joint_angles(samples)["knee_r"]], axis=1)  # (S, 2F)
    rows = []
    with np.errstate(invalid="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ref_lo, ref_hi = np.nanpercentile(knee, 5, 0), np.nanpercentile(knee, 95, 0)
            rng = np.random.default_rng(0)
            for n in (15, 30, 45, S):
                widths, moves = [], []
                for _ in range(20 if n < S else 1):
                    sub = knee[rng.choice(S, n, replace=False)]
                    lo, hi = np.nanpercentile(sub, 5, 0), np.nanpercentile(sub, 95, 0)
                    widths.append(np.nanmean(hi - lo))
                    moves.append(np.nanmean(np.abs(lo - ref_lo) + np.abs(hi - ref_hi)) / 2)
                rows.append([n, float(np.mean(widths)), float(np.mean(moves))])
    return rows


def _band_widths(result):
    """Mean 90 % band width (deg) of each angle family in ``angles.csv`` (knee, hip, elbow)."""
    import csv

    widths = {}
    with open(result / "angles.csv", newline="") as fh:
        for row in csv.DictReader(fh):
            fam = row["angle"].split("_")[0]
            if fam in ("knee", "hip", "elbow"):
                w = float(row["hi_deg"]) - float(row["lo_deg"])
                if np.isfinite(w):
                    widths.setdefault(fam, []).append(w)
    return {k: float(np.mean(v)) for k, v in widths.items()}


def _sharing_table(py, clip, tmp, shared_out, shared_wall):
    """Runs with a noise copy per draw and shared by two, two seeds each: wall time and widths."""
    runs = [("2 (default)", 0, shared_out, shared_wall)]
    for k, seed in (("2 (default)", 1), ("1", 0), ("1", 1)):
        out = Path(tmp) / f"share{k[0]}_{seed}"
        w, _ = _wall([py, "-m", "probreg", "run", str(clip), "--out", str(out), "--seed", str(seed), "--quiet",
                      "--draws-per-noise-copy", k[0]])
        runs.append((k, seed, out, w))
    rows = []
    for k, seed, out, w in runs:
        b = _band_widths(out)
        t = json.loads((out / "run.json").read_text())["timings_s"]
        rows.append([k, seed, w, t["propagation_s"], b.get("knee"), b.get("hip"), b.get("elbow")])
    return md_table(["draws per noise copy", "seed", "CLI wall s", "propagation s", "knee band deg",
                     "hip band deg", "elbow band deg"], rows)


def run(args=None):
    rep = BenchReport("speed", "Where the time of `probreg run` goes (CLI wall time, decode and start-up included)")
    rep.add(__doc__.split("\n\n", 1)[1])
    import cv2

    baseline = source_tree(args.baseline) if getattr(args, "baseline", None) else None
    with tempfile.TemporaryDirectory(prefix="probreg-bench-speed-") as tmp:
        clip = _typical_clip(args, tmp)
        meta = json.loads((clip / "clip.json").read_text())
        F = int(meta.get("n_frames") or len(list((clip / "frames").glob("*"))))
        py = sys.executable
        first = sorted((clip / "frames").glob("*.jpg"))[0]
        ref_start = _reference_s(first)
        t_help = min(_wall([py, "-m", "probreg", "--help"])[0] for _ in range(3))
        t_imports = min(_wall([py, "-c", "import probreg.pipeline, probreg.report.html, arviz, emcee, cv2, "
                                         "scipy.optimize"])[0] for _ in range(2))
        t0 = time.perf_counter()
        cpu0 = _self_cpu()
        for p in sorted((clip / "frames").glob("*.jpg")):
            cv2.imread(str(p))
        t_decode, cpu_alone = time.perf_counter() - t0, np.subtract(_self_cpu(), cpu0)
        cpu_read = _read_like_the_run(clip)
        walls, cpus, timings = [], [], None
        for k in range(2):
            out = Path(tmp) / f"out{k}"
            w, code = _wall([py, "-m", "probreg", "run", str(clip), "--out", str(out), "--seed", "0", "--quiet"],
                            cpu=cpus)
            walls.append(w)
            t = json.loads((out / "run.json").read_text())["timings_s"]
            if timings is None or w <= min(walls):
                timings, best_out, cpu = t, out, cpus[-1]
        best = min(walls)
        stages = [("start-up (python -m probreg --help)", t_help),
                  ("lanes (decode included)", timings["lanes_s"]), ("precompute", timings["precompute_s"]),
                  ("sampling (emcee)", timings["sampling_s"]), ("propagation", timings["propagation_s"])]
        if "branch_s" in timings:  # it holds the chosen model's precompute (listed above)
            stages.append(("lens inference and the family branch (both branches' evidence)",
                           timings["branch_s"] - timings["precompute_s"]))
        if "noise_copies_wait_s" in timings:
            stages.append(("waiting for the bootstrap's noise copies (made while the sampler runs)",
                           timings["noise_copies_wait_s"]))
        if "decomposition_s" in timings:
            stages.append(("band decomposition", timings["decomposition_s"]))
        in_run = sum(v for n, v in stages if not n.startswith("start-up"))
        stages.append(("other work inside the run (summaries, inference data, verdict)",
                       timings["total_s"] - in_run))
        stages.append(("imports of the run, writing the files, posterior.nc and the report (the rest)",
                       best - timings["total_s"] - t_help))
        rep.add(f"Clip: `{clip.name}`, {F} frames, {meta['image_size'][0]}x{meta['image_size'][1]}, "
                f"{meta['fps']:g} fps. Wall times of the two runs: {', '.join(f'{w:.1f} s' for w in walls)}; "
                f"exit {code}.\n")
        rep.add("## Breakdown of the best run\n")
        rep.add(md_table(["stage", "seconds", "share %"], [[n, v, 100 * v / best] for n, v in stages] +
                         [["**total (CLI wall)**", best, 100.0]]))
        rep.add(f"Also measured: importing everything a run imports {t_imports:.2f} s (a part of the rest); "
                f"decoding the {F} frames alone {t_decode:.2f} s ({1000 * t_decode / F:.1f} ms/frame; CPU "
                f"{_per_frame(cpu_alone, F)}); registration with decode {1000 * timings['lanes_s'] / F:.1f} "
                f"ms/frame.\n")
        rep.add(f"Read the way the run reads them (a decode thread a few frames ahead, the images freed as "
                f"they are used), the frames cost CPU {_per_frame(cpu_read, F)}: a fresh process's decode loop "
                "above pays much of its system time for the first touch of every new 6 MB image, which "
                "the run's reader mostly does not (docs/method.md, \"Speed of the registration\": that and "
                "a luma plus half-size colour decode, tried twice and not kept).\n")
        rep.add(f"CPU time of the best run, all its processes: {cpu:.1f} s, {cpu / best:.2f} cores busy on "
                f"average over its {best:.1f} s wall. On two cores the wall time cannot fall below "
                f"{cpu / 2:.1f} s without less work; {7.5:g} s needs the CPU time at or below {2 * 7.5:g} s.\n")
        rep.numbers.update(wall_s=best, walls=walls, cpu_s=cpu, cpus=cpus,
                           per_frame_lanes_ms=1000 * timings["lanes_s"] / F,
                           decode_ms=1000 * t_decode / F, decode_cpu_ms=(1000 * cpu_alone / F).tolist(),
                           read_cpu_ms=(1000 * np.asarray(cpu_read) / F).tolist(), help_s=t_help, **{k: v for k, v in timings.items()})
        rep.add("## Targets (issue 29)\n")
        rep.add(md_table(["target", "wanted", "measured", "met"], [
            ["typical 250-frame 1080p clip, CLI wall", "<= 7.5 s (moonshot 5 s)", f"{best:.1f} s",
             "yes" if best <= 7.5 else "**no**"],
            ["registration incl. decode", "<= 15 ms/frame", f"{1000 * timings['lanes_s'] / F:.1f} ms/frame",
             "yes" if 1000 * timings["lanes_s"] / F <= 15 else "**no**"],
            ["`probreg --help` imports no matplotlib/arviz", "none", "numpy and probreg.geometry only "
             "(checked by tests/architecture)", "yes"]]))
        rep.add("## Sharing the bootstrap's noise copies: time and band widths\n")
        rep.add(_sharing_table(py, clip, tmp, best_out, best))
        rep.add("## How many draws the bands need\n")
        rep.add("Knee bands (5-95 % of the draws, both knees, every frame) from random subsets of the run's "
                "draws (20 subsets each): mean width, and the mean shift of the band edges from those of all "
                "draws. The bands of `angles.csv` add the calibrated scale to these.\n")
        rep.add(md_table(["draws", "mean band width deg", "mean edge shift vs all draws deg"],
                         _band_stability(best_out)))
        if baseline is not None:
            pairs = getattr(args, "repeats", None) or 3
            rep.add(f"## Against another revision, the same minutes\n\nBaseline: `{baseline}`; {pairs} pairs, "
                    "the baseline first in each.\n")
            text, numbers = _baseline_section(py, clip, tmp, baseline, pairs)
            rep.add(text)
            rep.numbers.update(numbers)
        ref_end = _reference_s(first)
    rep.add("## The machine's speed\n")
    rep.add(f"Reference workload (fixed, one core; the smaller the faster): {ref_start:.3f} s at the start, "
            f"{ref_end:.3f} s at the end of this bench.\n")
    rep.numbers.update(reference_s=[ref_start, ref_end])
    return rep
