"""Golden outputs: what `r2s synth` prints for a scene and a configuration, pinned byte for byte.

A pin holds the program, its cost, status and `certified`, and SHA-256 hashes of the Scenic text and of the
`--format json` document without its stats; beside them the solver queries and search nodes it took. Pins are
written case by case, each in a process of its own (as `r2s synth` runs), by the core of a given source tree:

    python tests/synth/test_static_golden.py --write [--tree PATH]     (default: this tree)

so that a later core can be held to an earlier one's output. The counts are checked only where a change of the
core must leave them alone (see `check`).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

KEYS = ("program", "cost", "status", "certified", "scenic_sha256", "json_sha256")


def case_output(scene, cfg: dict) -> dict:
    from synth.config import SynthConfig
    from synth.synthesize import synthesize

    result = synthesize(scene, SynthConfig(**cfg))
    doc = result.to_json_dict()
    stats = doc.pop("stats")
    return {"program": str(result.program), "cost": result.cost, "status": result.status,
            "certified": result.certified,
            "scenic_sha256": hashlib.sha256(result.scenic.encode()).hexdigest(),
            "json_sha256": hashlib.sha256(json.dumps(doc, indent=1).encode()).hexdigest(),
            "smt_queries": stats["smt_queries"], "nodes_expanded": stats["nodes_expanded"]}


def output(scene, cfg: dict) -> dict:
    """case_output, in this process, except for the monolithic strategy: z3's optimum among equally cheap orders
    depends on the terms its context already holds, so a monolithic answer is pinned as `r2s synth` gives it, in a
    fresh process (a process that solved other frames first may answer another optimal order)."""
    if cfg.get("strategy") == "monolithic":
        return fresh_output(scene, cfg, Path(__file__).resolve().parents[2])
    return case_output(scene, cfg)


def fresh_output(scene, cfg: dict, tree: Path) -> dict:
    proc = subprocess.run([sys.executable, __file__, json.dumps(cfg)], input=scene.to_json(), capture_output=True,
                          text=True, env=dict(os.environ, PYTHONPATH=str(tree)), cwd=tree, check=True)
    return json.loads(proc.stdout)


def check(got: dict, pin: dict, cfg: dict) -> None:
    """The output is the pinned one. The paper's all-SMT mode asks the solver the same questions (issue 18 made the
    default oracle ask it fewer); every strategy but auto expands the same nodes (auto's A* prunes more)."""
    for key in KEYS:
        assert got[key] == pin[key], key
    if cfg.get("oracle") == "smt":
        assert got["smt_queries"] == pin["smt_queries"]
    if cfg.get("strategy", "auto") != "auto":
        assert got["nodes_expanded"] == pin["nodes_expanded"]


def load_pins(path: Path) -> dict[tuple[str, str], dict]:
    """Pins by (frame, configuration as canonical JSON)."""
    return {(p["frame"], key(p["config"])): p for p in json.loads(path.read_text())["cases"]}


def key(cfg: dict) -> str:
    return json.dumps(cfg, sort_keys=True)


def case_ids(cases: list[tuple[str, dict]]) -> list[str]:
    return [f"{f}-{'-'.join(map(str, c.values()))}" for f, c in cases]


def write(path: Path, cases: list[tuple[str, dict]], scenes: dict, tree: Path) -> None:
    """Pin every case, each in a fresh process whose `synth` comes from `tree`."""
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=tree).stdout.strip()
    out = []
    for frame, cfg in cases:
        out.append({"frame": frame, "config": cfg, **fresh_output(scenes[frame], cfg, tree)})
        print(frame, cfg, out[-1]["cost"], out[-1]["nodes_expanded"], flush=True)
    path.write_text(json.dumps({"written_at_commit": commit or "unknown", "cases": out}, indent=1) + "\n")
    print(f"wrote {path}")


def tree_argument(argv: list[str]) -> Path:
    return Path(argv[argv.index("--tree") + 1]).resolve() if "--tree" in argv else Path(__file__).resolve().parents[2]


if __name__ == "__main__":
    # One case: the configuration as argument, the scene JSON on stdin, the output as JSON on stdout.
    import synth
    from synth.scene import scene_from_dict

    print(f"synth from {Path(synth.__file__).parent}", file=sys.stderr)
    print(json.dumps(case_output(scene_from_dict(json.loads(sys.stdin.read())), json.loads(sys.argv[1]))))
