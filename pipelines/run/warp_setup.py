"""Initialise Warp for command-line use: errors only, and without the
native-code notice that a machine has no CUDA driver (CPU runs are the
default; asking for ``run.device=cuda`` there still fails with a clear
message)."""

from __future__ import annotations

import os
import sys

import warp as wp

_CUDA_NOTICE = "Could not find or load the NVIDIA CUDA driver"


def init_warp() -> None:
    wp.config.log_level = wp.LOG_ERROR
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no real stderr (e.g. captured): plain init
        wp.init()
        return
    r, w = os.pipe()
    try:
        os.dup2(w, 2)
        wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(w)
        with os.fdopen(r, "r", errors="replace") as f:
            text = f.read()
    for line in text.splitlines(keepends=True):
        if _CUDA_NOTICE not in line:
            sys.stderr.write(line)
