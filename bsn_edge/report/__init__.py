"""``bsn-report``: a run of ``bsn-run`` made visible: one self-contained page and the numbers behind it."""

from bsn_edge.report.build import make_report
from bsn_edge.report.drive import Damage, Drive, Onset, read_drive

__all__ = ["Damage", "Drive", "Onset", "make_report", "read_drive"]
