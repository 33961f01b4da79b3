"""A clip's frames as scene JSON files, as a user makes them with `r2s scene` (the input of `r2s synth
--behaviours`, `r2s check` and `r2s simulate` on a clip)."""

from __future__ import annotations

from pipeline.scenes import scene as frame_scene


def scene_files(frames, ids, out) -> list[str]:
    """Each frame id of the frames dataset `frames` as a scene JSON file in the folder `out`, in order."""
    paths = []
    for k, fid in enumerate(ids):
        path = out / f"f{k:04d}.json"
        path.write_text(frame_scene(str(frames), fid).to_json())
        paths.append(str(path))
    return paths
