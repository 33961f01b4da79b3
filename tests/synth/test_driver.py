"""The one synthesis driver (synth.driver): a frame and a window run the same stages under the one stage timer into
the one result type, and what differs between them (the oracle, the certified frames, the names in errors) is
their Subject's."""

from __future__ import annotations

import time
from dataclasses import fields

import pytest

from synth import SynthResult, synthesize, synthesize_window
from synth.driver import CertificationError, StageTimer
from synth.result import RESULT_FIELDS, STAGES
from synth.window.program import WindowResult

# Two frames of one scene: car1 in both, ped2 only in the second (a window declares it for that frame).
FRAMES = [
    {"frame_id": "f0", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
                                    {"id": "car1", "type": "Car", "x": 0.5, "y": 8, "heading": 2}]},
    {"frame_id": "f1", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
                                    {"id": "car1", "type": "Car", "x": 0.4, "y": 9, "heading": 1},
                                    {"id": "ped2", "type": "Pedestrian", "x": -6, "y": 3, "heading": 90}]},
]


@pytest.fixture
def stages_run(monkeypatch):
    """The names of the stages the driver's timer runs, in order, for every synthesis of the test."""
    names: list[str] = []
    stage = StageTimer.stage

    def recorded(self, name):
        names.append(name)
        return stage(self, name)

    monkeypatch.setattr(StageTimer, "stage", recorded)
    return names


@pytest.mark.parametrize("run", [lambda: synthesize(FRAMES[0]), lambda: synthesize(FRAMES[1]),
                                 lambda: synthesize_window(FRAMES), lambda: synthesize_window(FRAMES[:1])],
                         ids=["frame", "frame-2", "window", "window-of-one"])
def test_a_frame_and_a_window_run_the_same_stages_in_one_timer(stages_run, run):
    started = time.perf_counter()
    result = run()
    wall = time.perf_counter() - started
    assert stages_run == list(STAGES)
    # each stage's seconds are the stats', within the synthesis's runtime, itself within the call's wall time
    seconds = [getattr(result.stats, f"{stage}_s") for stage in STAGES]
    assert all(s > 0 for s in seconds)
    assert sum(seconds) <= result.stats.runtime_s <= wall
    assert result.certified  # the default oracle has a solver: every frame's program is certified


def test_the_stage_timer_sums_a_stage_run_twice_and_times_one_that_raises():
    timer = StageTimer()
    for _ in range(2):
        with timer.stage("a"):
            time.sleep(0.01)
    with pytest.raises(KeyError), timer.stage("b"):
        time.sleep(0.01)
        raise KeyError("b")
    assert set(timer.seconds) == {"a", "b"}
    assert timer.seconds["a"] >= 0.02 and timer.seconds["b"] >= 0.01
    assert timer.elapsed() >= sum(timer.seconds.values())


def test_a_window_result_is_the_frame_result_with_its_frames():
    window, frame = synthesize_window(FRAMES), synthesize(FRAMES[0])
    assert type(window) is WindowResult and isinstance(window, SynthResult) and type(frame) is SynthResult
    # one declaration of the fields: the window's are SynthResult's, then its frames
    assert [f.name for f in fields(window)] == [f.name for f in fields(frame)] + ["frame_ids"]
    assert (window.frame_id, window.frame_ids, window.first_frame, window.last_frame) == ("f0", ("f0", "f1"), "f0",
                                                                                          "f1")
    assert window.n_entities == 2 and frame.n_entities == 1
    for result in (window, frame):
        doc = result.to_json_dict()
        for f in RESULT_FIELDS:
            if f.source != "run":
                assert isinstance(result.value(f), f.type), f
                holder = doc["stats"] if f.source == "stats" else doc
                assert f.source == "config" or holder[f.name] == result.value(f)
    # the window's document is the frame's keys with the window's before the stats
    frame_keys, window_keys = list(frame.to_json_dict()), list(window.to_json_dict())
    assert window_keys == frame_keys[:-1] + ["first_frame", "last_frame", "frames", "stats"]
    assert window.to_json_dict()["frames"] == 2


def test_a_refuted_program_is_an_internal_error_naming_the_window_frame(monkeypatch):
    """Certification is the driver's, frame by frame on each frame's solver: a refutation raises, and a window's
    names the frame it was refuted in (the solver is made to refute here: it never does on its own)."""
    refuted: list[tuple[str, list[str]]] = []

    def refute(backend, program, scene):
        ids = [st.id for st in program.statements]
        refuted.append((scene.frame_id, ids))
        return ids[-1:]

    monkeypatch.setattr("synth.driver.certify", refute)
    with pytest.raises(CertificationError, match=r"^the solver refutes the statements of car1$"):
        synthesize(FRAMES[0])
    assert refuted == [("f0", ["car1"])]
    with pytest.raises(CertificationError, match=r"^frame f0: the solver refutes the statements of car1$"):
        synthesize_window(FRAMES)
    # the first frame refuted stops the window; f0 is asked about its own program: ped2, absent from it, is not there
    assert refuted[1:] == [("f0", ["car1"])]
    assert CertificationError.exit_code == 1
