"""What a run needs to be reproduced: code version, packages, machine."""

from __future__ import annotations

import hashlib
import json
import platform
import socket
import subprocess
import sys
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
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


# pipeline code that reads results but never shapes a run (paths below pipelines/, folders ending in /)
POST_PROCESSING = ("report/", "bench/", "recording/recordings.py", "recording/display.py", "replay.py",
                   "sweeps/callback.py", "run/multiruns.py")


def code_hash(root: Path = REPO) -> str:
    """SHA-256 of the sources a run executes (``mpm/``, ``pipelines/`` but
    the post-processing tools): changes with any such edit, committed or not."""
    h = hashlib.sha256()
    for pkg in ("mpm", "pipelines"):
        for f in sorted((root / pkg).rglob("*.py")):
            if pkg == "pipelines" and f.relative_to(root / pkg).as_posix().startswith(POST_PROCESSING):
                continue
            h.update(str(f.relative_to(root)).encode())
            h.update(f.read_bytes())
    return h.hexdigest()[:16]


# keys that do not change a run's result: they are left out of its hash (scale only feeds
# interpolations, whose resolved values are hashed; a resumed run keeps the hash of the run it continues)
UNHASHED = {"run": ("force", "plan", "checkpoint_every", "resume"), "log": ("progress",), "scale": None}


def config_hash(config: dict, code: str, files: dict | None = None) -> str:
    """Content hash of a resolved config (a plain dict), the code version,
    the versions of the packages a run computes with and the digests of the
    files it reads (``files``: name -> digest, e.g. meshes): two jobs with the
    same hash compute the same thing."""
    cfg = {}
    for k, v in config.items():
        drop = UNHASHED.get(k, ())
        if drop is None:
            continue
        cfg[k] = {kk: vv for kk, vv in v.items() if kk not in drop} if isinstance(v, dict) else v
    versions = {k: v for k, v in package_versions().items() if k in ("python", "warp-lang", "numpy")}
    text = json.dumps({"config": cfg, "versions": versions, **({"files": files} if files else {})},
                      sort_keys=True, default=str)
    return hashlib.sha256(f"{code}\n{text}".encode()).hexdigest()[:16]
