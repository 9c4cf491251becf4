"""`volsmpl report`: the paper's tables as data (`paper`), every result table beside them, staleness by the code
that made each result (`import_closure`), and the re-run checks that bring a stale result back (`result_check`)."""
from volsmpl.report.build import SECTIONS, Section, build_report

__all__ = ["SECTIONS", "Section", "build_report"]
