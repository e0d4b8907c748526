"""What each clip-verdict reason means and what a user can do about it (the report's table and
:func:`explain_reason`); the checks themselves are :mod:`probreg.inference.verdict`'s."""

from __future__ import annotations

__all__ = ["REASON_HELP", "explain_reason"]

#: For each verdict reason (by the words it starts with): what it means for the results, and what a
#: user can do about it.  The report shows these beside the reasons.
REASON_HELP = {
    "short clip": (
        ("the angles span less than a second: under two strides nothing ties strides together (the "
         "smoothing, the noise model, the checks of the legs' swing and of the time base), and the "
         "verdict cannot tell a good result from a bad one"),
        "give a longer clip: at least a second, better two or more strides (1.5 s)",
    ),
    "frames_with_angles": (
        "no frame produced an angle: there is nothing to use",
        "check the lane overlays and the keypoints (is the athlete detected?)",
    ),
    "calibrated_frames": (
        "too few frames found lanes that give a camera: the rest is guessed from them",
        "check the lane overlays; a clip with the straight's lines in view calibrates",
    ),
    "lanes_agree_frames": (
        ("many frames' lanes do not fit the clip's static camera: lines were misread, or the broadcast"
         " cut to another camera"),
        "check the lane overlays frame by frame; cut the clip to one camera shot",
    ),
    "R-hat": (
        "the sampler did not converge: the bands are not a posterior yet",
        "run with more --max-steps",
    ),
    "ESS": (
        "too few independent posterior draws of the camera height",
        "run with more --max-steps",
    ),
    "posterior multimodal": (
        "two different camera heights explain the clip; the median lies between them",
        "give the camera height (--height-m) or the athlete's stature (--stature) if known",
    ),
    "prior-dominated height": (
        "the clip did not measure the camera height; every metric number rests on the prior",
        "give the camera height (--height-m) or the athlete's stature (--stature)",
    ),
    "height barely fixes the camera": (
        ("the camera sits where a small change of height is a large change of focal length and "
         "distance: positions and speeds are loose"),
        "give the athlete's stature (--stature) or the camera height (--height-m)",
    ),
    "camera_side evidence ratio": (
        "which side of the track the camera stands on is not settled by the motion",
        "give it (--camera-side main or far) if you know it",
    ),
    "branch evidence ratio": (
        ("a far camera with a long lens and a close one looking down steeply explain the lanes about "
         "equally well: the scale of everything hangs on the choice"),
        "give --branch narrow or wide, or the camera height, if known",
    ),
    "bone length cv": (
        "cameras and skeleton do not fit together (rays miss their limb spheres, draws disagree)",
        "check the keypoints and the lane overlays",
    ),
    "running speed": (
        "the athlete runs faster than any human: the camera puts them at the wrong scale",
        "check the lane overlays; give the camera height or the stature if known",
    ),
    "stature prior conflict": (
        "the stature left its prior far behind: the camera makes the limbs the wrong size",
        "check the lane overlays; give the athlete's stature (--stature) if known",
    ),
    "keypoint noise unidentified": (
        ("the 2D detections' noise drifts too slowly to be measured: the smoothing and the bands rest "
         "on a guessed level"),
        "use a better 2D pose model",
    ),
    "knee band wide": (
        "the knee bands are too wide to measure the knee at the ~3 deg kinematics needs",
        "give the camera height or the stature if known; use a clip from a nearer camera",
    ),
    "no plausible camera": (
        ("the lanes allow no camera that the priors and the limbs accept (e.g. spurious lines of a "
         "grazing view)"),
        ("check the lane overlays; widen the camera-height prior (--height-m, --height-log-sd) if the "
         "camera is unusual"),
    ),
    "lanes ": (
        "how many frames ended with this lane status (run.json frame_status, described in the README)",
        "frames without the straight's lines cannot calibrate",
    ),
    "knee flexion peak": (
        ("the knees never bend as a runner's swing leg does (90-130 deg): the 2D keypoints do not follow "
         "the legs, or the athlete is not running"),
        "look at the keypoints on the frames; use a stronger 2D pose model",
    ),
    "knee flexion beyond": (
        ("the lifted knees fold further than a human knee can (past 160 deg): the 2D keypoints do not lie "
         "on the legs"),
        "look at the keypoints on the frames; use a stronger 2D pose model",
    ),
    "legs too short in the image": (
        ("the thighs and shanks are only a few pixels (or a few noise sds) long in the image: their "
         "directions, and every angle, are noise"),
        "check that the keypoints are in the frames' pixels (not a crop's or a smaller copy's); use a closer view",
    ),
    "keypoints off the athlete": (
        ("the 2D skeleton does not lie on a person in the frames: along its bones the image looks like "
         "the track around it.  The keypoints belong to other images (a pose model run on a resized, "
         "cropped or padded copy; another clip), and the camera and every angle built on them are "
         "meaningless however narrow their bands"),
        ("give keypoints in these frames' pixels (run the pose model on the frames themselves: "
         "probreg detect; or rescale its coordinates to clip.json's image_size); the report's overlay "
         "shows where the skeleton lies"),
    ),
    "skeleton upside down in the image": (
        ("the keypoints' trunk points down in the image: their y axis points up (a biomechanics "
         "tool's or a plot's convention), not down as the image's rows do; every position and angle "
         "is built on a mirrored skeleton"),
        "give y in image rows (y_image = image height - 1 - y; probreg import --trc-image-height does it for TRC files)",
    ),
    "left/right labels unsure": (
        ("the 2D detector often called the left leg right: probreg set the labels right from the "
         "motion, but which leg is the left one is close to a guess"),
        "compare the left and right curves with the video; use a stronger 2D pose model",
    ),
    "oblique view": (
        ("the camera looks at the runner from far off the side: much of the legs' motion runs along "
         "the rays, and knee errors average ~4 deg even with the true camera"),
        "prefer a camera nearer the side of the runner (a main-stand or long-lens view)",
    ),
    "camera cut": (
        ("the clip switches cameras, and it was estimated as one static camera (--shot all): the "
         "camera height is pulled between two cameras, and every angle may be far off"),
        "run one shot at a time (the default estimates the longest; --shot N picks shot N)",
    ),
    "repeated frames": (
        ("the stream repeats its frames (e.g. 25 fps content in a 50 fps stream): the motion stops every "
         "other frame, which the noise model and the smoothing read as motion, and the bands are far too narrow"),
        "give the frames once each: extract the clip at its content's frame rate",
    ),
    "given lens contradicts": (
        ("the lane lines' curvature under the given k1 puts the camera at another height than the clip's own "
         "evidence (ground track, planted feet, limbs): a lens calibrated at another zoom, another lens, or "
         "(on close, low views) height terms that are off themselves"),
        "check the lens calibration (its zoom setting), or run without --dist to infer the lens",
    ),
    **dict.fromkeys(("slow motion", "fast motion", "time base unclear"), (
        ("the clip's time does not run at its frame rate (a slow-motion replay, or a wrong fps): every "
         "time-based number (cadence, speed, contact times) is off by that factor, and the smoothing's "
         "models of the motion are set for another speed"),
        "give the replay's slow-down, e.g. --slow-motion 4 (or the clip's true frame rate in clip.json)",
    )),
}


def explain_reason(reason):
    """``(meaning, what to do)`` of a verdict reason (:data:`REASON_HELP`), or None for a reason
    it does not know.

    >>> explain_reason("oblique view (48 deg from the side)")[1]
    'prefer a camera nearer the side of the runner (a main-stand or long-lens view)'
    >>> explain_reason("something else") is None
    True
    """
    for key in sorted(REASON_HELP, key=len, reverse=True):
        if str(reason).startswith(key):
            return REASON_HELP[key]
    return None
