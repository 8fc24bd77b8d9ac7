"""The training curve of a run (``RUN/log.jsonl``) as a PNG: VAE reconstruction PSNR, Ψ_θ loss, and the
validation PSNR per view against the frozen baseline."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np


def read_log(run: str | Path) -> list[dict[str, Any]]:
    path = Path(run) / "log.jsonl"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no training log (is {run} a pilworld train run folder?)")
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def _smooth(y: np.ndarray[Any, Any], window: int) -> np.ndarray[Any, Any]:
    if len(y) < window or window < 2:
        return y
    kernel = np.ones(window) / window
    out: np.ndarray[Any, Any] = np.convolve(y, kernel, mode="valid")
    return out


def plot_training_curve(run: str | Path, out: str | Path, title: str | None = None) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    records = read_log(run)
    phases = {r["phase"] for r in records}
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    vae = [r for r in records if r["phase"] == "vae"]
    if vae:
        steps = np.array([r["step"] for r in vae])
        psnr = np.array([r["psnr"] for r in vae])
        w = 25
        axes[0].plot(steps[w - 1 :] if len(steps) >= w else steps, _smooth(psnr, w))
        axes[0].set(title="stage 1a: frame VAE (train batch)", xlabel="step", ylabel="reconstruction PSNR [dB]")
    else:
        axes[0].set_axis_off()
    den_phase = "denoiser" if "denoiser" in phases else "lora"
    den = [r for r in records if r["phase"] == den_phase]
    if den:
        steps = np.array([r["step"] for r in den])
        loss = np.array([r["loss"] for r in den])
        w = 50
        axes[1].plot(steps[w - 1 :] if len(steps) >= w else steps, _smooth(loss, w))
        axes[1].set(title=f"{den_phase}: latent loss (moving mean of {w})", xlabel="step", ylabel="loss", yscale="log")
        val = [r for r in den if r.get("val")]
        # Runs before the pooled metric logged the mean of per-frame PSNRs (capped at 100 dB on still views).
        pooled = bool(val) and "psnr_pooled" in next(iter(val[0]["val"].values()))
        key = "psnr_pooled" if pooled else "psnr"
        for view in val[0]["val"] if val else []:
            s = [r["step"] + 1 for r in val]
            (line,) = axes[2].plot(s, [r["val"][view][key] for r in val], marker="o", label=view)
            frozen = [r["val"][view].get(f"{key}_frozen") for r in val]
            if all(f is not None for f in frozen):
                axes[2].plot(s, frozen, ls="--", color=line.get_color(), alpha=0.6)
        what = "pooled" if pooled else "mean per frame, 100 dB cap"
        axes[2].set(title=f"validation PSNR ({what}); frozen dashed", xlabel="step", ylabel="PSNR [dB]")
        if val:
            axes[2].legend(fontsize=8)
    fig.suptitle(title or str(run))
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
