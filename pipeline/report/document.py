"""report.md and report.html from a programs file or dataset: one document model, two renderers.

The statistics come from pipeline.report.stats (DuckDB queries) and the pictures from pipeline.report.plots; this
module only arranges them into sections and tables, then prints that one document as Markdown and as
self-contained HTML (inline CSS, plots embedded as base64), so the two files can never disagree.

Sections are built by the functions of SECTIONS, in order, each from the shared ReportContext (the numbers are
computed once, on first use): a new section is one more function there, or one passed to write_report as
`extra` (a verb option that adds a section passes its builder).
"""

from __future__ import annotations

import base64
import html
import re
import shlex
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import pandas as pd

from pipeline.programs import STATUSES
from pipeline.report.data import BANDS, NEAR, STATIONARY_SPEED, DataFrames, DataLook, data_looks, data_overview
from pipeline.report.plots import PLOT_FILES, Plot, all_plots
from pipeline.report.stats import (
    ABSOLUTE_COST_PER_ENTITY,
    FailureGroup,
    GroupStats,
    LookFrame,
    ProgramsDB,
    RelationUsage,
    SideBySide,
    by_bucket,
    by_config,
    failures,
    frames_to_look_at,
    relation_usage,
    side_by_side,
)
from synth.errors import InputError

MD_NAME, HTML_NAME = "report.md", "report.html"
SIDE_BY_SIDE_TITLE = "Strategies side by side (Table 3 layout)"
# Table-3 cells for frames that produced no time worth comparing, in the paper's words where it has them.
STOPPED = {"timeout": "TO", "memout": "OOM", "error": "ERR"}
MISSING = "—"


# ------------------------------------------------------------------------------------------------ model

@dataclass(frozen=True)
class Table:
    headers: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    align: str  # one letter a column: l (text) or r (numbers)
    groups: tuple[tuple[str, int], ...] = ()  # optional header row above: (label, columns spanned)
    marks: tuple[tuple[int, int, str], ...] = ()  # (row, column, "best" | "stopped")


@dataclass(frozen=True)
class Details:
    """A block of text (a program) behind a one-line summary: folded in HTML, a <details> block in Markdown."""

    summary: str
    code: str


@dataclass(frozen=True)
class Section:
    title: str
    blocks: tuple[str | Table | Plot | Details, ...]  # a str is one plain-text paragraph


@dataclass(frozen=True)
class Document:
    title: str
    intro: tuple[str, ...]
    sections: tuple[Section, ...]


# ------------------------------------------------------------------------------------------------ numbers

def fmt_seconds(v: float | None) -> str:
    if v is None or pd.isna(v):
        return MISSING
    return f"{v:.3f}" if v < 10 else (f"{v:.1f}" if v < 1000 else f"{v:.0f}")


def fmt_float(v: float | None, digits: int = 2) -> str:
    return MISSING if v is None or pd.isna(v) else f"{v:.{digits}f}"


def fmt_pct(v: float | None) -> str:
    return MISSING if v is None or pd.isna(v) else f"{v:.1f}%"


# ------------------------------------------------------------------------------------------------ sections

STAT_HEADERS = (
    "Frames", *STATUSES, "Optimal %", "Mean cost", "Cost / entity", "Runtime median (s)", "p95 (s)", "max (s)",
    "Peak RSS (MB)", "SMT queries",
)


def _stat_cells(s: GroupStats) -> tuple[str, ...]:
    return (
        str(s.frames), *(str(s.count(st)) for st in STATUSES), fmt_pct(s.optimal_pct), fmt_float(s.mean_cost),
        fmt_float(s.cost_per_entity),
        fmt_seconds(s.runtime_median), fmt_seconds(s.runtime_p95), fmt_seconds(s.runtime_max),
        fmt_float(s.peak_rss_mb, 1), str(s.smt_queries),
    )


def config_section(stats: list[GroupStats]) -> Section:
    table = Table(("Strategy", *STAT_HEADERS), tuple((s.config, *_stat_cells(s)) for s in stats),
                  "l" + "r" * len(STAT_HEADERS))
    return Section("By strategy", (
        "One line per strategy over all its frames. Mean cost and cost per entity (mean of cost / N) count frames "
        f"with a program; the absolute-coordinate program costs {ABSOLUTE_COST_PER_ENTITY} per entity. Runtimes "
        "count frames that ran (errors excluded); peak RSS is the largest in the group.",
        table,
    ))


def bucket_section(stats: list[GroupStats]) -> Section:
    table = Table(("N", "Strategy", *STAT_HEADERS), tuple((s.bucket, s.config, *_stat_cells(s)) for s in stats),
                  "ll" + "r" * len(STAT_HEADERS))
    return Section("By entity count", ("N is the number of entities in the frame, ego excluded.", table))


def side_by_side_section(t: SideBySide) -> Section:
    configs = tuple(t.status.columns)
    rows, marks = [], []
    for r, (frame_id, n) in enumerate(t.frames[["frame_id", "n_entities"]].itertuples(index=False)):
        cells, times = [str(frame_id), str(n)], {}
        for config in configs:
            status, secs, mem = t.status.at[frame_id, config], t.runtime_s.at[frame_id, config], \
                t.peak_rss_mb.at[frame_id, config]
            col = len(cells)
            if pd.isna(status):
                cells += [MISSING, MISSING]
                continue
            if status in STOPPED:
                cells.append(STOPPED[status])
                marks.append((r, col, "stopped"))
            elif status == "feasible":  # stopped with a program but no proof: its time is no finishing time
                cells.append(f"{fmt_seconds(secs)} (F)")
                marks.append((r, col, "stopped"))
            else:
                cells.append(fmt_seconds(secs))
                times[col] = secs
            if status == "memout":
                cells.append("OOM")
                marks.append((r, col + 1, "stopped"))
            else:  # failure rows record 0 MB when nothing was measured
                cells.append(fmt_float(mem, 1) if mem and mem > 0 else MISSING)
        raced = sum(not pd.isna(t.status.at[frame_id, c]) for c in configs)
        if times and raced > 1:  # bold the fastest finisher, as the paper does, when two or more ran the frame
            best = min(times.values())
            marks += [(r, c, "best") for c, v in times.items() if v == best]
        rows.append(tuple(cells))
    table = Table(("Frame", "N", *(h for _ in configs for h in ("Time (s)", "Mem (MB)"))), tuple(rows),
                  "lr" + "rr" * len(configs), groups=(("", 2), *((c, 2) for c in configs)), marks=tuple(marks))
    shown = (f"{len(rows)} of {t.total_frames} frames, spread evenly over N."
             if len(rows) < t.total_frames else f"All {t.total_frames} frames.")
    return Section(SIDE_BY_SIDE_TITLE, (
        f"Rows are frames in ascending N, columns are strategies, as in the paper's Table 3. {shown} "
        "TO = stopped at the time limit, OOM = stopped at the memory limit, ERR = error, (F) = stopped with a "
        f"program not proven optimal, {MISSING} = not run; "
        "the fastest time in a row is in bold. Mem is the worker's peak resident memory.",
        table,
    ))


def relation_section(usage: RelationUsage, configs: tuple[str, ...], plot: Plot) -> Section:
    rows = tuple((kind, *(str(int(usage.counts.loc[kind, c])) for c in configs),
                  str(int(usage.counts.loc[kind].sum()))) for kind in usage.kinds)
    motion = (" Motion: stationary and moving like cost 0, relative speed 1, absolute speed 2."
              if usage.motion else "")
    lanes = (" Lanes: same lane, lane left / right and oncoming lane cost 0; in intersection, on crosswalk, off road "
             "and off lane 1; a lane by id and anywhere 2." if usage.lanes else "")
    blocks: list[str | Table | Plot] = [
        "Counts of each relation in the programs, read from the DSL text (a program the counts do not account for is parsed with the DSL's own parser). "
        "ahead / behind / left / right and toward / away are the cost-0 relations; relative position and "
        "relative heading are the cost-1 fallbacks; absolute position and absolute heading cost 2." + motion + lanes,
        Table(("Relation", *configs, "Total"), rows, "l" + "r" * (len(configs) + 1)),
        plot,
    ]
    shares = {c: usage.lane_shares(c) for c in configs}
    if any(shares.values()):
        blocks.append("Where the entities are, by their lane clauses: in a lane (a lane relation or a lane by id), in "
                      "no lane (off lane, off road), or either (in an intersection, on a crosswalk, anywhere).")
        blocks.append(Table(("Config", "in a lane", "in no lane", "either"),
                            tuple((c, *(f"{100 * v:.1f}%" for v in s.values())) for c, s in shares.items() if s),
                            "lrrr"))
    if usage.unparsable:
        blocks.append(f"{usage.unparsable_total} program(s) are not in the DSL and are not counted, e.g. "
                      + "; ".join(f"{c} {f}: {m}" for c, f, m in usage.unparsable[:3]) + ".")
    return Section("Relation usage", tuple(blocks))


def failure_section(groups: list[FailureGroup], limit: int = 20) -> Section:
    if not groups:
        return Section("Failures", ("No frame failed.",))
    rows = tuple((g.config, g.status, str(g.frames), g.message, ", ".join(g.examples)) for g in groups[:limit])
    blocks: list[str | Table | Plot] = [
        "Frames that carry an error message, grouped by strategy, status and message (first line).",
        Table(("Strategy", "Status", "Frames", "Message", "Examples"), rows, "llrll"),
    ]
    if len(groups) > limit:
        blocks.append(f"… and {len(groups) - limit} more group(s).")
    return Section("Failures", tuple(blocks))


def _png_name(frame_id: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", frame_id).strip("_") + ".png"


def render_command(frames: str, programs: str, frame_id: str) -> str:
    """The shell line that draws a frame with its program (`r2s render -` reads the scene from stdin)."""
    q = shlex.quote
    return (f"r2s scene {q(frames)} {q(frame_id)} | r2s render - --programs {q(programs)} "
            f"--out {q(_png_name(frame_id))}")


def look_section(frames: list[LookFrame], frames_path: str | None, programs: str) -> Section:
    if not frames:
        return Section(FRAMES_TITLE, ("No frame stands out: no program, no runtime, no failure.",))
    where = frames_path or "FRAMES"
    rows = tuple((f.frame_id, f.reason, f.config, f.status, str(f.n_entities),
                  MISSING if f.cost is None else str(f.cost), MISSING if f.lower_bound is None else str(f.lower_bound),
                  fmt_seconds(f.runtime_s), render_command(where, programs, f.frame_id)) for f in frames)
    blocks: list[str | Table | Plot | Details] = [
        "Frames worth a look: the largest costs, the slowest, and a few of each way a frame can stop short "
        "(feasible, timeout, memout, error). Each command draws the frame's scene with its program's references."
        + ("" if frames_path else " FRAMES stands for the frames the programs came from (`r2s report --frames` "
                                  "fills it in)."),
        Table(("Frame", "Why", "Strategy", "Status", "N", "Cost", "Lower bound", "Runtime (s)", "Render"), rows,
              "llllrrrrl"),
    ]
    for f in frames:
        text = f.program if f.program else f"(no program) {f.error or ''}".strip()
        blocks.append(Details(f"{f.frame_id} ({f.config}, {f.status}, cost {MISSING if f.cost is None else f.cost})",
                              text))
    return Section(FRAMES_TITLE, tuple(blocks))


FRAMES_TITLE = "Frames worth a look"
DATA_TITLE = "The data"
DATA_LOOK_TITLE = "Frames worth a look for a data user"


def data_section(o: DataFrames) -> Section:
    """What the frames hold: entities by type, their distance from ego and their speed."""
    band_names = [f"{lo:g}–{hi:g} m" for lo, hi in zip(BANDS, BANDS[1:])] + [f"{BANDS[-1]:g}+ m"]
    speed = ("Median speed (m/s)", f"Stationary (≤ {STATIONARY_SPEED:g} m/s)") if o.has_speed else ()
    rows = tuple((t.type, str(t.boxes), str(t.frames), fmt_pct(100 * t.frames / o.frames if o.frames else None),
                  fmt_float(t.distance_median, 1), fmt_float(t.distance_p90, 1), str(t.near),
                  *((fmt_float(t.speed_median), fmt_pct(100 * t.stationary / t.boxes)) if o.has_speed else ()))
                 for t in o.types)
    bands = tuple((t.type, *(str(n) for n in t.bands)) for t in o.types)
    return Section(DATA_TITLE, (
        f"{o.frames} frame(s) of {o.scenes} scene(s), {o.boxes} entity boxes besides ego (one entity in one frame): "
        f"median {o.per_frame_median:g} per frame, at most {o.per_frame_max}. Distances are between centres, from "
        "each frame's ego" + ("; speeds as the frames carry them." if o.has_speed else
                              "; the frames carry no speeds."),
        Table(("Type", "Boxes", "Frames with one", "Share of frames", "Median distance (m)", "p90 distance (m)",
               f"Within {NEAR:g} m", *speed), rows, "lrrrrrr" + "rr" * o.has_speed),
        "Boxes by distance from ego:",
        Table(("Type", *band_names), bands, "l" + "r" * len(band_names)),
    ))


def data_look_section(looks: list[DataLook], frames_path: str | None, programs: str) -> Section:
    where = frames_path or "FRAMES"
    rows = tuple((f.frame_id, f.reason, f.detail, render_command(where, programs, f.frame_id)) for f in looks)
    text = ("Frames a data user would open first: the most crowded, the nearest to ego, pedestrians close to ego, "
            "the fastest, the rarest types, and the frames whose programs use the relations used least. Each command "
            "draws the frame with its program."
            if frames_path else
            "Frames whose programs use the relations used least (`r2s report --frames F` adds the most crowded, the "
            "nearest to ego, the fastest, the rarest types). FRAMES stands for the frames the programs came from.")
    if not looks:
        return Section(DATA_LOOK_TITLE, (text, "None: no program uses a relation."))
    return Section(DATA_LOOK_TITLE, (text, Table(("Frame", "Why", "What", "Render"), rows, "llll")))


class ReportContext:
    """What sections are built from: the programs in DuckDB, the options, and the numbers several sections share
    (each computed on first use)."""

    def __init__(self, db: ProgramsDB, out: Path, programs: str, frames: str | None = None,
                 max_table_rows: int = 40) -> None:
        self.db, self.out, self.programs, self.frames, self.max_table_rows = db, out, programs, frames, max_table_rows

    @cached_property
    def config_stats(self) -> list[GroupStats]:
        return by_config(self.db)

    @cached_property
    def bucket_stats(self) -> list[GroupStats]:
        return by_bucket(self.db)

    @cached_property
    def usage(self) -> RelationUsage:
        return relation_usage(self.db)

    @cached_property
    def data(self) -> DataFrames | str | None:
        """What the frames hold; None without --frames; why not (one line) when --frames names no readable frames
        (it also only fills in the render commands, so the report is still written, and says so)."""
        if self.frames is None:
            return None
        try:
            return data_overview(self.db, self.frames)
        except InputError as exc:
            return f"The frames given with --frames could not be read, so there is no report about the data: {exc}"

    @cached_property
    def plots(self) -> list[Plot]:
        return all_plots(self.db, self.bucket_stats, self.usage, self.out)  # relation usage last: with its table


SectionBuilder = Callable[[ReportContext], "Section | None"]


def _side_by_side(ctx: ReportContext) -> Section | None:
    if len(ctx.db.overview.configs) < 2:
        return None
    return side_by_side_section(side_by_side(ctx.db, ctx.max_table_rows))


SECTIONS: tuple[SectionBuilder, ...] = (
    lambda ctx: config_section(ctx.config_stats),
    lambda ctx: bucket_section(ctx.bucket_stats),
    _side_by_side,
    lambda ctx: Section("Plots", tuple(ctx.plots[:-1])),
    lambda ctx: relation_section(ctx.usage, ctx.db.overview.configs, ctx.plots[-1]),
    lambda ctx: None if ctx.data is None else data_section(ctx.data) if isinstance(ctx.data, DataFrames)
    else Section(DATA_TITLE, (ctx.data,)),
    lambda ctx: data_look_section(data_looks(ctx.db, ctx.data if isinstance(ctx.data, DataFrames) else None),
                                  ctx.frames, ctx.programs),
    lambda ctx: look_section(frames_to_look_at(ctx.db), ctx.frames, ctx.programs),
    lambda ctx: failure_section(failures(ctx.db)),
)


def build_document(ctx: ReportContext, extra: Sequence[SectionBuilder] = ()) -> Document:
    o = ctx.db.overview
    intro = [
        f"Programs: {o.source}. {o.rows} row(s): {o.frames} distinct frame(s) under {len(o.configs)} strategy "
        f"configuration(s) ({', '.join(o.configs)}).",
        f"Oracles: {', '.join(o.oracles) or MISSING}; solvers: {', '.join(o.solvers) or MISSING}; r2sgen version(s): "
        f"{', '.join(o.versions) or MISSING}.",
    ]
    if o.duplicates_dropped:
        intro.append(f"{o.duplicates_dropped} repeated (frame, strategy) row(s) were dropped; the last one counts.")
    sections = [s for build in (*SECTIONS, *extra) if (s := build(ctx)) is not None]
    return Document("r2s report", tuple(intro), tuple(sections))


# ------------------------------------------------------------------------------------------------ markdown

def _walk(doc: Document, heading: Callable[[str], str], table: Callable[[Table], str], plot: Callable[[Plot], str],
          text: Callable[[str], str], details: Callable[[Details], str]) -> list[str]:
    """The sections' headings and blocks in order, each rendered by the function for its kind."""
    out = []
    for s in doc.sections:
        out.append(heading(s.title))
        out += [table(b) if isinstance(b, Table) else plot(b) if isinstance(b, Plot)
                else details(b) if isinstance(b, Details) else text(b) for b in s.blocks]
    return out


# Every string of the document is plain text, much of it data (frame ids, strategy names, error messages,
# programs, file names: anyone's). The HTML renderer escapes it with html.escape; the Markdown renderer with
# md_text and md_code (md_html_text inside its one HTML block, a program's summary line), so that a Markdown
# viewer shows the text and nothing else: no raw HTML (a `<script` or an `<iframe src=javascript:...>` in a frame
# id), no link, no code span or emphasis, no new block from a newline or a leading `#`, `-` or `1.`, and no code
# fence closed from inside. The only links are to the plots we wrote.
_MD_ACTIVE = re.compile(r"([\\`*_\[\]|~])")
_MD_NUMBERED = re.compile(r"\d+(?=[.)])")


def md_text(text: str, block: bool = True) -> str:
    """Plain text as Markdown inline content that renders as exactly that text, on one line; `block`: it starts a
    block (a paragraph), where a leading `-` or `1.` would make a list (in a table cell or a heading it would not)."""
    text = " ".join(str(text).splitlines()).strip()  # every line break CommonMark or Python knows
    text = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    text = _MD_ACTIVE.sub(r"\\\1", text)
    if not block:
        return text
    if text[:1] in ("-", "+", "=", "#"):  # a list item, a heading or its underline at the start of a block
        return "\\" + text
    start = _MD_NUMBERED.match(text)  # "1." or "1)": an ordered list
    return f"{start.group()}\\{text[start.end():]}" if start else text


def md_html_text(text: str) -> str:
    """Plain text inside an HTML block of report.md (a <details> block's <summary>), on one line. CommonMark
    leaves an HTML block as it is, but some renderers read Markdown inside HTML, so the text is escaped for both:
    every ASCII character other than a letter, a digit or a space becomes a numeric character reference, which
    HTML decodes and Markdown shows as that character (`![p](http://...)` is no image in either, `http://` no
    autolink, `<` no tag)."""
    line = " ".join(str(text).splitlines()).strip()
    return "".join(f"&#{ord(c)};" if c.isascii() and not c.isalnum() and c != " " else c for c in line)


def md_code(code: str) -> str:
    """A fenced code block that holds `code` verbatim: its fence is longer than any run of backticks in it."""
    longest = max((len(run) for run in re.findall(r"`+", code)), default=0)
    fence = "`" * max(3, longest + 1)
    return f"{fence}\n{code}\n{fence}"


def _md_cell(text: str, mark: str | None) -> str:
    text = md_text(text, block=False)
    return f"**{text}**" if mark == "best" and text else text


def _md_table(t: Table) -> str:
    headers = list(t.headers)
    if t.groups:  # Markdown has no spanning headers: carry the group's name into each of its columns
        names = [g for g, span in t.groups for _ in range(span)]
        headers = [f"{g}: {h}" if g else h for g, h in zip(names, headers)]
    marks = {(r, c): m for r, c, m in t.marks}
    lines = ["| " + " | ".join(_md_cell(h, None) for h in headers) + " |",
             "|" + "|".join(":---" if a == "l" else "---:" for a in t.align) + "|"]
    lines += ["| " + " | ".join(_md_cell(v, marks.get((r, c))) for c, v in enumerate(row)) + " |"
              for r, row in enumerate(t.rows)]
    return "\n".join(lines)


def render_markdown(doc: Document) -> str:
    out = [f"# {md_text(doc.title, block=False)}", *map(md_text, doc.intro)]
    out += _walk(doc, lambda title: f"## {md_text(title, block=False)}", _md_table,
                 lambda plot: f"![{md_text(plot.title)}]({_own_file(plot.filename)})\n\n*{md_text(plot.caption)}*",
                 md_text,
                 lambda d: f"<details><summary>{md_html_text(d.summary)}</summary>\n\n"
                           f"{md_code(d.code)}\n\n</details>")
    return "\n\n".join(out) + "\n"


def _own_file(name: str) -> str:
    """A link target: only the name of a file this report wrote beside report.md (PLOT_FILES)."""
    if name not in PLOT_FILES:
        raise ValueError(f"not a file of the report: {name!r}")
    return name


# ------------------------------------------------------------------------------------------------ html

CSS = """
:root { --ink: #1d2733; --muted: #5b6675; --rule: #d9dee5; --band: #f4f6f9; --accent: #0072B2; }
* { box-sizing: border-box; }
body { margin: 0; font: 15px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, Helvetica, Arial, sans-serif;
       color: var(--ink); background: #fff; }
main { max-width: 1180px; margin: 0 auto; padding: 28px 28px 64px; }
h1 { font-size: 28px; margin: 0 0 8px; }
h2 { font-size: 20px; margin: 40px 0 10px; padding-bottom: 4px; border-bottom: 2px solid var(--accent); }
p { margin: 8px 0; }
p.intro { color: var(--muted); }
nav { margin: 14px 0 8px; display: flex; flex-wrap: wrap; gap: 6px; }
nav a { font-size: 13px; padding: 3px 10px; border: 1px solid var(--rule); border-radius: 14px;
        color: var(--accent); text-decoration: none; }
nav a:hover { background: var(--band); }
.scroll { overflow-x: auto; margin: 10px 0 16px; border: 1px solid var(--rule); border-radius: 6px; }
table { border-collapse: collapse; font-size: 13px; width: 100%; }
th, td { padding: 5px 5px; border-bottom: 1px solid var(--rule); white-space: nowrap; }
/* Headers wrap (they are words, not numbers), so wide tables fit common widths instead of scrolling. */
th { background: var(--band); font-weight: 600; text-align: left; position: sticky; top: 0; white-space: normal;
     vertical-align: bottom; }
@media (max-width: 900px) { main { padding: 16px 8px 40px; } table { font-size: 11.5px; }
                            th, td { padding: 4px 3px; } }
th.group { text-align: center; border-left: 1px solid var(--rule); }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; }
td.wrap { white-space: normal; min-width: 220px; word-break: break-word; }
tbody tr:nth-child(even) { background: #fafbfc; }
tbody tr:hover { background: #eef4fa; }
td.best { font-weight: 700; }
td.stopped { font-weight: 600; color: #8a3b00; background: #fbefe6; }
details { margin: 6px 0; border: 1px solid var(--rule); border-radius: 6px; padding: 4px 10px; }
details summary { cursor: pointer; font-size: 13px; }
pre { font-size: 12px; line-height: 1.4; overflow-x: auto; max-width: 100%; margin: 6px 0; }
figure { margin: 18px 0 26px; }
figure img { max-width: 100%; height: auto; border: 1px solid var(--rule); border-radius: 6px; }
figcaption { color: var(--muted); font-size: 13px; margin-top: 4px; }
"""


def _anchor(title: str) -> str:
    return "".join(ch if ch.isalnum() else "-" for ch in title.lower()).strip("-")


def _html_table(t: Table) -> str:
    marks = {(r, c): m for r, c, m in t.marks}
    head = ""
    if t.groups:
        head = "<tr>" + "".join(f'<th class="group" colspan="{span}">{html.escape(g)}</th>' for g, span in t.groups)
        head += "</tr>"
    head += "<tr>" + "".join(f'<th class="num">{html.escape(h)}</th>' if a == "r" else f"<th>{html.escape(h)}</th>"
                             for a, h in zip(t.align, t.headers)) + "</tr>"
    body = []
    for r, row in enumerate(t.rows):
        cells = []
        for c, v in enumerate(row):
            classes = ["num" if t.align[c] == "r" else ("wrap" if len(v) > 60 else "")]
            classes.append(marks.get((r, c), ""))
            cls = " ".join(x for x in classes if x)
            cells.append(f'<td class="{cls}">{html.escape(v)}</td>' if cls else f"<td>{html.escape(v)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f'<div class="scroll"><table><thead>{head}</thead><tbody>{"".join(body)}</tbody></table></div>'


def _html_figure(plot: Plot, images: dict[str, bytes]) -> str:
    data = base64.b64encode(images[plot.filename]).decode("ascii")
    return (f'<figure><img src="data:image/png;base64,{data}" alt="{html.escape(plot.title)}">'
            f"<figcaption><b>{html.escape(plot.title)}.</b> {html.escape(plot.caption)}</figcaption></figure>")


def render_html(doc: Document, images: dict[str, bytes]) -> str:
    """Self-contained: one file with inline CSS and the plots embedded, fit to mail or attach."""
    parts = [f"<h1>{html.escape(doc.title)}</h1>", *(f'<p class="intro">{html.escape(p)}</p>' for p in doc.intro),
             "<nav>" + "".join(f'<a href="#{_anchor(s.title)}">{html.escape(s.title)}</a>' for s in doc.sections)
             + "</nav>"]
    parts += _walk(doc, lambda title: f'<h2 id="{_anchor(title)}">{html.escape(title)}</h2>', _html_table,
                   lambda plot: _html_figure(plot, images), lambda text: f"<p>{html.escape(text)}</p>",
                   lambda d: f"<details><summary>{html.escape(d.summary)}</summary><pre>{html.escape(d.code)}</pre>"
                             "</details>")
    body = "\n".join(parts)
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            f"<title>{html.escape(doc.title)}</title>\n<style>{CSS}</style>\n</head>\n<body>\n<main>\n{body}\n"
            f"</main>\n</body>\n</html>\n")


# ------------------------------------------------------------------------------------------------ writing

def write_report(programs: str | Path, out: Path, frames: str | None = None, max_table_rows: int = 40,
                 extra: Sequence[SectionBuilder] = (), db: ProgramsDB | None = None) -> Path:
    """Write report.md, report.html and the PNGs into the (existing, empty) directory out; returns report.html."""
    own = db is None
    db = db or ProgramsDB(programs)
    try:
        ctx = ReportContext(db, out, str(programs), frames, max_table_rows)
        doc = build_document(ctx, extra)
        plots = ctx.plots
    finally:
        if own:
            db.close()
    (out / MD_NAME).write_text(render_markdown(doc), encoding="utf-8")
    images = {plot.filename: (out / plot.filename).read_bytes() for plot in plots}
    (out / HTML_NAME).write_text(render_html(doc, images), encoding="utf-8")
    return out / HTML_NAME
