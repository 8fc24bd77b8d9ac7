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
        # Runs before the pooled metric logged the mean of per-frame PSNRs (capped at 100 dB on still views);
        # a resumed run can hold both, so each family is drawn on its own (legacy faded, pooled solid).
        views = list(val[0]["val"]) if val else []
        for i, view in enumerate(views):
            color = f"C{i}"
            for key, style in (("psnr", {"marker": "x", "alpha": 0.4}), ("psnr_pooled", {"marker": "o"})):
                pts = [(r["step"] + 1, r["val"][view]) for r in val if key in r["val"].get(view, {})]
                if not pts:
                    continue
                label = view if key == "psnr_pooled" else f"{view} (mean per frame)"
                axes[2].plot([p[0] for p in pts], [p[1][key] for p in pts], color=color, label=label, **style)
                frozen = [(p[0], p[1].get(f"{key}_frozen")) for p in pts if p[1].get(f"{key}_frozen") is not None]
                if key == "psnr_pooled" and frozen:
                    axes[2].plot([f[0] for f in frozen], [f[1] for f in frozen], ls="--", color=color, alpha=0.6)
        axes[2].set(title="validation PSNR (pooled: solid; frozen: dashed)", xlabel="step", ylabel="PSNR [dB]")
        if val:
            axes[2].legend(fontsize=8)
    fig.suptitle(title or str(run))
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
