"""``deepmorph export``: a model's networks as ONNX files, with a manifest, for other programs.

:func:`export_model` writes ``decoder.onnx``, ``detector.onnx`` (when the model has a detector
that can be exported), ``verifier.onnx`` (when it has a proposal verifier) and ``manifest.json``
into a folder, all or none, and can store the graphs in a bundle (an old bundle then needs no
export when it is loaded). The graphs are the ones the bundle stores, else exported now and
checked against PyTorch. The manifest
(:func:`manifest`) says what each graph takes and gives, and the numbers a host program needs
for the steps around them: the template and its geometry, the framing, the code
(``docs/export.md``).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from deepmorph_core import __version__
from deepmorph_core.fileio import atomic_write_all, check_target, output_folder, refuse_to_overwrite
from deepmorph_core.graphs import StoredGraph
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.plugins import Registry, default_registry
from deepmorph_core.reading_channel import channel_name
from deepmorph_detect.network import INPUT_SIZE, STRIDE
from deepmorph_detect.read import RECTIFY_WIDTH_FACTOR
from deepmorph_detect.universal import UniversalDetector, ink_square
from deepmorph_detect.verifier import (
    CROP_GROWTH,
    CROP_PERCENTILES,
    CROP_RANGE,
    CROP_SIZE,
    stored_verifier,
    verifier_graph,
)

FORMAT = "deepmorph-export/1"
FILES = {"decoder": "decoder.onnx", "detector": "detector.onnx", "verifier": "verifier.onnx"}


@dataclass
class ExportSummary:
    """What :func:`export_model` wrote.

    Attributes:
        files: file name -> ``{"path", "bytes", "sha256"}`` of each file written.
        graphs: network -> ``"stored"`` (taken from the bundle) or ``"exported"`` (made now).
        bundle: the bundle written with the graphs, if any.
        notes: what was left out and why.
    """

    files: dict[str, dict[str, Any]] = field(default_factory=dict)
    graphs: dict[str, str] = field(default_factory=dict)
    bundle: str | None = None
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {"files": self.files, "graphs": self.graphs, "bundle": self.bundle, "notes": self.notes}


def model_graphs(model: DeepMorphModel, registry: Registry | None = None) -> tuple[dict[str, StoredGraph], list[str]]:
    """The model's graphs (the stored ones, the others exported now and kept in
    ``model.graphs``), and notes on any network left out.

    Raises:
        GraphError: a network could not be exported or its graph differs from PyTorch.
        PluginError: the model names a detector that is not installed.
    """
    notes: list[str] = []
    if "decoder" not in model.graphs:
        model.graphs["decoder"] = model.decoder_graph()
    meta = model.meta.detector
    shipped: dict[str, StoredGraph] = {}  # the universal detector's: not stored in the bundle (no weights there)
    if meta is None:
        universal = UniversalDetector.graph(model)
        if universal is None:
            notes.append("no detector: the universal detector's file holds no ONNX graph")
        else:
            notes.append("detector: the universal one (its quadrilaterals are ink squares: manifest.json)")
            shipped["detector"] = universal
    else:
        detector = (registry or default_registry()).detector(meta.name)
        make = getattr(detector, "graph", None)
        graph = make(model) if make is not None else None
        if graph is None:
            notes.append(f"no detector: the {meta.name!r} detector has no ONNX graph")
        else:
            model.graphs["detector"] = graph
    verifier = stored_verifier(model)
    if verifier is not None and "verifier" not in model.graphs:
        model.graphs["verifier"] = verifier_graph(verifier)
    return {**{name: model.graphs[name] for name in FILES if name in model.graphs}, **shipped}, notes


def manifest(model: DeepMorphModel, graphs: dict[str, StoredGraph]) -> dict[str, Any]:
    """What the exported graphs take and give, and what a host program needs around them
    (JSON-ready; each field is explained in ``docs/export.md``)."""
    h, w = model.image_size
    md = model.drawing
    viewbox = list(md.drawing.viewbox)
    view_width = model.width * RECTIFY_WIDTH_FACTOR
    decoder = graphs["decoder"].meta
    out: dict[str, Any] = {
        "format": FORMAT,
        "deepmorph": __version__,
        "drawing": model.meta.drawing_name,
        "decoder": {
            "file": FILES["decoder"],
            "sha256": decoder.sha256,
            "opset": decoder.opset,
            "input": {
                "name": "image",
                "shape": [1, 1, h, w],
                "type": "float32",
                "values": "gray in [0, 1]: 1 is white paper, 0 is ink",
                # the gray a colour photo becomes: sum of red, green and blue times these weights
                "channel": {"name": channel_name(md.channel), "rgb_weights": list(md.channel)},
            },
            "output": {
                "name": "logits",
                "shape": [1, model.codec.spec.code_bits],
                "meaning": "one logit per code bit, in code-word order; sigmoid(logit) is P(bit = 1)",
            },
            "framing": {
                "size": [h, w],
                "ink_moments": [round(float(v), 6) for v in model.canonical_moments()],
                "meaning": "the ink's centre (cx, cy) and spread (sx, sy) in decoder pixels: a rectified view is "
                "scaled and shifted so that its own ink moments land here, white beyond its edges",
            },
            "spatial_transformer": bool(model.meta.decoder.spatial_transformer),
            "max_abs_diff_vs_pytorch": decoder.max_abs_diff,
        },
        "detector": None,
        "verifier": None,
        "template": {
            "svg": md.to_svg(md.neutral_values()[0]),
            "viewbox": viewbox,
            "frame_corners": [
                [viewbox[0], viewbox[1]],
                [viewbox[0] + viewbox[2], viewbox[1]],
                [viewbox[0] + viewbox[2], viewbox[1] + viewbox[3]],
                [viewbox[0], viewbox[1] + viewbox[3]],
            ],
            "rectified_size": list(md.drawing.pixel_size(view_width)),
            "meaning": "the unmorphed drawing in SVG units; a detection's quadrilateral is the frame corners "
            "(the viewBox: top left, top right, bottom right, bottom left) seen in the photo",
        },
        "code": model.codec.describe(),
    }
    if "detector" in graphs:
        det = graphs["detector"].meta
        W, H = INPUT_SIZE
        out["detector"] = {
            "file": FILES["detector"],
            "sha256": det.sha256,
            "opset": det.opset,
            "input": {
                "name": "image",
                "shape": [1, 1, H, W],
                "type": "float32",
                "values": "the photo's gray levels in [0, 1], shrunk by one scale s = min(W / width, H / height) "
                "with area averaging, placed at the top left and padded to the input size by repeating the "
                "edge pixels; the graph standardises it itself",
            },
            "outputs": {
                "heat": {
                    "shape": [1, 1, H // STRIDE, W // STRIDE],
                    "meaning": "logit that a drawing's centre lies in each cell of the stride grid",
                },
                "corners": {
                    "shape": [1, 8, H // STRIDE, W // STRIDE],
                    "meaning": "x, y of the four frame corners relative to each cell's centre, in cells "
                    "(the corners' cyclic order may start at any corner)",
                },
            },
            "stride": STRIDE,
            "threshold": 0.3,
            "max_detections": 12,
            "max_abs_diff_vs_pytorch": det.max_abs_diff,
        }
        if model.meta.detector is None:  # the universal detector: its quadrilaterals are ink squares
            md = model.drawing
            square = ink_square(md.to_svg(md.neutral_values()[0]), md.drawing.viewbox)
            out["detector"]["name"] = UniversalDetector.name
            out["detector"]["quadrilateral"] = {
                "corners": [[round(float(x), 4), round(float(y), 4)] for x, y in square],
                "meaning": "a detection's quadrilateral is these points (SVG units: the square around the "
                "drawing's ink), not the frame corners: map it to template.frame_corners through the "
                "homography from these points to the quadrilateral",
            }
    if "verifier" in graphs and model.meta.verifier is not None:
        ver = graphs["verifier"].meta
        out["verifier"] = {
            "file": FILES["verifier"],
            "sha256": ver.sha256,
            "opset": ver.opset,
            "input": {
                "name": "crops",
                "shape": [4, 1, CROP_SIZE, CROP_SIZE],
                "type": "float32",
                "values": f"the photo's gray (the decoder's channel) inside a detector quadrilateral grown by "
                f"{CROP_GROWTH} about its corners' mean, warped bilinearly to {CROP_SIZE} x {CROP_SIZE} pixels "
                "(the quadrilateral's corners at the outer corners of the corner pixels, edges repeated), "
                f"stretched so that its {CROP_PERCENTILES[0]:g}th and {CROP_PERCENTILES[1]:g}th percentiles are "
                f"0 and 1, clipped to {list(CROP_RANGE)}; then that crop turned 0, 1, 2 and 3 quarter turns",
            },
            "output": {
                "name": "probability",
                "shape": [4],
                "meaning": "the probability that each turn of the crop is this drawing; the proposal's score is "
                "the largest",
            },
            "threshold": model.meta.verifier.threshold,
            "meaning": "a universal detector's proposal scored below the threshold is another drawing: the wider "
            "alignment searches can be skipped for it",
            "max_abs_diff_vs_pytorch": ver.max_abs_diff,
        }
    return out


def export_model(model_path: str | Path, out_dir: str | Path | None, bundle: str | Path | None = None) -> ExportSummary:
    """Write the model's graphs and manifest into ``out_dir`` (all or none) and, with
    ``bundle``, the model with its graphs stored (``bundle`` may be the model file itself).

    Raises:
        DeepMorphError: an unusable model, an output that cannot be written or would replace
            the model, or a network that could not be exported.
    """
    targets = {name: Path(out_dir) / name for name in [*FILES.values(), "manifest.json"]} if out_dir else {}
    if out_dir is not None:
        output_folder(out_dir, f"--out {out_dir}")
        for target in targets.values():
            refuse_to_overwrite(target, "--out", [("model file", model_path)])
    if bundle is not None:
        check_target(bundle, f"--bundle {bundle}")
    model = DeepMorphModel.load(model_path)
    stored = set(model.graphs)
    graphs, notes = model_graphs(model)
    summary = ExportSummary(graphs={name: "stored" if name in stored else "exported" for name in graphs}, notes=notes)
    if out_dir is not None:
        data = {FILES[name]: graph.data for name, graph in graphs.items()}
        data["manifest.json"] = (json.dumps(manifest(model, graphs), indent=1) + "\n").encode()
        atomic_write_all((targets[name], blob) for name, blob in data.items())
        summary.files = {
            name: {"path": str(targets[name]), "bytes": len(blob), "sha256": hashlib.sha256(blob).hexdigest()}
            for name, blob in data.items()
        }
    if bundle is not None:
        model.save(bundle, extra=model.extra_tensors)  # a checkpoint's state stays resumable
        summary.bundle = str(bundle)
    return summary


__all__ = ["FILES", "FORMAT", "ExportSummary", "export_model", "manifest", "model_graphs"]
