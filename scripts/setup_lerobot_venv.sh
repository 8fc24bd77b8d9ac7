#!/usr/bin/env bash
# Create (or reuse) a separate virtualenv with LeRobot 0.4.4, used ONLY as an external reference
# reader by scripts/lerobot_compat_check.py (never imported by pilworld). Default path:
# .venv-lerobot in the checkout, or the path given as $1. Idempotent: if the venv already has the pinned versions
# and `LeRobotDataset` imports, nothing is installed.
#
# Why these pins: lerobot 0.4.4 (newest release supporting Python 3.11; writes/reads the v3.0 layout)
# requires torch>=2.2.1,<2.11 and torchvision>=0.21,<0.26, so the project's local torch 2.13/2.14
# wheels cannot be used. `pip install lerobot==0.4.4` resolves torch 2.10.0 + torchvision 0.25.0 +
# torchcodec 0.10.0 from PyPI (CUDA 12.8 build with nvidia-* wheels, ~8.3 GB venv; runs on CPU).
# The pins below are exactly what that resolution installed.
#
# torchcodec (LeRobot's default video decoder whenever the package is importable) needs FFmpeg
# shared libraries (major 4-8) from the system. On Debian 12 they come from apt (FFmpeg 5.1). Without
# them, loading works only with video_backend="pyav" (lerobot_compat_check.py --video-backend auto
# falls back to pyav by itself). Set LEROBOT_VENV_NO_APT=1 to skip the apt step.
set -euo pipefail

VENV="${1:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/.venv-lerobot}"
PY="${PYTHON:-python3.11}"
PINS=(lerobot==0.4.4 torch==2.10.0 torchvision==0.25.0 torchcodec==0.10.0)
FFMPEG_DEBS=(libavcodec59 libavformat59 libavutil57 libswscale6 libswresample4 libavdevice59 libavfilter8)
export PIP_DISABLE_PIP_VERSION_CHECK=1

log() { printf '[setup_lerobot_venv] %s\n' "$*" >&2; }

venv_ok() {
  [ -x "$VENV/bin/python" ] || return 1
  HF_HUB_OFFLINE=1 "$VENV/bin/python" - <<'EOF' >/dev/null 2>&1
import importlib.metadata as m
want = {"lerobot": "0.4.4", "torch": "2.10.0", "torchvision": "0.25.0", "torchcodec": "0.10.0"}
for pkg, ver in want.items():
    got = m.version(pkg).split("+")[0]
    assert got == ver, (pkg, got, ver)
from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: F401
EOF
}

torchcodec_ok() {
  "$VENV/bin/python" -c 'from torchcodec.decoders import VideoDecoder' >/dev/null 2>&1
}

if venv_ok; then
  log "$VENV already has ${PINS[*]}"
else
  if ! command -v "$PY" >/dev/null 2>&1; then
    PY=python3
  fi
  if ! "$PY" -c 'import sys; sys.exit(0 if (3, 10) <= sys.version_info[:2] < (3, 12) else 1)'; then
    log "error: need Python 3.10 or 3.11 for lerobot 0.4.4 (got $("$PY" --version 2>&1)); set PYTHON="
    exit 1
  fi
  if [ ! -x "$VENV/bin/python" ]; then
    log "creating virtualenv $VENV with $("$PY" --version 2>&1)"
    "$PY" -m venv "$VENV"
  fi
  log "pip install ${PINS[*]}  (large download: CUDA build of torch)"
  "$VENV/bin/pip" install "${PINS[@]}"
  venv_ok || { log "error: install finished but the version/import check failed"; exit 1; }
fi

if torchcodec_ok; then
  log "torchcodec loads (system FFmpeg present)"
elif [ "${LEROBOT_VENV_NO_APT:-0}" != "1" ] && [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
  log "torchcodec cannot load FFmpeg; apt-get install ${FFMPEG_DEBS[*]}"
  if ! DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${FFMPEG_DEBS[@]}" >/dev/null 2>&1; then
    apt-get update >/dev/null 2>&1 || true
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${FFMPEG_DEBS[@]}" >/dev/null 2>&1 \
      || log "warning: apt install of FFmpeg libraries failed"
  fi
  torchcodec_ok && log "torchcodec loads now" \
    || log "warning: torchcodec still unusable; use video_backend='pyav'"
else
  log "warning: torchcodec cannot load (no system FFmpeg 4-8); LeRobot must be used with video_backend='pyav'"
fi

"$VENV/bin/python" - <<'EOF'
import importlib.metadata as m
print("lerobot-venv ready:", ", ".join(f"{p}=={m.version(p)}" for p in ("lerobot", "torch", "torchvision", "torchcodec", "av", "datasets", "pyarrow")))
EOF
