"""One timing process of bench_synth.py: synthesize frames with the source tree at --code, one request at a time.

    python bench/synth_worker.py --code TREE [--config '{"oracle": "smt"}'] [--profile OUT.pstats]

Reads one JSON line per frame on stdin, `{"set": NAME, "scene": SCENE_JSON}`, and answers each with one JSON line
on stdout: the program, hashes of its Scenic text and JSON document (without stats), and where the time went. The
benchmark runs a worker per tree and hands them the frames in turn, so both trees see the same machine load. The
tree at --code goes first on sys.path, so the same script times today's tree and a frozen checkout of an older
commit; trees whose SynthStats lack the stage split (oracle_s, ranges_s, certify_s, render_s; before issue 18)
are timed by wrapping the stages' functions as synthesize calls them. The first frame is run twice, the first
time to warm the process (z3 context, lazy imports) and not timed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

STAGES = ("oracle_s", "ranges_s", "certify_s", "render_s")


def _stage_timers():
    """Wrap the stages of an older synthesize() (module-level names it calls) with timers; returns the totals."""
    import synth.synthesize as mod

    totals = dict.fromkeys(STAGES, 0.0)

    def timed(fn, key):
        def wrapper(*a, **k):
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                totals[key] += time.perf_counter() - t
        return wrapper

    make_oracle = mod.make_oracle

    def oracle_with_table(scene, config):
        t = time.perf_counter()
        oracle = make_oracle(scene, config)
        if config.strategy == "auto":
            oracle.full_table()  # synthesize asks for it next; cached, so this moves its time here
        totals["oracle_s"] += time.perf_counter() - t
        return oracle

    mod.make_oracle = oracle_with_table
    mod.build_program = timed(mod.build_program, "ranges_s")
    mod.render_scenic = timed(mod.render_scenic, "render_s")
    from synth.smt import Z3Backend

    Z3Backend.certify = timed(Z3Backend.certify, "certify_s")
    return totals


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--code", required=True, help="the source tree to time")
    ap.add_argument("--config", default="{}", help="SynthConfig fields as JSON")
    ap.add_argument("--profile", help="write a cProfile of the frames (not the warm-up) to this file at the end")
    args = ap.parse_args()
    code = Path(args.code).resolve()
    sys.path.insert(0, str(code))
    import synth

    if Path(synth.__file__).resolve().parent.parent != code:
        print(f"synth_worker: imported {synth.__file__}, not the tree at {code}", file=sys.stderr)
        return 1
    from synth.config import SynthConfig
    from synth.scene import scene_from_dict
    from synth.synthesize import synthesize

    try:
        from synth.result import SynthStats
    except ImportError:  # a tree from before the one driver (issue 36) declares it beside synthesize
        from synth.synthesize import SynthStats

    split = "certify_s" in SynthStats.__dataclass_fields__
    totals = None if split else _stage_timers()
    config = SynthConfig(**json.loads(args.config))
    profiler, warm = None, False
    if args.profile:
        import cProfile

        profiler = cProfile.Profile()
    for line in sys.stdin:
        if not line.strip():
            continue
        item = json.loads(line)
        scene = scene_from_dict(item["scene"])
        if not warm:
            synthesize(scene, config)
            warm = True
        if totals is not None:
            for k in totals:
                totals[k] = 0.0
        if profiler is not None:
            profiler.enable()
        t = time.perf_counter()
        r = synthesize(scene, config)
        wall = time.perf_counter() - t
        if profiler is not None:
            profiler.disable()
        st = r.stats
        stages = {k: getattr(st, k) for k in STAGES} if split else dict(totals)
        doc = r.to_json_dict()
        doc.pop("stats")
        print(json.dumps({
            "set": item["set"], "frame_id": r.frame_id, "n": r.n_entities, "status": r.status, "cost": r.cost,
            "lower_bound": r.lower_bound, "certified": r.certified, "program": str(r.program),
            "scenic_sha256": hashlib.sha256(r.scenic.encode()).hexdigest(),
            "json_sha256": hashlib.sha256(json.dumps(doc, indent=1).encode()).hexdigest(),
            "wall_s": wall, "runtime_s": st.runtime_s, "search_s": st.search_s, "smt_s": st.smt_s,
            "smt_queries": st.smt_queries, "nodes_expanded": st.nodes_expanded, **stages,
        }), flush=True)
    if profiler is not None:
        profiler.dump_stats(args.profile)
    return 0


if __name__ == "__main__":
    sys.exit(main())
