"""Image metrics for world-model predictions: PSNR, SSIM, optional LPIPS, and a per-view/per-frame accumulator.

Conventions (the figures in the benchmark JSON mean exactly this):

* **Inputs** are uint8 or float tensors ``[..., 3, H, W]`` on the 0–255 scale (a float image is *not*
  assumed to be in [0, 1]; pass ``data_range=1.0`` for that). Every function returns one value per
  image, a float64 tensor of the leading shape ``[...]``.
* **PSNR** = 10·log10(R² / MSE), the MSE over all channels and pixels of one image, R = 255. Identical
  images (MSE = 0) get :data:`PSNR_CAP_DB` = 100 dB instead of +inf, so means stay finite. Any other
  8-bit pair up to 224×224 stays below the cap (one unit of error in one channel of one pixel is
  95.1 dB at 128², 99.9 dB at 224²); larger images are clamped to it.
* **SSIM** follows Wang, Bovik, Sheikh & Simoncelli (2004) and their reference ``ssim_index.m``: an 11×11
  Gaussian window with σ = 1.5 (normalised to sum 1), K1 = 0.01, K2 = 0.03, L = 255 (so
  C1 = (K1·L)², C2 = (K2·L)²), local statistics from *valid* filtering (no padding: the SSIM map is
  (H−10)×(W−10) and the score is its plain mean), the biased local variance E[x²] − E[x]². It is computed
  on each RGB channel separately (no conversion to luminance, no down-sampling — the reference's automatic
  2× down-sampling only applies to images wider than 256 px) and the three channel means are averaged.
  This equals ``skimage.metrics.structural_similarity(..., gaussian_weights=True, sigma=1.5,
  use_sample_covariance=False, data_range=255, channel_axis=...)`` up to float rounding. Images must be
  at least 11×11.
* **Averages** over images are means of the per-image values (the video-prediction convention);
  :class:`SingleStepScores` also reports ``psnr_pooled``, the PSNR of the mean MSE, which the cap does
  not dominate when some predictions are bit-exact.
* **LPIPS** (Zhang et al. 2018, AlexNet trunk, v0.1) only when the ``lpips`` package is installed *and*
  the AlexNet backbone weights are on disk already; nothing is ever downloaded (see :func:`load_lpips`).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch

PSNR_CAP_DB = 100.0  # reported for identical images (MSE = 0) instead of +inf
SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_K1 = 0.01
SSIM_K2 = 0.03
DATA_RANGE = 255.0

# torchvision's file name for the ImageNet AlexNet weights (what lpips' "alex" trunk loads).
LPIPS_BACKBONE_FILE = "alexnet-owt-7be5be79.pth"
LPIPS_WEIGHTS_ENV = "PILWORLD_LPIPS_WEIGHTS"

# Images per SSIM pass: bounds the float64 working set (a few maps × 3 channels × N × H × W).
_SSIM_CHUNK = 64

LpipsFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def _pair(pred: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Validate a prediction/target pair and return both as float64 on one device."""
    for name, x in (("pred", pred), ("target", target)):
        if not isinstance(x, torch.Tensor):
            raise ValueError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
        if x.dtype != torch.uint8 and not x.dtype.is_floating_point:
            raise ValueError(f"{name}: expected uint8 or floating-point images, got dtype {x.dtype}")
        if x.dim() < 3 or x.shape[-3] != 3:
            raise ValueError(f"{name}: expected images [..., 3, H, W] (channels first), got shape {tuple(x.shape)}")
    if pred.shape != target.shape:
        raise ValueError(f"pred: shape {tuple(pred.shape)} differs from target's {tuple(target.shape)}")
    return pred.double(), target.to(pred.device).double()


def mse(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Per-image mean squared error over channels and pixels (float64, leading shape)."""
    p, t = _pair(pred, target)
    return (p - t).square().mean(dim=(-3, -2, -1))


def psnr_from_mse(mse: torch.Tensor, *, data_range: float = DATA_RANGE) -> torch.Tensor:
    """10·log10(R² / MSE), capped at :data:`PSNR_CAP_DB`."""
    # The cap replaces +inf for MSE = 0; the clamp also keeps float noise (MSE ~1e-30) from exceeding it.
    db = 10.0 * torch.log10(data_range**2 / mse.double().clamp_min(1e-300))
    return db.clamp(max=PSNR_CAP_DB)


def psnr(pred: torch.Tensor, target: torch.Tensor, *, data_range: float = DATA_RANGE) -> torch.Tensor:
    """Per-image PSNR in dB (float64, leading shape), capped at :data:`PSNR_CAP_DB` (identical images)."""
    return psnr_from_mse(mse(pred, target), data_range=data_range)


def gaussian_window(size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> torch.Tensor:
    """The 1-D normalised Gaussian (float64); the 2-D window is its outer product (it is separable)."""
    x = torch.arange(size, dtype=torch.float64) - (size - 1) / 2
    g = torch.exp(-(x**2) / (2 * sigma**2))
    return g / g.sum()


def _band(n: int, g: torch.Tensor) -> torch.Tensor:
    """[n, n − len(g) + 1] matrix whose column j holds ``g`` at rows j … j + len(g) − 1 (valid 1-D filtering)."""
    taps = g.numel()
    m = torch.zeros(n, n - taps + 1, dtype=g.dtype, device=g.device)
    for j in range(n - taps + 1):
        m[j : j + taps, j] = g
    return m


def ssim(pred: torch.Tensor, target: torch.Tensor, *, data_range: float = DATA_RANGE) -> torch.Tensor:
    """Per-image SSIM (float64, leading shape); see the module docstring for the exact definition."""
    p, t = _pair(pred, target)
    H, W = p.shape[-2:]
    if H < SSIM_WINDOW or W < SSIM_WINDOW:
        raise ValueError(f"pred: SSIM needs images of at least {SSIM_WINDOW}x{SSIM_WINDOW} pixels, got {H}x{W}")
    lead = p.shape[:-3]
    x = p.reshape(-1, H, W)  # every channel of every image is filtered on its own
    y = t.reshape(-1, H, W)
    g = gaussian_window().to(p.device)
    # The separable Gaussian as two banded matrix products: exact float64 valid filtering, and several
    # times faster on CPU than float64 conv2d (which has no optimised kernel for 1-channel planes).
    rows, cols = _band(H, g).T.contiguous(), _band(W, g)

    def blur(z: torch.Tensor) -> torch.Tensor:
        return rows @ (z @ cols)

    c1 = (SSIM_K1 * data_range) ** 2
    c2 = (SSIM_K2 * data_range) ** 2
    out = []
    step = _SSIM_CHUNK * 3
    for i in range(0, x.shape[0], step):
        xs, ys = x[i : i + step], y[i : i + step]
        mu_x, mu_y = blur(xs), blur(ys)
        mu_xx, mu_yy, mu_xy = mu_x * mu_x, mu_y * mu_y, mu_x * mu_y
        var_x = blur(xs * xs) - mu_xx
        var_y = blur(ys * ys) - mu_yy
        cov = blur(xs * ys) - mu_xy
        smap = ((2 * mu_xy + c1) * (2 * cov + c2)) / ((mu_xx + mu_yy + c1) * (var_x + var_y + c2))
        out.append(smap.mean(dim=(-2, -1)))
    per_channel = torch.cat(out).reshape(*lead, 3) if out else torch.zeros(*lead, 3, dtype=torch.float64)
    return per_channel.mean(dim=-1)


# ---------------------------------------------------------------------- LPIPS (optional)


def lpips_weights_dir(weights_dir: Path | None = None) -> Path:
    """Where the AlexNet backbone file is looked for.

    ``weights_dir`` if given, else ``$PILWORLD_LPIPS_WEIGHTS``, else torch hub's checkpoint folder
    (``$TORCH_HOME/hub/checkpoints``, default ``~/.cache/torch/hub/checkpoints``), which is where
    torchvision would have stored the file had it downloaded it once.
    """
    if weights_dir is not None:
        return Path(weights_dir).expanduser()
    env = os.environ.get(LPIPS_WEIGHTS_ENV)
    if env:
        return Path(env).expanduser()
    return Path(torch.hub.get_dir()) / "checkpoints"


def load_lpips(weights_dir: Path | None = None) -> tuple[LpipsFn | None, str]:
    """LPIPS (AlexNet, v0.1) as ``fn(pred, target) -> per-image distance``, or ``(None, why not)``.

    Never downloads: the ``lpips`` package is only constructed with a random trunk (``pnet_rand=True``,
    so torchvision fetches nothing) and its bundled linear-layer weights (``pretrained=True`` reads a
    file inside the package), after which the ImageNet AlexNet weights are loaded from the local file
    ``alexnet-owt-7be5be79.pth`` in :func:`lpips_weights_dir`. Without the package or the file the
    caller gets ``None`` and a reason to report.
    """
    try:
        import lpips  # type: ignore[import-not-found, unused-ignore]
    except ImportError:
        return None, "lpips package not installed"
    path = lpips_weights_dir(weights_dir) / LPIPS_BACKBONE_FILE
    if not path.is_file():
        return None, f"backbone weights not found at {path} (set ${LPIPS_WEIGHTS_ENV} or TORCH_HOME)"
    try:
        net: Any = lpips.LPIPS(net="alex", version="0.1", pretrained=True, pnet_rand=True, verbose=False)
        backbone = torch.load(path, map_location="cpu", weights_only=True)
        # lpips splits torchvision's ``features`` Sequential into slice1..slice5, keeping each layer's
        # index as its name: parameter "slice2.3.weight" is torchvision's "features.3.weight".
        state = {}
        for name in net.net.state_dict():
            _, index, param = name.split(".", 2)
            state[name] = backbone[f"features.{index}.{param}"]
        net.net.load_state_dict(state)
        net.eval()
    except Exception as err:  # a broken install or file must not abort a benchmark that can report without it
        return None, f"lpips could not be set up from {path}: {err}"

    def distance(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        p, t = _pair(pred, target)
        lead = p.shape[:-3]
        scale = DATA_RANGE / 2  # lpips expects [-1, 1]
        a = (p.reshape(-1, *p.shape[-3:]) / scale - 1).float()
        b = (t.reshape(-1, *t.shape[-3:]) / scale - 1).float()
        with torch.no_grad():
            d = torch.cat([net(a[i : i + 64], b[i : i + 64]).flatten() for i in range(0, a.shape[0], 64)])
        return d.double().reshape(lead)

    return distance, "ok"


# ---------------------------------------------------------------------- accumulation


class SingleStepScores:
    """Sums per-image PSNR / SSIM (/ LPIPS) of K-frame predictions by view and by future frame index.

    :meth:`add` takes uint8 ``[B, V, K, 3, H, W]`` predictions and targets; :meth:`summarize` returns
    means over every image added: overall, per view, and per frame index (1..K into the future). Beside
    the metrics:

    * ``exact``: the fraction of images predicted bit-exactly (those score :data:`PSNR_CAP_DB`). On
      lossless simulated data a view that does not move (an idle arm's wrist camera) is exact for the
      frozen baseline, and the capped values then dominate its mean PSNR;
    * ``psnr_pooled``: PSNR of the mean MSE over the same images, which an exact image pulls up only
      by its share of the MSE, not by a cap — the fairer comparison where ``exact`` is not small.
    """

    def __init__(self, lpips: LpipsFn | None = None) -> None:
        self._lpips = lpips
        self.views: tuple[str, ...] | None = None
        self._sums: dict[str, torch.Tensor] = {}  # metric -> float64 [V, K] sum over samples
        self.samples = 0  # clips (B summed over calls)

    def add(self, pred: torch.Tensor, target: torch.Tensor, views: Sequence[str]) -> None:
        self.add_scores(self.score(pred, target), views)

    def score(self, pred: torch.Tensor, target: torch.Tensor) -> dict[str, torch.Tensor]:
        """Per-image values of ``pred`` against ``target`` ([B, V, K] each), for :meth:`add_scores`.

        Computing them once and adding them to several accumulators (overall and per task) halves the
        cost of SSIM, the expensive part.
        """
        if pred.dim() != 6:
            raise ValueError(f"pred: expected [B, V, K, 3, H, W], got shape {tuple(pred.shape)}")
        err = mse(pred, target)  # [B, V, K], as every value below
        values = {"psnr": psnr_from_mse(err), "ssim": ssim(pred, target), "mse": err}
        values["exact"] = (pred == target).flatten(-3).all(dim=-1).double()
        if self._lpips is not None:
            values["lpips"] = self._lpips(pred, target)
        return values

    def add_scores(self, values: dict[str, torch.Tensor], views: Sequence[str]) -> None:
        """Accumulate values from :meth:`score` (of any accumulator with the same LPIPS setting)."""
        if ("lpips" in values) != (self._lpips is not None):
            raise ValueError("add_scores: values scored with another LPIPS setting")
        views = tuple(views)
        n_views = int(values["mse"].shape[1])
        if len(views) != n_views:
            raise ValueError(f"views: {len(views)} names for {n_views} views in pred")
        if self.views is None:
            self.views = views
        elif views != self.views:
            raise ValueError(f"views: {list(views)} differ from the {list(self.views)} added before")
        for name, v in values.items():
            s = v.sum(dim=0).cpu()
            if name in self._sums and self._sums[name].shape != s.shape:
                raise ValueError(f"pred: K={s.shape[1]} differs from the K={self._sums[name].shape[1]} added before")
            self._sums[name] = self._sums[name] + s if name in self._sums else s
        self.samples += int(values["mse"].shape[0])

    def summarize(self) -> dict[str, Any]:
        """Means: ``{psnr, ssim, psnr_pooled, exact[, lpips], per_view: {view: {name: x}}, per_frame: {name: [K]}}``.

        Also ``clips`` (samples added) and ``images`` (samples × views × K).
        """
        if self.views is None or self.samples == 0:
            raise ValueError("SingleStepScores: nothing added")
        n = self.samples
        out: dict[str, Any] = {}
        per_view: dict[str, dict[str, float]] = {v: {} for v in self.views}
        per_frame: dict[str, list[float]] = {}
        for name, total in self._sums.items():
            mean = total / n  # [V, K]
            overall, by_view, by_frame = mean.mean(), mean.mean(dim=1), mean.mean(dim=0)
            if name == "mse":  # reported as the PSNR of the pooled MSE (see the class docstring)
                name = "psnr_pooled"
                overall, by_view, by_frame = (psnr_from_mse(x) for x in (overall, by_view, by_frame))
            out[name] = float(overall)
            for i, v in enumerate(self.views):
                per_view[v][name] = float(by_view[i])
            per_frame[name] = [float(x) for x in by_frame]
        out["per_view"] = per_view
        out["per_frame"] = per_frame
        out["clips"] = n
        first = next(iter(self._sums.values()))
        out["images"] = n * first.numel()
        return out
