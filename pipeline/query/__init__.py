"""Scenario mining (`r2s query`): a pattern compiled to one DuckDB query (sql), run over a frames dataset with the
exact re-check and the streaming write of the matches (mining)."""
