"""A learned judge on disk: ``judge.json`` (what it reads, how it decides, the data it came from, its validation)
beside ``model.safetensors`` (the fold networks, ``fold<k>.<param>``). Never a pickle.

Loading checks everything it relies on and names the file and the field when something is off: a
missing or foreign ``judge.json``, weights that do not fit it, a damaged safetensors file.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from safetensors.torch import load_file, save_file

from pilworld.io.atomic import atomic_write, write_json
from pilworld.judges.learned.inputs import InputSpec
from pilworld.judges.learned.labels import Labelled
from pilworld.judges.learned.net import JudgeNet
from pilworld.judges.learned.train import TrainedJudge, TrainSettings, settings_json

FORMAT = "pilworld-judge/1"
CONFIG_FILE = "judge.json"
WEIGHTS_FILE = "model.safetensors"


class JudgeFolderError(ValueError):
    """A judge folder that cannot be used: missing, foreign or damaged files (the message names which)."""


def provenance(labelled: Sequence[Labelled], source: str) -> dict[str, Any]:
    """The data a judge came from: each dataset, its labelled episodes and labels, and one digest of them all."""
    per_root: dict[str, dict[str, Any]] = {}
    digest = hashlib.sha256()
    for lab in labelled:
        entry = per_root.setdefault(str(lab.root.resolve()), {"episodes": 0, "successes": 0})
        entry["episodes"] += 1
        entry["successes"] += int(lab.success)
        digest.update(f"{lab.root.resolve()}|{lab.index}|{int(lab.success)}\n".encode())
    return {"labels": source, "datasets": per_root, "episodes": len(labelled), "sha256": digest.hexdigest()}


def save_judge(judge: TrainedJudge, out: Path, data: dict[str, Any], name: str) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    tensors = {
        f"fold{k}.{key}": value.detach().contiguous().float()
        for k, net in enumerate(judge.nets)
        for key, value in net.state_dict().items()
    }
    atomic_write(out / WEIGHTS_FILE, lambda tmp: save_file(tensors, str(tmp), metadata={"format": FORMAT}))
    write_json(
        out / CONFIG_FILE,
        {
            "format": FORMAT,
            "name": name,
            "inputs": judge.spec.to_json(),
            "settings": settings_json(judge.settings),
            "folds": len(judge.nets),
            "temperature": judge.temperature,
            "threshold": judge.threshold,
            "instructions": judge.instructions,
            "data": data,
            "validation": judge.validation,
        },
    )
    return out


@dataclass(frozen=True)
class JudgeFolder:
    path: Path
    name: str
    spec: InputSpec
    settings: TrainSettings
    nets: tuple[JudgeNet, ...]
    temperature: float
    threshold: float
    instructions: dict[str, int]
    data: dict[str, Any]
    validation: dict[str, Any]


def read_config(folder: Path) -> dict[str, Any]:
    path = folder / CONFIG_FILE
    if not folder.is_dir():
        raise JudgeFolderError(f"{folder}: no such judge folder (train one: pilworld judge train)")
    if not path.is_file():
        raise JudgeFolderError(f"{path}: missing; {folder} is not a judge folder (pilworld judge train writes one)")
    try:
        config = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise JudgeFolderError(f"{path}: damaged, not JSON ({err.msg if hasattr(err, 'msg') else err})") from None
    if not isinstance(config, dict) or config.get("format") != FORMAT:
        got = config.get("format") if isinstance(config, dict) else type(config).__name__
        raise JudgeFolderError(f"{path}: format {got!r} is not {FORMAT!r}")
    return config


def load_judge(folder: str | Path) -> JudgeFolder:
    """A judge folder, checked; :class:`JudgeFolderError` naming the file and field otherwise."""
    root = Path(folder)
    config = read_config(root)
    path = root / CONFIG_FILE
    try:
        spec = InputSpec.from_json(config["inputs"])
        known = {f.name for f in fields(TrainSettings)}
        stored: dict[str, Any] = {"imagined": 0.0} | dict(config["settings"])  # judges trained before it: none
        settings = TrainSettings(**{k: v for k, v in stored.items() if k in known})
        folds = int(config["folds"])
        temperature, threshold = float(config["temperature"]), float(config["threshold"])
        instructions = {str(k): int(v) for k, v in dict(config["instructions"]).items()}
        name = str(config.get("name") or root.name)
    except (KeyError, TypeError, ValueError) as err:
        raise JudgeFolderError(f"{path}: invalid field ({type(err).__name__}: {err})") from None
    if not (temperature > 0 and 0.5 <= threshold <= 1 and folds >= 1):
        raise JudgeFolderError(f"{path}: temperature {temperature}, threshold {threshold}, folds {folds} out of range")
    weights = root / WEIGHTS_FILE
    if not weights.is_file():
        raise JudgeFolderError(f"{weights}: missing judge weights")
    try:
        tensors = load_file(str(weights))
    except Exception as err:  # safetensors raises its own error type (and OSError, RuntimeError)
        detail = " ".join(str(err).split()) or type(err).__name__
        raise JudgeFolderError(f"{weights}: damaged, not a readable safetensors file ({detail})") from None
    nets = []
    for k in range(folds):
        net = JudgeNet(spec.inputs, spec.state_dim, spec.side, settings.width, arch=settings.arch)
        prefix = f"fold{k}."
        state = {key[len(prefix) :]: v for key, v in tensors.items() if key.startswith(prefix)}
        try:
            net.load_state_dict(state, strict=True)
        except RuntimeError as err:
            first = " ".join(str(err).split())[:160]
            raise JudgeFolderError(f"{weights}: fold {k} does not fit {CONFIG_FILE} ({first})") from None
        net.eval()
        nets.append(net)
    return JudgeFolder(
        path=root,
        name=name,
        spec=spec,
        settings=settings,
        nets=tuple(nets),
        temperature=temperature,
        threshold=threshold,
        instructions=instructions,
        data=dict(config.get("data") or {}),
        validation=dict(config.get("validation") or {}),
    )
