"""Command-line checks shared by the examples.

A bad argument ends a script before anything is built, with one line on
stderr, ``error: --option: value; accepted: what``, and exit code 2 (as the
project's own commands do). Each check is an argparse ``type``: argparse
calls it while it parses and hands its message to :meth:`Parser.error`.

The scripts import this module from their own folder, which Python puts
first on the path when it runs a script.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from pathlib import Path


class Parser(argparse.ArgumentParser):
    """argparse whose errors (its own and the checks') take one line,
    ``error: --option: ...``, with exit code 2, and whose ``--help`` shows
    each option's default."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", argparse.ArgumentDefaultsHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str):
        self.exit(2, f"error: {message.removeprefix('argument ')}\n")


def _refuse(value: str, accepted: str):
    raise argparse.ArgumentTypeError(f"{value}; accepted: {accepted}")


def _number(text: str) -> float | None:
    try:
        x = float(text)
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def positive(unit: str):
    """A finite number > 0 [``unit``]: nan, inf, 0 and negatives are refused."""
    accepted = f"a finite number > 0 [{unit}]"

    def check(text: str) -> float:
        x = _number(text)
        if x is None or x <= 0.0:
            _refuse(text, accepted)
        return x
    return check


def bounded(lo: float, hi: float, unit: str):
    """A finite number in [lo, hi] [``unit``]."""
    accepted = f"a finite number from {lo:g} to {hi:g} [{unit}]"

    def check(text: str) -> float:
        x = _number(text)
        if x is None or not lo <= x <= hi:
            _refuse(text, accepted)
        return x
    return check


def integer(lo: int, hi: int, step: int = 1):
    """An integer from lo to hi (a multiple of ``step``)."""
    accepted = f"an integer from {lo} to {hi}" + (f", a multiple of {step}" if step > 1 else "")

    def check(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            _refuse(text, accepted)
        if not lo <= n <= hi or n % step:
            _refuse(text, accepted)
        return n
    return check


def bounded_list(lo: float, hi: float, unit: str, most: int = 8):
    """1 to ``most`` comma-separated finite numbers in [lo, hi] [``unit``]."""
    accepted = f"1 to {most} comma-separated numbers from {lo:g} to {hi:g} [{unit}]"

    def check(text: str) -> list[float]:
        values = [_number(part) for part in text.split(",")]
        if not 1 <= len(values) <= most or any(x is None or not lo <= x <= hi for x in values):
            _refuse(text, accepted)
        return values
    return check


def integer_list(lo: int, hi: int, most: int = 8):
    """1 to ``most`` comma-separated integers from lo to hi."""
    accepted = f"1 to {most} comma-separated integers from {lo} to {hi}"

    def check(text: str) -> list[int]:
        try:
            values = [int(part) for part in text.split(",")]
        except ValueError:
            _refuse(text, accepted)
        if not 1 <= len(values) <= most or any(not lo <= n <= hi for n in values):
            _refuse(text, accepted)
        return values
    return check


def choice(names):
    """One of ``names``."""
    names = list(names)

    def check(text: str) -> str:
        if text not in names:
            _refuse(text, ", ".join(names))
        return text
    return check


def cuda_devices() -> int:
    """How many CUDA devices Warp finds. Warp is initialised here with its
    native start-up messages silenced (without a CUDA driver it writes a
    warning to stderr; the device check says it in its own words)."""
    import warp as wp

    sys.stderr.flush()
    saved, null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)
    return wp.get_cuda_device_count()


def device(text: str) -> str:
    """``cpu``, or ``cuda`` / ``cuda:N`` where Warp finds that CUDA device."""
    n = cuda_devices()
    cuda = re.fullmatch(r"cuda(?::(\d+))?", text)
    if text == "cpu" or (cuda and n and (cuda[1] is None or int(cuda[1]) < n)):
        return text
    _refuse(text, "cpu, cuda, " + ", ".join(f"cuda:{i}" for i in range(n)) if n
            else "cpu (Warp finds no CUDA device on this machine)")


def out_dir(text: str) -> Path:
    """A folder this process can write to, or one it can create (its nearest
    existing parent a writable folder). Nothing is created here."""
    path = Path(text).expanduser()
    if path.exists():
        if not path.is_dir():
            _refuse(text, "a folder to write into (this is a file)")
        if not os.access(path, os.W_OK | os.X_OK):
            _refuse(text, "a folder to write into (this one is not writable)")
        return path
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        _refuse(text, f"a folder to write into or create ({parent} is not a writable folder)")
    return path
