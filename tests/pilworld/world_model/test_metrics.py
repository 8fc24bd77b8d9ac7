"""Image metrics: hand-checked PSNR/SSIM values, an independent numpy SSIM, and the per-view/per-frame bookkeeping."""

from __future__ import annotations

import itertools
import math
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import torch

from pilworld.world_model.metrics import PSNR_CAP_DB, SingleStepScores, load_lpips, psnr, ssim

C1 = (0.01 * 255) ** 2
C2 = (0.03 * 255) ** 2


def _noisy(rng: np.random.Generator, base: np.ndarray, sigma: float) -> np.ndarray:
    return np.clip(base + rng.normal(0, sigma, base.shape), 0, 255).round().astype(np.uint8)


def ssim_reference(x: np.ndarray, y: np.ndarray) -> float:
    """SSIM by the paper's formulas, one window position at a time (float64, no shortcuts)."""
    r = np.arange(11) - 5.0
    g = np.exp(-(r**2) / (2 * 1.5**2))
    w = np.outer(g, g)
    w /= w.sum()
    scores = []
    for c in range(x.shape[0]):
        a, b = x[c].astype(np.float64), y[c].astype(np.float64)
        vals = []
        for i in range(a.shape[0] - 10):
            for j in range(a.shape[1] - 10):
                pa, pb = a[i : i + 11, j : j + 11], b[i : i + 11, j : j + 11]
                mu_a, mu_b = (w * pa).sum(), (w * pb).sum()
                var_a = (w * (pa - mu_a) ** 2).sum()
                var_b = (w * (pb - mu_b) ** 2).sum()
                cov = (w * (pa - mu_a) * (pb - mu_b)).sum()
                vals.append(
                    ((2 * mu_a * mu_b + C1) * (2 * cov + C2)) / ((mu_a**2 + mu_b**2 + C1) * (var_a + var_b + C2))
                )
        scores.append(np.mean(vals))
    return float(np.mean(scores))


# ---------------------------------------------------------------------- PSNR


def test_psnr_of_a_known_mse() -> None:
    pred = torch.zeros(2, 3, 3, 16, 16, dtype=torch.uint8)
    target = torch.full((2, 3, 3, 16, 16), 10, dtype=torch.uint8)  # MSE = 100 everywhere
    out = psnr(pred, target)
    assert out.shape == (2, 3) and out.dtype == torch.float64
    assert torch.allclose(out, torch.full((2, 3), 10 * math.log10(255**2 / 100), dtype=torch.float64))
    # MSE 1 over a quarter of the pixels: MSE = 0.25 → 54.15 dB; float input on the same 0–255 scale agrees.
    t2 = torch.zeros(3, 8, 8, dtype=torch.uint8)
    t2[:, :4, :4] = 1
    assert psnr(torch.zeros(3, 8, 8), t2.float()).item() == pytest.approx(10 * math.log10(255**2 / 0.25))


def test_psnr_of_identical_images_is_capped() -> None:
    x = torch.randint(0, 256, (4, 3, 12, 12), dtype=torch.uint8)
    assert torch.all(psnr(x, x) == PSNR_CAP_DB)
    y = x.clone()
    y[0, 0, 0, 0] ^= 1  # one unit of error in one channel of one pixel stays below the cap
    assert psnr(x, y)[0] < PSNR_CAP_DB


# ---------------------------------------------------------------------- SSIM


def test_ssim_of_identical_images_is_one() -> None:
    x = torch.randint(0, 256, (2, 3, 3, 20, 24), dtype=torch.uint8)
    out = ssim(x, x)
    assert out.shape == (2, 3)
    assert torch.allclose(out, torch.ones(2, 3, dtype=torch.float64), atol=1e-12)


def test_ssim_of_flat_images_has_the_closed_form() -> None:
    # Zero variance everywhere: the contrast-structure term is C2/C2 = 1, only luminance remains.
    a, b = 100.0, 140.0
    x, y = torch.full((3, 16, 16), a), torch.full((3, 16, 16), b)
    assert ssim(x, y).item() == pytest.approx((2 * a * b + C1) / (a * a + b * b + C1), rel=1e-12)


def test_ssim_decreases_with_noise() -> None:
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:32, 0:32]
    base = np.stack([xx * 6, yy * 6, (xx + yy) * 3]).astype(np.float64) + 20  # smooth gradients
    clean = torch.from_numpy(base.round().astype(np.uint8))
    scores = [ssim(torch.from_numpy(_noisy(rng, base, s)), clean).item() for s in (2, 8, 20, 50)]
    assert all(a > b for a, b in itertools.pairwise(scores)), scores
    assert scores[0] < 1.0


def test_ssim_matches_a_numpy_reference() -> None:
    rng = np.random.default_rng(1)
    x = rng.integers(0, 256, (3, 16, 19), dtype=np.uint8)
    y = _noisy(rng, x.astype(np.float64), 30)
    got = ssim(torch.from_numpy(x), torch.from_numpy(y)).item()
    assert got == pytest.approx(ssim_reference(x, y), abs=1e-10)


def test_bad_inputs_name_the_field() -> None:
    x = torch.zeros(2, 3, 16, 16, dtype=torch.uint8)
    with pytest.raises(ValueError, match="pred: shape"):
        psnr(x, torch.zeros(2, 3, 16, 15, dtype=torch.uint8))
    with pytest.raises(ValueError, match=r"target: expected images \[\.\.\., 3, H, W\]"):
        ssim(x, torch.zeros(2, 16, 16, 3, dtype=torch.uint8))  # channels last
    with pytest.raises(ValueError, match="pred: expected uint8 or floating"):
        psnr(x.long(), x)
    with pytest.raises(ValueError, match="at least 11x11"):
        ssim(torch.zeros(3, 8, 8), torch.zeros(3, 8, 8))


# ---------------------------------------------------------------------- accumulation


def test_scores_keep_views_and_frames_apart() -> None:
    B, V, K = 2, 3, 4
    target = torch.randint(0, 256, (B, V, K, 3, 16, 16), dtype=torch.uint8)
    pred = target.clone()
    pred[:, 1, 2] = (pred[:, 1, 2].int() + 10).clamp(max=255).to(torch.uint8)  # error only in view 1, frame 3
    views = ("cam_high", "cam_left_wrist", "cam_right_wrist")
    scores = SingleStepScores(lpips=lambda p, t: (p.double() - t.double()).abs().mean(dim=(-3, -2, -1)))
    scores.add(pred[:1], target[:1], views)
    scores.add(pred[1:], target[1:], views)
    out = scores.summarize()
    bad_psnr = psnr(pred[:, 1, 2], target[:, 1, 2]).mean().item()
    bad_ssim = ssim(pred[:, 1, 2], target[:, 1, 2]).mean().item()
    assert bad_psnr < 40 and bad_ssim < 1
    assert out["clips"] == B and out["images"] == B * V * K
    exact_view = {
        "psnr": PSNR_CAP_DB,
        "ssim": pytest.approx(1.0),
        "psnr_pooled": PSNR_CAP_DB,
        "exact": 1.0,
        "lpips": 0.0,
    }
    assert out["per_view"]["cam_high"] == exact_view
    # Pooled: one image in four of view 1 has all the error, so its mean MSE is a quarter of that image's.
    bad_mse = (pred[:, 1, 2].double() - target[:, 1, 2].double()).square().mean().item()
    pooled = 10 * math.log10(255**2 / (bad_mse / K))
    assert out["per_view"]["cam_left_wrist"]["psnr_pooled"] == pytest.approx(pooled)
    assert out["psnr_pooled"] == pytest.approx(10 * math.log10(255**2 / (bad_mse / (V * K))))
    assert out["per_frame"]["psnr_pooled"][2] == pytest.approx(10 * math.log10(255**2 / (bad_mse / V)))
    assert out["per_view"]["cam_left_wrist"]["exact"] == 0.75 and out["exact"] == (V * K - 1) / (V * K)
    assert out["per_frame"]["exact"] == [1.0, 1.0, pytest.approx(2 / 3), 1.0]
    assert out["per_view"]["cam_right_wrist"]["psnr"] == PSNR_CAP_DB
    assert out["per_view"]["cam_left_wrist"]["psnr"] == pytest.approx((3 * PSNR_CAP_DB + bad_psnr) / K)
    assert out["per_view"]["cam_left_wrist"]["ssim"] == pytest.approx((3 + bad_ssim) / K)
    assert out["per_frame"]["psnr"] == pytest.approx([PSNR_CAP_DB] * 2 + [(2 * PSNR_CAP_DB + bad_psnr) / 3, 100])
    assert out["per_frame"]["ssim"][2] == pytest.approx((2 + bad_ssim) / 3)
    assert out["per_frame"]["lpips"][:2] == [0.0, 0.0] and out["per_frame"]["lpips"][2] > 0
    assert out["psnr"] == pytest.approx((V * K - 1) * PSNR_CAP_DB / (V * K) + bad_psnr / (V * K))
    assert out["ssim"] == pytest.approx(np.mean(out["per_frame"]["ssim"]))


def test_scores_reject_inconsistent_input() -> None:
    scores = SingleStepScores()
    with pytest.raises(ValueError, match="nothing added"):
        scores.summarize()
    x = torch.zeros(1, 2, 3, 3, 12, 12, dtype=torch.uint8)
    with pytest.raises(ValueError, match="views: 1 names for 2 views"):
        scores.add(x, x, ["a"])
    scores.add(x, x, ["a", "b"])
    with pytest.raises(ValueError, match="views:"):
        scores.add(x, x, ["b", "a"])
    with pytest.raises(ValueError, match="pred: expected"):
        scores.add(x[0], x[0], ["a", "b"])


# ---------------------------------------------------------------------- LPIPS is optional and never downloads


def test_lpips_absent_is_reported(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "lpips", None)  # import fails as if not installed
    fn, reason = load_lpips(tmp_path)
    assert fn is None and reason == "lpips package not installed"
    fake = types.ModuleType("lpips")
    fake.LPIPS = lambda **kw: pytest.fail("constructed without local backbone weights")  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "lpips", fake)
    fn, reason = load_lpips(tmp_path)
    assert fn is None and reason.startswith(f"backbone weights not found at {tmp_path}")
    monkeypatch.setenv("PILWORLD_LPIPS_WEIGHTS", str(tmp_path / "env"))
    assert str(tmp_path / "env") in load_lpips(None)[1]
