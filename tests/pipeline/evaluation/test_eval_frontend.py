"""`r2s eval-frontend`: the paper's Table 4 protocol, checked against numbers worked out by hand."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from frames.rows import scene_to_rows, write_frames
from pipeline.evaluation.frontend import Detected, assign, evaluate, metrics
from synth.scene import Entity, make_scene
from tests.support import assert_one_line_error, run_r2s

EGO = Entity("ego", "Car", 0.0, 0.0, 0.0)


def _frames(path, frames: dict[str, list[tuple[str, str, float, float, float]]]) -> str:
    rows = []
    for fid, objs in frames.items():
        ents = [EGO] + [Entity(i, t, x, y, h) for i, t, x, y, h in objs]
        rows += scene_to_rows(make_scene(fid, ents))
    write_frames(pd.DataFrame(rows), path)
    return str(path)


# Worked by hand:
#  f1: A matched at 1.0 m (0.6, 0.8) / 10 deg, B at 3.0 m / 10 deg, C's prediction 6 m away: rejected (FP + FN).
#  f2: D matched at 0.5 m / 30 deg (350 vs 20 wraps), plus a hallucinated car far away (FP).
#  f3: in the ground truth only: E is a miss.   f4: in the predictions only: a false positive.
GT = {
    "s/1": [("car1", "Car", 0.0, 10.0, 0.0), ("car2", "Car", 10.0, 0.0, 90.0), ("pedestrian3", "Pedestrian", 0.0, 25.0, 180.0)],
    "s/2": [("car1", "Car", -15.0, 15.0, 350.0)],
    "s/3": [("truck1", "Truck", 35.0, 0.0, 0.0)],
}
PRED = {
    "s/1": [("car1", "Car", 0.6, 10.8, 10.0), ("car2", "Car", 10.0, 3.0, 80.0), ("pedestrian3", "Pedestrian", 0.0, 31.0, 180.0)],
    "s/2": [("car1", "Car", -15.0, 15.5, 20.0), ("car2", "Car", 40.0, 40.0, 0.0)],
    "s/4": [("car1", "Car", 5.0, 5.0, 0.0)],
}


@pytest.fixture
def files(tmp_path):
    return _frames(tmp_path / "pred.parquet", PRED), _frames(tmp_path / "gt.parquet", GT)


def test_metrics_by_hand(files, tmp_path):
    pred, gt = files
    out = tmp_path / "eval"
    proc = run_r2s("eval-frontend", pred, gt, "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "1 frame(s) only in the ground truth" in proc.stdout
    doc = json.loads((out / "metrics.json").read_text())
    o = doc["overall"]
    assert (o["tp"], o["fp"], o["fn"]) == (3, 3, 2)
    assert o["precision"] == pytest.approx(3 / 6)
    assert o["recall"] == pytest.approx(3 / 5)
    assert o["f1"] == pytest.approx(6 / 11)
    assert o["position_error_median_m"] == pytest.approx(1.0)
    assert o["heading_error_median_deg"] == pytest.approx(10.0)
    assert (o["tp_per_frame"], o["fp_per_frame"], o["fn_per_frame"]) == pytest.approx((0.75, 0.75, 0.5))
    assert doc["frames"] == 4 and doc["frames_only_in_gt"] == ["s/3"] and doc["frames_only_in_pred"] == ["s/4"]
    rbr = doc["recall_by_range"]
    assert rbr["0-10"] == {"gt": 0, "tp": 0, "recall": None}
    assert rbr["10-20"]["recall"] == 1.0 and rbr["20-30"]["recall"] == 0.5 and rbr["30+"]["recall"] == 0.0
    cat = doc["per_category"]
    assert (cat["Car"]["tp"], cat["Car"]["fp"], cat["Car"]["fn"]) == (3, 2, 0)
    assert cat["Car"]["precision"] == pytest.approx(0.6) and cat["Car"]["recall"] == 1.0
    assert (cat["Pedestrian"]["tp"], cat["Pedestrian"]["fp"], cat["Pedestrian"]["fn"]) == (0, 1, 1)
    assert cat["Truck"]["precision"] is None and cat["Truck"]["recall"] == 0.0 and cat["Truck"]["f1"] == 0.0
    table = (out / "table.md").read_text()
    assert "| Method | Precision | Recall | F1 | TP/img | FP/img | FN/img | Pos. Err. (m) | Head Err. (deg) |" in table
    assert "| pred | 0.500 | 0.600 | 0.545 | 0.8 | 0.8 | 0.5 | 1.00 | 10.0 |" in table
    assert (out / "recall_by_range.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # A looser gate takes C's 6 m pair: one more TP, one FP and one FN fewer.
    proc = run_r2s("eval-frontend", pred, gt, "--out", str(out), "--max-distance", "6.5", "--name", "PGD")
    o = json.loads((out / "metrics.json").read_text())["overall"]
    assert (o["tp"], o["fp"], o["fn"]) == (4, 2, 1)
    assert "| PGD |" in (out / "table.md").read_text()


def test_assignment_is_optimal_not_greedy():
    # Greedy nearest-first pairs (0,12)-(0,13) at 1 m and leaves (0,15)-(0,10) at 5 m; the optimum is 2 + 2.
    gt = (Detected("Car", 0.0, 10.0, 0.0, 10.0), Detected("Car", 0.0, 13.0, 0.0, 13.0))
    pred = (Detected("Car", 0.0, 12.0, 0.0, 12.0), Detected("Car", 0.0, 15.0, 0.0, 15.0))
    pairs = assign(gt, pred, 5.0)
    assert [(q.gt, q.pred, q.position_error) for q in pairs] == [(0, 0, 2.0), (1, 1, 2.0)]
    # The assignment comes first, the distance gate after (the paper's wording).
    far = (Detected("Car", 0.0, 20.0, 0.0, 20.0),)
    assert assign(far, pred, 5.0) == (assign(far, pred, 5.0)[0],) and assign(far, pred, 4.0) == ()
    doc = metrics(evaluate({"f": gt}, {"f": ()}, 5.0))
    assert doc["overall"]["precision"] is None and doc["overall"]["recall"] == 0.0


def test_bad_input_exits_2(files, tmp_path):
    pred, gt = files
    out = str(tmp_path / "o")
    assert_one_line_error(run_r2s("eval-frontend", pred, str(tmp_path / "missing.parquet"), "--out", out), 2,
                          "does not exist")
    junk = tmp_path / "junk.parquet"
    junk.write_bytes(b"not parquet")
    assert_one_line_error(run_r2s("eval-frontend", str(junk), gt, "--out", out), 2, "parquet")
    for bad in ("-1", "0", "nan", "inf"):
        assert_one_line_error(run_r2s("eval-frontend", pred, gt, "--out", out, f"--max-distance={bad}"), 2,
                              "max-distance")
    assert_one_line_error(run_r2s("eval-frontend", pred, gt), 2, "--out")
    a_file = tmp_path / "file"
    a_file.write_text("x")
    assert_one_line_error(run_r2s("eval-frontend", pred, gt, "--out", str(a_file)), 2, "not a directory")
    assert not (tmp_path / "o").exists()


def test_the_plot_is_byte_identical_across_runs(tmp_path):
    """Deterministic output: no matplotlib version or timestamp inside the PNG."""
    from frames.rows import scene_to_rows, write_frames
    from synth.scene import scene_from_dict

    scene = scene_from_dict({"frame_id": "s/0", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": "car1", "type": "Car", "x": 1, "y": 9, "heading": 3},
        {"id": "pedestrian2", "type": "Pedestrian", "x": -4, "y": 22, "heading": 90}]})
    write_frames(scene_to_rows(scene), tmp_path / "gt.parquet")
    outs = []
    for k in range(2):
        out = tmp_path / f"out{k}"
        proc = run_r2s("eval-frontend", str(tmp_path / "gt.parquet"), str(tmp_path / "gt.parquet"), "--out", str(out))
        assert proc.returncode == 0, proc.stderr
        outs.append({p.name: p.read_bytes() for p in out.iterdir() if p.suffix == ".png"})
    assert outs[0] and outs[0] == outs[1]
    assert all(b"matplotlib" not in data for data in outs[0].values())
