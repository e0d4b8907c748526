"""Clip-level partial sports field registration: frames -> lanes -> families -> cameras.

The broadcast camera is static over a clip, so one scalar (camera height by default) selects a family
member in every frame.  This module runs lane detection over a clip, smooths the vanishing point over
time, builds every frame's family, keeps lane-line indices consistent across frames and anchors them
to the athlete's lane.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import numpy as np

from ..geometry import JOINT_INDEX, Camera, distort_normalized
from ..io.clip import Clip
from ..lanes import (
    FrameLanes,
    LaneDetectorConfig,
    merged_lines_note,
    smooth_vanishing_points,
    split_shots,
    line_straightness_px,
    track_lanes,
    undistort_frame_lanes,
)
from .cuts import find_clip_cuts
from .side import camera_side_evidence, forward_px_of
from .family import CalibrationError, CalibrationFamily, SequenceCalibration

__all__ = ["DEFAULT_HEIGHT_M", "ANKLE_HEIGHT_M", "ClipRegistration", "athlete_ground_track", "lane_anchor_shift",
           "register_frames", "register_clip", "undistorted_members", "left_out_notes"]


#: Height used when none is given and no posterior is available: the median of
#: probreg's broadcast-camera height prior (see ``probreg.inference.priors``).
DEFAULT_HEIGHT_M = 12.0

#: Typical ankle-joint-centre height above the ground (0.039 x stature, Winter 2009).
ANKLE_HEIGHT_M = 0.07

def athlete_ground_track(cameras, keypoints_px, ground_height_m=ANKLE_HEIGHT_M):
    """Per-frame ground position (x, y) of the athlete from the ankle nearest the camera cast
    onto the plane of the ankle height; NaN where a frame has no camera or no ankles."""
    out = np.full((len(cameras), 2), np.nan)
    if keypoints_px is None:
        return out
    ank = np.asarray(keypoints_px, float)[:, [JOINT_INDEX["l_ankle"], JOINT_INDEX["r_ankle"]], :2]
    for i, cam in enumerate(cameras):
        if cam is None or i >= len(ank):
            continue
        p = ank[i][np.all(np.isfinite(ank[i]), -1)]
        if len(p):
            g = cam.cast_to_ground(p, height_m=ground_height_m)
            g = g[np.all(np.isfinite(g), -1)]
            if len(g):
                # the ankle nearest the camera: a swinging ankle, cast onto the plane of
                # the ankle height, lands beyond the athlete
                out[i] = g[np.argmin(np.linalg.norm(g - cam.C, axis=1)), :2]
    return out


def lane_anchor_shift(ground_track_m, athlete_lane=None, lane_width_m=1.22):
    """Whole-lane shift of the line indices that puts the athlete in their lane.

    One constant for the clip: the athlete's feet lie in ``athlete_lane`` (1-based), or,
    when it is not given, in the lane holding the median of the ground track.

    Parameters
    ----------
    ground_track_m : ndarray, shape (F, 2)
        The athlete's ground position per frame (NaN where unknown), with the current offsets.

    >>> lane_anchor_shift(np.array([[0.0, -3.05 - 2.44]]), athlete_lane=3)
    -2
    """
    ok = np.all(np.isfinite(ground_track_m), -1)
    if not ok.any():
        return 0
    w = lane_width_m
    y = float(np.median(ground_track_m[ok, 1]))
    lane = athlete_lane if athlete_lane is not None else int(np.floor(-y / w)) + 1
    return int(np.round((y + w * (lane - 0.5)) / w))


#: Camera heights (m) at which :func:`glitch_vote` asks whether a frame is off the zoom path.
GLITCH_HEIGHTS = tuple(np.geomspace(2.0, 60.0, 7))

@dataclass
class ClipRegistration:
    """Lanes and calibration families of every frame of a clip."""

    frame_lanes: list
    sequence: SequenceCalibration
    forward_px: np.ndarray
    image_size: tuple
    lane_width_m: float = 1.22
    #: the clip's camera shots and the one estimated (:func:`probreg.lanes.shots.split_shots`;
    #: None when the registration was not made from the clip's frames)
    shots: object = None

    def branch_copy(self):
        """An independent copy to orient and build a branch's model on (the families, caches and
        camera side are its own); the frames' lanes, frozen and never changed, are shared."""
        return copy.deepcopy(self, {id(self.frame_lanes): self.frame_lanes})

    def status_counts(self):
        out = {}
        for f in self.frame_lanes:
            out[f.status] = out.get(f.status, 0) + 1
        return out

    def cameras(self, height_m, keypoints_px=None, athlete_lane=None, dist=None, branch="narrow",
                undistort_iterations=2):
        """Per-frame cameras (None where a frame has no lanes) of the member at ``height_m``.

        With known distortion the lane support points are undistorted with the
        member's focal length and the family is rebuilt, a few times (the
        undistortion needs ``f``, ``f`` needs the lines).

        Returns
        -------
        cameras : list of Camera or None
        info : dict
            ``line_offset`` (absolute index of observed line 0 after anchoring), ``consistency_m``.
        """
        if keypoints_px is not None and not getattr(self, "_oriented", False):
            self.orient(height_m, keypoints_px, branch)  # camera side by evidence (fps 50 assumed)
        seq = self.sequence
        if dist is not None and np.any(dist):
            fams = list(seq.families)
            for _ in range(undistort_iterations):
                for i, (fl, fam) in enumerate(zip(self.frame_lanes, fams)):
                    if fam is None:
                        continue
                    try:
                        f = fam.member(height_m=height_m).focal_px
                    except CalibrationError:
                        continue
                    ufl = undistort_frame_lanes(fl, dist, f)
                    fams[i] = _family_or_none(ufl, self.forward_px, self.lane_width_m)
            seq = SequenceCalibration(fams, self.image_size, self.lane_width_m)
        seq.branch = branch
        seq.line_offsets = self.track_offsets(seq, height_m)
        extra = 0
        if keypoints_px is not None:
            extra = lane_anchor_shift(athlete_ground_track(seq.cameras_at_height(height_m), keypoints_px),
                                      athlete_lane, self.lane_width_m)
        cams = seq.cameras_at_height(height_m, extra_offset=extra, dist=dist)
        status = [fl.status for fl in self.frame_lanes]
        for i, c in enumerate(cams):
            if c is None and status[i] == "ok":
                status[i] = "no_member"
        for i in _zoom_outliers(cams):
            cams[i] = None
            status[i] = "inconsistent"
        ys = np.array([c.C[1] for c in cams if c is not None])
        info = {"line_offsets": (seq.line_offsets + extra).tolist(), "frame_status": status,
                "consistency_m": float(1.4826 * np.median(np.abs(ys - np.median(ys)))) if len(ys) > 1 else float("nan")}
        return cams, info


    def track_offsets(self, seq, height_m):
        """Per-frame line-index offsets that give every physical line (``track_id``) one
        absolute index over the clip; frames that share no line with the previous ones fall
        back to the camera's lateral position, which also overrides the identities when they
        would make the (static) camera jump sideways by one or two lanes from one frame to the
        next (identities slip).  Larger jumps are not repaired here: at a wrong height the
        lateral position drifts and would be "repaired" into a self-consistent wrong answer.
        Frames whose family is off the zoom path at every height (:meth:`glitch_frames`) do
        not hand identities on, and a second pass outvotes short runs off by whole lanes."""
        members = seq.members_at_height(height_m)
        # frames whose family is off the clip's zoom path at every height have a wrong family
        # (a spurious or misplaced line): they must not hand line identities on; they get the
        # offset of their neighbours
        odd = set(self.glitch_frames()) & {t for t, m in enumerate(members) if m is not None}
        trusted = [None if t in odd else m for t, m in enumerate(members)]
        offsets = self._offsets_pass(seq, trusted)
        for t in sorted(odd):
            # the nearest trusted frame before it, else after it
            ref = next((u for u in range(t - 1, -1, -1) if trusted[u] is not None),
                       next((u for u in range(t + 1, len(members)) if trusted[u] is not None), None))
            if ref is not None:
                y_ref = trusted[ref].y_m - self.lane_width_m * offsets[ref]
                offsets[t] = int(np.round((members[t].y_m - y_ref) / self.lane_width_m))
        return _settle_offsets(offsets, trusted, self.lane_width_m)

    def glitch_frames(self, heights=GLITCH_HEIGHTS, min_share=0.8):
        """Frames whose lane family leaves the clip's smooth zoom path at *every* camera height
        (cached; :func:`glitch_vote` on the families of the detected lines)."""
        if getattr(self, "_glitches", None) is not None:
            return self._glitches
        seq = self.sequence
        self._glitches = glitch_vote(seq.focal_at_height, np.array([f is not None for f in seq.families]), heights,
                                     min_share)
        return self._glitches

    def _offsets_pass(self, seq, members):
        """The sequential pass of :meth:`track_offsets` over the trusted members."""
        offsets = np.zeros(len(members), int)
        known = {}  # track id -> absolute index
        prev_y = None
        for t, (fl, fam, m) in enumerate(zip(self.frame_lanes, seq.families, members)):
            if fam is None or m is None:
                continue
            k = fam.oriented_indices(m)
            ids = [ln.track_id for ln in fl.lines]
            common = [(kk, known[i]) for kk, i in zip(k, ids) if i is not None and i in known]
            if common:
                off = int(np.median([a - kk for kk, a in common]))
                if prev_y is not None:
                    # the camera is static: its lateral position cannot jump by a lane between
                    # frames, so such a jump means the followed line identities slipped
                    geo = int(np.round((m.y_m - prev_y) / self.lane_width_m))
                    if 1 <= abs(geo - off) <= 2 and abs(m.y_m - self.lane_width_m * geo - prev_y) < 0.3 * self.lane_width_m:
                        off = geo
            elif prev_y is not None:
                off = int(np.round((m.y_m - prev_y) / self.lane_width_m))
            else:
                off = 0
            offsets[t] = off
            for kk, i in zip(k, ids):
                if i is not None:
                    known[i] = kk + off
            y = m.y_m - self.lane_width_m * off
            # the reference follows the (slowly drifting, at a wrong height) lateral position;
            # a frame whose family is off by more than a third of a lane does not move it
            if prev_y is None or abs(y - prev_y) < 0.3 * self.lane_width_m:
                prev_y = y
        return offsets

    def orient(self, height_m, keypoints_px, branch="narrow", fps=50.0, given="auto"):
        """Fix the camera side (the running direction): lane lines cannot tell +x from -x,
        the athlete can (:func:`probreg.calibration.side.camera_side_evidence`, with the
        cameras of the "main" hypothesis at ``height_m``).  Returns the :class:`CameraSide`."""
        if not np.array_equal(self.forward_px, forward_px_of("main")):
            self.set_camera_side("main")
        seq = self.sequence
        seq.branch = branch
        # line offsets only shift cameras and cast points across the track together: the
        # along-track motion the side is read from does not depend on them
        ground = athlete_ground_track(seq.cameras_at_height(height_m), keypoints_px)
        side = camera_side_evidence(ground, keypoints_px, fps, given=given)
        self.set_camera_side(side.chosen)
        self.camera_side = side
        return side

    def set_camera_side(self, side):
        """Rebuild the families for a camera side (``"main"``: track +x to the image right)."""
        fwd = forward_px_of(side)
        if not np.array_equal(fwd, self.forward_px):
            self.forward_px = fwd
            fams = [_family_or_none(fl, self.forward_px, self.lane_width_m) for fl in self.frame_lanes]
            self.sequence = SequenceCalibration(fams, self.image_size, self.lane_width_m)
            self._glitches = None
        self._oriented = True
        return self


def _settle_offsets(offsets, members, lane_width_m, half_window=12):
    """Second pass over the line-index offsets: the static camera's lateral position (member's
    ``y`` minus the offset's lanes) is compared with its running median over the neighbouring
    frames, and a frame off by whole lanes is moved back.  A short run of frames that took
    wrong indices from one bad frame (whose geometry happened to fit a whole-lane jump) is
    outvoted by the frames around it."""
    offsets = offsets.copy()
    idx = [t for t, m in enumerate(members) if m is not None]
    if len(idx) < 3:
        return offsets
    y = np.array([members[t].y_m - lane_width_m * offsets[t] for t in idx])
    for n, t in enumerate(idx):
        lo, hi = max(0, n - half_window), min(len(idx), n + half_window + 1)
        shift = int(np.round((y[n] - np.median(y[lo:hi])) / lane_width_m))
        if shift:
            offsets[t] += shift
    return offsets


def glitch_vote(focal_at, present, heights=GLITCH_HEIGHTS, min_share=0.8):
    """Frames whose family leaves the clip's smooth zoom path at *every* camera height.

    At a wrong height the focal length of a correct family also wanders, so a frame
    singled out at one height only says little; a spurious or misplaced line makes its
    frame an outlier whichever height is true.  Heights at which fewer than
    ``min_share`` of the frames with a family have a member do not vote; at the others
    a frame with a family but without a member counts as off the path.

    Parameters
    ----------
    focal_at : callable
        ``focal_at(h)`` -> (F,) focal length of each frame's member at height ``h``
        (NaN: no member).
    present : ndarray of bool (F,)
        Frames with a family.
    """
    present = np.asarray(present, bool)
    n_fam = int(present.sum())
    common, votes = None, 0
    for h in heights:
        f = np.asarray(focal_at(float(h)), float)
        has = np.isfinite(f)
        if has.sum() >= max(min_share * n_fam, 5):
            # a frame with lanes but no member at a height most frames reach is as odd as
            # one off the zoom path there (its family does not fit the clip's camera)
            odd = set(_zoom_outliers(f)) | {int(t) for t in np.flatnonzero(present & ~has)}
            common = odd if common is None else common & odd
            votes += 1
            if votes >= 2 and not common:  # an intersection only shrinks
                break
    return sorted(common) if votes >= 2 else []


def _zoom_outliers(cameras, half_window=12, rel_tol=0.02, n_sigma=6.0):
    """Frames whose focal length leaves the clip's smooth zoom path.

    The path is the running median of the log focal lengths over the
    ``2 half_window + 1`` neighbouring frames with a member, which follows a
    steady zoom as long as the window is symmetric.  Within ``half_window`` of
    the clip's ends the window is one-sided and its median lags a zooming
    camera -- or the fast focal drift of a height near the family's turning
    point -- so there the path is a robust local line (Theil-Sen slope, median
    offset) through the same frames.

    ``cameras``: Camera or family members (anything with ``focal_px``) or None per frame,
    or an array of focal lengths (NaN: none).

    >>> class C: pass
    >>> cams = []
    >>> for i in range(40):  # a steady 1 % zoom per frame, one glitch
    ...     c = C(); c.focal_px = 2000 * 1.01 ** i * (1.1 if i == 30 else 1.0); cams.append(c)
    >>> _zoom_outliers(cams)
    [30]
    """
    if isinstance(cameras, np.ndarray) and cameras.dtype.kind == "f":
        with np.errstate(invalid="ignore", divide="ignore"):
            f = np.log(cameras)
    else:
        f = np.array([np.log(c.focal_px) if c is not None else np.nan for c in cameras])
    ok = np.flatnonzero(np.isfinite(f))
    if len(ok) < 5:
        return []
    t, y = ok.astype(float), f[ok]
    path = np.empty(len(ok))
    for j in range(len(ok)):
        w = slice(max(0, j - half_window), j + half_window + 1)
        tw, yw = t[w], y[w]
        if j - half_window >= 0 and j + half_window < len(ok):
            path[j] = np.median(yw)
            continue
        a, b = np.triu_indices(len(tw), 1)
        slope = np.median((yw[b] - yw[a]) / (tw[b] - tw[a]))
        path[j] = np.median(yw - slope * (tw - t[j]))
    res = y - path
    sigma = 1.4826 * np.median(np.abs(res))
    bad = np.abs(res) > max(n_sigma * sigma, np.log1p(rel_tol))
    return [int(i) for i in ok[bad]]


def _family_or_none(fl: FrameLanes, forward_px, lane_width_m):
    if not fl.ok:
        return None
    try:
        return CalibrationFamily.from_frame_lanes(fl, forward_px=forward_px, lane_width_m=lane_width_m)
    except CalibrationError:
        return None


def undistorted_members(frame_lanes: FrameLanes, family, focal_px, dist, forward_px=(1.0, 0.0),
                        lane_width_m=1.22, anchor_ratio=1.5, height_window=None, branch=None,
                        min_shift_px=0.02):
    """Family members at ``focal_px`` for lines seen through a distorting lens.

    OpenCV's distortion acts on normalised coordinates, so undistorting the
    lines needs the focal length -- which is exactly what varies along the
    family.  The lines are undistorted at anchor focal lengths ``anchor_ratio``
    apart, a family is built for each, and each requested member blends the two
    anchor families whose focal lengths bracket its own (linear in log f;
    rotations re-orthonormalised).  Every member is thus, to second order,
    built from lines undistorted with its own focal length: on a 30 deg FOV
    frame with ``k1 = -0.25`` the blended heights are within 0.1 % of the
    exact ones at anchors 1.5x apart (the distortion itself moves them 1.1 %).

    Parameters
    ----------
    frame_lanes : FrameLanes
        The frame's (distorted) lanes.
    family : CalibrationFamily
        The family of the distorted lines (used to find the relevant members).
    focal_px : array_like (n,)
    dist : array_like (5,)
        ``[k1, k2, p1, p2, k3]``.
    height_window : (float, float) or None
        Only members whose distorted-family height lies in this range are
        computed (the others are returned invalid); saves anchors.
    branch : {"narrow", "wide", None}
        Only members of this branch (longer / shorter focal lengths than the
        family's highest member, with one anchor step of margin) are computed.
    min_shift_px : float
        Where the lens moves no support point by more than this (long focal
        lengths: the shift falls as ``1 / f**2``), the members of the distorted
        lines are returned as they are; no anchors are spent there.

    Returns
    -------
    dict of arrays as :meth:`CalibrationFamily.members` (``valid``, ``height_m``, ``y_m``,
    ``R``, ``index_flipped``).
    """
    fgrid = np.atleast_1d(np.asarray(focal_px, float))
    m0 = family.members(fgrid)
    n = len(fgrid)
    out = {"valid": np.zeros(n, bool), "height_m": np.full(n, np.nan), "y_m": np.full(n, np.nan),
           "R": np.full((n, 3, 3), np.nan), "index_flipped": np.zeros(n, bool)}
    need = m0["valid"] & np.isfinite(m0["height_m"])
    if height_window is not None:
        with np.errstate(invalid="ignore"):
            need &= (m0["height_m"] >= height_window[0]) & (m0["height_m"] <= height_window[1])
    lf = np.log(fgrid)
    step = np.log(max(float(anchor_ratio), 1.01))
    if branch is not None and need.any():
        top = lf[int(np.nanargmax(np.where(m0["valid"], m0["height_m"], np.nan)))]
        need &= (lf >= top - step) if branch == "narrow" else (lf <= top + step)
    # members the lens leaves as they are: no support point moves by min_shift_px
    r = max(float(np.max(np.linalg.norm(ln.points_px - family.principal_point, axis=1)))
            for ln in frame_lanes.lines)
    dirs = r * np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [0.7071, 0.7071], [-0.7071, 0.7071]])
    xn = (dirs[None] / fgrid[:, None, None]).reshape(-1, 2)
    moved = (distort_normalized(xn, dist) - xn).reshape(len(fgrid), len(dirs), 2) * fgrid[:, None, None]
    shift = np.linalg.norm(moved, axis=-1).max(-1)
    plain = need & (shift < min_shift_px)
    for key in out:
        out[key][plain] = m0[key][plain]
    need &= ~plain
    if not need.any():
        return out
    lo, hi = lf[need].min() - step, lf[need].max() + step
    anchors = np.linspace(lo, hi, max(int(np.ceil((hi - lo) / step)) + 1, 2))
    undone = [undistort_frame_lanes(frame_lanes, dist, float(np.exp(a)), spacing=False) for a in anchors]
    fams = [_family_or_none(u, forward_px, lane_width_m) for u in undone]
    k = np.clip(np.searchsorted(anchors, lf) - 1, 0, len(anchors) - 2)
    # the plumb line: a known lens straightens the lines only near the true focal length;
    # members whose lines it leaves bent are not cameras of this lens
    bent = _bent_members(np.array([line_straightness_px(u) for u in undone]), anchors, lf)
    # each anchor family's members on the two intervals it borders, computed once
    at_anchor = {}
    for j, fam_j in enumerate(fams):
        idx = np.flatnonzero(need & ((k == j) | (k == j - 1)))
        if fam_j is not None and len(idx):
            at_anchor[j] = (idx, fam_j.members(fgrid[idx]))

    def take(j, sel):
        idx, m = at_anchor[j]
        pos = np.searchsorted(idx, sel)
        return {key: m[key][pos] for key in ("valid", "height_m", "y_m", "R", "index_flipped")}

    for j in range(len(anchors) - 1):
        sel = np.flatnonzero((k == j) & need)
        if not len(sel) or j not in at_anchor or j + 1 not in at_anchor:
            continue
        ma, mb = take(j, sel), take(j + 1, sel)
        w = np.clip((lf[sel] - anchors[j]) / (anchors[j + 1] - anchors[j]), 0.0, 1.0)
        out["valid"][sel] = ma["valid"] & mb["valid"]
        for key in ("height_m", "y_m"):
            out[key][sel] = (1 - w) * ma[key] + w * mb[key]
        Rm = (1 - w)[:, None, None] * ma["R"] + w[:, None, None] * mb["R"]
        fin = np.all(np.isfinite(Rm), axis=(1, 2))
        if fin.any():
            u, _, vt = np.linalg.svd(Rm[fin])
            Rm[fin] = u @ vt
        out["R"][sel] = Rm
        out["index_flipped"][sel] = np.where(w < 0.5, ma["index_flipped"], mb["index_flipped"])
    out["valid"] &= ~bent
    return out


def _bent_members(straightness_px, anchors, log_f, slack_px=0.5):
    """Members (at ``log_f``) whose lines, undistorted with their own focal length, stay bent.

    ``straightness_px``: :func:`probreg.lanes.undistort.line_straightness_px` of the lines
    undistorted at the ``anchors`` (log focal lengths), interpolated linearly between them.
    Bent means more than twice the straightest anchor's value plus ``slack_px`` (the anchors
    are spaced too far apart to land on the straightest focal length).  NaN scores bend nothing.

    >>> a = np.log([1000.0, 1500.0, 2250.0, 3375.0])
    >>> _bent_members(np.array([30.0, 3.0, 0.3, 0.6]), a, np.log([1200.0, 1600.0, 2250.0, 3000.0]))
    array([ True,  True, False, False])
    """
    s = np.asarray(straightness_px, float)
    ok = np.isfinite(s)
    if ok.sum() < 2:
        return np.zeros(len(log_f), bool)
    limit = 2.0 * float(np.min(s[ok])) + slack_px
    return np.interp(log_f, anchors[ok], s[ok]) > limit


def register_frames(frame_lanes, image_size, forward_px=(1.0, 0.0), lane_width_m=1.22, smooth=True):
    """Families from already detected lanes (optionally VP-smoothed over time)."""
    fls = smooth_vanishing_points(frame_lanes) if smooth else list(frame_lanes)
    fams = [_family_or_none(fl, forward_px, lane_width_m) for fl in fls]
    seq = SequenceCalibration(fams, tuple(image_size), lane_width_m)
    return ClipRegistration(frame_lanes=fls, sequence=seq, forward_px=np.asarray(forward_px, float),
                            image_size=tuple(image_size), lane_width_m=lane_width_m)


#: clips with at least this many frames (in an image folder) follow their lanes in two parts,
#: the second on a forked process, when two cores are there (:func:`register_clip`)
SPLIT_MIN_FRAMES = 60
#: the share of the frames the calling process follows itself when a clip is split (less than
#: half: it also runs the import warm-up of :func:`probreg.pipeline.run_clip` meanwhile, about a
#: second of one core; at 0.45 the background part of ``run_a`` finished 0.4-0.7 s before the
#: calling one, at 0.40 both end together)
SPLIT_SHARE = 0.40


def _track_sized(frames, image_size, config, keypoints_px, warmup=0):
    """:func:`probreg.lanes.track_lanes` on frames ``(index, image)`` of which those whose size is not
    the clip's ``image_size`` count as unreadable: status ``bad_image``, their size in
    ``extra["image_size_px"]`` (their lines, in other pixels, would give another camera)."""
    wrong = {}

    def sized():
        for i, img in frames:
            if img is not None and (img.shape[1], img.shape[0]) != tuple(image_size):
                wrong[i], img = [int(img.shape[1]), int(img.shape[0])], None
            yield i, img

    fls = track_lanes(sized(), config, keypoints_px=keypoints_px, warmup=warmup)
    return [replace(fl, extra={**fl.extra, "image_size_px": wrong[fl.frame]}) if fl.frame in wrong else fl
            for fl in fls]


def left_out_notes(reg: ClipRegistration):
    """The input notes about frames left out of the lane step (status ``bad_image``): images whose
    size is not the clip's, and images that do not decode (a damaged file, a video frame); far lines merged (one note).

    >>> from probreg.lanes import FrameLanes
    >>> fls = [FrameLanes(status="bad_image", frame=3, extra={"image_size_px": [960, 540]}),
    ...        FrameLanes(status="no_lines", frame=4), FrameLanes(status="bad_image", frame=5)]
    >>> for note in left_out_notes(ClipRegistration(fls, None, np.array([1.0, 0.0]), (1920, 1080))):
    ...     print(note)
    1 frame(s) not 1920x1080 like the clip (first: frame 3, 960x540): left out of the lane step
    1 frame image(s) could not be decoded (first: frame 5): no lanes there, status bad_image or bridged_bad_image
    """
    bad = [fl for fl in reg.frame_lanes if fl.status == "bad_image"]
    wrong = [fl for fl in bad if "image_size_px" in fl.extra]
    broken = [fl.frame for fl in bad if "image_size_px" not in fl.extra]
    (w, h), notes = reg.image_size, []
    if wrong:
        notes.append(f"{len(wrong)} frame(s) not {w}x{h} like the clip (first: frame {wrong[0].frame}, "
                     f"{wrong[0].extra['image_size_px'][0]}x{wrong[0].extra['image_size_px'][1]}): left out of the "
                     "lane step")
    if broken:
        notes.append(f"{len(broken)} frame image(s) could not be decoded (first: frame {broken[0]}): no lanes there, "
                     "status bad_image or bridged_bad_image")
    return notes + [n for n in (merged_lines_note(reg.frame_lanes),) if n]


def register_clip(clip: Clip, config: LaneDetectorConfig = LaneDetectorConfig(), smooth=True,
                  mask_athlete=True, progress=None, background=None, started=None, shot="longest"):
    """Detect lanes in every frame of a clip and build the per-frame families.

    With ``mask_athlete`` and the clip's keypoints, line evidence near the athlete is
    ignored (:func:`probreg.lanes.athlete_mask`).  Frames that cannot be read get status
    ``bad_image``, frames whose image file is missing ``missing_image``; nothing raises for
    bad content.  ``progress(desc, total)``, when given, makes a progress bar (``update(n)``,
    ``close()``; e.g. ``tqdm``) that counts the frames.

    With ``background`` (a function that starts ``work()`` elsewhere and returns a function
    waiting for its result, e.g. :func:`probreg.inference.parallel.fork_call`), a clip of
    :data:`SPLIT_MIN_FRAMES` frames or more in an image folder is followed in two parts, the
    first :data:`SPLIT_SHARE` of it here, the rest in the background from a frame the single
    pass would detect in full too, two frames early to replay the global motion and colour change
    at the seam (so every frame is measured exactly as in one pass: the result does not depend on
    the cores), its line identities then continued from the first part's
    (:func:`probreg.lanes.tracking.stitch_tracks`).
    ``started()``, when given, is called once the background work is started (threads must
    start only then: a fork while another thread holds an import lock could hang).

    Camera cuts are found from the lanes' own families and the frames' colour changes
    (:func:`probreg.calibration.cuts.find_clip_cuts`); the registration's ``shots`` says where
    they are.  ``shot`` (``"longest"``, ``"all"`` or a shot's
    index) picks the frames whose lanes are used: the frames of the other shots get the lane
    status ``other_shot`` (no lines), so that one static camera is estimated from one shot.
    Raises ``ValueError`` for a ``shot`` the clip does not have.
    """
    from ..io.frames import iter_frames
    from ..lanes.tracking import stitch_tracks

    kp = clip.keypoints_px if mask_athlete else None
    missing = set(clip.missing_images)
    n = clip.n_frames
    # the second part starts on a frame the one pass would detect in full anyway (every
    # ``redetect_every``-th): both parts then measure every frame as the one pass does
    step = max(int(config.redetect_every), 1)
    mid = int(n * SPLIT_SHARE) // step * step if background is not None and clip.frame_paths \
        and n >= SPLIT_MIN_FRAMES else n
    mid = mid if 0 < mid < n else n
    # the second part starts two frames early: they only replay the global-motion and colour state
    # the one pass has at its seam (:func:`probreg.lanes.track_lanes` ``warmup``)
    warm = min(2, mid)
    second = background(lambda: _track_sized(iter_frames(clip, start=mid - warm), clip.image_size, config, kp,
                                             warmup=warm)) if mid < n else None
    if started is not None:
        started()
    bar = progress("lanes", n) if progress is not None else None
    frames = iter_frames(clip, mid)
    try:
        fls = []
        for fl in _track_sized(frames, clip.image_size, config, kp):
            fls.append(fl)
            if bar is not None:
                bar.update(1)
        if second is not None:
            fls += stitch_tracks(fls, second())
            if bar is not None:
                bar.update(n - mid)
    finally:
        frames.close()
        if bar is not None:
            bar.close()
    fls = [replace(fl, image_size=clip.image_size,
                   status="missing_image" if fl.frame in missing or i in missing else fl.status)
           if fl.status == "bad_image" else fl for i, fl in enumerate(fls)]
    change = [fl.extra.get("colour_change", np.nan) for fl in fls]
    # the lanes' own families (before the vanishing-point smoother, which would blur a cut)
    raw = [_family_or_none(fl, (1.0, 0.0), clip.lane_width_m) for fl in fls]
    cuts, info = find_clip_cuts(change, raw, clip.image_size)
    shots = split_shots(change, len(fls), shot, cuts=cuts, steps=info["steps"], vetoed=info["vetoed"],
                        lanes=[fl.ok for fl in fls])
    if shots.split:
        a, b = shots.frames
        fls = [fl if a <= i < b else replace(fl, status="other_shot", lines=(), vanishing_point=None, vp_cov=None)
               for i, fl in enumerate(fls)]
    reg = register_frames(fls, clip.image_size, (1.0, 0.0), clip.lane_width_m, smooth=smooth)
    reg.shots = shots
    return reg


def camera_json(cameras, height_m, n_frames, lo=None, hi=None):
    """The ``camera.json`` document of CLIP_FORMAT (frames without a camera get nulls)."""
    frames = []
    for i in range(n_frames):
        c: Camera | None = cameras[i] if i < len(cameras) else None
        if c is None:
            frames.append({"frame": i, "K": None, "R": None, "C": None, "dist": None, "fov_deg": None})
        else:
            frames.append({"frame": i, **c.to_dict()})
    return {"height_m": {"median": height_m, "lo": height_m if lo is None else lo,
                         "hi": height_m if hi is None else hi},
            "frames": frames}
