"""Training the universal detector (:mod:`deepmorph_detect.universal`) on many drawings.

    python -m deepmorph.training.universal DRAWING_FOLDER... --out universal-detector.safetensors

Every step draws a fresh batch of scenes (the one capture simulator, :mod:`deepmorph_detect.scenes`,
at ``medium`` and ``hard``): zero to four prints of drawings drawn from the folders (each folder
equally often, then a drawing of it; line drawings with their stroke widths scaled by 0.5 to 1.5;
colour drawings printed through the colour plugins), and ArUco markers and QR codes as
negatives. The target of every print is its **ink square** (:func:`~deepmorph_detect.universal.ink_square`).

**Held out** (:func:`held_out`), so that benchmarks measure it on drawings it never saw: every
drawing a benchmark panel names (:data:`PANEL_DRAWINGS`: the colour panel of ``bench/colour.py``,
the capacity panel and its held-out icons of ``bench/capacity.py``, and the ghost), and one
drawing in eight of every set, by the first byte of the SHA-256 of its name (below 32).

Steps, log, checkpoints (the detector file itself, with the optimiser's state until it is
finished), ``--resume`` and Ctrl-C are :mod:`deepmorph.training.loop`'s, as for ``train-detector``.
"""

from __future__ import annotations

import argparse
import hashlib
import re
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from pydantic import Field

from deepmorph.training.detector import (
    DetectorRun,
    SceneBatches,
    SceneTrainingConfig,
    optimiser_tensors,
    restore_optimiser,
)
from deepmorph.training.loop import TrainingLoop
from deepmorph_core.bundle import TrainingRecord
from deepmorph_core.device import DEVICES
from deepmorph_core.errors import DeepMorphError, DeepMorphWarning
from deepmorph_core.graphs import GraphError
from deepmorph_core.render import render_svg_rgb
from deepmorph_core.severity import PHOTO_SIZE
from deepmorph_core.svg.reader import viewbox_of
from deepmorph_core.svg.secure import SvgError, parse_svg_bytes, read_svg_bytes
from deepmorph_detect.centrenet import detector_graph
from deepmorph_detect.network import INPUT_SIZE
from deepmorph_detect.scenes import Art, Scene, SceneMaker
from deepmorph_detect.universal import (
    INK_LEVEL,
    INK_RENDER_WIDTH,
    UniversalMeta,
    ink_square_of,
    load_universal,
    save_universal,
)

#: Drawings named by benchmark panels (``bench/colour.py``, ``bench/capacity.py``), never trained on.
PANEL_DRAWINGS = frozenset(
    "bar-chart crystal-oscillator reading switch-camera face-without-mouth pink-heart "
    "backhand-index-pointing-left-light books "
    "bold airplay codepen phone-call figma codesandbox github youtube settings flag phone-forwarded "
    "phone-incoming ghost book bell-off coffee phone-missed phone-outgoing cpu gift mail package phone-off "
    "table trash-2".split()
)
#: Share of every set held out by name: the first byte of its name's SHA-256 below this, of 256.
HELD_OUT_BYTE = 32
HELD_OUT_RULE = "every benchmark panel drawing, and each drawing whose name's SHA-256 starts with a byte below 32"


def held_out(name: str) -> bool:
    """Whether a drawing (its file name without ``.svg``) is kept out of training."""
    return name in PANEL_DRAWINGS or hashlib.sha256(name.encode()).digest()[0] < HELD_OUT_BYTE


class UniversalConfig(SceneTrainingConfig):
    """Universal detector training settings (stored in the file); ``max_prints``: the most
    drawings a scene holds."""

    steps: int = Field(default=6000, ge=1, le=10_000_000)
    max_prints: int = Field(default=4, ge=1, le=8)


@dataclass(frozen=True)
class PoolDrawing:
    """A drawing scenes may print: its SVG, viewBox, whether it is colour, and its ink square."""

    name: str
    svg: str
    viewbox: tuple[float, float, float, float]
    colour: bool
    square: np.ndarray


@dataclass
class DrawingPool:
    """The drawings of each folder that training may print (held-out ones left out), and how
    many of each folder could not be used."""

    sets: dict[str, list[PoolDrawing]]
    skipped: dict[str, int]

    def summary(self) -> dict[str, Any]:
        """What the detector file records of its training set."""
        return {
            "sets": {name: len(drawings) for name, drawings in self.sets.items()},
            "skipped": self.skipped,
            "held_out_rule": HELD_OUT_RULE,
        }


def load_drawing(path: Path) -> PoolDrawing:
    """One drawing for the pool (``currentColor`` drawn black).

    Raises:
        DeepMorphError: it cannot be read or rendered, or shows no ink.
    """
    try:
        data = read_svg_bytes(path)
        root = parse_svg_bytes(data, str(path))
        viewbox = viewbox_of(root, str(path))
    except SvgError as exc:
        raise DeepMorphError(f"{path}: {exc}") from None
    svg = data.decode("utf-8", errors="replace").replace("currentColor", "#000")
    try:
        rgb = render_svg_rgb(svg, INK_RENDER_WIDTH)  # one render: the ink, its square, its colour
    except Exception as exc:  # noqa: BLE001 - any renderer failure leaves the drawing out
        raise DeepMorphError(f"{path}: not rendered ({exc})") from None
    if rgb.min() >= INK_LEVEL:
        raise DeepMorphError(f"{path}: no ink")
    colour = bool((rgb.max(-1) - rgb.min(-1)).max() > 0.1)
    return PoolDrawing(path.stem, svg, viewbox, colour, ink_square_of(rgb, viewbox))


def load_pool(folders: list[Path], limit: int = 0) -> DrawingPool:
    """Every drawing of ``folders`` that is not held out and renders (at most ``limit`` a folder)."""
    sets: dict[str, list[PoolDrawing]] = {}
    skipped: dict[str, int] = {}
    for folder in folders:
        files = [p for p in sorted(folder.glob("*.svg")) if not held_out(p.stem)]
        files = files[:limit] if limit else files
        loaded = []
        for path in files:
            try:
                loaded.append(load_drawing(path))
            except DeepMorphError:
                skipped[folder.name] = skipped.get(folder.name, 0) + 1
        if loaded:
            sets[folder.name] = loaded
    if not sets:
        raise DeepMorphError("no drawings to train on: give folders of .svg files")
    return DrawingPool(sets, skipped)


_STROKE_WIDTH = re.compile(r'stroke-width="([0-9.]+)"')


class PoolSceneMaker(SceneMaker):
    """Scenes of drawings drawn from a pool: the truth of each print is its ink square."""

    def __init__(
        self, pool: DrawingPool, size: tuple[int, int], severity: str, seed: int, camera_width: int | None
    ) -> None:
        self._set_up(size, severity, seed, camera_width, [], colour=True)
        self.pool = list(pool.sets.values())
        self.viewbox = (0.0, 0.0, 1.0, 1.0)
        self._chosen: PoolDrawing | None = None

    def _next_drawing(self) -> tuple[float, float, float, float]:
        group = self.pool[int(self.rng.integers(len(self.pool)))]
        self._chosen = group[int(self.rng.integers(len(group)))]
        return self._chosen.viewbox

    def _drawing_art(self, width: int) -> tuple[Art, np.ndarray | None, np.ndarray]:
        chosen = self._chosen
        assert chosen is not None
        svg = chosen.svg
        if not chosen.colour:  # line drawings at other pen widths than the artist's
            factor = self.rng.uniform(0.5, 1.5)
            svg = _STROKE_WIDTH.sub(lambda m: f'stroke-width="{float(m.group(1)) * factor:.3g}"', svg)
        return self._render(chosen.name, svg, width, cache=False, colour=chosen.colour), None, chosen.square


class PoolBatches(SceneBatches):
    """:class:`~deepmorph.training.detector.SceneBatches` of pool scenes."""

    def __init__(self, pool: DrawingPool, config: UniversalConfig, start: int, stop: int) -> None:
        super().__init__(None, config, start, stop)
        self.pool = pool

    def makers(self) -> dict[str, SceneMaker]:
        return {
            sev: PoolSceneMaker(self.pool, INPUT_SIZE, sev, seed=self.cfg.seed, camera_width=PHOTO_SIZE)
            for sev in ("medium", "hard")
        }

    def make(self, maker: SceneMaker, rng: np.random.Generator) -> Scene:
        n = int(rng.integers(0, self.cfg.max_prints + 1))
        qr = "https://example.com/" + str(int(rng.integers(10**6))) if rng.random() < 0.1 else None
        return maker.make(drawings=n, aruco=bool(rng.random() < 0.2), qr=qr)


class UniversalRun(DetectorRun):
    """Training (or resuming) the universal detector; every checkpoint writes the file ``out``."""

    def __init__(
        self, pool: DrawingPool, config: UniversalConfig, out: Path, resume_from: dict[str, Any] | None = None
    ) -> None:
        self.pool = pool
        self.set_up(config, out)
        self.record = TrainingRecord(total_steps=config.steps)
        if resume_from is not None:
            self.net.load_state_dict(resume_from["net"].state_dict())
            restore_optimiser(self.opt, resume_from["tensors"])
            self.record = resume_from["meta"].record
        self.record.threads = torch.get_num_threads()
        self.record.device = self.device.type
        self._batches = None

    def dataset(self) -> PoolBatches:
        return PoolBatches(self.pool, self.cfg, self.record.step, self.cfg.steps)

    def checkpoint(self) -> None:
        meta = UniversalMeta(
            width=self.cfg.width, config=self.cfg.model_dump(), record=self.record, training_set=self.pool.summary()
        )
        graph, extra = None, {}
        if self.record.finished:
            self.net.eval()
            try:
                graph = detector_graph(self.net)
            except GraphError as exc:
                warnings.warn(DeepMorphWarning(f"the detector's ONNX graph was not stored: {exc}"), stacklevel=2)
        else:
            extra = optimiser_tensors(self.opt, self.record.step)
        save_universal(self.out, self.net, meta, graph, extra)


def train_universal(  # noqa: PLR0913
    folders: list[Path],
    out: Path,
    config: UniversalConfig,
    resume: bool = False,
    limit: int = 0,
    on_log: Callable[[dict[str, Any]], None] | None = None,
) -> tuple[Path, float]:
    """Train (or resume) the universal detector on the drawings of ``folders``; the file and
    the seconds it took. With ``resume``, ``out`` is an interrupted checkpoint and its stored
    settings are used.

    Raises:
        DeepMorphError: nothing to train on, ``out`` exists (without ``resume``), or there is no
            interrupted training at ``out`` to resume.
        Interrupted: Ctrl-C (the checkpoint says how to resume).
    """
    resume_from = None
    if resume:
        net, _, meta, tensors = load_universal(out)
        if meta.record.finished or "dtrain.step" not in tensors:
            raise DeepMorphError(f"{out}: no interrupted training to resume")
        config = UniversalConfig(**meta.config)
        resume_from = {"net": net, "meta": meta, "tensors": tensors}
    elif out.exists():
        raise DeepMorphError(f"{out}: already exists; choose another --out or pass --resume")
    t0 = time.perf_counter()
    pool = load_pool(folders, limit)
    print(f"pool: {pool.summary()} in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    run = UniversalRun(pool, config, out, resume_from)
    loop = TrainingLoop(out, config)
    summary = loop.run(run, on_log)
    return out, summary.elapsed_s


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folders", type=Path, nargs="+", help="folders of .svg drawings")
    p.add_argument("--out", type=Path, required=True, help="the detector file to write (also the checkpoint)")
    p.add_argument("--steps", type=int, default=UniversalConfig().steps)
    p.add_argument("--batch", type=int, default=UniversalConfig().batch)
    p.add_argument("--lr", type=float, default=UniversalConfig().lr)
    p.add_argument("--channels", type=int, default=UniversalConfig().width)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--device", choices=DEVICES, default="auto", help="where the network trains")
    p.add_argument("--limit", type=int, default=0, help="at most N drawings a folder (quick runs)")
    p.add_argument("--resume", action="store_true")
    args = p.parse_args(argv)
    config = UniversalConfig(
        steps=args.steps, batch=args.batch, lr=args.lr, width=args.channels, seed=args.seed,
        threads=args.threads, workers=args.workers, device=args.device,
    )  # fmt: skip
    try:
        out, seconds = train_universal(args.folders, args.out, config, args.resume, args.limit)
    except DeepMorphError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out} ({config.steps} steps in {seconds:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
