"""The independent pieces of an input, for `r2s extract --jobs`: one scenario file, log, MCAP file or bag each.

Each piece is a valid input of its source on its own (every source accepts a single file, log or bag), so a
worker extracts it with the source's own `extract`, exactly as the whole input would be, one piece after
another. A source whose input cannot be split (nuScenes: thirteen tables for every scene) is one piece.
"""

from __future__ import annotations

from pathlib import Path

from extractors.base import files_with_suffix, require_path


def input_units(source: str, input_path: str) -> list[str]:
    """The pieces of `input_path`, in the order the source's extract reads them."""
    path = require_path(input_path, f"{source} input")
    if source == "scenarionet":
        from extractors.scenarionet import scenario_files

        return [str(f) for f in scenario_files(path)]
    if source == "argoverse2":
        from extractors.argoverse2 import annotation_files

        return [str(f) for f in annotation_files(path)]
    if source == "mcap":
        return [str(f) for f in files_with_suffix(path, [".mcap"], "MCAP files")]
    if source == "rosbag":
        from extractors.rosbag import bag_paths

        return [str(b) for b, _ in bag_paths(path)]
    return [str(Path(input_path))]
