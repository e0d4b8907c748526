"""Benchmarks: each module measures one thing and writes Markdown (with its command) to ``reports/``.

Run them with ``probreg bench NAME`` (``probreg bench --list`` shows the names).
"""

from .common import BENCHMARKS, BenchReport, run_benchmark

__all__ = ["BENCHMARKS", "BenchReport", "run_benchmark"]
