"""Following drawings through video frames (Locator.track, SequenceLocator) on the bundled model."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.backgrounds import random_background
from deepmorph_detect.locate import Locator
from deepmorph_detect.scenes import SceneMaker
from deepmorph_detect.track import SequenceLocator, track


@pytest.fixture(scope="module")
def video(model: DeepMorphModel):
    """A print filmed for 8 frames by a camera that moves the image by about 6 px per frame."""
    return SceneMaker(model, severity="medium", seed=8).make(drawings=1, frames=8, shake_px=6.0)


def _corner_error(found: np.ndarray, truth: np.ndarray) -> float:
    return float(np.linalg.norm(found - truth, axis=1).mean())


def test_shaken_frames_move_the_truth_with_them(model: DeepMorphModel, video) -> None:
    assert len(video.frames) == len(video.frame_warps) == 8
    np.testing.assert_allclose(video.frame_warps[0], np.eye(3))
    truth = video.placements[0]
    np.testing.assert_allclose(video.corners_in_frame(truth, 0), truth.corners)
    steps = [np.abs(video.corners_in_frame(truth, k + 1) - video.corners_in_frame(truth, k)).max() for k in range(7)]
    assert 0.5 < np.median(steps) < 20, steps
    # without shake the frames are the same layout, as before
    still = SceneMaker(model, severity="medium", seed=8).make(drawings=1, frames=3)
    assert all(np.array_equal(w, np.eye(3)) for w in still.frame_warps)


def test_a_moving_print_is_followed_with_its_payload_and_pose(locator: Locator, video) -> None:
    follow = SequenceLocator(locator)
    truth = video.placements[0]
    errors = []
    fast = 0
    for k, frame in enumerate(video.frames):
        found = follow(frame, camera=video.camera)
        assert len(found) == 1, f"frame {k}"
        (det,) = found
        assert det.result.ok and np.array_equal(det.result.payload, truth.payload), f"frame {k}"
        if k > 0:
            # read again from the track's morph, or (a frame it misread) the whole way from there
            assert det.source == "tracked" and det.morph_check in ("tracked", "passed"), f"frame {k}"
            assert det.to_json()["pose_aligned_to"] == "decoded morph"
            fast += det.morph_check == "tracked"
        errors.append(_corner_error(det.corners, video.corners_in_frame(truth, k)))
    assert (follow.searched, follow.tracked) == (1, 7)
    assert fast >= 5
    # followed frames keep the sub-pixel corners of a full search
    assert np.median(errors) < 0.8, errors


def test_full_searches_come_back_regularly(locator: Locator, video) -> None:
    follow = SequenceLocator(locator, redetect_every=3)
    for frame in video.frames:
        follow(frame, camera=video.camera)
    assert follow.searched == 3 and follow.tracked == 5  # frames 0, 3 and 6 searched
    with pytest.raises(DeepMorphError, match="redetect_every"):
        SequenceLocator(locator, redetect_every=0)


def test_a_lost_drawing_is_searched_for_and_found_again(locator: Locator, video) -> None:
    follow = SequenceLocator(locator)
    assert len(follow(video.frames[0])) == 1
    empty = random_background(np.random.default_rng(3), (640, 480))
    assert track(locator, empty, follow._previous) == []
    assert follow(empty) == []  # the track is lost: a full search, which finds nothing
    assert follow.searched == 2
    (again,) = follow(video.frames[1])  # nothing to follow: searched, and found
    assert again.source == "detector" and again.result.ok
    assert follow.searched == 3


def test_unread_drawings_are_not_followed(locator: Locator, video) -> None:
    (det,) = locator.locate(video.frames[0])
    unread = replace(det, result=replace(det.result, ok=False), morph_check="not run")
    assert track(locator, video.frames[1], [unread]) == []


def test_another_payload_than_the_tracks_loses_its_ok(model: DeepMorphModel, locator: Locator, video) -> None:
    (det,) = locator.locate(video.frames[0])
    assert det.result.ok
    other = det.result.payload.copy()
    other[:4] ^= 1  # as if the track had confirmed another payload
    claimed = replace(det, result=replace(det.result, payload=other))
    (found,) = track(locator, video.frames[1], [claimed])
    # the frame reads the print's own payload, which is not the track's: withdrawn
    assert np.array_equal(found.result.payload, det.result.payload)
    assert not found.result.ok and found.morph_check == "track conflict"
