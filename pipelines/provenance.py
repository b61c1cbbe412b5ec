"""What a run needs to be reproduced: code version, packages, machine."""

from __future__ import annotations

import platform
import socket
import subprocess
import sys
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("warp-lang", "numpy", "rerun-sdk", "hydra-core", "omegaconf", "aulmpm-toolkit")


def git_state(path: Path = REPO) -> dict:
    """Commit hash and dirty flag of the checkout holding the code (or unknown)."""

    def git(*args):
        return subprocess.run(["git", "-C", str(path), *args], capture_output=True, text=True,
                              timeout=10).stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        commit, dirty = "", False
    return {"git_commit": commit or "unknown", "git_dirty": dirty}


def package_versions() -> dict:
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def device_name(device: str) -> str:
    import warp as wp

    d = wp.get_device(device)
    return f"{d.alias}: {d.name}" if d.is_cuda else f"cpu: {platform.processor() or platform.machine()}"


def collect(device: str, precision: str, seed: int, overrides: list[str]) -> dict:
    return {
        **git_state(),
        "packages": package_versions(),
        "device": device_name(device),
        "precision": precision,
        "seed": seed,
        "overrides": list(overrides),
        "command": " ".join(getattr(sys, "orig_argv", sys.argv)),
        "host": socket.gethostname(),
        "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
