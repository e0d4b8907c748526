"""OpenSim scaling and inverse kinematics with credible bands (``probreg opensim RESULT``).

A probreg result holds the posterior-median 3D joints and a set of posterior draws
(``joints3d.npz``: ``median`` and ``samples``).  This module scales Pose2Sim's COCO-17 OpenSim
model to the median markers (``markers.trc``), then runs OpenSim's inverse kinematics on the median
and on every draw's markers: the IK joint angles of the draws give each OpenSim coordinate a
credible band, which no single-camera tool offers.

Needs the optional ``opensim`` package (``pip install 'probreg[opensim]'``) and Pose2Sim's model and
set-up files, read at run time from an installed Pose2Sim package (``pip install --no-deps
pose2sim``) or from a folder given with ``--pose2sim-setup`` (Pose2Sim's ``OpenSim_Setup``): never
copied into probreg.

Files written (``OUT``, default ``RESULT/opensim``):

``model_scaled.osim``
    Pose2Sim's simple full-body model with the COCO-17 markers, scaled by OpenSim's ``ScaleTool``
    from marker distances (measurement-based scaling, the measurement set of Pose2Sim's
    ``Scaling_Setup_Pose2Sim_Coco17.xml``) averaged over the clip, and the given body mass.
``ik_angles.mot``
    OpenSim IK of the posterior-median markers (OpenSim's own storage file; rotations in degrees).
``ik_bands.csv``
    ``frame,time_s,coordinate,unit,median,lo,hi``: per frame and model coordinate the IK of the
    median markers and its 90 % band: the 5 % / 95 % quantiles of the IK over the posterior draws,
    taken about the draws' own median and placed around the median's IK.
``ik_bands.png``
    Knee and hip IK angles (left and right) over time with their bands (COCO-17 has no foot
    markers: the ankle coordinates are not observed).
``ik.json``
    Settings, the draws used, the Pose2Sim files used and the IK marker error per run.
"""

from __future__ import annotations

import contextlib
import csv
import importlib.util
import os
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .io.clip import ClipFormatError, write_json
from .io.opensim import read_mot, read_trc, write_trc
from .io.output import atomic_output_dir, prepare_output

__all__ = ["find_pose2sim_setup", "opensim_ik", "read_ik_bands", "POSE2SIM_FILES", "OpenSimUnavailable"]

#: The Pose2Sim files used (in its ``OpenSim_Setup`` folder).
POSE2SIM_FILES = {"model": "Model_Pose2Sim_simple.osim", "markers": "Markers_Coco17.xml",
                  "scaling": "Scaling_Setup_Pose2Sim_Coco17.xml", "ik": "IK_Setup_Pose2Sim_Coco17.xml"}


class OpenSimUnavailable(RuntimeError):
    """OpenSim or Pose2Sim's model files are not installed (a user error: say how to install them)."""


def _opensim():
    try:
        import opensim
    except ImportError:
        raise OpenSimUnavailable("the OpenSim Python package is not installed: pip install 'probreg[opensim]' "
                                 "(the 'opensim' wheel of the package registry)") from None
    opensim.Logger.removeFileSink()  # OpenSim would write opensim.log into the working directory
    return opensim


def find_pose2sim_setup(path=None):
    """Pose2Sim's ``OpenSim_Setup`` folder: ``path`` when given, else the installed Pose2Sim's
    (found without importing Pose2Sim, whose import pulls its whole toolchain).

    Raises
    ------
    OpenSimUnavailable
        When neither holds the files of :data:`POSE2SIM_FILES`.
    """
    if path is None:
        spec = importlib.util.find_spec("Pose2Sim")
        if spec is None or not spec.submodule_search_locations:
            raise OpenSimUnavailable("Pose2Sim's OpenSim model files are needed: pip install --no-deps pose2sim "
                                     "(only its files are used), or give --pose2sim-setup DIR (its OpenSim_Setup)")
        path = Path(list(spec.submodule_search_locations)[0]) / "OpenSim_Setup"
    path = Path(path)
    missing = [f for f in POSE2SIM_FILES.values() if not (path / f).is_file()]
    if missing:
        raise OpenSimUnavailable(f"{path}: not Pose2Sim's OpenSim_Setup folder (missing {', '.join(missing)})")
    return path


@contextlib.contextmanager
def _in_dir(path):
    """Run OpenSim's tools inside ``path``: their setup files name every file relative to it (OpenSim
    resolves some paths against the setup file's folder and others against the working directory)."""
    here = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(here)


def _set(root, tag, text):
    for el in root.iter(tag):
        el.text = text


def _time_range(times, markers, min_markers=10):
    """First and last time of the frames with at least ``min_markers`` finite markers."""
    ok = np.isfinite(markers).all(-1).sum(-1) >= min_markers
    if ok.sum() < 2:
        raise ValueError(f"fewer than 2 frames have {min_markers} of the 14 markers: nothing for OpenSim to fit")
    idx = np.flatnonzero(ok)
    return float(times[idx[0]]), float(times[idx[-1]])


def _mirror_fix(osim, markerset, tol_m=0.02):
    """Make the pelvis' hip markers mirror images of each other (in the pelvis frame, ``z`` is
    lateral).  Pose2Sim 0.10.49's ``Markers_Coco17.xml`` places ``RHip`` 0.40 m below the pelvis
    (a knee's location), which makes the right thigh 0.13 m long in the model; when the two hip
    markers are not mirror images, the one farther from its mirrored partner's height is replaced
    by the mirror of the other.  Returns the fixes made (recorded in ``ik.json``)."""
    try:
        left, right = markerset.get("LHip"), markerset.get("RHip")
    except Exception:  # noqa: BLE001 -- OpenSim raises its own exception type for a missing name
        return []
    if left.getParentFrameName() != right.getParentFrameName():
        return []
    lo = np.array(left.get_location().to_numpy())
    ro = np.array(right.get_location().to_numpy())
    mirror = np.array([1.0, 1.0, -1.0])
    if np.linalg.norm(lo * mirror - ro) <= tol_m:
        return []
    # the marker that sits implausibly far from the pelvis origin is the wrong one
    bad, good, good_loc = (right, left, lo) if np.linalg.norm(ro) > np.linalg.norm(lo) else (left, right, ro)
    old = bad.get_location().to_numpy().tolist()
    bad.set_location(osim.Vec3(*(good_loc * mirror)))
    return [f"{bad.getName()} moved from {np.round(old, 4).tolist()} to the mirror of {good.getName()} "
            f"{np.round(good_loc * mirror, 4).tolist()} (pelvis frame)"]


def _scale(osim, setup, trc, work, mass_kg, t_range, fixes):
    """Scaled model (markers of Pose2Sim's COCO-17 set) from the markers of ``trc``."""
    model = osim.Model(str(setup / POSE2SIM_FILES["model"]))
    markers = osim.MarkerSet(str(setup / POSE2SIM_FILES["markers"]))
    fixes.extend(_mirror_fix(osim, markers))
    model.set_MarkerSet(markers)
    model.initSystem()
    generic = work / "model_generic.osim"
    model.printToXML(str(generic))
    tree = ET.parse(setup / POSE2SIM_FILES["scaling"])
    root = tree.getroot()
    _set(root, "mass", f"{mass_kg:g}")
    _set(root, "model_file", generic.name)
    _set(root, "marker_set_file", "Unassigned")
    _set(root, "scaling_order", " measurements")
    _set(root, "marker_file", Path(trc).name)
    _set(root, "time_range", f" {t_range[0]:.6f} {t_range[1]:.6f}")
    scaled = work / "model_scaled.osim"
    _set(root, "output_model_file", scaled.name)
    for placer in root.iter("MarkerPlacer"):
        for ap in placer.findall("apply"):
            ap.text = "false"
    for tag in ("output_motion_file", "output_marker_file", "output_scale_file"):
        _set(root, tag, "Unassigned")
    path = work / "scaling_setup.xml"
    tree.write(path, encoding="utf-8", xml_declaration=True)
    with _in_dir(work):
        osim.ScaleTool(path.name).run()  # (its return value is not a reliable success flag across versions)
    if not scaled.exists():
        raise RuntimeError("OpenSim's ScaleTool failed (see its messages above)")
    return scaled


def _ik(osim, setup, model, trc, out_mot, t_range, work):
    tree = ET.parse(setup / POSE2SIM_FILES["ik"])
    root = tree.getroot()
    _set(root, "model_file", Path(model).name)
    _set(root, "marker_file", Path(trc).name)
    _set(root, "time_range", f"{t_range[0]:.6f} {t_range[1]:.6f}")
    _set(root, "output_motion_file", Path(out_mot).name)
    _set(root, "results_directory", ".")
    _set(root, "report_errors", "false")
    path = work / f"ik_setup_{Path(out_mot).stem}.xml"
    tree.write(path, encoding="utf-8", xml_declaration=True)
    with _in_dir(work):
        osim.InverseKinematicsTool(path.name).run()
    if not Path(out_mot).exists():
        raise RuntimeError(f"OpenSim's inverse kinematics failed on {Path(trc).name}")
    cols, t, data = read_mot(out_mot)
    return cols, t, data


def _rotational(osim, model_path):
    """Names of the model's rotational coordinates (angles, in degrees in IK output)."""
    m = osim.Model(str(model_path))
    cs = m.getCoordinateSet()
    return {cs.get(i).getName() for i in range(cs.getSize()) if cs.get(i).getMotionType() == 1}


def opensim_ik(result_dir, out_dir=None, n_draws=20, setup=None, mass_kg=70.0, overwrite=False, seed=0,
               log=print):
    """Scale the model and run IK on the median and on ``n_draws`` posterior draws of a result.

    Returns the path of the output folder (see the module docstring for its files).
    """
    osim = _opensim()
    setup = find_pose2sim_setup(setup)
    result_dir = Path(result_dir)
    out_dir = Path(out_dir) if out_dir is not None else result_dir / "opensim"
    for need in ("joints3d.npz", "markers.trc"):
        if not (result_dir / need).is_file():
            raise ClipFormatError(f"{result_dir}: no {need} (not a probreg result folder, or one written before "
                                  f"OpenSim export existed: run 'probreg run' again)")
    prepare_output(out_dir, inputs=[], overwrite=overwrite)
    try:
        npz = np.load(result_dir / "joints3d.npz")
        median, samples = npz["median"], (npz["samples"] if "samples" in npz.files else None)
    except (OSError, ValueError, KeyError) as exc:
        raise ClipFormatError(f"{result_dir / 'joints3d.npz'}: cannot read ({exc})") from None
    names, times, markers = read_trc(result_dir / "markers.trc")
    fps = 1.0 / np.median(np.diff(times)) if len(times) > 1 else 50.0
    t_range = _time_range(times, markers)
    rng = np.random.default_rng(seed)
    draws = []
    if samples is not None and n_draws > 0:
        draws = sorted(rng.choice(len(samples), min(n_draws, len(samples)), replace=False).tolist())
    osim.Logger.setLevelString("error")
    osim.ModelVisualizer.addDirToGeometrySearchPaths(str(setup / "Geometry"))
    with tempfile.TemporaryDirectory(prefix="probreg-opensim-") as scratch, \
            atomic_output_dir(out_dir, overwrite=overwrite, inputs=[result_dir / "joints3d.npz"], log=log) as tmp:
        work = Path(scratch)
        trc = work / "median.trc"
        write_trc(trc, median, fps)
        fixes = []
        scaled = _scale(osim, setup, trc, work, mass_kg, t_range, fixes)
        rot = _rotational(osim, scaled)
        cols, t, med = _ik(osim, setup, scaled, trc, work / "ik_median.mot", t_range, work)
        log(f"opensim: scaled model and IK of the median markers ({len(t)} frames)")
        runs = []
        for k, s in enumerate(draws):
            dtrc = work / f"draw_{s:03d}.trc"
            write_trc(dtrc, samples[s], fps)
            dcols, dt, d = _ik(osim, setup, scaled, dtrc, work / f"ik_draw_{s:03d}.mot", t_range, work)
            if dcols != cols or len(dt) != len(t):
                raise RuntimeError(f"the IK of draw {s} has other columns or frames than the median's")
            runs.append(d)
            log(f"opensim: IK of draw {k + 1}/{len(draws)}")
        (tmp / "model_scaled.osim").write_bytes(scaled.read_bytes())
        (tmp / "ik_angles.mot").write_bytes((work / "ik_median.mot").read_bytes())
        stack = np.array(runs) if runs else med[None]
        # the band: the draws' spread about their own median, placed around the median's IK (as
        # probreg.inference.angle_bands does), so it always holds the reported value
        with np.errstate(invalid="ignore"):
            centre = np.nanmedian(stack, 0)
            lo = med - (centre - np.nanpercentile(stack, 5, 0))
            hi = med + (np.nanpercentile(stack, 95, 0) - centre)
        frames = np.rint(t * fps).astype(int)
        with open(tmp / "ik_bands.csv", "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["frame", "time_s", "coordinate", "unit", "median", "lo", "hi"])
            for i in range(len(t)):
                for c, name in enumerate(cols):
                    unit = "deg" if name in rot else "m"
                    w.writerow([int(frames[i]), f"{t[i]:.4f}", name, unit, f"{med[i, c]:.4f}", f"{lo[i, c]:.4f}",
                                f"{hi[i, c]:.4f}"])
        _ik_figure(tmp / "ik_bands.png", t, cols, med, lo, hi)
        write_json(tmp / "ik.json", {"pose2sim_setup": str(setup), "files": POSE2SIM_FILES, "mass_kg": mass_kg,
                                    "draws": draws, "n_draws": len(draws), "time_range_s": list(t_range),
                                    "opensim_version": getattr(osim, "__version__", "unknown"),
                                    "coordinates": cols, "rotational": sorted(rot), "pose2sim_fixes": fixes})
    return out_dir


#: coordinates of the figure: (title, left, right, sign).  COCO-17 has no foot markers, so the
#: ankle coordinates stay at their defaults; the elbow's IK often sits at the model's 150 deg limit
#: (the wrist marker alone does not fix the forearm's pronation), so neither is shown.
_FIGURE = (("knee flexion", "knee_angle_l", "knee_angle_r", 1.0), ("hip flexion", "hip_flexion_l", "hip_flexion_r", 1.0))


def _ik_figure(path, t, cols, med, lo, hi):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 3.4))
    axes = fig.subplots(1, len(_FIGURE))
    for ax, (title, left, right, sign) in zip(axes, _FIGURE):
        for name, col, side in ((left, "tab:blue", "L"), (right, "tab:orange", "R")):
            if name not in cols:
                continue
            c = cols.index(name)
            a, b = sorted((sign * lo[:, c], sign * hi[:, c]), key=lambda v: np.nanmean(v))
            ax.fill_between(t, a, b, color=col, alpha=0.25, lw=0)
            ax.plot(t, sign * med[:, c], color=col, label=f"{side} (IK of the median, 90 % band over draws)")
        ax.set_title(f"OpenSim {title}")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("deg")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def read_ik_bands(path):
    """``ik_bands.csv`` -> {coordinate: (frames, median, lo, hi)}."""
    rows = {}
    with open(path, newline="", encoding="utf-8") as fh:
        r = csv.DictReader(fh)
        for row in r:
            rows.setdefault(row["coordinate"], []).append(
                [float(row["frame"]), float(row["median"]), float(row["lo"]), float(row["hi"])])
    return {k: tuple(np.array(v).T) for k, v in rows.items()}

