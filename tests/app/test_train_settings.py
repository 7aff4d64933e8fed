"""The training settings are declared once (:mod:`deepmorph.training.settings`): ``TrainConfig``,
``deepmorph train`` and ``train-many``, ``deepmorph.train`` and the studio's Train form take
their defaults (and, where they say them, bounds and help) from there, and change with it."""

from __future__ import annotations

import dataclasses
import inspect
import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal, Union, get_args, get_origin, get_type_hints

import pytest
import typer
from typer.testing import CliRunner

import deepmorph
from deepmorph.cli import application
from deepmorph.cli import commands as cli
from deepmorph.studio.app import train_form, training_settings
from deepmorph.training.codec import TrainConfig, tune_decoder
from deepmorph.training.settings import DEFAULTS, PAYLOAD_BITS, TUNE_DEFAULTS, TrainSettings, TuneSettings, exposed
from deepmorph_core.bundled import BUNDLED_DRAWING
from deepmorph_core.errors import DeepMorphError

ROOT = Path(__file__).resolve().parents[2]
#: ``deepmorph train``'s options that are not training settings, with their keyword in
#: ``deepmorph.train`` (``None``: only shapes the command's output).
NOT_SETTINGS = {"svg": "drawing", "out_path": "out", "payload_bits": "payload_bits", "crc": "crc_bits",
                "ecc_t": "ecc_t", "resume": "resume", "move": "move", "shift": "shift", "scale": "scale",
                "rotate": "rotate", "drop": "drop_unsupported", "validation": "validation", "as_json": None}  # fmt: skip


@dataclasses.dataclass(frozen=True)
class Declared:
    """A command's option as its function declares it."""

    flags: tuple[str, ...]
    help: str | None
    min: float | None
    max: float | None
    choices: tuple[Any, ...] | None
    default: Any


def declared(command: Callable[..., Any]) -> dict[str, Declared]:
    """Every option of a command function, by parameter name (also read by tests/app/test_cli_conventions.py's way)."""
    defaults = inspect.signature(command).parameters
    found = {}
    for name, hint in get_type_hints(command, include_extras=True).items():
        if get_origin(hint) is not Annotated:
            continue
        base, *meta = get_args(hint)
        option = next((m for m in meta if isinstance(m, (typer.models.OptionInfo, typer.models.ArgumentInfo))), None)
        if option is None:
            continue
        if get_origin(base) is Union:
            base = next(a for a in get_args(base) if a is not type(None))
        choices = get_args(base) if get_origin(base) is Literal else None
        decls = (option.default, *(option.param_decls or ()))
        flags = tuple(f for f in decls if isinstance(f, str) and f.startswith("-"))
        found[name] = Declared(flags, option.help, getattr(option, "min", None), getattr(option, "max", None),
                               choices, defaults[name].default)  # fmt: skip
    return found


def test_trainconfig_is_the_declared_settings() -> None:
    assert issubclass(TrainConfig, TrainSettings)
    assert list(TrainConfig.model_fields) == [f.name for f in dataclasses.fields(TrainSettings)]
    assert TrainConfig().model_dump() == dataclasses.asdict(DEFAULTS)
    with pytest.raises(ValueError, match="less than or equal to 4096"):  # the declared bounds are validated
        TrainConfig(batch=4097)


def test_the_cli_and_the_facade_take_each_setting_as_declared() -> None:
    """Each exposed setting is an option of ``deepmorph train`` named after its field, with its
    flag, default, bounds, choices and help, and a keyword of ``deepmorph.train`` with its
    default; every other option is one of a known few, with the same default in both."""
    options = declared(cli.train)
    keywords = inspect.signature(deepmorph.train).parameters
    settings = exposed()
    assert set(options) == set(settings) | set(NOT_SETTINGS)
    assert set(keywords) == {s.keyword for s in settings.values()} | {k for k in NOT_SETTINGS.values() if k} | {
        "on_log",
        "on_warning",
    }
    for field, setting in settings.items():
        option, default = options[field], getattr(DEFAULTS, field)
        flag = f"--{setting.option}" + (f"/--no-{setting.option}" if setting.switch else "")
        assert option.flags == (flag,), field
        assert option.default == default and keywords[setting.keyword].default == default, field
        assert setting.gt is None, field  # a command-line range is closed
        assert (option.min, option.max) == (setting.ge, setting.le), field
        assert (set(option.choices) if option.choices else None) == (set(setting.choices or ()) or None), field
        assert option.help == (setting.help or option.help) and option.help, (
            field
        )  # --seed, --device, --threads: shared
    for name, keyword in NOT_SETTINGS.items():
        if keyword and options[name].flags:  # options (the arguments are required)
            cli_default, api_default = options[name].default, keywords[keyword].default
            assert cli_default == api_default or cli_default == str(api_default), name  # --payload-bits "24"
    assert keywords["payload_bits"].default == PAYLOAD_BITS
    many = declared(cli.train_many)
    shared = {field: many[field] for field in settings if field in many}
    assert set(shared) == {"steps", "batch", "width", "print_px", "severity", "seed", "device", "threads"}
    for field, option in shared.items():
        assert option.default == getattr(DEFAULTS, field) and (option.min, option.max) == (
            settings[field].ge,
            settings[field].le,
        ), field


def test_no_options_and_no_keywords_train_alike(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """``deepmorph train`` with no options, ``deepmorph.train`` with no keywords and the studio's
    Train form left as it is hand training the same settings: ``TrainConfig``'s defaults."""
    import deepmorph.training.codec

    calls: list[dict[str, Any]] = []

    def recorded(svg: Any, out: Any, **kwargs: Any) -> None:  # where the faces hand over
        calls.append(kwargs)
        raise DeepMorphError("recorded")

    monkeypatch.setattr(deepmorph.training.codec, "train_model", recorded)
    res = CliRunner().invoke(application(), ["train", str(BUNDLED_DRAWING), "--out", str(tmp_path / "cli.dmm")])
    assert res.exit_code == 1 and "error: recorded" in res.output, res.output
    with pytest.raises(DeepMorphError, match="recorded"):
        deepmorph.train(BUNDLED_DRAWING, tmp_path / "api.dmm")
    from_cli, from_api = calls
    handed = ("payload_bits", "crc_bits", "ecc_t", "bounds", "resume", "drop_unsupported", "validation_samples")
    assert {k: from_cli[k] for k in handed} == {k: from_api[k] for k in handed}
    configs = [TrainConfig(**{k: v for k, v in c["train"].items() if v is not None}) for c in calls]
    assert configs[0] == configs[1] == TrainConfig()
    assert set(from_cli["train"]) == set(from_api["train"]) == set(exposed())
    studio = training_settings({})["train"]
    assert {k: studio[k] for k in ("steps", "batch", "width")} == {
        k: getattr(DEFAULTS, k) for k in ("steps", "batch", "width")
    }


def _another(field: str, default: Any) -> Any:
    """A value of setting ``field`` other than ``default``, within its bounds."""
    setting = exposed()[field]
    if setting.switch:
        return not default
    if setting.choices:
        return next(c for c in setting.choices if c != default)
    if default is None:
        return int(setting.ge or 0) + 1
    if isinstance(default, float):
        return (default + setting.le) / 2
    return default + 1


#: The settings ``deepmorph train-many`` takes as options (besides ``--device``).
MANY = ("steps", "batch", "width", "print_px", "severity", "seed", "threads")


def test_each_setting_given_reaches_training_under_its_field(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Every setting given to ``deepmorph train`` as an option, or to ``deepmorph.train`` as a
    keyword, other than its default, is what training is handed under the setting's field (and
    those ``train-many`` takes, under theirs)."""
    import torch

    import deepmorph.training.codec
    import deepmorph.training.many

    changed = {field: _another(field, getattr(DEFAULTS, field)) for field in exposed()}
    calls: list[dict[str, Any]] = []

    def recorded(*args: Any, **kwargs: Any) -> None:  # where the faces hand over
        calls.append(kwargs["train"])
        raise DeepMorphError("recorded")

    monkeypatch.setattr(deepmorph.training.codec, "train_model", recorded)
    monkeypatch.setattr(deepmorph.training.many, "train_many", recorded)
    options = []
    for field, value in changed.items():
        setting = exposed()[field]
        if setting.switch:
            options.append(f"--{'' if value else 'no-'}{setting.option}")
        else:
            options += [f"--{setting.option}", str(value)]
    threads = torch.get_num_threads()  # --threads sets this process's
    try:
        res = CliRunner().invoke(application(), ["train", str(BUNDLED_DRAWING), "--out", str(tmp_path / "m.dmm"),
                                                 *options])  # fmt: skip
        assert res.exit_code == 1 and "error: recorded" in res.output, res.output
        many_options = [a for f in MANY for a in (f"--{exposed()[f].option}", str(changed[f]))]
        res = CliRunner().invoke(application(), ["train-many", str(tmp_path), "--out", str(tmp_path / "models"),
                                                 *many_options])  # fmt: skip
        assert res.exit_code == 1 and "error: recorded" in res.output, res.output
    finally:
        torch.set_num_threads(threads)
    with pytest.raises(DeepMorphError, match="recorded"):
        deepmorph.train(BUNDLED_DRAWING, tmp_path / "api.dmm",
                        **{exposed()[field].keyword: value for field, value in changed.items()})  # fmt: skip
    from_cli, from_many, from_api = calls
    assert from_cli == from_api == changed
    assert from_many == {**{f: changed[f] for f in MANY}, "device": DEFAULTS.device}


CHANGED = """
import dataclasses, inspect, json, sys
import deepmorph.training.settings as settings
changed = json.loads(sys.argv[1])
settings.DEFAULTS = dataclasses.replace(settings.DEFAULTS, **changed)
settings.PAYLOAD_BITS, settings.RENDER_SAMPLES, settings.PHOTO_SAMPLES = 25, 1500, 300
from tests.app.test_train_settings import declared
import deepmorph
from deepmorph.studio.app import train_form, training_settings
from deepmorph.cli import commands
faces = {
    "deepmorph train": {n: o.default for n, o in declared(commands.train).items()},
    "deepmorph train-many": {n: o.default for n, o in declared(commands.train_many).items()},
    "deepmorph validate": {n: o.default for n, o in declared(commands.validate).items()},
    "deepmorph.train": {n: p.default for n, p in inspect.signature(deepmorph.train).parameters.items()},
    "studio form": {n: v["default"] for n, v in train_form().items()},
    "studio run": {**training_settings({})["train"], "validation": training_settings({})["validation"]},
    "--validation help": declared(commands.train)["validation"].help,
}
print(json.dumps(faces, default=repr))  # a required one has no default
"""


def test_a_changed_default_reaches_every_face() -> None:
    """Change the declared defaults (in a fresh process), and every face offers the new ones:
    none of them keeps a copy of its own."""
    changed = {field: _another(field, getattr(DEFAULTS, field)) for field in exposed()}
    done = subprocess.run([sys.executable, "-c", CHANGED, json.dumps(changed)], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    faces = json.loads(done.stdout)
    settings = exposed()
    for field, value in changed.items():
        assert faces["deepmorph train"][field] == value, field
        assert faces["deepmorph.train"][settings[field].keyword] == value, field
        if field in faces["deepmorph train-many"]:
            assert faces["deepmorph train-many"][field] == value, field
    assert faces["deepmorph train"]["payload_bits"] == "25" and faces["deepmorph.train"]["payload_bits"] == 25
    assert (faces["deepmorph validate"]["samples"], faces["deepmorph validate"]["photos"]) == (1500, 300)
    assert "(default 1500,300; 0: none)" in faces["--validation help"]
    form = {k: changed[settings_field] for k, settings_field in (("steps", "steps"), ("batch", "batch"),
                                                                  ("image_width", "width"))}  # fmt: skip
    assert {k: faces["studio form"][k] for k in form} == form and faces["studio form"]["validation"] == 300
    assert faces["studio run"]["validation"] == [1500, 300]
    assert (faces["studio run"]["steps"], faces["studio run"]["width"]) == (changed["steps"], changed["width"])


def test_the_studio_form_says_the_settings_bounds() -> None:
    form = train_form()
    for name, field in (("steps", "steps"), ("batch", "batch"), ("image_width", "width")):
        setting = exposed()[field]
        assert form[name]["default"] == getattr(DEFAULTS, field) and form[name]["min"] == setting.ge
        assert form[name]["max"] <= setting.le


TUNE_CHANGED = """
import dataclasses, inspect, json, sys
import deepmorph.training.settings as settings
settings.TUNE_DEFAULTS = dataclasses.replace(settings.TUNE_DEFAULTS, steps=801, small_prints=0.25, lr=1e-3)
from tests.app.test_train_settings import declared
from deepmorph.cli import commands
from deepmorph.training.codec import tune_decoder
cli = {n: o.default for n, o in declared(commands.tune_decoder).items()}
api = {n: p.default for n, p in inspect.signature(tune_decoder).parameters.items()}
print(json.dumps({"cli": [cli[k] for k in ("steps", "small_prints", "lr")],
                  "api": [api[k] for k in ("steps", "small_prints", "lr")]}))
"""


def test_tuning_settings_are_declared_once() -> None:
    """``deepmorph tune-decoder`` and :func:`~deepmorph.training.codec.tune_decoder` take their defaults,
    bounds and help from :class:`TuneSettings`, and a changed default reaches both."""
    options, signature = declared(cli.tune_decoder), inspect.signature(tune_decoder).parameters
    for field, setting in exposed(TuneSettings).items():
        default = getattr(TUNE_DEFAULTS, field)
        assert options[field].default == signature[field].default == default, field
        assert options[field].flags == (f"--{setting.option}",) and options[field].help == setting.help
        assert (options[field].min, options[field].max) == (setting.ge, setting.le), field
    done = subprocess.run([sys.executable, "-c", TUNE_CHANGED], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == {"cli": [801, 0.25, 1e-3], "api": [801, 0.25, 1e-3]}
