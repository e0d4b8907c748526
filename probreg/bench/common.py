"""Shared plumbing of the benchmarks: registry, Markdown writing, environment notes."""

from __future__ import annotations

import datetime as _dt
import importlib
import os
import platform
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["BENCHMARKS", "BenchReport", "run_benchmark", "md_table", "find_shared_data", "verdict_text"]

#: name -> "module:function"; each function takes (args namespace) and returns a BenchReport.
BENCHMARKS = {
    "realism": "probreg.bench.realism:run",
    "synth-speed": "probreg.bench.synth_speed:run",
    "registration": "probreg.bench.registration:run",
    "lifting": "probreg.bench.lifting:run",
    "posterior": "probreg.bench.posterior:run",
    "band-calibration": "probreg.bench.band_calibration:run",
    "detect": "probreg.bench.detect:run",
    "distortion": "probreg.bench.distortion:run",
    "validation": "probreg.bench.validation:run",
    "video": "probreg.bench.video:run",
    "speed": "probreg.bench.speed:run",
    "batch": "probreg.bench.batch:run",
    "cuts": "probreg.bench.cuts:run",
    "replays": "probreg.bench.replays:run",
    "rails": "probreg.bench.rails:run",
    "long-clips": "probreg.bench.long_clips:run",
    "on-athlete": "probreg.bench.on_athlete:run",
    "race": "probreg.bench.race:run",
}


@dataclass
class BenchReport:
    """A benchmark's result: a title, Markdown sections and headline numbers."""

    name: str
    title: str
    sections: list = field(default_factory=list)
    numbers: dict = field(default_factory=dict)

    def add(self, text):
        self.sections.append(text.rstrip() + "\n")

    def to_markdown(self, command):
        head = [f"# {self.title}", "",
                f"Command: `{command}`  ",
                f"Measured: {_dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')} on "
                f"{platform.machine()} with {os.cpu_count()} cores, Python {platform.python_version()}, "
                f"{_versions_text()}", ""]
        return "\n".join(head) + "\n" + "\n".join(self.sections)


def _versions_text():
    """The installed versions a benchmark's numbers depend on, for its header (``numpy 2.4.6, scipy
    1.17.1, OpenCV 4.14.0.94, emcee 3.1.6``; :func:`probreg.io.software_versions`)."""
    from ..io.provenance import software_versions

    v = software_versions()
    return ", ".join(f"{label} {v[key]}" for key, label in (("numpy", "numpy"), ("scipy", "scipy"),
                                                            ("opencv", "OpenCV"), ("emcee", "emcee"))
                     if v.get(key))


def verdict_text(verdict, reasons):
    """A verdict with its reasons for a table cell.

    >>> verdict_text("ok", []), verdict_text("unreliable", ["a", "b"])
    ('ok', 'unreliable (a; b)')
    """
    return verdict + (f" ({'; '.join(reasons)})" if reasons else "")


def md_table(header, rows, floatfmt="{:.2f}"):
    """A Markdown table; floats are formatted with ``floatfmt``."""
    def fmt(v):
        if isinstance(v, (float, np.floating)):
            return "n/a" if not np.isfinite(v) else floatfmt.format(v)
        return str(v)
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v) for v in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


#: folders of ``shared/data`` (a ``--shared`` path to ``shared`` itself is taken to mean its ``data``)
SHARED_DATA_PARTS = ("validation", "mocap", "paper_frames")


def find_shared_data(explicit=None):
    """Locate ``shared/data`` (benchmarks only; the package never needs it): the folder given
    (``--shared``), else ``$PROBREG_SHARED_DATA``, ``../shared/data`` from the working folder or
    beside the checkout; ``None`` when none is there.

    Raises
    ------
    ValueError
        When a folder is given and is not there: a benchmark never runs on another folder than
        the one asked for.
    """
    if explicit:
        path = Path(explicit).expanduser()
        if not path.is_dir():
            raise ValueError(f"--shared {explicit}: no such folder (give the path of shared/data)")
        if not any((path / n).is_dir() for n in SHARED_DATA_PARTS) and (path / "data").is_dir():
            path = path / "data"
        return path.resolve()
    cands = [os.environ.get("PROBREG_SHARED_DATA"), Path.cwd() / "../shared/data",
             Path(__file__).resolve().parents[3] / "shared/data"]
    for c in cands:
        if c and Path(c).is_dir():
            return Path(c).resolve()
    return None


def is_bench_report(path):
    """Whether ``path`` is a report a benchmark wrote (its third line names the ``probreg bench``
    command), which a new run of it may replace."""
    try:
        lines = Path(path).read_text(encoding="utf-8", errors="replace").splitlines()[:3]
    except OSError:
        return False
    return len(lines) == 3 and lines[0].startswith("# ") and lines[2].startswith("Command: `probreg bench")


def run_benchmark(name, args, reports_dir="reports"):
    """Run a registered benchmark and write ``reports/bench_<name>.md``; returns the path.  A file of
    that name which no benchmark wrote is refused before the benchmark runs (never replaced)."""
    from ..io.output import check_file_output, write_file_output

    if name not in BENCHMARKS:
        raise ValueError(f"unknown benchmark {name!r}; choose from {sorted(BENCHMARKS)}")
    path = Path(reports_dir) / f"bench_{name}.md"
    plan = check_file_output(path, is_bench_report, owner="a probreg benchmark")
    mod, fn = BENCHMARKS[name].split(":")
    report = getattr(importlib.import_module(mod), fn)(args)
    text = report.to_markdown(typed_command(name))
    write_file_output(path, lambda tmp: tmp.write_text(text, encoding="utf-8"), plan, is_bench_report)
    return path


def typed_command(name, argv=None):
    """The command line a report was made with, options included: ``probreg ...`` as typed, also
    through ``python -m probreg`` (whose ``argv[0]`` is ``probreg/__main__.py``); called from
    Python, the plain ``probreg bench NAME``.

    >>> typed_command("batch", ["/x/bin/probreg", "bench", "batch", "--repeats", "12"])
    'probreg bench batch --repeats 12'
    >>> typed_command("speed", ["/src/probreg/__main__.py", "bench", "speed", "--suite-dir", "/tmp/a b"])
    "probreg bench speed --suite-dir '/tmp/a b'"
    >>> typed_command("speed", ["pytest", "-q"])
    'probreg bench speed'
    """
    argv = sys.argv if argv is None else argv
    a0 = Path(argv[0]) if argv else Path()
    typed = a0.name == "probreg" or (a0.name == "__main__.py" and a0.parent.name == "probreg")
    if typed and argv[1:2] == ["bench"]:
        return "probreg " + " ".join(shlex.quote(a) for a in argv[1:])
    return "probreg bench " + name
