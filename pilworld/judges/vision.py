"""The automatic image judge of a paired run: success from the frames and the first hallucination frame.

It composes :class:`~pilworld.judges.vision_success.VisionSuccessJudge` (did the subtask succeed, from
the images alone) and :class:`~pilworld.judges.hallucination.HallucinationDetector` (the first frame
showing one of the paper's hallucination categories) into one judge, ``judge_id`` "vision", so both
answers land in one outcomes row per episode — the row the metrics read for SR and HFR, like a person's
annotation would. It judges both branches alike and reads no privileged simulator state.

A success verdict after a hallucination is kept as the success judge saw it: the paper's judges also
score success and hallucination separately.
"""

from __future__ import annotations

from pilworld.data.episode import Episode
from pilworld.data.outcomes import JudgeKind
from pilworld.judges.base import JudgeContext, Verdict
from pilworld.judges.hallucination import HallucinationDetector
from pilworld.judges.vision_success import VisionSuccessJudge


class VisionJudge:
    """Success (image-only) and first hallucination frame (automatic detector) in one verdict."""

    def __init__(
        self, success: VisionSuccessJudge | None = None, hallucination: HallucinationDetector | None = None
    ) -> None:
        self.success = success or VisionSuccessJudge()
        self.hallucination = hallucination or HallucinationDetector()

    @property
    def judge_id(self) -> str:
        return "vision"

    @property
    def kind(self) -> JudgeKind:
        return "vision"

    def judge(self, episode: Episode, context: JudgeContext) -> Verdict:
        s = self.success.judge(episode, context)
        h = self.hallucination.judge(episode, context)
        reasons = [
            r
            for r in (f"success: {s.reason}" if s.reason else "", f"hallucination: {h.reason}" if h.reason else "")
            if r
        ]
        return Verdict(
            success=s.success, first_hallucination_frame=h.first_hallucination_frame, reason="; ".join(reasons)
        )
