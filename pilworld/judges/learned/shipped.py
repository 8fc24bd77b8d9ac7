"""The learned judge that ships with pilworld: the default success judge of ``pilworld demo`` and ``bench paired``.

Trained like any user's judge, by ``pilworld judge train`` on labelled episodes (the simulator's checker)
of the paper's three tasks under the flat look, layouts of seeds 10,000,000+ — reserved for it and seen
by no world model, bench or demo (docs/judges.md, "The shipped judge" has the command and its figures).
It is data, not code: nothing here knows a task; on any other task it abstains (instructions it never saw).
"""

from __future__ import annotations

from pathlib import Path

SHIPPED_JUDGE = Path(__file__).resolve().parent / "weights" / "sim_paper_flat"
