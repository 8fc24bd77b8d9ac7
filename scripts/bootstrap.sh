#!/usr/bin/env bash
# Create or reuse the project's virtual environment (.venv inside the checkout) and install the
# project into it. Idempotent: a stamp of pyproject.toml skips the install when nothing changed.
# Sourced by scripts/demo and scripts/test; safe to run on its own.
#
# PyTorch: when the venv has no torch, install torch==2.13.0 first. On this project's CPU machines
# that picks the local CPU wheel; an unpinned `torch` would pull a multi-GB CUDA build. GPU users can
# pre-install the torch build they want into .venv (or set PILWORLD_TORCH_SPEC) before running this.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${PILWORLD_VENV:-$ROOT/.venv}"
PY="${PYTHON:-python3}"
TORCH_SPEC="${PILWORLD_TORCH_SPEC:-torch==2.13.0}"
export PIP_DISABLE_PIP_VERSION_CHECK=1

log() { printf '[bootstrap] %s\n' "$*" >&2; }

if ! command -v "$PY" >/dev/null 2>&1; then
  log "error: $PY not found; install Python 3.11+ or set PYTHON=/path/to/python3"
  exit 1
fi
if ! "$PY" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)'; then
  log "error: Python 3.11+ is required, $PY is $("$PY" --version 2>&1)"
  exit 1
fi

if [ ! -x "$VENV/bin/python" ]; then
  log "creating virtual environment in $VENV"
  if ! "$PY" -m venv "$VENV"; then
    log "error: '$PY -m venv' failed; on Debian/Ubuntu install the venv module (apt-get install python3-venv)"
    exit 1
  fi
fi

# Headless OpenGL for the simulated rig (MuJoCo renders through EGL; Mesa draws on the CPU). A bare
# Debian/Ubuntu machine lacks the libraries; install them when we can (root + apt), else say how.
if ! ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1'; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    log "installing headless OpenGL (libegl1 libegl-mesa0 libgl1-mesa-dri) for the simulated rig ..."
    if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
          libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 >/dev/null; }; then
      log "warning: apt-get could not install EGL; the simulated rig will not render"
    fi
  else
    log "warning: no libEGL found; install libegl1 libegl-mesa0 libgl1-mesa-dri for the simulated rig"
  fi
fi

# Headless Chromium for the report's browser test (and the judge UI): Debian's package, installed when
# we can (root + apt); otherwise the browser tests skip with a reason. Idempotent and quick when present.
bash "$ROOT/scripts/install-chromium.sh" || log "warning: Chromium could not be installed; browser tests will skip"

stamp="$VENV/.pilworld-install"
want="$(cat "$ROOT/pyproject.toml" | sha256sum | cut -d' ' -f1) $ROOT"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  exit 0
fi

pip_log="$VENV/pip-install.log"
pip_install() {
  # pip's output goes to a log (it is long and full of index warnings); show its tail on failure.
  if ! "$VENV/bin/python" -m pip install "$@" >>"$pip_log" 2>&1; then
    log "error: pip install $* failed; last lines of $pip_log:"
    tail -n 25 "$pip_log" >&2
    exit 1
  fi
}

: >"$pip_log"
if ! "$VENV/bin/python" -c 'import torch' >/dev/null 2>&1; then
  log "installing $TORCH_SPEC (CPU build) ..."
  pip_install "$TORCH_SPEC"
fi
log "installing pilworld and its dependencies (editable, with dev tools and the Wan2.1 backend) ..."
pip_install -e "$ROOT[dev,wan]"
echo "$want" >"$stamp"
log "environment ready: $VENV"
