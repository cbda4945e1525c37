"""Task functions for the dead-worker test of ``detect`` (module level: spawned workers
import them)."""

from __future__ import annotations

import os


def die_on_second(job, indices):
    """Kill the worker process on the task holding tile (0, 1); others return no records."""
    if (0, 1) in indices:
        os._exit(3)
    return "ok", []
