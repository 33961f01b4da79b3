"""`r2s report --query PATTERN --frames FRAMES`: a report section on the frames that match a pattern.

The match count comes from pipeline.query.mining over the frames the programs came from; the frames with the most
bindings are listed with their first binding, each program the run wrote for them and the command that renders
the frame with its program. The section is one more builder passed to pipeline.report.document.write_report.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import pyarrow.parquet as pq

from pipeline.query.mining import query_frames
from pipeline.report.document import MISSING, Details, ReportContext, Section, SectionBuilder, Table, render_command
from pipeline.report.stats import programs_text
from synth.config import SynthConfig
from synth.patterns.one_frame import Pattern


@dataclass(frozen=True)
class MatchedFrame:
    frame_id: str
    n_matches: int
    binding: dict[str, str]


def top_matches(matches: Path, top: int) -> list[MatchedFrame]:
    """The frames with the most bindings (ties in input order), from a matches.parquet."""
    rows = pq.read_table(matches, columns=["frame_id", "n_matches", "binding"]).to_pylist()
    ranked = sorted(range(len(rows)), key=lambda i: (-rows[i]["n_matches"], i))[:top]
    return [MatchedFrame(rows[i]["frame_id"], rows[i]["n_matches"], rows[i]["binding"]) for i in ranked]


def longest_events(events: Path, top: int) -> list[dict]:
    """The events with the most frames (ties in the file's order: by first frame), from an events.parquet."""
    rows = pq.read_table(events).to_pylist()
    return [rows[i] for i in sorted(range(len(rows)), key=lambda i: (-rows[i]["n_frames"], i))[:top]]


def query_section(pattern: Pattern, pattern_name: str, frames: str, top: int = 10,
                  config: SynthConfig | None = None) -> SectionBuilder:
    def build(ctx: ReportContext) -> Section:
        with tempfile.TemporaryDirectory(prefix="r2s-report-query-") as tmp:
            summary = query_frames(frames, pattern, Path(tmp) / "matches.parquet", config=config, log=lambda _: None)
            best = top_matches(Path(tmp) / "matches.parquet", top)
            events = query_frames(frames, pattern, Path(tmp) / "events.parquet", config=config, events=True,
                                  log=lambda _: None)
            longest = longest_events(Path(tmp) / "events.parquet", top)
        section = matches_section(ctx, pattern, pattern_name, frames, summary, best)
        return Section(section.title, section.blocks + events_blocks(events.events, longest))

    return build


def events_blocks(n_events: int, longest: list[dict]) -> tuple:
    """The events paragraph and the table of the longest (`r2s query --events`)."""
    text = (f"{n_events} event(s): maximal runs of consecutive frames of a scene in which the same binding (the same "
            "tracks) matches" + (f". The {len(longest)} with the most frames:" if longest else "."))
    if not longest:
        return (text,)
    rows = tuple(
        (e["scene"], ", ".join(f"{n} = {i} (track {e['tracks'][n]})" for n, i in e["binding"].items()),
         e["first_frame"], e["last_frame"], MISSING if e["duration_s"] is None else f"{e['duration_s']:g}",
         str(e["n_frames"])) for e in longest)
    return (text, Table(("Scene", "Binding", "First frame", "Last frame", "Duration (s)", "Frames"), rows, "llllrr"))


def matches_section(ctx: ReportContext, pattern: Pattern, pattern_name: str, frames: str, summary,
                    best: list[MatchedFrame]) -> Section:
    ids = [m.frame_id for m in best]
    programs = ctx.db.sql("SELECT frame_id, config, status, cost, filename, file_row_number FROM p "
                          "WHERE frame_id IN (SELECT unnest(?)) ORDER BY frame_id, config", [ids])
    texts = programs_text(ctx.db, [(f, r) for *_, f, r in programs])
    by_frame: dict[str, list[tuple]] = {}
    for row in programs:
        by_frame.setdefault(row[0], []).append(row)
    blocks: list[str | Table | Details] = [
        Details(f"The pattern ({pattern_name}); its names are variables", str(pattern).rstrip("\n")),
        f"{summary.frames_matched} of {summary.frames_scanned} frames match, with {summary.bindings} binding(s) in all "
        f"(a binding gives each name a different entity of the frame under which every statement holds). "
        + (f"The {len(best)} frame(s) with the most bindings, each with its first binding (the nearest entities), "
           "the program of every strategy that ran it and the command that renders it:" if best else ""),
    ]
    if best:
        rows = []
        for m in best:
            binding = ", ".join(f"{name} = {entity}" for name, entity in m.binding.items())
            runs = by_frame.get(m.frame_id, [])
            cost = ", ".join(f"{MISSING if r[3] is None else r[3]} ({r[1]})" for r in runs) or "not in the programs"
            rows.append((m.frame_id, str(m.n_matches), binding, cost, render_command(frames, ctx.programs, m.frame_id)))
        blocks.append(Table(("Frame", "Bindings", "First binding", "Cost (strategy)", "Render"), tuple(rows), "lrlll"))
        for m in best:
            for frame_id, config, status, cost, filename, row in by_frame.get(m.frame_id, []):
                text = texts.get((filename, row)) or "(no program)"
                blocks.append(Details(f"{frame_id} ({config}, {status}, cost {MISSING if cost is None else cost})",
                                      text.rstrip("\n")))
    return Section(f"Frames matching {pattern_name}", tuple(blocks))
