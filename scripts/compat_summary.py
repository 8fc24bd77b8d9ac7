"""One line from lerobot_compat_check.py's JSON (stdin): loaded?, counts and the largest differences."""

import json
import sys

d = json.loads(sys.stdin.read().strip().splitlines()[-1])
keys = (d.get("compare") or {}).get("keys", {})
diffs = ", ".join(f"{k} max {v['max_abs_diff']:g} mean {v['mean_abs_diff']:.3g}" for k, v in keys.items())
delta_ok = (d.get("delta_check") or {}).get("ok")
print(
    f"ok={d['ok']} lerobot {d.get('lerobot_version')} ({d.get('video_backend')}): {d.get('num_episodes')} episodes, "
    f"{d.get('num_frames')} frames; {diffs}; delta_timestamps check ok={delta_ok}"
)
