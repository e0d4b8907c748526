"""Output folders that never lose a user's data.

Every folder probreg writes (a result, a calibration, a synthetic or imported clip) is built
under a temporary name beside its target and renamed into place only when complete, with a
marker file, ``.probreg``, that lists the files probreg wrote.  The rules:

* an empty or absent target is written;
* a target that is a probreg folder holding only files probreg wrote is replaced (a re-run);
* any other non-empty target (foreign files, or files a user added to a result) is refused,
  unless ``overwrite`` is set, and then it is **moved aside** to ``TARGET.previous-<time>``,
  never deleted;
* a target equal to an input folder, inside one, or containing one is always refused;
* the target's parent must be writable, which is checked before any work starts
  (:func:`prepare_output`);
* temporaries left by a run that was killed (``.TARGET.tmp-<pid>-*`` with a
  ``.probreg-incomplete`` marker whose process is gone) are removed on the next start;
* an interrupted run (Ctrl-C, an error) removes its own temporary and leaves the previous
  result as it was.

A single output file (``probreg detect``'s keypoints, by default the clip's own
``keypoints2d.json``) follows the same rules (:func:`check_file_output`, :func:`write_file_output`):
a file probreg wrote is replaced, any other is refused, or with ``overwrite`` moved aside to
``FILE.previous-<time>``; the new file is written under a temporary name and renamed into place.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from pathlib import Path

__all__ = ["MARKER", "atomic_output_dir", "prepare_output", "OutputRefused", "check_file_output",
           "write_file_output"]

#: name of the marker file of every folder probreg writes
MARKER = ".probreg"
_INCOMPLETE = ".probreg-incomplete"


class OutputRefused(FileExistsError):
    """The output folder cannot be used without risking data probreg did not write."""


def _is_relative_to(a: Path, b: Path):
    try:
        a.relative_to(b)
        return True
    except ValueError:
        return False


def _written_files(folder: Path):
    """Files (relative paths) below ``folder``, folders as their own entry, marker excluded."""
    out = set()
    for p in folder.rglob("*"):
        rel = p.relative_to(folder).as_posix()
        if rel != MARKER:
            out.add(rel + ("/" if p.is_dir() else ""))
    return out


def _foreign_files(target: Path):
    """Entries of an existing folder that probreg did not write (empty set: all ours).

    ``None`` when the folder carries no probreg marker at all."""
    marker = target / MARKER
    if not marker.is_file():
        return None
    try:
        doc = json.loads(marker.read_text(encoding="utf-8"))
        listed = set(doc["files"])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        return set()  # marker of an older probreg (plain text, no list): the folder is ours
    return _written_files(target) - listed


def _pid_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def _remove_stale_temporaries(target: Path):
    """Remove ``.NAME.tmp-PID-*`` folders of dead runs (only those carrying our marker)."""
    removed = []
    parent = target.parent
    if not parent.is_dir():
        return removed
    for p in parent.glob(f".{target.name}.tmp-*"):
        inc = p / _INCOMPLETE
        if not (p.is_dir() and inc.is_file()):
            continue
        try:
            pid = int(inc.read_text().split()[0])
        except (ValueError, IndexError, OSError):
            continue
        if not _pid_alive(pid):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


def prepare_output(target, inputs=(), overwrite=False):
    """Check that ``target`` can be written, before any work starts.

    Parameters
    ----------
    target : path-like
        The output folder.
    inputs : sequence of path-like
        Input folders or files of the command: the target may not be one of them, lie inside
        one, or contain one.
    overwrite : bool
        Allow a non-empty target that holds files probreg did not write (they are moved aside,
        never deleted).

    Returns
    -------
    str
        ``"new"``, ``"replace"`` (a probreg folder of ours) or ``"move_aside"``.

    Raises
    ------
    ValueError
        If the target is, lies inside, or contains an input.
    OutputRefused
        If the target is a file, or a non-empty folder with foreign files and not ``overwrite``.
    PermissionError
        If the target's parent folder cannot be created or written.
    """
    t = Path(target).expanduser()
    tr = t.resolve()
    for inp in inputs:
        if inp is None:
            continue
        ir = Path(inp).expanduser().resolve()
        if tr == ir or _is_relative_to(tr, ir) or _is_relative_to(ir, tr):
            raise ValueError(f"{t}: the output folder may not be the input {inp}, lie inside it or "
                             f"contain it (writing there could destroy the input); choose another --out")
    if t.exists() and not t.is_dir():
        raise OutputRefused(f"{t}: exists and is not a folder; choose another --out")
    parent = t.parent if str(t.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputRefused(f"{parent}: exists and is not a folder, so {t.name} cannot be made in it") from None
    except OSError as exc:
        raise PermissionError(f"{parent}: cannot create the output's parent folder ({exc.strerror})") from None
    # a real probe: os.access says yes to root even on read-only folders
    try:
        probe = Path(tempfile.mkdtemp(prefix=f".{t.name}.probe-", dir=parent))
        probe.rmdir()
    except OSError as exc:
        raise PermissionError(f"{parent}: output folder is not writable ({exc.strerror})") from None
    _remove_stale_temporaries(t)
    if not t.exists() or not any(t.iterdir()):
        return "new"
    foreign = _foreign_files(t)
    if foreign is not None and not foreign:
        return "replace"
    if overwrite:
        return "move_aside"
    what = ("was not written by probreg" if foreign is None else
            "holds files probreg did not write: " + ", ".join(sorted(foreign)[:5])
            + (" ..." if len(foreign) > 5 else ""))
    raise OutputRefused(f"{t}: folder is not empty and {what} (use --overwrite to move it aside to "
                        f"{t.name}.previous-<time>, or choose another --out)")


class atomic_output_dir:
    """Context manager: build an output folder under a temporary name, rename it on success.

    See the module docstring for the rules; the checks of :func:`prepare_output` run again on
    entry and, for what the target holds, once more just before the rename (a user may have
    added files during a long run).

    Parameters
    ----------
    target : path-like
    overwrite : bool
        Move a non-empty foreign target aside instead of refusing it.
    inputs : sequence of path-like
        Input folders the target may not touch.
    log : callable
        Receives a one-line note when a folder is moved aside.

    Raises
    ------
    ValueError, OutputRefused, PermissionError
        As :func:`prepare_output`.
    """

    def __init__(self, target, overwrite=False, inputs=(), log=None):
        self.target = Path(target)
        self.overwrite = overwrite
        self.inputs = tuple(inputs)
        self.log = log
        self.tmp = None

    def __enter__(self):
        prepare_output(self.target, self.inputs, self.overwrite)
        t = self.target
        parent = t.parent if str(t.parent) else Path(".")
        try:
            self.tmp = Path(tempfile.mkdtemp(prefix=f".{t.name}.tmp-{os.getpid()}-", dir=parent))
        except OSError as exc:
            raise PermissionError(f"{parent}: cannot create the output folder there ({exc.strerror})") from None
        os.chmod(self.tmp, 0o755)
        (self.tmp / _INCOMPLETE).write_text(f"{os.getpid()}\n")
        return self.tmp

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:  # includes KeyboardInterrupt: the previous result stays as it was
            shutil.rmtree(self.tmp, ignore_errors=True)
            return False
        (self.tmp / _INCOMPLETE).unlink()
        files = sorted(_written_files(self.tmp))
        from .. import __version__

        (self.tmp / MARKER).write_text(json.dumps({"written_by": "probreg", "version": __version__,
                                                   "files": files}, indent=1) + "\n", encoding="utf-8")
        t = self.target
        if t.exists() and any(t.iterdir()):
            foreign = _foreign_files(t)
            if foreign is None or foreign:
                if not self.overwrite:
                    shutil.rmtree(self.tmp, ignore_errors=True)
                    raise OutputRefused(f"{t}: files were added to the folder during the run; "
                                        f"nothing was replaced (use --overwrite to move it aside)")
                aside = t.with_name(f"{t.name}.previous-{time.strftime('%Y%m%d-%H%M%S')}-{self.tmp.name[-6:]}")
                os.replace(t, aside)
                os.replace(self.tmp, t)
                if self.log is not None:
                    self.log(f"note: the previous contents of {t} were moved to {aside}")
                return False
            old = t.with_name(f".{t.name}.old-{self.tmp.name[-8:]}")
            os.replace(t, old)
            os.replace(self.tmp, t)
            shutil.rmtree(old, ignore_errors=True)
        else:
            if t.exists():
                t.rmdir()  # empty
            os.replace(self.tmp, t)
        return False


def check_file_output(path, is_ours, overwrite=False, owner="probreg"):
    """Before any work: may the single output file ``path`` be written?  (``owner``: who writes it,
    for the message.)

    Returns ``"new"`` (nothing there), ``"replace"`` (a file ``is_ours(path)`` says probreg wrote)
    or ``"move_aside"`` (another file, and ``overwrite``).

    Raises
    ------
    OutputRefused
        If ``path`` is a folder, or a file probreg did not write and not ``overwrite``.
    """
    p = Path(path).expanduser()
    if p.is_dir():
        raise OutputRefused(f"{p}: is a folder; give the output file's name")
    if not p.exists():
        return "new"
    if is_ours(p):
        return "replace"
    if overwrite:
        return "move_aside"
    raise OutputRefused(f"{p}: exists and was not written by {owner} (use --overwrite to move it aside to "
                        f"{p.name}.previous-<time>, or choose another --out)")


def write_file_output(path, write, plan, is_ours):
    """Write the single output file ``path``: ``write(tmp)`` fills a temporary file beside it, which
    is renamed into place.  ``plan`` is :func:`check_file_output`'s answer; a file that appeared at
    ``path`` since, and is not ours, is refused as there (unless the plan moves it aside).  Returns
    the path the previous file was moved to, or None.

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> (d / "kp.json").write_text("mine")
    4
    >>> ours = lambda p: p.read_text() == "probreg"
    >>> aside = write_file_output(d / "kp.json", lambda t: t.write_text("probreg"),
    ...                           check_file_output(d / "kp.json", ours, overwrite=True), ours)
    >>> (d / "kp.json").read_text(), aside.read_text(), aside.name.startswith("kp.json.previous-")
    ('probreg', 'mine', True)
    """
    p = Path(path).expanduser()
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.name}.tmp-{os.getpid()}")
    aside = None
    try:
        write(tmp)
        if p.exists() and not is_ours(p):
            if plan != "move_aside":
                raise OutputRefused(f"{p}: a file probreg did not write appeared there during the run; nothing "
                                    f"was replaced (the new one would have gone there; use --overwrite)")
            aside = p.with_name(f"{p.name}.previous-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}")
            os.replace(p, aside)
        os.replace(tmp, p)
    finally:
        if tmp.exists():
            tmp.unlink()
    return aside
