"""Results layer: per-episode evaluation and sweep records -> the paper's tables and figures.

Needs only pandas and matplotlib: the report can be drawn on any machine that holds the
records, without torch, Ray or PyBullet.
"""

from grits_lab.report.build import ReportResult, build_report, default_out_dir
from grits_lab.report.run_records import RunData, load_run, normalize_records
from grits_lab.intervals import Rate, rate, wilson_interval

__all__ = [
    "Rate",
    "ReportResult",
    "RunData",
    "build_report",
    "default_out_dir",
    "load_run",
    "normalize_records",
    "rate",
    "wilson_interval",
]
