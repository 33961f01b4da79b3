"""The report (`r2s report`): statistics of a programs dataset (stats), its plots (plots), the optional scenario
mining section (query_section), arranged into one document printed as Markdown and HTML (document), written whole (output). `from pipeline.report import
report` is its Python API (docs/api.md), imported on first use."""


def __getattr__(name: str):
    if name == "report":
        from pipeline.report.output import report

        return report
    raise AttributeError(f"module 'pipeline.report' has no attribute {name!r}")
