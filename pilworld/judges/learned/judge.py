"""The learned success judge as a :class:`~pilworld.judges.base.Judge`: a verdict, or an abstention, per episode.

It reads a judge folder (:mod:`.folder`) and answers from the episode alone (:mod:`.inputs`): success when
the calibrated probability is at least 0.5. It abstains — ``Verdict.success`` None, so no row is recorded
and the episode is left to people — when its confidence is under the folder's threshold, or when the
instruction is none it was trained on (a judge knows only the tasks it has seen labelled). An episode from
other cameras than its training data is an error (:class:`~.inputs.JudgeInputError`), not an abstention:
that judge belongs to another rig.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.outcomes import JudgeKind
from pilworld.judges.base import JudgeContext, Verdict
from pilworld.judges.learned.examples import Example, episode_example
from pilworld.judges.learned.folder import JudgeFolder, load_judge
from pilworld.judges.learned.inputs import instruction_key
from pilworld.judges.learned.train import sigmoid


@dataclass(frozen=True)
class Prediction:
    probability: float  # calibrated P(success); NaN for an instruction the judge never saw
    confident: bool  # confidence max(p, 1 − p) at least the judge's threshold, and a known instruction
    reason: str


class LearnedSuccessJudge:
    """Success from the frames, the state and the instruction, learned from labelled episodes."""

    def __init__(self, folder: str | Path | JudgeFolder, judge_id: str = "learned") -> None:
        self.folder = folder if isinstance(folder, JudgeFolder) else load_judge(folder)
        self._id = judge_id

    @property
    def judge_id(self) -> str:
        return self._id

    @property
    def kind(self) -> JudgeKind:
        return "vision"

    def predict_example(self, example: Example) -> Prediction:
        f = self.folder
        if instruction_key(example.instruction) not in f.instructions:
            said = f"abstained: instruction {example.instruction!r} not in its training data"
            return Prediction(float("nan"), False, said)
        frames = torch.from_numpy(example.frames).float().div_(255)  # (E, V, 6, S, S)
        state = torch.from_numpy(example.state)
        context = torch.from_numpy(np.repeat(example.context[None], len(frames), axis=0))
        with torch.no_grad():
            logit = float(torch.stack([net(frames, state, context).mean() for net in f.nets]).mean())
        p = float(sigmoid(np.float64(logit / f.temperature)))
        conf = max(p, 1 - p)
        if conf < f.threshold:
            return Prediction(p, False, f"abstained: confidence {conf:.2f} < {f.threshold:.2f} (p={p:.2f})")
        return Prediction(p, True, f"p={p:.2f}")

    def predict(self, episode: Episode, rig: RigConfig | None = None) -> Prediction:
        return self.predict_example(episode_example(episode, self.folder.spec, rig))

    def judge(self, episode: Episode, context: JudgeContext) -> Verdict:
        pred = self.predict(episode, context.rig)
        return Verdict(success=(pred.probability >= 0.5) if pred.confident else None, reason=pred.reason)
