"""Which side of the track the camera stands on: a discrete hypothesis decided by evidence.

Lane lines cannot tell the two sides apart.  A family built with track ``+x`` running to the
image right (``forward_px = (1, 0)``) puts the camera outside the track, on the home straight's
stands ("main"); the family built with ``+x`` to the image left is the same family turned by
180° about the vertical, which puts the camera across the infield ("far").  Every likelihood
term of the clip model is unchanged by that turn, so the side is settled by the one thing that
differs: athletics runs counter-clockwise, so on the home straight the athlete runs along
``+x``.  Two independent cues say which way that is in the image:

``ground_track``
    the athlete's ground position over the clip, cast with the cameras of one hypothesis
    (panning included), moves along ``+x`` or ``-x``; the slope's z-score (standard error
    widened for the residuals' autocorrelation) gives the probability of each direction,
    ``Phi(z)`` and ``Phi(-z)``;
``knee_fold``
    a knee bends backwards: in a side view the shank folds behind the thigh, so the sign of
    the 2D bend hip-knee-ankle tells the image direction of running in every frame with a
    clearly bent knee, independent of the camera's motion.  A clear bend (|sin| >= 0.3)
    points the right way with probability 0.95 (detector swaps and outliers), and frames
    closer than 0.1 s count as one observation.

The log-evidence of each side is the sum over the cues; the side with more evidence is
chosen unless the user gives it (``--camera-side``, ``clip.json`` ``"camera_side"``).  Both
scores go to ``run.json``; a log-evidence ratio below :data:`MIN_LOG_RATIO` or cues that
disagree make the clip verdict ``unreliable``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import JOINT_INDEX

__all__ = ["CameraSide", "SIDES", "MIN_LOG_RATIO", "camera_side_evidence", "forward_px_of", "requested_side"]

#: the two hypotheses
SIDES = ("main", "far")
#: a side chosen with a smaller log-evidence ratio (20:1) is not trusted by the clip verdict
MIN_LOG_RATIO = float(np.log(20.0))
_CAP = 200.0  # cap on one cue's log-likelihood ratio (keeps the numbers readable; never decisive alone)


def requested_side(option, clip_meta, where="clip.json"):
    """The side the user asks for: the command-line option unless it is ``"auto"``, else
    ``clip.json``'s ``"camera_side"``, else ``"auto"``.

    Raises
    ------
    ValueError
        If ``clip.json`` names another side (``where`` says which file).

    >>> requested_side("auto", {"camera_side": "far"})
    'far'
    >>> requested_side("main", {"camera_side": "far"})
    'main'
    """
    given = option if option != "auto" else clip_meta.get("camera_side", "auto")
    if given not in ("auto",) + SIDES:
        raise ValueError(f"{where}: 'camera_side' must be auto, main or far, got {given!r}")
    return given


def forward_px_of(side):
    """Image direction of track ``+x`` for a camera side (main: to the right)."""
    if side not in SIDES:
        raise ValueError(f"camera side must be one of {SIDES}, got {side!r}")
    return np.array([1.0, 0.0]) if side == "main" else np.array([-1.0, 0.0])


@dataclass(frozen=True)
class CameraSide:
    """The camera side of a clip and the evidence for each hypothesis.

    Attributes
    ----------
    chosen : str
        ``"main"`` or ``"far"``.
    source : str
        ``"evidence"`` (chosen by the scores) or ``"given"`` (by the user).
    log_evidence : dict
        ``{"main": float, "far": float}``: summed log-likelihood of the cues.
    cues : dict
        Per cue, its statistics and log-likelihood ratio main vs far (``llr``).
    """

    chosen: str
    source: str
    log_evidence: dict = field(default_factory=dict)
    cues: dict = field(default_factory=dict)

    @property
    def log_ratio(self):
        """|log-evidence(main) - log-evidence(far)|."""
        return abs(self.log_evidence.get("main", 0.0) - self.log_evidence.get("far", 0.0))

    @property
    def cues_disagree(self):
        llr = [c["llr"] for c in self.cues.values() if abs(c["llr"]) >= MIN_LOG_RATIO]
        return len(llr) >= 2 and min(llr) < 0 < max(llr)

    def to_dict(self):
        return {"chosen": self.chosen, "source": self.source, "log_evidence": dict(self.log_evidence),
                "log_ratio": self.log_ratio, "cues": self.cues}


def _ground_track_cue(ground_xy, fps):
    """z-score of the along-track slope of a ground track (F, 2) and its log-likelihood ratio."""
    from scipy.stats import norm

    x = np.asarray(ground_xy, float)[:, 0]
    ok = np.isfinite(x)
    if ok.sum() < 5:
        return {"z": 0.0, "speed_mps": float("nan"), "frames": int(ok.sum()), "llr": 0.0}
    t = np.flatnonzero(ok) / fps
    xs = x[ok]
    # robust line: a few gross casts (a swinging ankle taken for the near one) must not decide
    b, a = np.polyfit(t, xs, 1)
    r = xs - (a + b * t)
    s = 1.4826 * np.median(np.abs(r - np.median(r)))
    keep = np.abs(r) <= 4 * max(s, 1e-6)
    if keep.sum() >= 5:
        t, xs = t[keep], xs[keep]
        b, a = np.polyfit(t, xs, 1)
        r = xs - (a + b * t)
    n = len(t)
    rho = float(np.clip(np.corrcoef(r[:-1], r[1:])[0, 1], 0.0, 0.99)) if n > 3 and np.std(r) > 0 else 0.0
    n_eff = max(n * (1 - rho) / (1 + rho), 3.0)
    se = np.sqrt(np.sum(r**2) / max(n - 2, 1) / np.sum((t - t.mean()) ** 2) * n / n_eff)
    z = float(b / se) if se > 0 else float(np.sign(b) * 50.0)
    llr = float(np.clip(norm.logcdf(z) - norm.logcdf(-z), -_CAP, _CAP))
    return {"z": z, "speed_mps": float(b), "frames": int(n), "llr": llr}


def _knee_fold_cue(keypoints_px, fps, min_sin=0.3, p_right=0.95):
    """Sign of the 2D knee bend: positive (image y down) when the athlete runs to the right."""
    kp = np.asarray(keypoints_px, float)
    votes = []
    for side in ("l", "r"):
        hip, knee, ank = (kp[:, JOINT_INDEX[f"{side}_{j}"], :2] for j in ("hip", "knee", "ankle"))
        a, b = knee - hip, ank - knee
        cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
        with np.errstate(invalid="ignore", divide="ignore"):
            s = cross / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        votes.append(np.where(np.isfinite(s) & (np.abs(s) >= min_sin), np.sign(s), 0.0))
    v = np.sum(votes, axis=0)  # per frame: -2..2
    n_pos, n_neg = int(np.sum(np.clip(v, 0, None))), int(np.sum(np.clip(-v, 0, None)))
    corr_frames = max(1.0, 0.1 * fps)  # neighbouring frames are not independent observations
    llr = float(np.clip((n_pos - n_neg) * np.log(p_right / (1 - p_right)) / corr_frames, -_CAP, _CAP))
    return {"bends_right": n_pos, "bends_left": n_neg, "llr": llr}


def camera_side_evidence(main_ground_xy, keypoints_px, fps, given="auto"):
    """Decide the camera side of a clip.

    Parameters
    ----------
    main_ground_xy : ndarray, shape (F, 2)
        The athlete's ground track (m, NaN where unknown) cast with the per-frame cameras of the
        "main" hypothesis (families built with ``forward_px = (1, 0)``) at any plausible camera
        height (the direction of motion does not depend on it);
        :func:`probreg.calibration.athlete_ground_track`.
    keypoints_px : ndarray, shape (F, 17, 3)
        H36M-17 keypoints.
    fps : float
    given : {"auto", "main", "far"}
        ``"auto"``: choose by evidence; otherwise the user's choice (evidence still reported).

    Returns
    -------
    CameraSide

    Examples
    --------
    A runner whose knees bend like a runner going to the image left, filmed by a camera that
    pans left, is seen from across the infield:

    >>> import numpy as np
    >>> kp = np.full((50, 17, 3), np.nan)
    >>> for side, dx in (("l", 0.0), ("r", 3.0)):
    ...     kp[:, JOINT_INDEX[f"{side}_hip"], :2] = [100 + dx, 100]
    ...     kp[:, JOINT_INDEX[f"{side}_knee"], :2] = [90 + dx, 140]   # thigh forward (left)
    ...     kp[:, JOINT_INDEX[f"{side}_ankle"], :2] = [110 + dx, 170]  # shank folded back (right)
    >>> camera_side_evidence(np.full((50, 2), np.nan), kp, 50.0).chosen
    'far'
    """
    if given not in ("auto",) + SIDES:
        raise ValueError(f"camera side must be auto, main or far, got {given!r}")
    cues = {"ground_track": _ground_track_cue(main_ground_xy, fps),
            "knee_fold": _knee_fold_cue(keypoints_px, fps)}
    llr = sum(c["llr"] for c in cues.values())
    # log-evidence of each side up to a common constant: the ratio is what matters
    log_ev = {"main": 0.5 * llr, "far": -0.5 * llr}
    if given != "auto":
        return CameraSide(chosen=given, source="given", log_evidence=log_ev, cues=cues)
    return CameraSide(chosen="main" if llr >= 0 else "far", source="evidence", log_evidence=log_ev, cues=cues)
