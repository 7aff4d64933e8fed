"""Close-ups read by worker processes (:mod:`deepmorph_detect.close_up_pool`): results in order,
and one clear error, not a hang, where a worker dies."""

from __future__ import annotations

import os

import pytest

import deepmorph_detect.close_up_pool as pool
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.locate import Locator


def _where(locator: Locator, shot: int) -> tuple[int, int]:
    """The shot and the process that read it (a worker's locator is its own)."""
    assert isinstance(locator, Locator)
    return shot, os.getpid()


def _dies_on_three(locator: Locator, shot: int) -> int:
    if shot == 3:
        os._exit(1)  # a worker killed, as for memory
    return shot


def test_results_come_back_in_order_from_both_workers() -> None:
    model = DeepMorphModel.load(BUNDLED_MODEL)
    read = list(pool.read_close_ups(model, range(12), _where, workers=2))
    assert [shot for shot, _ in read] == list(range(12))
    assert os.getpid() not in {pid for _, pid in read}  # read in the workers, not here
    assert [shot for shot, _ in pool.read_close_ups(model, range(3), _where, workers=1)] == [0, 1, 2]


def test_a_dead_worker_is_an_error_not_a_wait(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pool, "ANSWER_WITHIN_S", 3.0)
    model = DeepMorphModel.load(BUNDLED_MODEL)
    with pytest.raises(DeepMorphError, match="gave no answer in 3 s"):
        list(pool.read_close_ups(model, range(6), _dies_on_three, workers=2))
