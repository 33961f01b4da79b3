"""Does a clip program contain a clip? (docs/dsl.md, "Behaviour programs".) The relational program on the clip's
first frame by r2s check's semantics, and each behaviour on its entity's track: boundaries found by dynamic
programming over (segment, boundary sample), each segment read by its kinds' `holds` (the tables, in floats,
within EPS), independent of how synthesis chose them."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from synth.behaviour.kinds import EPS
from synth.behaviour.program import Behaviour, ClipProgram, Segment, parse_clip_program
from synth.behaviour.track import Clip, Track, read_clip
from synth.config import SynthConfig, as_config
from synth.scene import Scene
from synth.semantics import CheckResult, Violation, check


def segment_holds(seg: Segment, track: Track, a: int, b: int, config: SynthConfig) -> bool:
    """Segment `seg` on samples a .. b of the track: its duration, path and pace."""
    s = track.samples
    return (seg.duration.contains(s[b].t - s[a].t, EPS)
            and (seg.path is None or seg.path.holds(s, track.steps, a, b))
            and seg.pace.holds(s, a, b, config))


def behaviour_holds(behaviour: Behaviour, track: Track, config: SynthConfig) -> bool:
    """Some boundaries 0 = b_0 < ... < b_m = n - 1 make every segment hold (one sample: one segment on it)."""
    if behaviour.after is not None and not behaviour.after.contains(track.samples[0].t, EPS):
        return False
    if behaviour.after is None and not track.from_start:
        return False
    if behaviour.parked:
        return all(x.speed <= config.v_stop + EPS for x in track.samples)
    n, segments = track.n, behaviour.segments
    if n == 1:
        return len(segments) == 1 and segment_holds(segments[0], track, 0, 0, config)
    reach = {0}  # the samples a segment boundary can be at, after the segments so far
    for seg in segments:
        reach = {b for a in reach for b in range(a + 1, n) if segment_holds(seg, track, a, b, config)}
        if not reach:
            return False
    return n - 1 in reach


def check_clip(program: ClipProgram | str, scenes: Sequence[Scene | Mapping[str, Any]] | Clip,
               config: SynthConfig | Mapping[str, Any] | None = None) -> CheckResult:
    """r2s check's verdict on a clip: the violations of the first frame's relational program, an entity with no
    behaviour (`missing`), a behaviour of nothing in the clip (`extra`), a behaviour that does not hold
    (`behaviour`)."""
    if isinstance(program, str):
        program = parse_clip_program(program)
    config = as_config(config)
    clip = scenes if isinstance(scenes, Clip) else read_clip(scenes)
    out = list(check(program.program, clip.scenes[0], config).violations)
    for track in clip.tracks:
        behaviour = program.behaviour(track.id)
        if behaviour is None:
            out.append(Violation(track.id, "missing", "no behaviour for it"))
        elif not behaviour_holds(behaviour, track, config):
            out.append(Violation(track.id, "behaviour", f"no boundaries make '{_short(behaviour)}' hold of its "
                                                        f"{track.n} samples"))
    known = {t.id for t in clip.tracks}
    out.extend(Violation(b.id, "extra", "not an entity of the clip") for b in program.behaviours if b.id not in known)
    return CheckResult(tuple(out))


def _short(behaviour: Behaviour) -> str:
    text = str(behaviour).strip().replace("\n", " ")
    return text if len(text) <= 120 else text[:117] + "..."
