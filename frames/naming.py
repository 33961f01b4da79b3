"""Stable entity ids: within a scene an entity keeps one id in every frame it appears in (docs/formats.md).

Ids are numbered per type by first appearance in the scene (`car1` is the first car the scene shows, `car7` the
seventh); entities first seen in the same frame are numbered by distance to ego, then by track id. The numbering
needs only the frames of one scene, in order, which is how every source yields them: a scene's frames come
together and scenes are independent, so the state is one scene's tracks and is dropped at the next scene.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field


@dataclass
class SceneNames:
    """The ids given so far in the current scene. Mutable on purpose (like the ExtractTally): a FrameBuilder
    names each frame's entities as the frames stream, and a new scene starts a new numbering."""

    scene: str | None = None
    ids: dict[tuple[str, int], str] = field(default_factory=dict)  # (track id, occurrence in a frame) -> id
    counts: Counter = field(default_factory=Counter)  # lower-case type -> ids given

    def name(self, scene: str, track_ids: Sequence[str], types: Sequence[str],
             distances: Sequence[float]) -> list[str]:
        """The ids of one frame's non-ego entities (parallel to the arguments).

        A track keeps the id it was first given in this scene, whatever its type later (a track whose class
        changes mid-scene stays one entity). A track id met twice in one frame (a source that repeats a box) is
        two entities: its k-th box in a frame (by distance) is the k-th entity of that track, each with its own
        stable id."""
        if scene != self.scene:
            self.scene, self.ids, self.counts = scene, {}, Counter()
        order = sorted(range(len(track_ids)), key=lambda i: (distances[i], track_ids[i]))
        seen: Counter = Counter()
        out = [""] * len(track_ids)
        for i in order:
            key = (track_ids[i], seen[track_ids[i]])
            seen[track_ids[i]] += 1
            if key not in self.ids:
                prefix = types[i].lower()
                self.counts[prefix] += 1
                self.ids[key] = f"{prefix}{self.counts[prefix]}"
            out[i] = self.ids[key]
        return out
