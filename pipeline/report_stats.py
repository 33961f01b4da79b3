"""The numbers of `r2s report`: a programs DataFrame in, frozen values and DataFrames out. No files, no plots.

A "config" is what a row was synthesized with, named by its strategy alone unless the file mixes oracles or
solvers (then "astar-cpa / smt", ...), so one programs file can hold several of the paper's columns.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
import pandas as pd

from pipeline.programs import STATUSES
from synth.dsl import AbsoluteHeading, AbsoluteXYPos
from synth.parts import HEADING, MOTION, POSITION

# Entity-count buckets (N excludes ego). Later buckets are wide because dense frames are rare and slow.
BUCKETS: tuple[tuple[int, int | None], ...] = ((0, 0), (1, 5), (6, 10), (11, 20), (21, 40), (41, 80), (81, None))
# The absolute-coordinate program declares every entity with `on Range @ Range, facing Range deg`: 2 + 2.
ABSOLUTE_COST_PER_ENTITY = AbsoluteXYPos.cost + AbsoluteHeading.cost
# Relation kinds in the order the grammar lists them (position first, then heading, then motion if any).
POSITION_KINDS = POSITION.kinds
HEADING_KINDS = HEADING.kinds
MOTION_KINDS = MOTION.kinds
RELATION_KINDS = POSITION_KINDS + HEADING_KINDS
ALL = "all"


def bucket_label(n: int) -> str:
    for lo, hi in BUCKETS:
        if n >= lo and (hi is None or n <= hi):
            return f"{lo}+" if hi is None else (str(lo) if lo == hi else f"{lo}-{hi}")
    return "?"  # negative counts: a damaged file, kept visible rather than dropped


def bucket_order(labels) -> list[str]:
    """Bucket labels in ascending order of N (labels are not sortable as text: '11-20' < '6-10')."""
    rank = {bucket_label(lo): i for i, (lo, _) in enumerate(BUCKETS)}
    return sorted(set(labels), key=lambda b: (rank.get(b, len(rank)), b))


@dataclass(frozen=True)
class Prepared:
    frame: pd.DataFrame  # the programs rows plus columns config and bucket, one row per (frame, config)
    configs: tuple[str, ...]  # in a stable order
    duplicates_dropped: int


def prepare(df: pd.DataFrame) -> Prepared:
    """Label each row with its config and N bucket; a frame run twice under one config counts once (the last run)."""
    out = df.copy()
    varying = [c for c in ("oracle", "solver") if out[c].nunique(dropna=False) > 1]
    out["config"] = out["strategy"].fillna("?").astype(str)
    for c in varying:
        out["config"] = out["config"] + " / " + out[c].fillna("?").astype(str)
    out["n_entities"] = out["n_entities"].fillna(-1).astype(int)
    out["bucket"] = out["n_entities"].map(bucket_label)
    before = len(out)
    out = out.drop_duplicates(subset=["frame_id", "config"], keep="last").reset_index(drop=True)
    configs = tuple(sorted(out["config"].unique()))
    return Prepared(out, configs, before - len(out))


@dataclass(frozen=True)
class GroupStats:
    """One line of the statistics tables: a config (or all) within a bucket (or all)."""

    config: str
    bucket: str
    frames: int
    statuses: tuple[tuple[str, int], ...]  # every status of STATUSES, in that order
    optimal_pct: float
    mean_cost: float | None  # over frames with a program
    cost_per_entity: float | None  # mean of cost / N over frames with a program and N > 0
    absolute_ratio: float | None  # the same over 4 (the absolute program's cost per entity): 1.0 = no better
    runtime_median: float | None  # over frames that ran (errors excluded: they record no search time)
    runtime_p95: float | None
    runtime_max: float | None
    peak_rss_mb: float | None  # the largest over the group (0, as failure rows may carry, means unknown)
    smt_queries: int

    def count(self, status: str) -> int:
        return dict(self.statuses)[status]


def _opt(v) -> float | None:
    return None if v is None or pd.isna(v) else float(v)


def group_stats(rows: pd.DataFrame, config: str, bucket: str) -> GroupStats:
    counts = Counter(rows["status"])
    with_program = rows[rows["cost"].notna()]
    cost = with_program["cost"].astype(float)
    n = with_program["n_entities"].astype(float)
    ran = rows.loc[(rows["status"] != "error") & rows["runtime_s"].notna(), "runtime_s"].astype(float).to_numpy()
    per_entity = (cost / n)[n > 0]
    rss = rows.loc[rows["peak_rss_mb"] > 0, "peak_rss_mb"]
    return GroupStats(
        config=config,
        bucket=bucket,
        frames=len(rows),
        statuses=tuple((s, int(counts.get(s, 0))) for s in STATUSES),
        optimal_pct=100.0 * counts.get("optimal", 0) / len(rows) if len(rows) else 0.0,
        mean_cost=_opt(cost.mean()) if len(cost) else None,
        cost_per_entity=_opt(per_entity.mean()) if len(per_entity) else None,
        absolute_ratio=_opt(per_entity.mean() / ABSOLUTE_COST_PER_ENTITY) if len(per_entity) else None,
        runtime_median=float(np.median(ran)) if len(ran) else None,
        runtime_p95=float(np.percentile(ran, 95)) if len(ran) else None,
        runtime_max=float(ran.max()) if len(ran) else None,
        peak_rss_mb=_opt(rss.max()) if len(rss) else None,
        smt_queries=int(rows["smt_queries"].fillna(0).sum()),
    )


def by_config(p: Prepared) -> list[GroupStats]:
    """One line per config over all its frames."""
    return [group_stats(p.frame[p.frame["config"] == c], c, ALL) for c in p.configs]


def by_bucket(p: Prepared) -> list[GroupStats]:
    """One line per (bucket, config) that has frames, buckets in ascending N."""
    out = []
    for b in bucket_order(p.frame["bucket"]):
        in_bucket = p.frame[p.frame["bucket"] == b]
        out.extend(group_stats(in_bucket[in_bucket["config"] == c], c, b)
                   for c in p.configs if (in_bucket["config"] == c).any())
    return out


# ------------------------------------------------------------------------------------------------ relations

def relation_kinds(program_text: str) -> Counter:
    """How often each relation kind occurs in one DSL program (parsed with the DSL's own parser)."""
    from synth.dsl import parse_program

    return Counter(part.kind(clause) for s in parse_program(program_text).statements for part, clause in s.clauses())


@dataclass(frozen=True)
class RelationUsage:
    counts: pd.DataFrame  # index RELATION_KINDS + MOTION_KINDS, one column per config, integer counts
    unparsable: tuple[tuple[str, str, str], ...]  # (config, frame_id, parser message) of programs not in the DSL

    @property
    def motion(self) -> bool:
        """Do any programs say how fast their entities move?"""
        return bool(self.counts.loc[list(MOTION_KINDS)].to_numpy().sum())

    @property
    def kinds(self) -> tuple[str, ...]:
        """The kinds to show: the paper's always, motion's when some program has them."""
        return RELATION_KINDS + (MOTION_KINDS if self.motion else ())


def relation_usage(p: Prepared) -> RelationUsage:
    counts = pd.DataFrame(0, index=list(RELATION_KINDS + MOTION_KINDS), columns=list(p.configs), dtype=int)
    unparsable = []
    from synth.dsl import DslError

    for config, frame_id, text in p.frame.loc[p.frame["program"].notna(), ["config", "frame_id", "program"]].itertuples(
            index=False):
        try:
            kinds = relation_kinds(text)
        except DslError as exc:  # a damaged program must not sink the whole report; it is listed instead
            unparsable.append((config, frame_id, str(exc)))
            continue
        for kind, k in kinds.items():
            counts.loc[kind, config] += k
    return RelationUsage(counts, tuple(unparsable))


# ------------------------------------------------------------------------------------------------ failures

@dataclass(frozen=True)
class FailureGroup:
    """Frames that failed the same way under one config: listed once, with a few examples."""

    config: str
    status: str
    message: str
    frames: int
    examples: tuple[str, ...]


def failures(p: Prepared, examples: int = 3) -> list[FailureGroup]:
    """Error rows (and any other row carrying an error message), grouped by config, status and message."""
    bad = p.frame[(p.frame["status"] == "error") | p.frame["error"].notna()].copy()
    bad["message"] = bad["error"].fillna("(no message)").astype(str).str.split("\n").str[0].str.slice(0, 200)
    out = []
    for (config, status, message), g in bad.groupby(["config", "status", "message"], sort=True):
        ids = sorted(g["frame_id"].astype(str))
        out.append(FailureGroup(config, status, message, len(ids), tuple(ids[:examples])))
    return sorted(out, key=lambda f: (-f.frames, f.config, f.status, f.message))


# ------------------------------------------------------------------------------------------------ table 3

@dataclass(frozen=True)
class SideBySide:
    """The paper's Table 3: one row per frame (by N), one (time, memory) pair of cells per config."""

    frames: pd.DataFrame  # columns frame_id, n_entities; rows in ascending N
    status: pd.DataFrame  # frame x config -> status (NaN: the config did not run the frame)
    runtime_s: pd.DataFrame
    peak_rss_mb: pd.DataFrame
    total_frames: int  # before sampling down to max_rows


def side_by_side(p: Prepared, max_rows: int = 40) -> SideBySide:
    """Pivot; with more than max_rows frames keep an even spread over the N order (first and last always)."""
    f = p.frame
    frames = (f.groupby("frame_id", sort=False)["n_entities"].max().reset_index()
              .sort_values(["n_entities", "frame_id"], kind="stable").reset_index(drop=True))
    total = len(frames)
    if total > max_rows:
        keep = sorted(set(np.linspace(0, total - 1, max_rows).round().astype(int)))
        frames = frames.iloc[keep].reset_index(drop=True)

    def pivot(col: str) -> pd.DataFrame:
        return f.pivot(index="frame_id", columns="config", values=col).reindex(
            index=frames["frame_id"], columns=list(p.configs))

    return SideBySide(frames, pivot("status"), pivot("runtime_s"), pivot("peak_rss_mb"), total)
