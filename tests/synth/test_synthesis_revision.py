"""The synthesis revision (synth/version.py) moves with the golden outputs: `r2s run` keeps a stored row only when
the row's version names this revision (docs/cli.md, "When a stored program is reused"), so a change that changes
what synthesis writes must bump it, or a resumed run would keep the rows of the code before.

The golden pins (tests/data/*_golden.json: programs, costs, statuses, Scenic and JSON hashes) are digested here,
and each revision records the digest of the pins it was released with. Rewriting the pins for an intended change
of the output fails this test until SYNTHESIS_REVISION is bumped and the new digest is recorded under it below; a
change the pins do not see (lanes, motion, windows) bumps the revision by hand (synth/version.py says so)."""

from __future__ import annotations

import hashlib
import json

from synth.version import ROWS_VERSION, SYNTHESIS_REVISION, __version__
from tests.support import DATA
from tests.support.golden import KEYS

PINS = ("static_golden.json", "crowd_golden.json")
# revision -> the digest of the golden outputs at that revision (append only: one digest a revision).
REVISIONS = {
    1: "e42ca50ea82b078f8c4ce0645fee75ff4835ec4dc4c62cbf32ff8cb100960401",
}


def golden_digest() -> str:
    """SHA-256 of the pinned outputs (not the solver counts nor the commit that wrote them), in pin order."""
    cases = [[name, c["frame"], c["config"], *(c[k] for k in KEYS)]
             for name in PINS for c in json.loads((DATA / name).read_text())["cases"]]
    return hashlib.sha256(json.dumps(cases, sort_keys=True).encode()).hexdigest()


def test_the_golden_outputs_are_those_of_this_synthesis_revision():
    digest = golden_digest()
    assert SYNTHESIS_REVISION == max(REVISIONS), "record the digest of the new revision in REVISIONS"
    assert REVISIONS[SYNTHESIS_REVISION] == digest, (
        f"the golden outputs changed (digest {digest}): bump SYNTHESIS_REVISION in synth/version.py and record the "
        "new digest under it in REVISIONS, so that r2s run recomputes the rows of the revision before")
    assert len(set(REVISIONS.values())) == len(REVISIONS)  # a revision is a change of the outputs


def test_rows_name_the_version_and_the_revision():
    assert ROWS_VERSION == f"{__version__}+synthesis.{SYNTHESIS_REVISION}"
