"""The rows a ScenarioNet scenario must give, computed from its arrays independently of the extractor (complex
rotation of the global offset by -ego_yaw), and the real nuScenes-mini scenarios shipped in data/, for the
extractor's tests on databases and on each converter's layout."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pandas as pd

from tests.support.extract import EXCERPT
from tests.support.scenarionet_layouts import load_real

REAL = sorted((EXCERPT / "scenarionet").glob("sd_*.pkl"))


def real_scenarios() -> list[dict]:
    return [load_real(p) for p in REAL]


def expected_rows(sd: dict) -> pd.DataFrame:
    """Every (frame, other track) the scenario holds: ego-frame x, y, heading by complex rotation of the global
    offset by -ego_yaw ((forward, left); our x = -left). nuScenes-derived scenarios give one frame per keyframe
    (10 Hz step 5k); the others one per step. Only steps where the ego is valid are frames."""
    meta, tracks = sd["metadata"], sd["tracks"]
    steps = int(sd["length"])
    stride = 5 if meta["dataset"] == "nuscenes" else 1
    scene = meta["scenario_id"]
    sdc = next(t for t in tracks if str(t) == str(meta["sdc_id"]))
    ego = tracks[sdc]["state"]
    out = []
    for step in range(0, steps, stride):
        if not np.asarray(ego["valid"]).reshape(steps)[step]:
            continue
        ex, ey = (float(v) for v in np.asarray(ego["position"]).reshape(steps, -1)[step, :2])
        eyaw = float(np.asarray(ego["heading"]).reshape(steps)[step])
        out.append({"frame_id": f"{scene}/{step // stride}", "track_id": None})
        for tid, tr in tracks.items():
            st = tr["state"]
            if tid == sdc or not np.asarray(st["valid"]).reshape(steps)[step]:
                continue
            x, y = (float(v) for v in np.asarray(st["position"]).reshape(steps, -1)[step, :2])
            z = complex(x - ex, y - ey) * cmath.exp(-1j * eyaw)
            yaw = float(np.asarray(st["heading"]).reshape(steps)[step])
            out.append({"frame_id": f"{scene}/{step // stride}", "track_id": str(tid), "ex": -z.imag, "ey": z.real,
                        "eh": math.degrees(yaw - eyaw) % 360.0})
    return pd.DataFrame(out)


def assert_rows_match(got: pd.DataFrame, scenarios: list[dict]) -> None:
    """The extractor's rows are exactly the scenarios' frames and boxes (all categories, unbounded radius)."""
    exp = pd.concat([expected_rows(sd) for sd in scenarios], ignore_index=True)
    assert set(got.frame_id) == set(exp.frame_id)
    assert got.frame_id.nunique() == exp.frame_id.nunique() == len(got[got.is_ego])
    exp = exp[exp.track_id.notna()]
    m = exp.merge(got[~got.is_ego], on=["frame_id", "track_id"], how="outer", indicator=True)
    assert (m["_merge"] == "both").all(), m[m["_merge"] != "both"][["frame_id", "track_id"]].head()
    assert len(m) == len(exp)
    assert (m.ex - m.x).abs().max() < 1e-3 and (m.ey - m.y).abs().max() < 1e-3
    gap = (m.eh - m.heading) % 360.0
    assert np.minimum(gap, 360.0 - gap).max() < 1e-3
