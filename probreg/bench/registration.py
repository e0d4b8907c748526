"""Partial sports field registration on the benchmark suite, the seed paper's frames, and its speed.

Metrics (per frame, then mean +- sd over all frames of all clips):

* lane-line error (px): for every detected line, the mean distance of its two
  endpoints from the true projection of the nearest true lane line (the
  paper's "line endpoints" error);
* vanishing-point error: (a) the angle (deg) between the estimated and true
  lane direction in camera coordinates, both back-projected with the true
  intrinsics (defined everywhere, also for a vanishing point at infinity);
  (b) the paper's relative measure ``100 |v_est - v_true| / |v_true - c|`` (%),
  ``c`` the image centre (it diverges for square-on views, where ``v`` is far away);
* with the true camera height selecting the member: FOV error (deg) and
  camera-location error (m, and % of the camera-athlete distance); the
  position along the track is unobservable and not scored.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from ..calibration import CalibrationError, CalibrationFamily, register_clip
from ..geometry import lane_line_y
from ..io.clip import load_clip, load_groundtruth
from ..lanes import detect_lanes, draw_lanes, track_lanes
from ..sim import SUITES, write_suite
from .common import BenchReport, find_shared_data, md_table

__all__ = ["run", "suite_dir", "frame_metrics"]

PAPER = {"lane_line_px": (21.98, 24.42), "vp_pct": (2.58, 1.89), "fov_deg": (3.07, 0.88),
         "loc_m": (0.85, 0.72), "loc_pct": 3.97}


def suite_dir(args, name="bench", images=True, n_frames=None):
    """An existing suite folder (``--suite-dir``) or a freshly generated one (temporary)."""
    given = getattr(args, "suite_dir", None)
    if given:
        given = Path(given)
        if all((given / c).is_dir() for c, _, _ in SUITES[name]):
            return given, None
        write_suite(name, given, images=images, n_frames=n_frames, overwrite=True)
        return given, None
    tmp = tempfile.TemporaryDirectory(prefix="probreg-suite-")
    write_suite(name, tmp.name, images=images, n_frames=n_frames)
    return Path(tmp.name), tmp


#: VP distance from the image centre (focal lengths) beyond which a view counts as square-on
SQUARE_ON_F = 1.0 / np.tan(np.radians(3.0))


def _true_line(cam, index):
    P = cam.projection_matrix
    y = float(lane_line_y(index))
    line = np.cross(P @ [0.0, y, 0.0, 1.0], P @ [1.0, y, 0.0, 1.0])
    return line / np.hypot(line[0], line[1])


def frame_metrics(fl, cam_true, cam_est=None, athlete_xy=None):
    """Registration errors of one frame against its true camera (undistorted geometry)."""
    out = {}
    if not fl.ok:
        return out
    true_lines = [_true_line(cam_true, i) for i in range(9)]
    errs = []
    for ln in fl.lines:
        e = ln.endpoints_px
        d = [np.mean(np.abs(e @ tl[:2] + tl[2])) for tl in true_lines]
        errs.append(min(d))
    out["lane_line_px"] = float(np.mean(errs))
    v = fl.vanishing_point
    r_est = np.linalg.solve(cam_true.K, v)
    r_true = cam_true.R @ [1.0, 0.0, 0.0]
    cosang = abs(r_est @ r_true) / np.linalg.norm(r_est)
    out["vp_deg"] = float(np.degrees(np.arccos(min(1.0, cosang))))
    vt = cam_true.K @ r_true
    c = cam_true.K[:2, 2]
    if abs(vt[2]) > 1e-12 and abs(v[2]) > 1e-12:
        vt2, ve2 = vt[:2] / vt[2], v[:2] / v[2]
        out["vp_pct"] = float(100 * np.linalg.norm(ve2 - vt2) / np.linalg.norm(vt2 - c))
        # where the view is within 3 deg of square-on (VP beyond cot 3 deg = 19 focal lengths
        # from the centre) the relative measure diverges; scored separately below
        if np.linalg.norm(vt2 - c) <= SQUARE_ON_F * cam_true.focal_px:
            out["vp_pct_oblique"] = out["vp_pct"]
    if cam_est is not None:
        out["fov_deg"] = abs(cam_est.fov_deg - cam_true.fov_deg)
        d = cam_est.C - cam_true.C
        loc = float(np.linalg.norm(d[1:]))
        out["loc_m"] = loc
        if athlete_xy is not None:
            dist = float(np.linalg.norm(cam_true.C[:2] - athlete_xy))
            out["loc_pct"] = 100 * loc / dist
        out["spacing_px"] = fl.spacing_residual_px
    return out


def _agg(values):
    v = np.array([x for x in values if np.isfinite(x)])
    if len(v) == 0:
        return float("nan"), float("nan"), float("nan")
    return float(v.mean()), float(v.std()), float(np.median(v))


def _suite_metrics(root, rep):
    rows, allm = [], {}
    for name, preset, seed in SUITES["bench"]:
        path = root / name
        clip = load_clip(path)
        gt = load_groundtruth(path)
        h = float(gt.cameras[0].C[2])
        reg = register_clip(clip)
        dist = gt.cameras[0].dist if np.any(gt.cameras[0].dist) else None
        cams, info = reg.cameras(h, clip.keypoints_px, clip.athlete_lane, dist=dist)
        pel = gt.joints3d_track_m[:, 0, :2]
        per = {}
        for i, (fl, ct, ce) in enumerate(zip(reg.frame_lanes, gt.cameras, cams)):
            m = frame_metrics(fl, ct.with_(dist=np.zeros(5)), ce, pel[i])
            for k, v in m.items():
                per.setdefault(k, []).append(v)
        for k, v in per.items():
            allm.setdefault(k, []).extend(v)
        counts = reg.status_counts()
        offs_ok = np.mean([c is not None and abs(c.C[1] - g.C[1]) < 0.61 for c, g in zip(cams, gt.cameras)])
        rows.append([name, preset, f"{counts.get('ok', 0)}/{len(reg.frame_lanes)}",
                     _agg(per.get("lane_line_px", []))[0], _agg(per.get("vp_deg", []))[0],
                     _agg(per.get("vp_pct", []))[2], _agg(per.get("fov_deg", []))[0],
                     _agg(per.get("loc_pct", []))[0], info["consistency_m"], offs_ok])
    rep.add("## Benchmark suite, per clip (means over frames; VP % is the median)\n")
    rep.add(md_table(["clip", "preset", "frames ok", "lane line px", "VP deg", "VP % (median)", "FOV err deg",
                      "location err %", "lateral spread m", "lane index right"], rows, "{:.3f}"))
    return allm


def _paper_frames(data, rep, overlay_dir):
    frames = sorted((data / "paper_frames").glob("*.jpeg"))
    rows = []
    fams = {}
    overlay_dir.mkdir(parents=True, exist_ok=True)
    for p in frames:
        img = cv2.imread(str(p))
        fl = detect_lanes(img)
        fam_ok = False
        hmax = float("nan")
        if fl.ok:
            try:
                fam = CalibrationFamily.from_frame_lanes(fl)
                _, mm = fam.focal_range()
                fam_ok = bool(np.any(mm["valid"]))
                hmax = float(np.nanmax(np.where(mm["valid"], mm["height_m"], np.nan))) if fam_ok else hmax
                fams[p.name] = fam
            except CalibrationError:
                pass
        out = draw_lanes(img, fl)
        cv2.imwrite(str(overlay_dir / (p.stem + ".jpg")), cv2.resize(out, (640, 360)),
                    [cv2.IMWRITE_JPEG_QUALITY, 80])
        rows.append([p.name, fl.status, len(fl.lines), fam_ok, hmax, fl.spacing_residual_px])
    rep.add("## Seed paper frames (shared/data/paper_frames)\n")
    rep.add("'family' = the frame's lines admit a one-DOF family (valid members exist); the family's "
            "members reach camera heights up to 'max height' (zoomed-in branch).\n")
    rep.add(md_table(["frame", "status", "lines", "family", "max height m", "spacing residual px"], rows))
    n_good = sum(1 for r in rows if r[2] >= 3 and r[3])
    rep.add(f"{n_good}/{len(rows)} frames give >= 3 lines and a family. Overlays (lines with their "
            f"index, vanishing point when in view): `{overlay_dir.as_posix()}/`.\n")
    pairs = {}
    for name in fams:
        pairs.setdefault(name.split(".")[0], []).append(name)
    prow = []
    for seq, names in sorted(pairs.items()):
        if len(names) != 2:
            continue
        for h in (5.0, 7.0, 9.0):
            try:
                ma, mb = (fams[n].member(height_m=h) for n in names)
            except CalibrationError:
                continue
            dy = (ma.y_m - mb.y_m) / 1.22
            shift = np.round(dy)
            prow.append([seq, h, ma.y_m, mb.y_m, int(shift), abs(ma.y_m - mb.y_m - 1.22 * shift),
                         ma.focal_px, mb.focal_px])
    rep.add("### Same static camera, two frames: lateral camera position at a common height\n")
    rep.add("The lateral position is relative to each frame's innermost observed line, so two frames "
            "of one camera agree up to a whole number of lane widths (column 'lane shift'); the "
            "residual is what remains.\n")
    rep.add(md_table(["sequence", "height m", "y frame A m", "y frame B m", "lane shift",
                      "residual m", "f A px", "f B px"], prow))
    return n_good, len(rows)


def _family_member(fl, height_m=10.0):
    """The work timed per frame after the lanes: family and its member at a height."""
    if fl.ok:
        try:
            CalibrationFamily.from_frame_lanes(fl).member(height_m=height_m)
        except CalibrationError:
            pass


def _speed(rep, root):
    """Per-frame time on one core: from scratch (Hough) and inside a clip (line tracking)."""
    cv2.setNumThreads(1)
    rows = []
    medians = {}
    try:
        for name in ("run_a", "tele_a", "wide_a", "distorted_a"):
            clip = load_clip(root / name)
            imgs = [cv2.imread(str(p)) for p in clip.frame_paths[:100]]
            scratch = []
            for img in imgs[:40]:
                t0 = time.perf_counter()
                _family_member(detect_lanes(img))
                scratch.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            for fl in track_lanes(enumerate(imgs)):
                _family_member(fl)
            per_frame_seq = (time.perf_counter() - t0) / len(imgs)
            rows.append([name, 1000 * np.median(scratch), 1000 * per_frame_seq])
            medians.setdefault("scratch", []).extend(scratch)
            medians.setdefault("seq", []).append(per_frame_seq)
    finally:
        cv2.setNumThreads(-1)
    rep.add("## Speed (1080p, one core: lanes + vanishing point + family member at a height)\n")
    rep.add(md_table(["clip", "single frame from scratch, median ms", "per frame inside a clip (tracking), mean ms"],
                     rows, "{:.1f}"))
    scratch_ms = 1000 * float(np.median(medians["scratch"]))
    seq_ms = 1000 * float(np.median(medians["seq"]))
    rep.add(f"Inside a clip (what `probreg calibrate` and `probreg run` do: lines are followed from "
            f"frame to frame, with a full detection every 10 frames) a frame takes **{seq_ms:.1f} ms**; "
            f"a single frame from scratch (Hough transform) **{scratch_ms:.1f} ms**. Target <= 15 ms: "
            f"{'met' if seq_ms <= 15 else 'not met'} inside a clip, "
            f"{'met' if scratch_ms <= 15 else 'not met'} from scratch. Timed with "
            f"`cv2.setNumThreads(1)`; the seed paper's Canny + Hough + mean-shift pipeline takes about "
            f"300 ms per 1280x720 frame.\n")
    return {"scratch_ms": scratch_ms, "sequence_ms": seq_ms}


def run(args=None):
    rep = BenchReport("registration", "Partial sports field registration")
    rep.add(__doc__.split("\n\n", 1)[1])
    root, tmp = suite_dir(args)
    try:
        allm = _suite_metrics(root, rep)
        table = []
        for key, label, unit in (("lane_line_px", "lane-line error", "px"),
                                 ("vp_pct", "vanishing-point error", "%"),
                                 ("vp_pct_oblique", "vanishing-point error, views >= 3 deg from square-on", "%"),
                                 ("vp_deg", "vanishing-point direction error", "deg"),
                                 ("fov_deg", "FOV error (true height)", "deg"),
                                 ("loc_m", "camera location error (true height)", "m"),
                                 ("loc_pct", "camera location error (true height)", "% of distance")):
            mean, sd, med = _agg(allm.get(key, []))
            paper = PAPER.get(key)
            ptxt = "-" if paper is None else (f"{paper[0]} +- {paper[1]}" if isinstance(paper, tuple) else f"{paper}")
            table.append([label, unit, f"{mean:.3f} +- {sd:.3f}", f"{med:.3f}", ptxt])
            rep.numbers[key] = {"mean": mean, "sd": sd, "median": med}
        rep.sections.insert(1, "## Summary (all frames of the 14-clip suite)\n\n" + md_table(
            ["metric", "unit", "probreg mean +- sd", "median", "seed paper"], table) +
            "\nTargets: VP <= 0.5 %, FOV <= 0.3 deg, location <= 1 % of the distance.\n\n"
            f"The paper's relative VP measure divides by the distance of the true VP from the image "
            f"centre, which grows without bound as the camera turns square-on to the straight (the "
            f"following camera passes that point in several clips); there a 0.01 deg direction error "
            f"gives hundreds of per cent.  The second VP row leaves out the "
            f"{len(allm.get('vp_pct', [])) - len(allm.get('vp_pct_oblique', []))} of "
            f"{len(allm.get('vp_pct', []))} frames within 3 deg of square-on; the direction error (deg) "
            f"is defined for every frame.\n")
        data = find_shared_data(getattr(args, "shared", None))
        if data is not None and (data / "paper_frames").is_dir():
            reports = Path(getattr(args, "reports", None) or "reports")
            _paper_frames(data, rep, reports / "registration_overlays")
        else:
            rep.add("shared/data/paper_frames not found: paper-frame check skipped.\n")
        rep.numbers["speed_ms"] = _speed(rep, root)
    finally:
        if tmp is not None:
            tmp.cleanup()
    return rep

