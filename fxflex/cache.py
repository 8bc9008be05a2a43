"""Where fxflex keeps what it can reuse across runs (meshes, eigenmodes, invariant matrices).

``$FXFLEX_CACHE`` if set, else ``~/.cache/fxflex``. Entries are keyed by a hash of everything they
depend on and written atomically (temporary file, then rename), so concurrent runs are safe.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_dir"]


def cache_dir(kind: str) -> Path:
    root = Path(os.environ.get("FXFLEX_CACHE") or Path.home() / ".cache" / "fxflex")
    path = root / kind
    path.mkdir(parents=True, exist_ok=True)
    return path
