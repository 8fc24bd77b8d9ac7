"""The learned success judge end to end on a tiny dataset it can learn: train, save, load, judge, evaluate."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pilworld.judges.base import JudgeContext
from pilworld.judges.learned.evaluate import DEGRADATIONS, evaluate
from pilworld.judges.learned.folder import (
    CONFIG_FILE,
    WEIGHTS_FILE,
    JudgeFolderError,
    load_judge,
    provenance,
    save_judge,
)
from pilworld.judges.learned.inputs import JudgeInputError
from pilworld.judges.learned.judge import LearnedSuccessJudge
from pilworld.judges.learned.labels import JudgeDataError, labelled_episodes
from pilworld.judges.learned.train import TrainSettings, choose_threshold, fit_temperature, fold_of, train_judge

from .synthetic import make_episode, write_labelled

SETTINGS = TrainSettings(folds=2, steps=120, batch=16, side=32, lr=3e-3)


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    base = tmp_path_factory.mktemp("judge")
    train = write_labelled(base / "train", episodes=48)
    held = write_labelled(base / "held", episodes=24, first=1000)
    labelled = labelled_episodes([train], "sim_checker")
    judge = train_judge(labelled, SETTINGS, progress=False)
    save_judge(judge, base / "J", provenance(labelled, "sim_checker"), "synthetic")
    return base / "J", held


def test_a_judge_learns_what_the_frames_show_and_reads_back(trained: tuple[Path, Path]) -> None:
    folder, held = trained
    judge = LearnedSuccessJudge(folder)
    result = evaluate(judge, [held], "sim_checker", progress=False)
    assert result["episodes"] == 24
    assert result["agreement"] >= 0.9, result
    assert result["abstain_share"] <= 0.25
    config = json.loads((folder / CONFIG_FILE).read_text())
    assert config["data"]["episodes"] == 48 and config["data"]["labels"] == "sim_checker"
    assert len(config["data"]["sha256"]) == 64
    assert 0.5 <= config["threshold"] <= 1 and config["temperature"] > 0
    assert config["validation"]["episodes"] == 48


def test_verdicts_are_deterministic_and_abstain_on_an_unknown_instruction(trained: tuple[Path, Path]) -> None:
    folder, _ = trained
    judge = LearnedSuccessJudge(folder)
    ep = make_episode(5000, True)
    a, b = judge.predict(ep), LearnedSuccessJudge(folder).predict(ep)
    assert a.probability == b.probability
    other = make_episode(5000, True)
    object.__setattr__(other, "task", "fold the towel.")
    verdict = judge.judge(other, JudgeContext(rig=None, task=""))  # type: ignore[arg-type]
    assert verdict.success is None and "not in its training data" in verdict.reason


def test_an_episode_from_other_cameras_is_an_error_naming_them(trained: tuple[Path, Path]) -> None:
    folder, _ = trained
    judge = LearnedSuccessJudge(folder)
    with pytest.raises(JudgeInputError, match="another rig's cameras"):
        judge.predict(make_episode(1, True, views=("cam_a", "cam_z")))
    with pytest.raises(JudgeInputError, match="64×64"):
        judge.predict(make_episode(1, True, size=64))


def test_degraded_frames_are_judged(trained: tuple[Path, Path]) -> None:
    folder, held = trained
    result = evaluate(LearnedSuccessJudge(folder), [held], "sim_checker", degrade=DEGRADATIONS["blur"], progress=False)
    assert result["episodes"] == 24 and result["agreement"] is not None


@pytest.mark.parametrize("damage", ["no-config", "foreign", "not-json", "no-weights", "cut-weights", "bad-field"])
def test_a_damaged_judge_folder_is_one_line_naming_the_file(
    trained: tuple[Path, Path], tmp_path: Path, damage: str
) -> None:
    import shutil

    folder = tmp_path / "J"
    shutil.copytree(trained[0], folder)
    config, weights = folder / CONFIG_FILE, folder / WEIGHTS_FILE
    if damage == "no-config":
        config.unlink()
    elif damage == "foreign":
        config.write_text(json.dumps({"format": "something-else"}))
    elif damage == "not-json":
        config.write_text("{")
    elif damage == "no-weights":
        weights.unlink()
    elif damage == "cut-weights":
        weights.write_bytes(weights.read_bytes()[:100])
    else:
        data = json.loads(config.read_text())
        data["inputs"]["state_dim"] = 7
        config.write_text(json.dumps(data))
    with pytest.raises(JudgeFolderError) as err:
        load_judge(folder)
    assert "\n" not in str(err.value) and str(folder) in str(err.value)


def test_no_labels_or_one_class_is_refused(tmp_path: Path) -> None:
    root = write_labelled(tmp_path / "d", episodes=6)
    with pytest.raises(JudgeDataError, match=r"no 'operator' labels.*sim_checker ×6"):
        labelled_episodes([root], "operator")
    one = write_labelled(tmp_path / "one", episodes=1)
    with pytest.raises(JudgeDataError, match="all 1 labelled episodes succeeded"):
        labelled_episodes([one], "sim_checker")


def test_human_labels_are_a_majority_vote(tmp_path: Path) -> None:
    from pilworld.data.outcomes import Outcome
    from pilworld.judges.learned.labels import labels_of

    rows = [Outcome(0, "human_1", "human", True, 6), Outcome(0, "human_2", "human", True, 6),
            Outcome(0, "human_3", "human", False, 6), Outcome(1, "human_1", "human", True, 6),
            Outcome(1, "human_2", "human", False, 6), Outcome(2, "operator", "human", False, 6)]  # fmt: skip
    assert labels_of(rows, "human") == {0: True}  # episode 1 is a tie: no label
    assert labels_of(rows, "operator") == {2: False}


def test_folds_keep_a_layout_together_and_balance_episodes() -> None:
    groups = np.repeat(np.arange(20), 5)  # 20 layouts, 5 checkpoints each
    folds = fold_of(groups, 5, seed=0)
    for g in range(20):
        assert len(set(folds[groups == g])) == 1
    assert sorted(np.bincount(folds).tolist()) == [20, 20, 20, 20, 20]


def test_temperature_and_threshold() -> None:
    rng = np.random.default_rng(0)
    z = rng.normal(0, 2, 2000)  # the true log-odds
    labels = (rng.random(2000) < 1 / (1 + np.exp(-z))).astype(np.float32)
    logits = 3 * z  # overconfident by 3×
    t = fit_temperature(logits.astype(np.float32), labels)
    assert 2.5 < t < 3.6
    prob = 1 / (1 + np.exp(-logits / t))
    thr = choose_threshold(prob, labels, budget=0.05, target=0.99)
    conf = np.maximum(prob, 1 - prob)
    assert (conf < thr).mean() <= 0.05 + 1e-9
    perfect = choose_threshold(np.where(labels > 0, 0.9, 0.1), labels, budget=0.05, target=0.99)
    assert perfect == 0.5  # nothing to gain by abstaining


def test_settings_are_validated() -> None:
    with pytest.raises(ValueError, match="folds=1"):
        TrainSettings(folds=1)
    with pytest.raises(ValueError, match="side=50"):
        TrainSettings(side=50)


def test_the_keypoint_encoder_gives_coordinates_in_the_image() -> None:
    import torch

    from pilworld.judges.learned.net import JudgeNet, SpatialSoftmax

    maps = torch.full((1, 2, 8, 8), -30.0)
    maps[0, 0, 0, 7] = 30.0  # top right
    maps[0, 1, 7, 0] = 30.0  # bottom left
    out = SpatialSoftmax()(maps)
    assert torch.allclose(out[0, :4], torch.tensor([1.0, -1.0, -1.0, 1.0]), atol=1e-3)  # x0, x1, y0, y1
    net = JudgeNet(2, 4, 32, arch="keypoints")
    assert net(torch.rand(3, 2, 6, 32, 32), torch.rand(3, 8), torch.rand(3, 80)).shape == (3,)
    with pytest.raises(ValueError, match="arch"):
        TrainSettings(arch="transformer")


def test_the_imagined_look_softens_only_the_end_frames_of_chosen_samples() -> None:
    import torch

    from pilworld.judges.learned.inputs import InputSpec
    from pilworld.judges.learned.train import _imagined_look, input_scales

    frames = torch.zeros(8, 2, 6, 32, 32)
    frames[:, :, :, 16, 16] = 1.0  # one bright pixel in the start and end frame of every input
    out = _imagined_look(frames, torch.Generator().manual_seed(0), 1.0, [0.5, 2.0])
    assert torch.equal(out[:, :, :3], frames[:, :, :3])  # the start frame is a real one: untouched
    assert bool((out[:, 1, 3:, 16, 16] < 0.5).all())  # the end frame's pixel spread …
    assert bool((out[:, 1, 3:, 16, 16] < out[:, 0, 3:, 16, 16]).all())  # … further where a pixel is finer
    again = _imagined_look(frames, torch.Generator().manual_seed(0), 1.0, [0.5, 2.0])
    assert torch.equal(out, again)  # seeded
    assert torch.equal(_imagined_look(frames, torch.Generator().manual_seed(0), 0.0, [0.5, 2.0]), frames)
    spec = InputSpec.from_views({"cam_high": (128, 128), "cam_left_wrist": (128, 128)}, 14, 64, release_crop=32)
    assert input_scales(spec) == [0.5, 0.5, 2.0]
    with pytest.raises(ValueError, match=r"imagined=1\.5"):
        TrainSettings(imagined=1.5)


def test_a_judge_saved_before_the_imagined_look_reads_back_without_it(trained: tuple[Path, Path]) -> None:
    folder, _ = trained
    config = json.loads((folder / CONFIG_FILE).read_text())
    assert config["settings"]["imagined"] == SETTINGS.imagined
    del config["settings"]["imagined"]
    old = folder.parent / "old"
    old.mkdir()
    (old / CONFIG_FILE).write_text(json.dumps(config))
    (old / WEIGHTS_FILE).write_bytes((folder / WEIGHTS_FILE).read_bytes())
    assert load_judge(old).settings.imagined == 0.0
