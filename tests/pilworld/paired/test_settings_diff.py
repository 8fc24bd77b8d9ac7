"""The one comparison of paired-run settings that resuming (``_check_config``) and ``real_from`` share."""

from __future__ import annotations

import json
from pathlib import Path

from pilworld.paired.runner import PairedConfig, settings_diff, stored_config

SIM = "configs/rig/sim_dual_ur5e.yaml"


def test_settings_diff_names_the_differing_keys_sorted() -> None:
    have = {"seed": 0, "spec": {"rounds": 2}, "rig": SIM, "tasks": ["a"]}
    want = {"seed": 1, "spec": {"rounds": 3}, "rig": SIM, "tasks": ["a"]}
    assert settings_diff(have, want, have.keys()) == ["seed", "spec"]
    assert settings_diff(have, want, ["rig", "tasks"]) == []
    # A key only one side has differs (None on the other).
    assert settings_diff({"a": 1}, {}, ["a"]) == ["a"]


def test_settings_diff_compares_rigs_by_the_file_they_name() -> None:
    absolute = str(Path(SIM).resolve())
    assert settings_diff({"rig": SIM}, {"rig": absolute}, ["rig"]) == []
    assert settings_diff({"rig": SIM}, {"rig": "configs/rig/other.yaml"}, ["rig"]) == ["rig"]


def test_stored_config_fills_keys_an_older_run_lacks_with_their_defaults(tmp_path: Path) -> None:
    """A run written before a setting existed had that setting's present default."""
    path = tmp_path / "paired_config.json"
    path.write_text(json.dumps({"seed": 5}))
    have = stored_config(path)
    assert have["seed"] == 5
    assert have["history"] is PairedConfig.history is True
    assert have["resize"] is PairedConfig.resize
