"""Golden outputs of the whole pipeline, for changes that must leave behaviour alone (a refactor, a move).

    python tools/golden_outputs.py OUT [--r2s PATH]      runs r2s on shipped data into OUT, writes OUT/digests.json
    python tools/golden_outputs.py --compare A B        exit 1 and the differing outputs if A and B differ

Every output of a fixed list of commands (programs, windows, Scenic text, scene JSON, samples, reports, queries,
exports) is digested. What a run measures rather than computes (seconds, memory, hosts, dates, the output's own
path) is left out of the digest: Parquet columns by name, text lines by pattern (below). Everything else must
be byte-identical. Takes about two minutes on two cores.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
KEY = "data/nuscenes-mini-keyframes/frames.parquet"
AV2 = "data/argoverse2-log-excerpt/frames.parquet"
FRAME = "scene-0103/0"

# (name, arguments); {out} is the output folder. Order matters: later commands read earlier outputs.
COMMANDS = [
    ("extract", ["extract", "scenarionet", "data/nuscenes-mini-excerpt/scenarionet", "--categories", "all",
                 "--out", "{out}/excerpt-frames.parquet"]),
    ("run", ["run", KEY, "--out", "{out}/programs", "--jobs", "2"]),
    ("run-motion", ["run", "{out}/excerpt-frames.parquet", "--motion", "--out", "{out}/motion.parquet", "--jobs", "2"]),
    ("run-lanes", ["run", AV2, "--lanes", "--motion", "--out", "{out}/lanes.parquet", "--jobs", "2"]),
    ("run-window", ["run", AV2, "--window", "2", "--lanes", "--out", "{out}/windows.parquet", "--jobs", "2"]),
    ("run-window-motion", ["run", "{out}/excerpt-frames.parquet", "--window", "2", "--motion",
                           "--out", "{out}/windows-motion.parquet", "--jobs", "2"]),
    ("report", ["report", "{out}/programs", "--frames", KEY, "--query", "data/patterns/queue-of-three.dsl",
                "--out", "{out}/report"]),
    ("query", ["query", KEY, "data/patterns/queue-of-three.dsl", "--out", "{out}/matches.parquet"]),
    ("query-temporal", ["query", "{out}/excerpt-frames.parquet", "data/patterns/vehicle-following-ego.dsl",
                        "--events", "--out", "{out}/events.parquet"]),
    ("query-lanes", ["query", AV2, "data/patterns/lanes/following.dsl", "--out", "{out}/lane-matches.parquet"]),
    ("scene", ["scene", KEY, FRAME, "--out", "{out}/scene.json"]),
    ("synth", ["synth", "{out}/scene.json", "--out", "{out}/scene.dsl"]),
    ("synth-json", ["synth", "{out}/scene.json", "--format", "json", "--out", "{out}/scene-result.json"]),
    ("synth-scenic", ["synth", "{out}/scene.json", "--format", "scenic", "--out", "{out}/scene.scenic"]),
    ("check", ["check", "{out}/scene.json", "{out}/scene.dsl"]),
    ("sample", ["sample", "{out}/scene.scenic", "--n", "5", "--seed", "0", "--out", "{out}/samples"]),
    ("scene-lanes", ["scene", AV2, "adcf7d18-0510-35b0-a2fa-b4cea13a6d76/0", "--out", "{out}/av2-scene.json"]),
    ("synth-lanes", ["synth", "{out}/av2-scene.json", "--lanes", "--motion", "--format", "scenic",
                     "--out", "{out}/av2-scene.scenic"]),
    ("moving-scene", ["scene", "{out}/excerpt-frames.parquet", FRAME, "--out", "{out}/moving-scene.json"]),
    ("moving-synth", ["synth", "{out}/moving-scene.json", "--motion", "--format", "scenic",
                      "--out", "{out}/moving-scene.scenic"]),
    ("moving-sample", ["sample", "{out}/moving-scene.scenic", "--n", "5", "--seed", "0", "--out", "{out}/moving-samples"]),
    ("export-scenarionet", ["export", "{out}/moving-scene.json", "{out}/moving-samples", "--to", "scenarionet",
                            "--program", "{out}/moving-scene.scenic", "--steps", "50", "--out", "{out}/scenarionet"]),
    ("export-openscenario", ["export", "{out}/moving-scene.json", "{out}/moving-samples", "--to", "openscenario",
                             "--program", "{out}/moving-scene.scenic", "--steps", "50", "--out", "{out}/openscenario"]),
]

# What a run measures, not what it computes.
MEASURED_COLUMN = re.compile(r"(time|seconds|elapsed|wall|memory|peak|rss|host|pid|created|started|finished|_s$)",
                             re.I)
MEASURED_TEXT = [
    (re.compile(r"\d+(\.\d+)?\s*(ms|s|sec|seconds|min|MB|MiB|GB|GiB)\b"), "<measured>"),
    (re.compile(r"\d{4}-\d\d-\d\d[T ]\d\d:\d\d(:\d\d(\.\d+)?)?(Z|[+-]\d\d:?\d\d)?"), "<date>"),
    (re.compile(r"\d+(\.\d+)? (frames|scenes|windows)/s"), "<rate>"),
]


def _text_digest(data: bytes, out: Path) -> str:
    text = data.decode("utf-8", errors="replace").replace(str(out), "<out>")
    for pattern, repl in MEASURED_TEXT:
        text = pattern.sub(repl, text)
    return hashlib.sha256(text.encode()).hexdigest()


def _stderr_digest(data: bytes, out: Path) -> str:
    """stderr without the lines that show a measurement: progress lines appear only when a run is slow."""
    lines = data.decode("utf-8", errors="replace").replace("\r", "\n").splitlines()
    kept = [ln for ln in lines if not any(p.search(ln) for p, _ in MEASURED_TEXT)]
    return _text_digest("\n".join(kept).encode(), out)


def _parquet_digest(path: Path) -> str:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    keep = [c for c in table.column_names if not MEASURED_COLUMN.search(c)]
    # Workers finish in any order: rows are compared as a sorted multiset.
    rows = sorted(json.dumps(r, sort_keys=True, default=repr) for r in table.select(keep).to_pylist())
    return hashlib.sha256("\n".join(rows).encode()).hexdigest()


def _unmeasured(doc):
    if isinstance(doc, dict):
        return {k: _unmeasured(v) for k, v in doc.items() if not MEASURED_COLUMN.search(k)}
    if isinstance(doc, list):
        return [_unmeasured(v) for v in doc]
    return doc


def _json_digest(path: Path, out: Path) -> str:
    try:
        doc = json.loads(path.read_text())
    except ValueError:
        return _text_digest(path.read_bytes(), out)
    return _text_digest(json.dumps(_unmeasured(doc), sort_keys=True).encode(), out)


def _report_digest(path: Path, out: Path) -> str:
    """The report's prose and query section; its tables and the frames it shows in <details> hold run times (and
    which frames were slowest), so they are left out."""
    kept, inside = [], False
    for line in path.read_text().splitlines():
        if line.startswith("<details"):
            inside = True
        if not inside and not line.startswith("|"):
            kept.append(line)
        if line.startswith("</details"):
            inside = False
    return _text_digest("\n".join(kept).encode(), out)


def digest_tree(out: Path) -> dict[str, str]:
    found = {}
    for path in sorted(p for p in out.rglob("*") if p.is_file() and p.name != "digests.json"):
        rel = str(path.relative_to(out))
        if path.suffix == ".parquet":
            found[rel] = _parquet_digest(path)
        elif path.suffix == ".json":
            found[rel] = _json_digest(path, out)
        elif path.name == "report.md":
            found[rel] = _report_digest(path, out)
        elif path.name == "report.html":  # rendered from report.md
            continue
        elif path.suffix in {".png", ".svg"}:  # pictures embed library versions and timestamps; their inputs are digested
            continue
        else:
            found[rel] = _text_digest(path.read_bytes(), out)
    return found


def run(out: Path, r2s: str) -> int:
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    streams = {}
    for name, args in COMMANDS:
        argv = [r2s] + [a.format(out=out) for a in args]
        proc = subprocess.run(argv, cwd=ROOT, capture_output=True)
        print(f"{name}: exit {proc.returncode}", file=sys.stderr)
        streams[name] = {"exit": proc.returncode, "stdout": _text_digest(proc.stdout, out),
                         "stderr": _stderr_digest(proc.stderr, out)}
        if proc.returncode:
            print(proc.stderr.decode()[-2000:], file=sys.stderr)
    doc = {"commands": streams, "files": digest_tree(out)}
    (out / "digests.json").write_text(json.dumps(doc, indent=1, sort_keys=True))
    return 0


def compare(a: Path, b: Path) -> int:
    da, db = (json.loads((p / "digests.json").read_text()) for p in (a, b))
    differ = []
    for section in ("commands", "files"):
        for key in sorted(set(da[section]) | set(db[section])):
            if da[section].get(key) != db[section].get(key):
                differ.append(f"{section}: {key}")
    for line in differ:
        print(line)
    print(f"{len(differ)} outputs differ" if differ else "identical", file=sys.stderr)
    return 1 if differ else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", type=Path)
    ap.add_argument("--r2s", default=str(ROOT / ".venv/bin/r2s"))
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
    args = ap.parse_args()
    if args.compare:
        return compare(*args.compare)
    if args.out is None:
        ap.error("OUT or --compare A B")
    return run(args.out.resolve(), args.r2s)


if __name__ == "__main__":
    sys.exit(main())
