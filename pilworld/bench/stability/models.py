"""The world models side by side: the bench's variants by name, and each one's models for the probes."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pilworld.bench.stability.rig_errors import RigError
from pilworld.bench.stability.settings import DEFAULT_MODELS, QUICK_CHECKPOINTS
from pilworld.bench.variants import ModelVariant, standard_variants, v2_variants
from pilworld.world_model.base import RigBound


def known_models() -> dict[str, ModelVariant]:
    """The variants the bench can run, by name (pilworld.bench.variants)."""
    return {v.name: v for v in standard_variants() + v2_variants()}


def resolve_models(names: Sequence[str] | None = None) -> list[ModelVariant]:
    """The variants named (default ``DEFAULT_MODELS``); an unknown or repeated name is a ``ValueError``."""
    wanted = list(DEFAULT_MODELS if names is None else names)
    known = known_models()
    if not wanted:
        raise ValueError(f"models: expected at least one of {', '.join(known)}")
    unknown = [n for n in wanted if n not in known]
    if unknown:
        raise ValueError(f"models: unknown {', '.join(unknown)}; known: {', '.join(known)}")
    if len(set(wanted)) != len(wanted):
        raise ValueError(f"models: listed twice: {', '.join(wanted)}")
    return [known[n] for n in wanted]


class Imaginer:
    """One variant's world models for the probes: per task (one for all tasks without task adapters), given the
    right rig or a wrong one (``wrong``: error key → (rig config, robot model or None)), each loaded once."""

    def __init__(
        self, variant: ModelVariant, rig_path: str | Path, rig: Any, wrong: dict[str, tuple[Any, Any]]
    ) -> None:
        variant.check()
        self.variant = variant
        self._rig_path, self._rig, self._wrong = rig_path, rig, wrong
        self._models: dict[tuple[str, str], Any] = {}
        self.binds_rig: bool | None = None  # known once a model is loaded

    def _load(self, task: str) -> Any:
        from pilworld.paired.runner import PairedConfig, load_model

        v = self.variant
        cfg = PairedConfig(
            rig=str(self._rig_path),
            task=task,
            checkpoints=list(QUICK_CHECKPOINTS),
            subtasks=1,
            out="",
            world_model=v.world_model,
            adapter=v.adapter,
            steps=v.steps,
            history=v.history,
            resize=v.resize,
        )
        model = load_model(cfg, self._rig, task)[0]
        self.binds_rig = isinstance(model, RigBound)
        return model

    def model(self, task: str, error: RigError | None = None) -> Any:
        """The model of ``task`` given the right rig (``error`` None) or the wrong one."""
        scope = "" if self.variant.adapter == "none" else task
        key = (scope, "" if error is None else error.key)
        if key not in self._models:
            if error is None:
                self._models[key] = self._load(task)
            else:
                model = self.model(task)  # the right rig's first: whether the model binds a rig at all
                if self.binds_rig:
                    model = self._load(task)
                    rig, robot = self._wrong[error.key]
                    if robot is None:
                        model.bind_rig(rig)
                    else:
                        model.bind_rig(rig, robot=robot)
                self._models[key] = model  # without bind_rig: the same model, only its control video Γ is wrong
        return self._models[key]

    def applies(self, error: RigError) -> bool:
        """Whether ``error`` reaches the model (one without ``bind_rig`` sees only Γ's head camera)."""
        if self.binds_rig is None:
            raise RuntimeError("applies: load a model first")
        return self.binds_rig or error.moves_head
