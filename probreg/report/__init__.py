"""The self-contained HTML report of a result folder (figures embedded), and the ground-truth
overview of a synthetic clip.
"""

from .html import HtmlReport, clip_report, draw_skeleton

__all__ = [
    "HtmlReport", "draw_skeleton", "clip_report",
]
