"""The machine a result was computed on (CPU, cores, memory, Python, date): the header of every
benchmark table and of the stored converged reference."""

from __future__ import annotations

import os
import platform
import time

__all__ = ["machine"]


def machine() -> dict:
    """CPU model, core count and memory, for the header of every benchmark table."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    mem = None
    try:
        with open("/proc/meminfo") as fh:
            mem = round(int(fh.readline().split()[1]) / 2**20, 1)
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "memory_gib": mem,
            "python": platform.python_version(), "date": time.strftime("%Y-%m-%d %H:%M")}
