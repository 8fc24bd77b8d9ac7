"""``pilworld report``: a paired run folder as one self-contained, offline ``report.html``."""

from pilworld.report.build import REPORT_FILE, build_report, report_stats

__all__ = ["REPORT_FILE", "build_report", "report_stats"]
