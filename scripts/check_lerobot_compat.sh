#!/usr/bin/env bash
# Proves that a dataset written by PiL-World's episode store loads with LeRobot's own LeRobotDataset
# (lerobot 0.4.4, the newest release for Python 3.11) and reads back the values we wrote.
#   scripts/check_lerobot_compat.sh [LEROBOT_VENV]
# Heavy (LeRobot pulls torch 2.10 + CUDA wheels, ~8 GB), so it is not part of scripts/test.
# Checks both video modes: lossless must be pixel-exact; h264 within mean 3 / max 140 levels.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
LEROBOT_VENV="${1:-$ROOT/.venv-lerobot}"
cd "$ROOT"
bash scripts/bootstrap.sh
bash scripts/setup_lerobot_venv.sh "$LEROBOT_VENV"
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT

status=0
for mode in lossless h264; do
  "$ROOT/.venv/bin/python" scripts/write_compat_dataset.py "$WORK/$mode" --video-mode "$mode"
  if [ "$mode" = lossless ]; then tol=(--image-atol 0); else tol=(--image-atol 140 --image-mean-atol 3); fi
  for backend in torchcodec pyav; do
    echo "== $mode dataset, LeRobot video backend $backend"
    rc=0
    "$LEROBOT_VENV/bin/python" scripts/lerobot_compat_check.py "$WORK/$mode" --compare-npz "$WORK/$mode.npz" \
      "${tol[@]}" --delta-check --video-backend "$backend" >"$WORK/out.txt" 2>"$WORK/err.txt" || rc=$?
    "$ROOT/.venv/bin/python" scripts/compat_summary.py <"$WORK/out.txt" || true
    if [ "$rc" -ne 0 ]; then status=1; echo "FAILED (exit $rc)"; tail -n 20 "$WORK/err.txt"; fi
  done
done
[ "$status" -eq 0 ] && echo "LeRobot compatibility: OK" || echo "LeRobot compatibility: FAILED"
exit "$status"
