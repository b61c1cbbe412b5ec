"""A command-line run's checkpoints: when they are written, where, what of
the recorder they keep, and which one ``run.resume=true`` continues from.

``run.checkpoint_every`` [s of simulated time]: 0 writes none; null writes
one every :data:`AUTO_WALL_S` seconds of wall time, or every
:data:`AUTO_COST` times the last write's time where that is longer, so that
writing them takes under 2 % of the run. Files
are ``<run dir>/checkpoints/ckpt-<step>.npz`` (mpm.checkpoint), the newest
:data:`KEEP` kept; their meta holds the config hash, the code version (the git
commit and the hash of the sources a run executes, pipelines.run.provenance),
the recording's id and the recorder's state (its series, tracks and metrics
so far), so that ``metrics.json`` describes the whole run.

On SIGTERM or SIGUSR1 (a cluster pre-empting the job; submitit's requeue) a
run writes a checkpoint at the next step boundary and ends ``preempted`` with
exit code :data:`PREEMPTED` (75, EX_TEMPFAIL: try again); the same command
with ``run.resume=true`` continues it (``run.resume=null``: where the run
directory holds a checkpoint, else from the start: a requeued job's own
command). The continued run logs into
``<recording>.resumed-<step>.rrd`` with the first file's recording id and,
at its end, appends it to the first file (:func:`join_recordings`, Rerun's
``rrd merge``): one recording, one file. Should the merge fail, both files
stay, and the viewer still shows them as one recording when both are opened.
"""

from __future__ import annotations

import pickle
import re
import time
from pathlib import Path

import mpm
from mpm.checkpoint import CheckpointError

from . import provenance
from ..config.errors import EXIT_CODES
from ..recording import recordings
from ..recording.sinks import timings_path
from ..config.fields import ConfigError

DIR = "checkpoints"
"""the folder of a run directory that holds its checkpoints"""
KEEP = 2
"""checkpoints kept (the newest); an older one is removed once a newer one is written"""
AUTO_WALL_S = 300.0
"""[s] wall time between checkpoints when run.checkpoint_every is null"""
AUTO_COST = 50.0
"""run.checkpoint_every null: at least this many times the last write's wall time between two (2 %)"""
PREEMPTED = EXIT_CODES["preempted"]
"""a run's exit code after SIGTERM or SIGUSR1 left a checkpoint (EX_TEMPFAIL: requeue and resume)"""
NAME = re.compile(r"ckpt-(\d+)\.npz")
# what a resumed recorder builds again (build, on_resume) rather than takes from the checkpoint
REBUILT = ("spec", "out_dir", "properties", "sink", "driver", "solver", "state", "model", "progress", "scheme",
           "solution", "X0", "mass0", "implicit", "names", "marked_names", "stretch_names", "built", "started")


def code_version() -> dict:
    """The code a run executes: git commit and the sources' hash."""
    return {"git_commit": provenance.git_state()["git_commit"], "code_hash": provenance.code_hash()}


def recorder_state(recorder) -> dict:
    """What a recorder has gathered so far, picklable: each attribute as it is, or an object's
    picklable attributes where the object holds the model (its tracks)."""
    out = {}
    for name, value in vars(recorder).items():
        if name in REBUILT:
            continue
        try:
            out[name] = ("value", pickle.loads(pickle.dumps(value)))
        except Exception:  # an object holding Warp arrays or the model: its own numbers only
            if hasattr(value, "__dict__"):
                out[name] = ("parts", {k: v for k, v in vars(value).items() if _picklable(v)})
    return out


def _picklable(value) -> bool:
    try:
        pickle.dumps(value)
        return True
    except Exception:
        return False


def restore_recorder(recorder, state: dict) -> None:
    """Put :func:`recorder_state`'s values back into a resumed recorder (after its on_resume)."""
    for name, (kind, value) in state.items():
        if kind == "value":
            setattr(recorder, name, value)
        elif getattr(recorder, name, None) is not None:
            vars(getattr(recorder, name)).update(value)


class Checkpoints:
    """A run's checkpoints: :meth:`due` after each batch of steps, :meth:`write` when it is."""

    def __init__(self, out_dir: Path, every: float | None, identity: dict, recording_id: str | None):
        self.dir = Path(out_dir) / DIR
        self.every = every
        self.meta = {"config_hash": identity.get("config_hash"), **code_version(), "recording_id": recording_id}
        self._since = time.monotonic()
        self._wall = AUTO_WALL_S  # [s] wall time between two (run.checkpoint_every null)
        self._next: float | None = None  # [s] the simulated time of the next one

    def describe(self) -> str:
        """One line: how often, and where."""
        if self.every == 0:
            return "checkpoints: none (run.checkpoint_every=0)"
        when = (f"every {AUTO_WALL_S / 60:g} minutes of wall time (run.checkpoint_every=null)" if self.every is None
                else f"every {self.every:g} s of simulated time")
        return f"checkpoints: {when}, the last {KEEP} kept in {self.dir}"

    def due(self, driver: mpm.Driver) -> bool:
        if self.every == 0 or not driver.running:
            return False
        if self.every is None:
            return time.monotonic() - self._since >= self._wall
        if self._next is None:
            self._next = (driver.time // self.every + 1) * self.every
        return driver.time >= self._next * (1 - 1e-12)

    def write(self, driver: mpm.Driver, recorder) -> Path:
        """The driver's and the recorder's state at ``driver.step``; the older ones beyond KEEP removed."""
        t0 = time.monotonic()
        self.dir.mkdir(parents=True, exist_ok=True)
        path = driver.save(self.dir / f"ckpt-{driver.step}.npz", {**self.meta, "recorder": recorder_state(recorder)})
        for old in listed(self.dir)[KEEP:]:
            old.unlink(missing_ok=True)
        self._since = time.monotonic()
        self._wall = max(AUTO_WALL_S, AUTO_COST * (self._since - t0))
        if self.every:
            self._next = (driver.time // self.every + 1) * self.every
        return path


def listed(folder: Path) -> list[Path]:
    """The checkpoints in ``folder``, newest (highest step) first."""
    found = [(int(m.group(1)), p) for p in Path(folder).glob("ckpt-*.npz") if (m := NAME.fullmatch(p.name))]
    return [p for _, p in sorted(found, reverse=True)]


def choose(out_dir: Path, identity: dict) -> tuple[mpm.checkpoint.Checkpoint, list[str]]:
    """``run.resume=true``: the newest checkpoint of ``out_dir`` that reads back, and a note for each newer
    one that did not; ConfigError (one line) when there is none, or it is another configuration's or
    another code version's."""
    folder, notes = Path(out_dir) / DIR, []
    files = listed(folder)
    if not files:
        raise ConfigError("run.resume", f"no checkpoint in {folder}; accepted: hydra.run.dir=<the directory of a "
                                        f"run that wrote one>")
    for path in files:
        try:
            data = mpm.checkpoint.read(path)
        except CheckpointError as e:
            notes.append(f"note: {e}; taking the one before")
            continue
        mine = {"config_hash": identity.get("config_hash"), **code_version()}
        for key in ("code_hash", "config_hash"):  # (the config hash covers the code too: name the code first)
            if data.meta.get(key) != mine[key]:
                what = "configuration" if key == "config_hash" else "code version"
                raise ConfigError("run.resume", f"{path} is of another {what} ({key} {data.meta.get(key)}, this "
                                                f"run's {mine[key]}); accepted: the same config and code")
        return data, notes
    raise ConfigError("run.resume", f"no checkpoint in {folder} reads back ({len(files)} damaged)")


def join_recordings(first: Path, part: Path) -> str:
    """Append a resumed run's recording ``part`` (and its timings file) to ``first``; "" or a note
    saying why the two files stay apart."""
    try:
        for a, b in ((first, part), (timings_path(first), timings_path(part))):
            if b.is_file():
                recordings.merge(a, b)
    except RuntimeError as e:
        return f"note: {e}; open both files: the viewer shows them as one recording"
    return ""

