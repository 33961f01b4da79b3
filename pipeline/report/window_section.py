"""The report's section on window programs (`r2s run --window`): how long a program stays the same, and what a
window costs against its frames' own programs (`r2s report WINDOWS --frame-programs PROGRAMS --frames FRAMES`).

All of it is DuckDB over the files (the programs' text is compared inside DuckDB, never loaded here). Consecutive
windows are a scene's windows of one configuration in time order; two are "identical" when their program texts
are, and have "the same relations" when their texts are equal once every Range is blanked (the same entities,
references and relations, whatever the Range values).
"""

from __future__ import annotations

from pipeline.errors import UserError
from pipeline.programs import programs_files
from pipeline.report.document import ReportContext, Section, SectionBuilder, Table, fmt_float, fmt_pct

WINDOW_COLUMNS = ("scene", "last_frame", "first_timestamp_us", "n_frames", "window_s")
TITLE = "Windows"

# One row per (window, configuration): the last row written wins, as for frames.
_WINDOWS = """
SELECT frame_id, scene, first_timestamp_us, last_timestamp_us, n_frames, window_s, config_hash, status, cost,
       program, regexp_replace(program, 'Range\\([^)]*\\)', 'Range', 'g') AS shape
FROM raw
QUALIFY row_number() OVER (PARTITION BY frame_id, config_hash ORDER BY filename DESC, file_row_number DESC) = 1
"""


def is_windows(ctx: ReportContext) -> bool:
    names = {r[0] for r in ctx.db.sql("DESCRIBE raw")}
    return all(c in names for c in WINDOW_COLUMNS)


def window_section(frames: str | None = None, frame_programs: str | None = None) -> SectionBuilder:
    """The builder: None for per-frame programs; with `frame_programs` (needs `frames`: where each frame is), the
    windows' costs against their frames' own."""

    def build(ctx: ReportContext) -> Section | None:
        if not is_windows(ctx):
            if frame_programs is not None:
                raise UserError(f"--frame-programs compares window programs with per-frame ones, but "
                                f"{ctx.programs} holds per-frame programs (r2s run without --window)")
            return None
        return Section(TITLE, stability(ctx) + (costs(ctx, frames, frame_programs) if frame_programs else ()))

    return build


def stability(ctx: ReportContext) -> tuple:
    rows = ctx.db.sql(f"""
        WITH w AS ({_WINDOWS}),
        s AS (SELECT *, lag(program) OVER k AS prev_program, lag(shape) OVER k AS prev_shape,
                     lag(frame_id) OVER k AS prev_frame
              FROM w WINDOW k AS (PARTITION BY config_hash, scene ORDER BY first_timestamp_us, frame_id)),
        st AS (SELECT frame_id, config_hash, split_part(line, ' = new ', 1) AS id, line
               FROM w, unnest(string_split(coalesce(shape, ''), chr(10))) AS t(line) WHERE contains(line, ' = new ')),
        kept AS (SELECT s.config_hash, count(*) AS both, count(*) FILTER (a.line = b.line) AS same
                 FROM s JOIN st a ON a.frame_id = s.frame_id AND a.config_hash = s.config_hash
                 JOIN st b ON b.frame_id = s.prev_frame AND b.config_hash = s.config_hash AND b.id = a.id
                 GROUP BY s.config_hash)
        SELECT window_s, s.config_hash, count(*), avg(n_frames), count(*) FILTER (status = 'optimal'), avg(cost),
               count(prev_frame), count(*) FILTER (program = prev_program), count(*) FILTER (shape = prev_shape),
               count(DISTINCT scene), any_value(kept.both), any_value(kept.same)
        FROM s LEFT JOIN kept USING (config_hash)
        GROUP BY window_s, s.config_hash ORDER BY window_s, s.config_hash""")
    table = []
    for window_s, config, n, frames, optimal, cost, pairs, same, shape, scenes, both, kept in rows:
        # Runs of windows with the same relations: each scene starts one, each change another.
        runs = scenes + (pairs - shape)
        table.append((f"{fmt_float(window_s)} s", config, str(n), fmt_float(frames, 1), fmt_pct(100 * optimal / n),
                      fmt_float(cost), str(pairs), _share(same, pairs), _share(shape, pairs), fmt_float(n / runs, 1),
                      _share(kept or 0, both or 0)))
    text = ("Consecutive windows: a scene's windows under one configuration, in time order. Identical: the same "
            "program text; same relations: the same text once every Range is blanked (entities, references and "
            "relations alike, Range values aside). A run is a stretch of consecutive windows with the same "
            "relations. Statements kept: of the entities declared in two consecutive windows, those whose statement "
            "is the same, Range values aside (the same reference and relation in every part).")
    return (text, Table(("window", "config hash", "windows", "frames per window", "optimal", "mean cost",
                         "consecutive pairs", "identical", "same relations", "windows per run", "statements kept"),
                        tuple(table), "rlrrrrrrrrr"))


def costs(ctx: ReportContext, frames: str | None, frame_programs: str) -> tuple:
    from frames.dataset import FramesDataset  # only --frames reads the frames

    if frames is None:
        raise UserError("--frame-programs needs --frames: the frames both programs came from (where each frame is)")
    frame_files = [p.path for p in FramesDataset.open(frames).parts]
    single_files = programs_files(frame_programs)
    rows = ctx.db.sql(f"""
        WITH w AS ({_WINDOWS}),
        f AS (SELECT DISTINCT frame_id, scene, timestamp_us FROM read_parquet(?)),
        s AS (SELECT frame_id, min(cost) AS cost FROM read_parquet(?, union_by_name = true)
              WHERE status = 'optimal' GROUP BY frame_id),
        per AS (SELECT w.window_s, w.config_hash, w.frame_id, any_value(w.cost) AS cost, any_value(w.n_frames) AS n,
                       max(s.cost) AS dearest, avg(s.cost) AS mean, count(s.cost) AS known
                FROM w JOIN f ON f.scene = w.scene AND f.timestamp_us BETWEEN w.first_timestamp_us AND w.last_timestamp_us
                LEFT JOIN s ON s.frame_id = f.frame_id
                WHERE w.cost IS NOT NULL
                GROUP BY w.window_s, w.config_hash, w.frame_id)
        SELECT window_s, config_hash, count(*), avg(cost), avg(dearest), avg(mean),
               count(*) FILTER (cost > dearest), count(*) FILTER (cost = dearest), sum(cost) / sum(dearest)
        FROM per WHERE known = n GROUP BY window_s, config_hash ORDER BY window_s, config_hash""",
                      [frame_files, single_files])
    table = tuple((f"{fmt_float(w)} s", config, str(n), fmt_float(cost), fmt_float(dearest), fmt_float(mean),
                   str(more), str(equal), fmt_float(ratio)) for w, config, n, cost, dearest, mean, more, equal, ratio
                  in rows)
    text = (f"Against the per-frame programs of {frame_programs}: each window whose every frame has an optimal "
            "per-frame program (its least cost among them), its cost beside its dearest frame's own (a lower bound: "
            "each frame's part of a window program is a program of that frame) and its frames' mean.")
    return (text, Table(("window", "config hash", "windows compared", "mean window cost", "mean dearest frame",
                         "mean frame cost", "costlier than every frame", "as cheap as the dearest frame",
                         "window cost / dearest frame"), table, "rlrrrrrrr"))


def _share(part: int, whole: int) -> str:
    return "n/a" if whole == 0 else f"{fmt_pct(100 * part / whole)} ({part})"
