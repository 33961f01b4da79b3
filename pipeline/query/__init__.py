"""Scenario mining (`r2s query`): a pattern compiled to one DuckDB query (sql), run over a frames dataset with the
exact re-check and the streaming write of the matches (mining), events (events) and temporal patterns (temporal).
`from pipeline.query import query` is its Python API (docs/api.md), imported on first use."""


def __getattr__(name: str):
    if name == "query":
        from pipeline.query.mining import query

        return query
    raise AttributeError(f"module 'pipeline.query' has no attribute {name!r}")
