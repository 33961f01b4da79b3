"""Files and how they are written and read, below extractors and pipeline: atomic writes (`atomic`), Parquet
datasets, their footers and rows read by range (`parquet`), and sets of frame ids at dataset scale
(`frame_index`), and input files opened as regular files only, read up to a limit
(`regular_files`). It knows no schema and imports neither synth, extractors nor pipeline (docs/layout.md)."""
