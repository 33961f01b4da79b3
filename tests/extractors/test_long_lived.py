"""A scenario's long-lived objects are left out of cyclic garbage collection while its frames are built
(extractors.base.LongLived): frozen during the frames, thawed after them however the caller stops, a caller's own
freeze never thawed, cycles still collected after the scope, and the frames the same whether it freezes or not."""

from __future__ import annotations

import gc
import pickle
import weakref

import pytest

from extractors.base import ExtractOptions, LongLived
from extractors.categories import ALL
from extractors.scenarionet import extract
from tests.support.waymo_maps import waymo_scenario


@pytest.fixture
def scenario(tmp_path):
    path = tmp_path / "sd_waymo_v1.2_synth.pkl"
    path.write_bytes(pickle.dumps(waymo_scenario(), protocol=4))
    return path


@pytest.fixture(autouse=True)
def thawed():
    gc.unfreeze()  # no test starts with, or leaves, objects frozen
    yield
    gc.unfreeze()


def _frames(path, maps=True):
    roads = []
    frames = list(extract(str(path), ExtractOptions(categories=ALL), maps=roads.append if maps else None))
    return frames, roads


@pytest.mark.parametrize("maps", [True, False])
def test_frozen_while_the_frames_are_built_and_thawed_after(scenario, maps):
    seen = []
    for rows in extract(str(scenario), ExtractOptions(categories=ALL), maps=(lambda road: None) if maps else None):
        seen.append(gc.get_freeze_count())
        assert rows
    assert seen and min(seen) > 0  # the scenario (and its map) frozen at every frame
    assert gc.get_freeze_count() == 0


def test_a_caller_that_stops_early_leaves_nothing_frozen(scenario):
    frames = extract(str(scenario), ExtractOptions(categories=ALL), maps=lambda road: None)
    next(frames)
    assert gc.get_freeze_count() > 0
    frames.close()
    assert gc.get_freeze_count() == 0


def test_a_caller_s_own_freeze_is_never_thawed_and_the_frames_are_the_same(scenario):
    mine, mine_roads = _frames(scenario)
    assert mine_roads and any("lanes" in r for f in mine for r in f)  # the map was read, the facts decided
    gc.freeze()
    frozen = gc.get_freeze_count()
    theirs, their_roads = _frames(scenario)
    assert gc.get_freeze_count() >= frozen  # the caller's objects still frozen: not the scope's to thaw
    assert theirs == mine and their_roads == mine_roads


def test_a_cycle_frozen_in_the_scope_is_collected_after_it():
    class Node:
        pass

    a, b = Node(), Node()
    a.other, b.other = b, a
    gone = weakref.ref(a)
    with LongLived() as scope:
        scope.keep()
        del a, b
        gc.collect()
        assert gone() is not None  # frozen: no collection visits it
    gc.collect()
    assert gone() is None
