"""Scene folders: labelled synthetic photos on disk (``deepmorph synth`` writes them,
``deepmorph bench-scenes`` and ``deepmorph bench-photos`` read them).

A folder holds ``scene_00000.png`` and its truth ``scene_00000.json`` (camera, and every
placement's kind, pose, homography, corners and payload) per scene, ``index.json``, and
``labels.csv`` (:mod:`deepmorph_detect.labels`: the model's codes in each photo, as a user
labels their own photos).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import atomic_write, output_folder, refuse_non_folder
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.labels import LABELS_NAME, label_rows, labels_text
from deepmorph_detect.scenes import Placement, SceneMaker


def check_scene_folder(out: Path) -> None:
    """Refuse, before any work, a place :func:`write_scenes` cannot fill without loss: a file,
    or a folder that already holds scenes (a second set would replace some of the first and
    leave the rest stale)."""
    refuse_non_folder(out)
    if out.is_dir() and (
        (out / "index.json").exists() or (out / LABELS_NAME).exists() or next(out.glob("scene_*"), None) is not None
    ):
        raise DeepMorphError(f"{out}: already holds scenes; write to a new folder, or remove them first")


def write_scenes(
    model: DeepMorphModel,
    out: Path,
    n: int,
    severity: str = "medium",
    seed: int = 0,
    size: tuple[int, int] = (640, 480),
    drawings: int = 1,
    distractors: int = 0,
    aruco: bool = True,
    empty_fraction: float = 0.0,
    on_scene: Any = None,
) -> Path:
    """Write ``n`` labelled scenes into ``out`` (``scene_00000.png`` + ``.json``, ``index.json``,
    ``labels.csv``).

    ``empty_fraction`` of the scenes hold no drawing of the model (only distractors and
    markers): the negatives for false-accept counts.

    Raises:
        DeepMorphError: ``out`` is a file, or a folder that already holds scenes (checked before
            any work: a second set would replace some of the first and leave the rest stale).
    """
    check_scene_folder(Path(out))
    out = output_folder(out)
    maker = SceneMaker(model, size, severity, seed=seed)
    rng = np.random.default_rng([seed, 7])
    names = []
    rows: list[list[str]] = []
    for i in range(n):
        empty = rng.random() < empty_fraction
        scene = maker.make(
            drawings=0 if empty else drawings,
            distractors=max(distractors, 1) if empty else distractors,
            aruco=aruco,
        )
        name = f"scene_{i:05d}"
        ok, buf = cv2.imencode(".png", scene.image)
        if not ok:  # pragma: no cover
            raise DeepMorphError("PNG encoding failed")
        atomic_write(out / f"{name}.png", buf.tobytes())
        atomic_write(out / f"{name}.json", json.dumps(scene.truth_json(), indent=1).encode())
        names.append(name)
        codes = [(p.payload, p.corners) for p in scene.placements if p.kind == "drawing" and p.payload is not None]
        rows += label_rows(f"{name}.png", codes)
        if on_scene:
            on_scene(i + 1)
    index = {"format": "deepmorph-scenes/1", "model": model.meta.drawing_name, "severity": severity,
             "seed": seed, "size": list(size), "scenes": names}  # fmt: skip
    atomic_write(out / LABELS_NAME, labels_text(rows).encode())
    atomic_write(out / "index.json", json.dumps(index, indent=1).encode())
    return out


def read_scenes(folder: Path) -> tuple[dict[str, Any], list[tuple[Path, dict[str, Any]]]]:
    """The index and ``(image path, truth)`` pairs of a scene folder; clear errors otherwise."""
    index_path = folder / "index.json"
    if not index_path.is_file():
        raise DeepMorphError(f"{folder}: not a scene folder (no index.json; make one with `deepmorph synth`)")
    try:
        index = json.loads(index_path.read_text())
        names = list(index["scenes"])
    except (ValueError, KeyError, TypeError):
        raise DeepMorphError(f"{index_path}: not a scene index written by `deepmorph synth`") from None
    scenes = []
    for name in names:
        truth_path = folder / f"{name}.json"
        try:
            truth = json.loads(truth_path.read_text())
            truth["placements"] = [Placement.from_json(p) for p in truth["placements"]]
        except (OSError, ValueError, KeyError, TypeError):
            raise DeepMorphError(f"{truth_path}: missing or malformed scene truth") from None
        scenes.append((folder / f"{name}.png", truth))
    return index, scenes


__all__ = ["check_scene_folder", "read_scenes", "write_scenes"]
