"""A matches file read back (`r2s render --matches`): the bindings of one frame, as (pattern name, entity id)
pairs. Only that frame's rows are read (a filter on frame_id: row-group statistics skip the rest)."""

from __future__ import annotations

import os

import pyarrow as pa
import pyarrow.dataset as ds

from pipeline.errors import UserError


def bindings_of_frame(path: str | os.PathLike, frame_id: str) -> tuple[tuple[tuple[str, str], ...], ...]:
    """Every binding of `frame_id` in a matches file (one per row: with `r2s query --all`, all of them), each as
    (name, entity id) pairs in the pattern's order; () when the frame has no match. A file that is not a matches
    file is a UserError."""
    try:
        dataset = ds.dataset(str(path), format="parquet")
        schema = dataset.schema
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise UserError(f"matches {path} is not a readable Parquet file ({str(exc)[:120]})") from None
    if ("frame_id" not in schema.names or "binding" not in schema.names
            or not pa.types.is_struct(schema.field("binding").type)
            or not all(pa.types.is_string(f.type) for f in schema.field("binding").type)):
        raise UserError(f"matches {path} is not a matches file of r2s query (it needs frame_id and a binding "
                        "struct of strings; an events file has no frame_id: use its first_frame with r2s scene)")
    try:
        rows = dataset.to_table(columns=["binding"], filter=ds.field("frame_id") == frame_id).to_pylist()
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise UserError(f"matches {path} is not readable ({str(exc)[:120]})") from None
    out = []
    for r in rows:
        pairs = tuple((name, eid) for name, eid in (r["binding"] or {}).items() if eid is not None)
        if pairs not in out:
            out.append(pairs)
    return tuple(out)
