"""Frame access for a clip: an image folder or a video file, read through OpenCV."""

from __future__ import annotations

from pathlib import Path

import cv2

from .clip import Clip, ClipFormatError

__all__ = ["iter_frames", "iter_frames_counted", "read_frame", "has_frames"]


def has_frames(clip: Clip):
    """Whether the clip has at least one image (frames/ folder) or a video."""
    return any(p is not None for p in clip.frame_paths) or clip.video_path is not None


def _imread(path):
    return None if path is None else cv2.imread(str(path), cv2.IMREAD_COLOR)


#: images decoded ahead of the consumer (a few frames: bounded memory at any image size)
PREFETCH = 4


def _prefetched(paths, n, start=0):
    """``(i, image or None)`` for ``start <= i < n``, decoded on a background thread while the caller
    works on the previous frames (OpenCV releases the GIL while it decodes, so decoding, a
    third of the lane step's time at 1080p, overlaps the lane measurement).  The same images
    in the same order as decoding them one by one."""
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    paths = list(paths)[:n]
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="probreg-decode") as pool:
        pending = deque()
        for i in range(start, n):
            pending.append(pool.submit(_imread, paths[i]) if i < len(paths) else None)
            if len(pending) > PREFETCH:
                j = i - PREFETCH
                fut = pending.popleft()
                yield j, (fut.result() if fut is not None else None)
        for j in range(max(n - len(pending), start), n):
            fut = pending.popleft()
            yield j, (fut.result() if fut is not None else None)


def read_frame(clip: Clip, index):
    """One frame (BGR uint8) or ``None`` when it is missing or unreadable."""
    if clip.frame_paths:
        if 0 <= index < len(clip.frame_paths):
            return _imread(clip.frame_paths[index])
        return None
    if clip.video_path is not None:
        cap = cv2.VideoCapture(str(clip.video_path))
        try:
            cap.set(cv2.CAP_PROP_POS_FRAMES, index)
            ok, img = cap.read()
            return img if ok else None
        finally:
            cap.release()
    return None


def iter_frames(clip: Clip, n_frames=None, start=0):
    """Yield ``(index, image or None)`` for every frame of the clip (``None``: missing or
    unreadable), from frame ``start`` on (image folders only; a video is read from its start).

    Raises
    ------
    ClipFormatError
        If the clip has neither ``frames/`` nor ``video.mp4``, or the video cannot be opened.
    """
    n = clip.n_frames if n_frames is None else n_frames
    if clip.frame_paths:
        yield from _prefetched(clip.frame_paths, n, start)
        return
    if start:
        raise ValueError("a video is read from its first frame")
    if clip.video_path is None:
        raise ClipFormatError(f"{Path(clip.path)}: no frames/ folder and no video.mp4")
    cap = cv2.VideoCapture(str(clip.video_path))
    if not cap.isOpened():
        raise ClipFormatError(f"{clip.video_path}: cannot open the video")
    try:
        for i in range(n):
            ok, img = cap.read()
            yield i, (img if ok else None)
    finally:
        cap.release()


def iter_frames_counted(clip: Clip, progress=None, desc="frames"):
    """:func:`iter_frames`, counting the frames on a bar made by ``progress(desc, total)`` (an
    object with ``update(n)`` and ``close()``, e.g. ``tqdm``); the bar is closed when the
    iteration ends, is abandoned or fails."""
    bar = progress(desc, clip.n_frames) if progress is not None else None
    try:
        for item in iter_frames(clip):
            yield item
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
