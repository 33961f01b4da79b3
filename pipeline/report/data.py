"""The numbers of the report's sections about the data rather than the synthesizer (`r2s report --frames F`; the
sections are arranged in pipeline.report.document): what the frames hold
(entities by type, how far from ego and how fast) and frames worth a look for a data user (the most crowded, the
nearest to ego, pedestrians close to ego, the fastest, the rarest types, and the frames whose programs use the
rarest relations, the last from the programs alone).

The frames are read by DuckDB from their Parquet files, streaming (a temporary table of one row per non-ego box
spills under the report's memory limit), distances measured from each frame's ego row."""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.report.stats import ProgramsDB, relation_usage

# Distance bands from ego, metres (the last is open).
BANDS = (0.0, 10.0, 20.0, 30.0, 50.0)
NEAR = 10.0  # "close to ego", metres
STATIONARY_SPEED = 0.5  # m/s: at most this fast counts as stationary (the DSL's default V_STOP)
PER_REASON = 3


@dataclass(frozen=True)
class TypeRow:
    """One entity type over the whole dataset (boxes are entity-frames: one entity in one frame)."""

    type: str
    boxes: int
    frames: int  # frames with at least one box of this type
    distance_median: float
    distance_p90: float
    near: int  # boxes within NEAR m of ego
    bands: tuple[int, ...]  # boxes per distance band (BANDS)
    speed_median: float | None  # None: no speeds
    stationary: int | None  # boxes with a speed at most STATIONARY_SPEED


@dataclass(frozen=True)
class DataFrames:
    frames: int
    scenes: int
    boxes: int
    per_frame_median: float
    per_frame_max: int
    has_speed: bool
    types: tuple[TypeRow, ...]  # most boxes first


@dataclass(frozen=True)
class DataLook:
    reason: str
    frame_id: str
    detail: str


def load_frames(db: ProgramsDB, frames: str) -> tuple[list[str], bool]:
    """Table `d` in the programs' DuckDB: every non-ego box of the frames with its distance to its frame's ego (and
    speed, NULL where the frames have none). Returns the frames' files and whether any speed is known."""
    from frames.dataset import FramesDataset  # only --frames reads the frames

    dataset = FramesDataset.open(frames)
    files = [p.path for p in dataset.parts]
    has_speed = any("speed" in p.optional for p in dataset.parts)
    speed = "r.speed" if has_speed else "NULL::DOUBLE"
    db.con.execute("DROP TABLE IF EXISTS d")
    db.con.execute(
        f"CREATE TEMP TABLE d AS SELECT r.frame_id, r.scene, r.entity_id, r.type, "
        f"sqrt((r.x - e.x) * (r.x - e.x) + (r.y - e.y) * (r.y - e.y)) AS dist, {speed} AS speed "
        f"FROM read_parquet($files, union_by_name = true) r JOIN "
        f"(SELECT frame_id, x, y FROM read_parquet($files, union_by_name = true) WHERE is_ego) e USING (frame_id) "
        f"WHERE NOT r.is_ego", {"files": files})
    return files, has_speed


def data_overview(db: ProgramsDB, frames: str) -> DataFrames:
    """What the frames hold (and table `d`, which data_looks reads)."""
    files, has_speed = load_frames(db, frames)
    n_frames, n_scenes = db.con.execute("SELECT count(DISTINCT frame_id), count(DISTINCT scene) FROM "
                                        "read_parquet($files, union_by_name = true) WHERE is_ego",
                                        {"files": files}).fetchone()
    boxes, median, most = db.sql("SELECT sum(n), median(n), max(n) FROM (SELECT frame_id, count(*) AS n FROM d "
                                 "GROUP BY frame_id)")[0]
    bands = ", ".join(f"count(*) FILTER (dist >= {lo} AND dist < {hi})" for lo, hi in zip(BANDS, BANDS[1:]))
    rows = db.sql(
        f"SELECT type, count(*), count(DISTINCT frame_id), median(dist), quantile_cont(dist, 0.9), "
        f"count(*) FILTER (dist < {NEAR}), [{bands}, count(*) FILTER (dist >= {BANDS[-1]})], median(speed), "
        f"count(*) FILTER (speed <= {STATIONARY_SPEED}) FROM d GROUP BY type ORDER BY count(*) DESC, type")
    types = tuple(TypeRow(t, int(b), int(f), float(dm), float(dp), int(nr), tuple(int(x) for x in bs),
                          None if sm is None else float(sm), int(st) if has_speed else None)
                  for t, b, f, dm, dp, nr, bs, sm, st in rows)
    # frames without any box still count as frames (with 0 entities): the median is over boxes' frames only
    return DataFrames(int(n_frames), int(n_scenes), int(boxes or 0), float(median or 0), int(most or 0), has_speed,
                      types)


def data_looks(db: ProgramsDB, overview: DataFrames | None, per_reason: int = PER_REASON) -> list[DataLook]:
    """Frames worth a look for a data user, a few per reason, most telling first (ties by frame id). Without the
    frames (overview None), only the rarest relations of the programs."""
    out: list[DataLook] = []
    if overview is not None:
        queries = [
            ("most entities", "SELECT frame_id, count(*) AS n FROM d GROUP BY frame_id ORDER BY n DESC, frame_id",
             lambda r: f"{r[1]} entities"),
            ("nearest to ego", "SELECT frame_id, arg_min(entity_id || ' (' || type || ')', dist), min(dist) AS m "
                               "FROM d GROUP BY frame_id ORDER BY m, frame_id",
             lambda r: f"{r[1]} at {r[2]:.1f} m from ego's centre"),
            (f"most pedestrians within {NEAR:g} m", f"SELECT frame_id, count(*) AS n FROM d WHERE type = 'Pedestrian' "
                                                  f"AND dist < {NEAR} GROUP BY frame_id ORDER BY n DESC, frame_id",
             lambda r: f"{r[1]} pedestrians"),
        ]
        if overview.has_speed:
            queries.append(("fastest entity", "SELECT frame_id, arg_max(entity_id || ' (' || type || ')', speed), "
                                              "max(speed) AS m FROM d WHERE speed IS NOT NULL GROUP BY frame_id "
                                              "ORDER BY m DESC, frame_id",
                            lambda r: f"{r[1]} at {r[2]:.1f} m/s"))
        for reason, sql, detail in queries:
            out += [DataLook(reason, r[0], detail(r)) for r in db.sql(f"{sql} LIMIT {per_reason}")]
        for t in sorted(overview.types, key=lambda t: (t.boxes, t.type))[:2]:
            rows = db.sql("SELECT frame_id, count(*) AS n FROM d WHERE type = ? GROUP BY frame_id ORDER BY n DESC, "
                          f"frame_id LIMIT {per_reason}", [t.type])
            out += [DataLook(f"rare type: {t.type} ({t.boxes} in all)", r[0], f"{r[1]} {t.type}") for r in rows]
    out += rarest_relations(db, per_reason)
    return out


def rarest_relations(db: ProgramsDB, per_reason: int = PER_REASON, kinds: int = 3) -> list[DataLook]:
    """The frames whose programs use the relation kinds used least (but used) over the whole run."""
    counts = relation_usage(db).counts.sum(axis=1)
    used = sorted(((int(n), kind) for kind, n in counts.items() if n > 0))[:kinds]
    out = []
    for n, kind in used:
        column = _KIND_SQL.get(kind)
        if column is None:
            continue
        rows = db.sql(f"SELECT DISTINCT frame_id FROM p WHERE has_program AND {column} > 0 ORDER BY frame_id "
                      f"LIMIT {per_reason}")
        out += [DataLook(f"rare relation: {kind} ({n} in all)", r[0], f"its program says `{kind}`") for r in rows]
    return out


# A relation kind (the report's names) as a count over p's per-program substring counts (stats._MARKS).
_KIND_SQL = {
    **{k: f'"k_{k}"' for k in ("ahead", "behind", "left", "right", "relative position", "toward", "away",
                               "relative heading", "stationary", "moving like", "relative speed")},
    "absolute position": '("k_at" - "k_relative position")',
    "absolute heading": '("k_deg" - "k_relative heading")',
    "absolute speed": '("k_speed" - "k_relative speed")',
}
