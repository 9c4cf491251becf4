"""`volsmpl report`: the paper's tables as data (`volsmpl.report.paper`), every result table beside them
(`volsmpl.report.build`, its sections in `volsmpl.report.sections`), staleness by the code that made each result
(`volsmpl.report.import_closure`) and the re-run checks that bring a stale result back
(`volsmpl.report.result_check`).

This package's own module runs nothing and re-exports nothing: the apps, the evaluation and the benchmark read
`volsmpl.report.paper`, and importing it must not make the report builder part of the code behind their tables (a
change of the builder would mark every table stale).

    from volsmpl.report import paper
    from volsmpl.report.build import build_report
"""
