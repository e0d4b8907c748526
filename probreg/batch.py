"""A season of races: ``probreg batch MANIFEST --out DIR`` on Dask distributed.

The manifest is a CSV with a ``clip`` column (a clip folder or a video; relative paths are taken
from the manifest's own folder) and optional columns that override the batch's options for one
clip (:data:`MANIFEST_COLUMNS`; an empty cell keeps the batch's value).  Every clip runs exactly as
``probreg run`` would (same options, same default seed 0: a clip's result does not depend on the
order of the manifest or on the worker that ran it) into ``DIR/<clip name>/``, written atomically.

Fault isolation
    A clip that fails (bad input, an error anywhere in the pipeline) is a ``failed`` row of
    ``DIR/summary.csv`` with its error message; the others go on.  A task whose worker dies is
    retried (``--retries``, default 2) on another worker.
Resumable
    Each result folder holds ``batch.json`` with a hash of the clip's inputs (clip description,
    keypoints, frames or video: names, sizes, modification times; the pose model), the options
    and the software (probreg, Python, numpy, SciPy, OpenCV, emcee, filterpy, ArviZ, onnxruntime:
    :func:`probreg.io.software_versions`).  A rerun skips clips whose result matches and leaves them
    byte for byte as they were; a batch killed at any moment and run again ends complete.  After an
    upgrade of any of those the clips run again (the log says which versions changed): a study's
    results never mix versions unnoticed, and a batch refuses to start on workers whose software
    differs from its own (:class:`BatchSetupError`; a worker that joins later fails its clips,
    naming the versions; ``run.json``'s ``"software"`` names each result's).  ``summary.csv`` is
    rebuilt from the result folders at the end of every run (written to a temporary file and
    renamed), so it never holds duplicate rows.
Where it runs
    By default a ``LocalCluster`` of ``--workers N`` single-threaded worker processes (BLAS pinned
    to one thread; inside a worker the pipeline uses one core, ``PROBREG_WORKERS=1``).  With
    ``--scheduler tcp://HOST:PORT`` the clips go to a running Dask scheduler: ``dask scheduler`` plus
    ``dask worker tcp://HOST:PORT --nthreads 1`` on each machine, or a cluster started by
    dask-jobqueue (SLURM/PBS) or dask-kubernetes; the workers need probreg installed and the clip
    paths and ``DIR`` on a shared file system.

Needs the optional ``dask[distributed]`` (``pip install 'probreg[dask]'``).
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .io import provenance
from .io.clip import ClipFormatError
from .io.output import MARKER, OutputRefused
from .io.provenance import software_versions  # this process's versions (the workers read provenance's)

__all__ = ["MANIFEST_COLUMNS", "SUMMARY_COLUMNS", "BatchEntry", "BatchSetupError", "read_manifest", "run_batch",
           "entry_hash"]


class BatchSetupError(RuntimeError):
    """The batch cannot start: Dask is not installed, or the workers' software differs from the batch's."""

#: optional manifest columns -> the ``probreg run`` option they override (and its type)
MANIFEST_COLUMNS = {
    "stature_m": ("stature", float), "stature_sd": ("stature_sd", float), "height_m": ("height_m", float),
    "height_log_sd": ("height_log_sd", float), "camera_side": ("camera_side", str), "model": ("model", "path"),
    "det_model": ("det_model", "path"), "athlete": ("athlete", str), "fps": ("fps", float),
    "seed": ("seed", int), "walkers": ("walkers", int), "max_steps": ("max_steps", int), "draws": ("draws", int),
    "dist": ("dist", str), "min_score": ("min_score", float), "name": ("name", str),
    "height_allowance": ("height_allowance", float), "shot": ("shot", str), "slow_motion": ("slow_motion", float),
}

#: columns of ``summary.csv``
SUMMARY_COLUMNS = ["clip", "name", "status", "error", "verdict", "verdict_reasons", "knee_l_median_deg",
                   "knee_r_median_deg", "knee_band_width_deg", "camera_height_m", "camera_height_lo_m",
                   "camera_height_hi_m", "wall_s", "skipped", "gait_verdict", "cuts", "frames_estimated"]

def _defaults():
    """The options of a batch entry with their ``probreg run`` defaults (read from the classes
    that own them)."""
    from .inference import SamplerSettings
    from .pipeline import RunOptions

    smp, run = SamplerSettings(), RunOptions()
    return {"stature": None, "stature_sd": None, "height_m": None, "height_log_sd": None,
            "camera_side": run.camera_side, "model": None, "det_model": None, "athlete": None, "fps": None,
            "seed": smp.seed, "walkers": smp.n_walkers, "max_steps": smp.max_steps, "draws": smp.n_draws,
            "dist": None, "min_score": run.min_score, "height_allowance": run.height_allowance, "shot": run.shot,
            "slow_motion": run.slow_motion}


#: options of a batch entry with their ``probreg run`` defaults
DEFAULTS = _defaults()


@dataclass
class BatchEntry:
    """One manifest row: the clip, its result folder's name and its options."""

    row: int
    clip: Path
    name: str
    options: dict


def read_manifest(path, base_options=None):
    """The entries of a manifest CSV, options merged over ``base_options`` (:data:`DEFAULTS`).

    Raises
    ------
    ClipFormatError
        For a missing or malformed manifest, a missing ``clip`` column, an unknown column or a
        value of the wrong type (naming the row and column).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
        reader = csv.DictReader(text.splitlines())
        rows = list(reader)
        header = [h.strip() for h in (reader.fieldnames or []) if h is not None]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ClipFormatError(f"{path}: cannot read the manifest ({exc})") from None
    rows = [{(k or "").strip(): v for k, v in r.items()} for r in rows]
    if "clip" not in header:
        raise ClipFormatError(f"{path}: the manifest needs a 'clip' column (got {', '.join(header) or 'no header'})")
    unknown = [h for h in header if h != "clip" and h not in MANIFEST_COLUMNS]
    if unknown:
        raise ClipFormatError(f"{path}: unknown column(s) {', '.join(unknown)} (known: clip, "
                              f"{', '.join(MANIFEST_COLUMNS)})")
    from .lanes.shots import is_shot_option

    base = {**DEFAULTS, **(base_options or {})}
    entries, used = [], set()
    for k, row in enumerate(rows, start=2):  # line numbers as a spreadsheet shows them
        clip_cell = (row.get("clip") or "").strip()
        if not clip_cell:
            raise ClipFormatError(f"{path}: line {k}: empty 'clip'")
        clip = Path(clip_cell).expanduser()
        if not clip.is_absolute():
            clip = (path.parent / clip).resolve()
        opts = dict(base)
        name = None
        for col, (dest, kind) in MANIFEST_COLUMNS.items():
            cell = (row.get(col) or "").strip()
            if not cell:
                continue
            try:
                value = (float(cell) if kind is float else int(cell) if kind is int else
                         str((path.parent / cell).resolve() if not Path(cell).is_absolute() else cell)
                         if kind == "path" else cell)
            except ValueError:
                raise ClipFormatError(f"{path}: line {k}, column '{col}': {cell!r} is not "
                                      f"{'a number' if kind is float else 'an integer'}") from None
            if dest == "name":
                name = _checked_name(value, path, k)
            elif dest == "camera_side" and value not in ("auto", "main", "far"):
                raise ClipFormatError(f"{path}: line {k}, column 'camera_side': {value!r} is not auto, main or far")
            elif dest == "shot" and not is_shot_option(value):
                raise ClipFormatError(f"{path}: line {k}, column 'shot': {value!r} is not longest, all or a number")
            elif dest == "slow_motion" and not 0 < value < float("inf"):
                raise ClipFormatError(f"{path}: line {k}, column 'slow_motion': {cell!r} is not a positive factor")
            elif dest == "seed" and value < 0:
                raise ClipFormatError(f"{path}: line {k}, column 'seed': {cell!r} is not a whole number >= 0")
            elif dest == "min_score" and not 0 <= value <= 1:
                raise ClipFormatError(f"{path}: line {k}, column 'min_score': {cell!r} is not a confidence in [0, 1]")
            else:
                opts[dest] = value
        name = _free_name(name or (clip.stem if clip.suffix else clip.name) or "clip", used)
        entries.append(BatchEntry(row=k, clip=clip, name=name, options=opts))
    return entries


def _checked_name(value, path, line):
    """A manifest's ``name`` cell as a result folder's name in ``DIR``: one plain folder name (no
    path separator, not ``.``/``..``, not hidden, not ``summary.csv``), else a ClipFormatError."""
    if (value in (".", "..") or value.startswith(".") or "/" in value or "\\" in value or "\0" in value
            or value.casefold() == "summary.csv"):
        raise ClipFormatError(f"{path}: line {line}, column 'name': {value!r} is not a folder name inside the "
                              f"output folder (no '/', '\\\\', leading '.', or 'summary.csv')")
    return value


def _free_name(name, used):
    """``name``, or ``name-2``, ``name-3``, ... when it is taken: every entry gets its own result
    folder, also where the file system ignores case (``Heat1`` and ``heat1``) and where a later
    clip is itself called ``heat1-2``.  ``used`` holds the case-folded names given so far.

    >>> used = set()
    >>> [_free_name(n, used) for n in ("x", "x", "x-2", "X", "y")]
    ['x', 'x-2', 'x-2-2', 'X-3', 'y']
    """
    base, k, candidate = name, 1, name
    while candidate.casefold() in used:
        k += 1
        candidate = f"{base}-{k}"
    used.add(candidate.casefold())
    return candidate


def _fingerprint(path):
    """Name, size and modification time of a file, or of every file below a folder."""
    p = Path(path)
    if p.is_file():
        st = p.stat()
        return [(p.name, st.st_size, st.st_mtime_ns)]
    if p.is_dir():
        out = []
        for q in sorted(p.rglob("*")):
            if q.is_file() and MARKER not in q.parts:
                st = q.stat()
                out.append((q.relative_to(p).as_posix(), st.st_size, st.st_mtime_ns))
        return out
    return [(p.name, None, None)]


def entry_hash(entry: BatchEntry, software=None):
    """Hash of what a clip's result depends on: its inputs, its options and the software that
    computes it (``software``: :func:`probreg.io.software_versions`, read when not given)."""
    h = hashlib.sha256()
    doc = {"software": software or software_versions(), "clip": str(entry.clip), "options": entry.options,
           "inputs": _fingerprint(entry.clip),
           "model": _fingerprint(entry.options["model"]) if entry.options.get("model") else None,
           "det_model": _fingerprint(entry.options["det_model"]) if entry.options.get("det_model") else None}
    h.update(json.dumps(doc, sort_keys=True, default=str).encode())
    return h.hexdigest()


def _run_options(o):
    from .inference import ModelPriors, SamplerSettings
    from .pipeline import RunOptions

    dist = None
    if o.get("dist"):
        vals = [float(v) for v in str(o["dist"]).split(",")]
        if len(vals) != 5:
            raise ValueError(f"dist needs five numbers k1,k2,p1,p2,k3, got {o['dist']!r}")
        dist = tuple(vals)
    priors = ModelPriors.from_options(height=o["height_m"], height_sd=o["height_log_sd"], stature=o["stature"],
                                      stature_sd=o["stature_sd"])
    sampler = SamplerSettings(n_walkers=int(o["walkers"]), max_steps=int(o["max_steps"]), n_draws=int(o["draws"]),
                              seed=int(o["seed"]))
    allowance = float(o["height_allowance"])
    if not (math.isfinite(allowance) and allowance >= 0):
        raise ValueError(f"height_allowance must be a finite number >= 0, got {o['height_allowance']!r}")
    return RunOptions(priors=priors, sampler=sampler, dist=dist, min_score=float(o["min_score"]),
                      camera_side=o["camera_side"], overwrite=False, height_allowance=allowance,
                      shot=str(o["shot"]), slow_motion=float(o["slow_motion"]))


def run_entry(entry: BatchEntry, out_dir, digest, software=None):
    """Run one clip (in a worker): a summary row; never raises for a failing clip.  With
    ``software`` (the batch's :func:`probreg.io.software_versions`), a worker whose own versions
    differ (one that joined the cluster after the batch's check) fails the clip, naming them."""
    from threadpoolctl import threadpool_limits

    os.environ["PROBREG_WORKERS"] = "1"  # the worker is one core: no process pool inside it
    t0 = time.perf_counter()
    target = Path(out_dir) / entry.name
    try:
        here = provenance.software_versions()
        if software is not None and here != software:
            raise BatchSetupError(f"this worker runs other software than the batch (batch -> worker): "
                                  f"{', '.join(software_changes(software, here))}")
        import tempfile

        from .pipeline import run_source

        o = entry.options
        athlete = [float(v) for v in str(o["athlete"]).split(",")] if o.get("athlete") else None
        with tempfile.TemporaryDirectory(prefix="probreg-batch-") as scratch, threadpool_limits(limits=1):
            stamp = Path(scratch) / "batch.json"
            stamp.write_text(json.dumps({"hash": digest, "clip": str(entry.clip), "row": entry.row, "options": o,
                                         "software": here}, indent=1, default=str) + "\n")
            run_source(entry.clip, target, _run_options(o), model=o.get("model"), det_model=o.get("det_model"),
                       athlete=athlete, fps=o.get("fps"), log=lambda *a: None, extra_files={"batch.json": stamp})
        row = _row_from_result(entry, target)
        row["wall_s"] = time.perf_counter() - t0
        _stamp_wall_time(target, row["wall_s"])
        return row
    except Exception as exc:  # noqa: BLE001 -- fault isolation: every failure becomes a row
        return {"clip": str(entry.clip), "name": entry.name, "status": "failed",
                "error": f"{type(exc).__name__}: {exc}".replace("\n", " ")[:500],
                "wall_s": time.perf_counter() - t0, "skipped": "no"}


def _stamp_wall_time(target, wall_s):
    """Record the clip's wall time in its ``batch.json``, for ``summary.csv`` when a rerun skips the
    clip.  (The result folder is complete already; a kill here loses only this number.)"""
    p = Path(target) / "batch.json"
    try:
        doc = json.loads(p.read_text())
        doc["wall_s"] = wall_s
        tmp = p.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(doc, indent=1, default=str) + "\n")
        os.replace(tmp, p)
    except (OSError, ValueError):
        pass


def _row_from_result(entry: BatchEntry, target):
    """A summary row from a finished result folder."""
    from .io.results import read_angles_csv

    run = json.loads((Path(target) / "run.json").read_text())
    verdict = run.get("verdict", "n/a")
    row = {"clip": str(entry.clip), "name": entry.name, "status": "ok" if verdict == "ok" else "flagged",
           "error": "", "verdict": verdict, "verdict_reasons": "; ".join(run.get("verdict_reasons", [])),
           "skipped": "no", "gait_verdict": run.get("gait_verdict", "n/a")}
    shots = run.get("shots") or {}  # camera cuts found and the frames of the shot estimated
    row.update(cuts=" ".join(map(str, shots.get("cuts", []))),
               frames_estimated="-".join(map(str, shots.get("frames_estimated", []))))
    h = run.get("height_m") or {}
    row.update(camera_height_m=h.get("median"), camera_height_lo_m=h.get("lo"), camera_height_hi_m=h.get("hi"))
    try:
        ang = read_angles_csv(Path(target) / "angles.csv")
        with np.errstate(invalid="ignore"):
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                row["knee_l_median_deg"] = float(np.nanmedian(ang["knee_l"][1]))
                row["knee_r_median_deg"] = float(np.nanmedian(ang["knee_r"][1]))
                row["knee_band_width_deg"] = float(np.nanmean(np.r_[ang["knee_l"][3] - ang["knee_l"][2],
                                                                    ang["knee_r"][3] - ang["knee_r"][2]]))
    except (ClipFormatError, KeyError, OSError):
        pass
    try:
        row["wall_s"] = json.loads((Path(target) / "batch.json").read_text()).get("wall_s")
    except (OSError, ValueError):
        pass
    return row


def _finished(entry, out_dir, digest, changed=None, software=None):
    """Whether ``DIR/<name>`` is a complete result of exactly this entry.  A complete result of other
    software than ``software`` (default: this installation's) adds the versions that differ to
    ``changed`` (a set of ``"name old -> new"``)."""
    target = Path(out_dir) / entry.name
    try:
        doc = json.loads((target / "batch.json").read_text())
    except (OSError, ValueError):
        return False
    complete = (target / MARKER).is_file() and (target / "run.json").is_file()
    if complete and doc.get("hash") != digest and changed is not None and isinstance(doc.get("software"), dict):
        changed.update(software_changes(doc["software"], software or software_versions()))
    return doc.get("hash") == digest and complete


def software_changes(old, new):
    """``["numpy 2.4.5 -> 2.4.6", ...]``: the versions that differ between two
    :func:`probreg.io.software_versions` records.

    >>> software_changes({"numpy": "2.4.5", "scipy": "1.17.1"}, {"numpy": "2.4.6", "scipy": "1.17.1"})
    ['numpy 2.4.5 -> 2.4.6']
    """
    return [f"{k} {old.get(k)} -> {new.get(k)}" for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]


def check_workers_software(client, software):
    """Raise :class:`BatchSetupError` when a worker of ``client`` runs other software than
    ``software`` (what the batch's hashes were made with): its results would carry versions the
    resume check never sees."""
    try:
        found = client.run(provenance.software_versions)  # the workers' own, whatever this process reads
    except Exception as exc:  # noqa: BLE001 -- e.g. a worker that cannot import probreg
        raise BatchSetupError(f"cannot read the Dask workers' software versions ({type(exc).__name__}: {exc}); "
                              f"every worker needs probreg installed") from None
    bad = {w: software_changes(software, v) for w, v in found.items() if v != software}
    if bad:
        lines = "; ".join(f"{w}: {', '.join(c)}" for w, c in sorted(bad.items()))
        raise BatchSetupError(f"the Dask workers run other software than this batch (this process -> worker): "
                              f"{lines}. Install the same versions on every worker and here, so that the "
                              f"results of a study do not mix versions")


def _prepare_batch_dir(out_dir):
    """``DIR`` is new, empty, or an earlier batch's folder (its ``.probreg`` marker says so)."""
    d = Path(out_dir)
    if d.exists() and not d.is_dir():
        raise OutputRefused(f"{d}: exists and is not a folder; choose another --out")
    if d.exists() and any(d.iterdir()):
        try:
            doc = json.loads((d / MARKER).read_text())
        except (OSError, ValueError):
            doc = {}
        if doc.get("kind") != "batch":
            raise OutputRefused(f"{d}: folder is not empty and is not a probreg batch folder; choose another --out "
                                f"(a batch only writes into an empty folder or its own)")
    d.mkdir(parents=True, exist_ok=True)
    (d / MARKER).write_text(json.dumps({"written_by": "probreg", "kind": "batch",
                                        "note": "per-clip result folders and summary.csv; other files are "
                                                "never touched"}, indent=1) + "\n")


def _write_summary(out_dir, rows):
    path = Path(out_dir) / "summary.csv"
    tmp = path.with_name(f".summary.csv.tmp-{os.getpid()}")
    with open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=SUMMARY_COLUMNS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if r.get(k) is None else (f"{r[k]:.4g}" if isinstance(r.get(k), float) else r[k]))
                        for k in SUMMARY_COLUMNS})
    os.replace(tmp, path)
    return path


def _dask():
    try:
        import dask  # noqa: F401
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise BatchSetupError("probreg batch runs on Dask distributed, which is not installed: "
                           "pip install 'probreg[dask]'") from None
    return Client, LocalCluster, as_completed


def _close_cluster(client, cluster, quiet=False):
    """Close the client and a local cluster.  ``quiet`` after a Ctrl-C: it reached the local
    workers too, and their nannies' errors while the cluster closes are no news (the finished
    clips are complete, the rest run again); Dask's log level is restored afterwards."""
    import logging

    logger = logging.getLogger("distributed")
    level = logger.level
    if quiet:
        logger.setLevel(logging.CRITICAL)
    try:
        client.close()
        if cluster is not None:
            cluster.close()
    finally:
        logger.setLevel(level)


def run_batch(manifest, out_dir, base_options=None, workers=None, scheduler=None, retries=2, progress=True,
              log=print):
    """Run every clip of ``manifest`` into ``out_dir`` (see the module docstring).

    Returns
    -------
    list of dict
        The summary rows, in manifest order (also written to ``out_dir/summary.csv``).
    """
    entries = read_manifest(manifest, base_options)
    Client, LocalCluster, as_completed = _dask()
    out_dir = Path(out_dir).resolve()
    for e in entries:
        if e.clip == out_dir or out_dir in e.clip.parents or e.clip in out_dir.parents:
            raise ValueError(f"{out_dir}: the batch folder may not be, contain or lie in the input {e.clip}")
    _prepare_batch_dir(out_dir)
    software = software_versions()
    digests = {e.name: entry_hash(e, software) for e in entries}
    rows, todo, changed = {}, [], set()
    for e in entries:
        if _finished(e, out_dir, digests[e.name], changed, software):
            row = _row_from_result(e, out_dir / e.name)
            row["skipped"] = "yes"
            rows[e.name] = row
        else:
            todo.append(e)
    log(f"batch: {len(entries)} clips, {len(entries) - len(todo)} already done, {len(todo)} to run")
    if changed:
        log(f"batch: results of other software run again ({', '.join(sorted(changed))})")
    if todo:
        cluster = None
        if scheduler:
            client = Client(scheduler)
        else:
            n = max(1, int(workers or os.cpu_count() or 1))
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                                   silence_logs=40)
            client = Client(cluster)
        bar, interrupted = None, False
        try:
            check_workers_software(client, software)
            link = getattr(client, "dashboard_link", None)
            if link:
                log(f"batch: Dask dashboard at {link}")
            futures = {client.submit(run_entry, e, str(out_dir), digests[e.name], software, retries=retries,
                                     pure=False, key=f"probreg-{e.name}-{digests[e.name][:10]}"): e for e in todo}
            if progress:
                import sys

                from tqdm import tqdm

                bar = tqdm(total=len(futures), desc="clips", file=sys.stderr, leave=False)
            for fut in as_completed(futures):
                e = futures[fut]
                try:
                    rows[e.name] = fut.result()
                except Exception as exc:  # noqa: BLE001 -- e.g. KilledWorker after the retries
                    rows[e.name] = {"clip": str(e.clip), "name": e.name, "status": "failed",
                                    "error": f"{type(exc).__name__}: {exc}"[:500], "skipped": "no"}
                if bar is not None:
                    bar.update(1)
                # the summary so far, for a look during a long batch (rebuilt at the end)
                _write_summary(out_dir, [rows[x.name] for x in entries if x.name in rows])
            if bar is not None:
                bar.close()
        except KeyboardInterrupt:
            interrupted = True
            if bar is not None:
                bar.close()
            raise
        finally:
            _close_cluster(client, cluster, quiet=interrupted)
    ordered = [rows[e.name] for e in entries]
    _write_summary(out_dir, ordered)
    counts = {s: sum(r["status"] == s for r in ordered) for s in ("ok", "flagged", "failed")}
    log(f"batch: {counts['ok']} ok, {counts['flagged']} flagged, {counts['failed']} failed -> {out_dir / 'summary.csv'}")
    return ordered
