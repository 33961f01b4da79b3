"""One timing process of bench_synth.py: synthesize every frame of a JSONL file with the source tree at --code.

    python bench/synth_worker.py FRAMES.jsonl --code TREE --out RESULTS.jsonl [--config '{"oracle": "smt"}']

The tree at --code goes first on sys.path, so the same script times today's tree and a frozen checkout of an
older commit. Each line of FRAMES is `{"set": NAME, "scene": SCENE_JSON}`; each line written is one frame's
record: the program, hashes of its Scenic text and JSON document, and where the time went. Trees whose
SynthStats lack the stage split (oracle_s, ranges_s, certify_s, render_s; commits before issue 18) are timed
by wrapping the stages' functions as synthesize calls them. One warm-up frame is run first and not recorded.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path


def _stage_timers(code: Path):
    """Wrap the stages of an older synthesize() (module-level names it calls) with timers; returns the totals."""
    import synth.synthesize as mod

    totals = {"oracle_s": 0.0, "ranges_s": 0.0, "certify_s": 0.0, "render_s": 0.0}

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
    ap.add_argument("frames")
    ap.add_argument("--code", required=True, help="the source tree to time")
    ap.add_argument("--out", required=True)
    ap.add_argument("--config", default="{}", help="SynthConfig fields as JSON")
    ap.add_argument("--profile", help="write a cProfile of the frames (not the warm-up) to this file")
    args = ap.parse_args()
    code = Path(args.code).resolve()
    sys.path.insert(0, str(code))
    import synth

    if Path(synth.__file__).resolve().parent.parent != code:
        print(f"synth_worker: imported {synth.__file__}, not the tree at {code}", file=sys.stderr)
        return 1
    import networkx  # noqa: F401  (the search imports it lazily: warm it, as a long run would have)

    from synth.config import SynthConfig
    from synth.scene import scene_from_dict
    from synth.synthesize import SynthStats, synthesize

    split = "certify_s" in SynthStats.__dataclass_fields__
    totals = None if split else _stage_timers(code)
    config = SynthConfig(**json.loads(args.config))
    lines = [json.loads(line) for line in Path(args.frames).read_text().splitlines() if line.strip()]
    synthesize(scene_from_dict(lines[0]["scene"]), config)  # warm-up: z3 context, lazy imports
    profiler = None
    if args.profile:
        import cProfile

        profiler = cProfile.Profile()
        profiler.enable()
    with open(args.out, "w") as out:
        for item in lines:
            scene = scene_from_dict(item["scene"])
            if totals is not None:
                for k in totals:
                    totals[k] = 0.0
            t = time.perf_counter()
            r = synthesize(scene, config)
            wall = time.perf_counter() - t
            st = r.stats
            stages = ({k: getattr(st, k) for k in ("oracle_s", "ranges_s", "certify_s", "render_s")} if split
                      else dict(totals))
            doc = r.to_json_dict()
            doc.pop("stats")
            out.write(json.dumps({
                "set": item["set"], "frame_id": r.frame_id, "n": r.n_entities, "status": r.status, "cost": r.cost,
                "lower_bound": r.lower_bound, "certified": r.certified, "program": str(r.program),
                "scenic_sha256": hashlib.sha256(r.scenic.encode()).hexdigest(),
                "json_sha256": hashlib.sha256(json.dumps(doc, indent=1).encode()).hexdigest(),
                "wall_s": wall, "runtime_s": st.runtime_s, "search_s": st.search_s, "smt_s": st.smt_s,
                "smt_queries": st.smt_queries, "nodes_expanded": st.nodes_expanded, **stages,
            }) + "\n")
            out.flush()
    if profiler is not None:
        profiler.disable()
        profiler.dump_stats(args.profile)
    return 0


if __name__ == "__main__":
    sys.exit(main())
