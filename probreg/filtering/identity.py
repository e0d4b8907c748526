"""Left and right kept apart: the detector's left/right labels of the legs repaired from the motion.

Seen from the side, a runner's legs cross twice a stride and the near leg hides the far one.
A pose detector then often gives the near leg the far leg's label, for a few frames at a time.
The lifting takes labels as given, so each side's knee angle becomes a mixture of the two legs:
on 14 tuning clips with runs of 2-10 swapped frames (6-45 % of the frames; true cameras and limb
lengths, docs/method.md) the knee error went from 3.4° to 19.6°. The cross-stride smoothing
down-weights a single swapped frame, but not runs of them.

The joints themselves say which is which: a joint moves smoothly, while a swapped label makes its
track jump to the other leg and back. For the legs (hips, knees and ankles together: a detector
decides which side of the body it sees, not joint by joint), every frame either keeps the
detector's labels or exchanges them. The sequence of choices minimises the tracks' second
differences (their acceleration, in units of the detection noise; each joint's share capped, so
an outlier costs the same under either labelling) plus a cost for every change between keeping
and exchanging and a small one per exchanged frame (a second-order Viterbi pass over the two
states, across missing frames). A run of swapped frames is then repaired whatever its length,
and the detector's labels stand where the tracks barely tell the sides apart. Where the legs
cross, the two knees are at one place but move in opposite directions: the second differences,
not the positions, tell them apart. The motion tells which keypoints form one track, not which
track is the left one: that is the detector's choice in most frames. The arms are left as
labelled: in a side view they overlap too much for their tracks to tell them apart (on a
simulated runner with 3 px noise, runs of swapped arms were found only in part). Deciding joint
by joint instead (each pair its own chain) repaired less: the hips, nearly one point in a side
view, carry no evidence of their own, and knees and ankles could settle on different legs.
"""

from __future__ import annotations

import numpy as np

from ..geometry import JOINT_INDEX

__all__ = ["LEFT_RIGHT_PAIRS", "relabel_left_right"]

#: the paired joints, (right, left) in H36M-17 names
LEFT_RIGHT_PAIRS = (("r_hip", "l_hip"), ("r_knee", "l_knee"), ("r_ankle", "l_ankle"),
                    ("r_shoulder", "l_shoulder"), ("r_elbow", "l_elbow"), ("r_wrist", "l_wrist"))

#: the limbs relabelled, as indices into :data:`LEFT_RIGHT_PAIRS`: the legs
LIMBS = ((0, 1, 2),)

#: cost of a change between keeping and exchanging the labels, in the units of the motion term
#: (squared second differences over their noise variance): a swap is repaired when the two sides'
#: joints lie more than about five noise standard deviations apart (a jump in and out of it costs
#: two squared second differences each way)
EXCHANGE_COST = 10.0

#: most a joint's squared second difference (over its noise variance) adds in a frame: a detector
#: outlier costs the same under either labelling, while a swapped leg jumps in six tracks at once
JUMP_CAP = 9.0

#: cost of each exchanged frame: the detector's labels stand where the tracks barely tell the
#: sides apart (a low grazing view, whose legs overlap in the image)
FRAME_COST = 1.0


def relabel_left_right(keypoints_px, noise_px, exchange_cost=EXCHANGE_COST, frame_cost=FRAME_COST):
    """The keypoints with the legs' left/right labels exchanged where the motion says the detector
    had them the wrong way round (module docstring).

    Parameters
    ----------
    keypoints_px : ndarray (F, 17, 2 or 3)
        H36M-17 keypoints (NaN = missing); the score channel moves with its joint.
    noise_px : float
        The detection noise (px, :func:`probreg.filtering.noise_model`); below 0.5 px it counts as
        0.5 px.
    exchange_cost, frame_cost : float
        Cost of a change between keeping and exchanging, and of each exchanged frame.

    Returns
    -------
    keypoints : ndarray (F, 17, C)
        A copy, relabelled.
    exchanged : ndarray (F, 6) bool
        Per frame and pair (:data:`LEFT_RIGHT_PAIRS`) whether the labels were exchanged (the
        legs' three pairs together; the arms' never).

    >>> t = np.arange(60.0)
    >>> kp = np.zeros((60, 17, 2))
    >>> kp[:, JOINT_INDEX["r_knee"]] = np.stack([10 * t, 5 * np.sin(t / 5)], 1)        # moves right
    >>> kp[:, JOINT_INDEX["l_knee"]] = np.stack([600 - 10 * t, 5 * np.cos(t / 5)], 1)  # moves left
    >>> bad = kp.copy(); r, l = JOINT_INDEX["r_knee"], JOINT_INDEX["l_knee"]
    >>> bad[20:26, [r, l]] = bad[20:26, [l, r]]                       # six frames labelled wrong
    >>> fixed, exchanged = relabel_left_right(bad, noise_px=1.0)
    >>> bool(np.allclose(fixed, kp)), np.flatnonzero(exchanged[:, 1]).tolist()
    (True, [20, 21, 22, 23, 24, 25])
    >>> same, none = relabel_left_right(kp, noise_px=1.0)               # right labels stay
    >>> bool(np.array_equal(same, kp)), int(none.sum())
    (True, 0)
    """
    kp = np.array(keypoints_px, float)
    if kp.ndim != 3 or kp.shape[1] != 17:
        raise ValueError(f"keypoints must have shape (F, 17, C), got {kp.shape}")
    F, P = len(kp), len(LEFT_RIGHT_PAIRS)
    exchanged = np.zeros((F, P), bool)
    if F < 3:
        return kp, exchanged
    idx = np.array([(JOINT_INDEX[r], JOINT_INDEX[l]) for r, l in LEFT_RIGHT_PAIRS])
    # Y[g, s, t]: a limb's three pairs (12 numbers) with its labels kept (s = 0) or exchanged (1)
    G = len(LIMBS)
    kept = kp[:, idx[np.ravel(LIMBS)], :2].reshape(F, G, 12)
    swapped = kp[:, idx[np.ravel(LIMBS)][:, ::-1], :2].reshape(F, G, 12)
    Y = np.stack([kept, swapped], 0).transpose(2, 0, 1, 3)  # (G, 2, F, 12)
    sd = max(float(noise_px) if np.isfinite(noise_px) else 0.5, 0.5)
    # step[b, c]: from state b to state c, a change and the frame's own share
    step = exchange_cost * (1.0 - np.eye(2)) + frame_cost * np.array([[0.0, 1.0], [0.0, 1.0]])
    state = np.zeros((F, G), np.int8)
    for g in range(G):
        # the chain runs over the frames where the limb was seen, bridging the others (the second
        # difference divided by the frames' spacing: a missing frame must not cut the track)
        t_seen = np.flatnonzero(np.isfinite(Y[g, 0]).any(axis=1))
        if len(t_seen) < 3:
            continue
        Z = Y[g][:, t_seen]  # (2, n, 12)
        h = np.diff(t_seen).astype(float)
        D = step + frame_cost * np.array([[0.0], [1.0]])  # D[a, b]: least cost with state a before, b now
        back = np.zeros((len(t_seen), 2, 2), np.int8)
        for k in range(2, len(t_seen)):
            h1, h2 = h[k - 2], h[k - 1]
            # acc[a, b, c] = (Z_c,k - Z_b,k-1) / h2 - (Z_b,k-1 - Z_a,k-2) / h1, the 2nd difference
            acc = ((Z[None, None, :, k] - Z[None, :, None, k - 1]) / h2
                   - (Z[None, :, None, k - 1] - Z[:, None, None, k - 2]) / h1)
            var = sd * sd * (1 / h1**2 + (1 / h1 + 1 / h2) ** 2 + 1 / h2**2)  # 6 sd^2 with no gap
            # each joint's share capped (an outlier must not pull the labels over): a missing joint adds nothing
            e = np.minimum(np.sum(acc.reshape(2, 2, 2, -1, 2) ** 2, axis=-1) / var, JUMP_CAP)
            total = D[:, :, None] + np.nansum(e, axis=-1)  # (a, b, c)
            back[k] = np.argmin(total, axis=0)
            D = np.min(total, axis=0) + step
        chosen = np.zeros(len(t_seen), np.int8)
        chosen[-2], chosen[-1] = np.unravel_index(np.argmin(D), D.shape)
        for k in range(len(t_seen) - 1, 1, -1):
            chosen[k - 2] = back[k, chosen[k - 1], chosen[k]]
        # the motion cannot tell which track is the left one: the detector's labels decide, where most
        # of its frames agree (already so with a cost per exchanged frame; without one, the two tie)
        state[t_seen, g] = 1 - chosen if chosen.mean() > 0.5 else chosen
    exchanged[:, :3 * G] = np.repeat(state.astype(bool), 3, axis=1)  # a limb's three pairs share its choice
    out = kp.copy()
    for p, (r, l) in enumerate(idx):
        rows = exchanged[:, p]
        out[rows, r], out[rows, l] = kp[rows, l], kp[rows, r]
    return out, exchanged
