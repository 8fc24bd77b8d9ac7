"""Paths of the LeRobot v3.0 layout, and how our writer maps episodes onto files.

```
ROOT/meta/info.json                       schema, fps, totals, path templates (LeRobot)
ROOT/meta/stats.json                      aggregated feature statistics (LeRobot)
ROOT/meta/tasks.parquet                   instruction ↔ task_index (LeRobot)
ROOT/meta/episodes/chunk-CCC/file-FFF.parquet   one row per episode: length, offsets, stats (LeRobot)
ROOT/meta/outcomes.parquet                one row per (episode, judge) (PiL-World)
ROOT/meta/pilworld.json                   our settings: views, names, video mode (PiL-World)
ROOT/data/chunk-CCC/file-FFF.parquet      per-frame rows (LeRobot + our columns)
ROOT/videos/observation.images.VIEW/chunk-CCC/file-FFF.mp4
```

v3.0 lets many episodes share a data file and an mp4 (offsets live in the episodes table). Our writer
gives every episode its own data file and its own mp4 per view (file number = episode index, 1000
files per chunk folder): then committing an episode never rewrites a file another episode lives in,
which is what makes a killed writer harmless. Readers (ours and LeRobot's) follow the episodes table
either way, and our reader also reads datasets packed the other way.
"""

from __future__ import annotations

from pathlib import Path

INFO = "meta/info.json"
STATS = "meta/stats.json"
TASKS = "meta/tasks.parquet"
OUTCOMES = "meta/outcomes.parquet"
PILWORLD = "meta/pilworld.json"
LOCK = "meta/.writer.lock"
EPISODES_DIR = "meta/episodes"
CHUNK_FILE = "chunk-{chunk_index:03d}/file-{file_index:03d}"
DATA_PATH = "data/" + CHUNK_FILE + ".parquet"
VIDEO_PATH = "videos/{video_key}/" + CHUNK_FILE + ".mp4"
EPISODES_PATH = EPISODES_DIR + "/" + CHUNK_FILE + ".parquet"
CHUNKS_SIZE = 1000  # files per chunk folder (LeRobot's default)
EPISODES_PER_META_FILE = 1000  # rows per meta/episodes file; only the last one is ever rewritten


def chunk_file(index: int, chunks_size: int = CHUNKS_SIZE) -> tuple[int, int]:
    """(chunk_index, file_index) of file number ``index``."""
    return divmod(index, chunks_size)


def data_path(root: Path, chunk_index: int, file_index: int) -> Path:
    return root / DATA_PATH.format(chunk_index=chunk_index, file_index=file_index)


def video_path(root: Path, video_key: str, chunk_index: int, file_index: int) -> Path:
    return root / VIDEO_PATH.format(video_key=video_key, chunk_index=chunk_index, file_index=file_index)


def episodes_meta_path(root: Path, meta_file_number: int) -> Path:
    c, f = chunk_file(meta_file_number)
    return root / EPISODES_PATH.format(chunk_index=c, file_index=f)


def episodes_meta_files(root: Path) -> list[Path]:
    """Every meta/episodes parquet file, in (chunk, file) order."""
    return sorted((root / EPISODES_DIR).glob("chunk-*/file-*.parquet"))
