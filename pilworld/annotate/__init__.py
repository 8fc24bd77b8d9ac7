"""Blinded judging by people: ``pilworld annotate serve|export|status`` (docs/annotate.md).

``store`` keeps judges and labels in ``RUN_DIR/annotations.sqlite``; ``catalog`` gives each judge their
own blinded queue; ``media`` re-encodes the videos without anything that could unblind; ``server`` is
the HTTP API; ``export`` turns labels into ``human_N`` outcomes and recomputes metrics and report;
``agreement`` measures how judges agree with each other and with the automatic judges.
"""
