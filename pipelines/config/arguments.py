"""The command-line options of the tools (replay, report, material point,
benchmark, ...): errors on one line ``error: <option>: <value>; accepted:
<what>`` with exit code 2, and the checks of output paths and numbers made
before any work."""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from .errors import EXIT_CONFIG


class Parser(argparse.ArgumentParser):
    """argparse, with its errors on one line and exit code 2."""

    def error(self, message: str):
        more = "" if "accepted:" in message else f"; accepted: see {self.prog} --help"
        self.exit(EXIT_CONFIG, f"error: {message}{more}\n")


def output_dir(option: str, path: Path | None) -> str | None:
    """Why ``path`` cannot be a directory to write into (None: it can): it
    exists and is not a directory, or its nearest existing parent is not a
    writable directory."""
    if path is None:
        return None
    path = Path(path)
    if path.exists() and not path.is_dir():
        return f"{option}: {path} is a file; accepted: a directory (it is created if missing)"
    parent = path
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        return f"{option}: {path}: {parent} is not a writable directory; accepted: a path in a writable directory"
    return None


def output_file(option: str, path: Path, suffix: str) -> str | None:
    """Why ``path`` cannot be written as a ``suffix`` file (None: it can):
    another suffix (the tool would overwrite a file that is not its kind), a
    directory, or a folder that does not exist or cannot be written."""
    path = Path(path)
    if path.suffix.lower() != suffix:
        return f"{option}: {path}; accepted: a file name ending in {suffix}"
    if path.is_dir():
        return f"{option}: {path} is a directory; accepted: a {suffix} file name"
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        return f"{option}: {path}: no folder {folder}; accepted: a {suffix} file in an existing folder"
    if not os.access(folder, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        return f"{option}: {path}: not writable; accepted: a {suffix} file in a writable folder"
    return None


def finite(option: str, value: float, low: float | None = None, strict: bool = False) -> str | None:
    """Why ``value`` is not a finite number (above ``low``) (None: it is)."""
    bound = "" if low is None else f" {'>' if strict else '>='} {low:g}"
    if not math.isfinite(value):
        return f"{option}: {value}; accepted: a finite number{bound}"
    if low is not None and (value < low or (strict and value == low)):
        return f"{option}: {value:g}; accepted: a number{bound}"
    return None
