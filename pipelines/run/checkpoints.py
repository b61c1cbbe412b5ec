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

On SIGTERM or SIGUSR1 (a cluster pre-empting the job) a run writes a
checkpoint at the next step boundary, ends ``preempted`` with exit code
:data:`PREEMPTED` (75, EX_TEMPFAIL: try again) and hands the signal on to the
handler that was there before it (submitit's requeue, pipelines.run.runner); the same command
with ``run.resume=true`` continues it (``run.resume=null``: where the run
directory holds a checkpoint, else from the start: a requeued job's own
command). Killed without warning (SIGKILL, a node lost), a run is continued
the same way from its newest checkpoint: a checkpoint is written once the
recording's files hold everything logged so far (``Sink.sync``), and keeps
their sizes; resuming cuts them back to those sizes (dropping what was logged
after it, and a message cut short), a continued run logs into
``<recording>.resumed-<step>.rrd`` with the first file's recording id (the
first file becomes ``<recording>.resumed-0.rrd``), and at its end the parts
are joined into ``<recording>`` (:func:`join_segments`, Rerun's ``rrd merge``),
and removed once the run has ended (completed or unstable):
one recording, one file, as the uninterrupted run's. Should the merge fail, the
parts stay, and the viewer still shows them as one recording when all are opened.
A checkpoint's temporary file left by a kill is removed by the next run.
"""

from __future__ import annotations

import os
import pickle
import re
import time
from concurrent.futures import ThreadPoolExecutor
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

    def __init__(self, out_dir: Path, every: float | None, identity: dict, recording_id: str | None,
                 segments: list | None = None):
        """``segments``: the recording's earlier parts, ``[name, size, timings size]`` each
        (:func:`resume_segments`)."""
        self.dir = Path(out_dir) / DIR
        self.every = every
        self.meta = {"config_hash": identity.get("config_hash"), **code_version(), "recording_id": recording_id}
        self.segments = list(segments or [])
        self.write_s: list[float] = []  # [s] each write's wall time (this process's)
        for tmp in self.dir.glob(".ckpt-*.tmp"):  # a write cut short by a kill
            tmp.unlink(missing_ok=True)
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
        meta = {**self.meta, "recorder": recorder_state(recorder)}
        sink = getattr(recorder, "sink", None)
        if sink is not None and len(sizes := list(sink.sync().items())) == 2:  # the recording and its timings
            (name, size), (_, timed) = sizes
            meta["segments"] = [*self.segments, [name, size, timed]]
        path = driver.save(self.dir / f"ckpt-{driver.step}.npz", meta)
        for old in listed(self.dir)[KEEP:]:
            old.unlink(missing_ok=True)
        self._since = time.monotonic()
        self._wall = max(AUTO_WALL_S, AUTO_COST * (self._since - t0))
        self.write_s.append(self._since - t0)
        if self.every:
            self._next = (driver.time // self.every + 1) * self.every
        return path


    def summary(self) -> dict:
        """metrics.json's entries: this process's checkpoint writes, their mean wall time [s] and the last
        one's size [bytes]."""
        files = listed(self.dir) if self.write_s else []
        return {"checkpoint_writes": len(self.write_s),
                "checkpoint_write_s": sum(self.write_s) / len(self.write_s) if self.write_s else None,
                "checkpoint_bytes": files[0].stat().st_size if files else None}


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


def segment(recording: str, step: int) -> str:
    """The name of a recording's part continued from ``step``: ``recording.rrd`` -> ``recording.resumed-<step>.rrd``."""
    return recording.replace(".rrd", f".resumed-{step}.rrd")


def _segment_files(out_dir: Path, recording: str) -> list[Path]:
    """Every part of ``recording`` in ``out_dir``, timings files included."""
    return sorted(Path(out_dir).glob(segment(recording, 0).replace("-0.rrd", "-*.rrd")))


def resume_segments(out_dir: Path, recording: str, data: mpm.checkpoint.Checkpoint) -> list:
    """Before continuing from ``data``: the recording's parts as the checkpoint found them (the first file
    renamed to part 0, each cut back to its size then, the parts of later killed runs removed);
    ``[name, size, timings size]`` each, in order ([] where the checkpoint kept none)."""
    out_dir = Path(out_dir)
    first, zero = out_dir / recording, out_dir / segment(recording, 0)
    for a, b in ((first, zero), (timings_path(first), timings_path(zero))):
        if a.is_file() and not b.is_file():  # (both: ``a`` is a join of the parts, killed before its end)
            a.replace(b)
    parts = [[zero.name if name == recording else name, size, timed]
             for name, size, timed in data.meta.get("segments", [])]
    for name, size, timed in parts:
        for path, n in ((out_dir / name, size), (timings_path(out_dir / name), timed)):
            if not path.is_file() or path.stat().st_size < n:
                raise ConfigError("run.resume", f"{path} is shorter than when {data.path.name} was written; "
                                                f"accepted: the run directory as the run left it")
            os.truncate(path, n)
    keep = {p for name, _, _ in parts for p in (out_dir / name, timings_path(out_dir / name))}
    for path in _segment_files(out_dir, recording):
        if path not in keep:
            path.unlink()
    return parts


def join_segments(out_dir: Path, recording: str, parts: list[str]) -> str:
    """The recording's parts (names, in order) joined into ``recording`` and its timings file; "" or a
    note saying why the parts stay apart. The parts are kept (:func:`drop_segments` once the run is recorded)."""
    out_dir = Path(out_dir)
    jobs = ((out_dir / recording, [out_dir / n for n in parts]),
            (timings_path(out_dir / recording), [timings_path(out_dir / n) for n in parts]))
    try:
        with ThreadPoolExecutor(len(jobs)) as pool:  # the two merges at once
            for done in [pool.submit(recordings.join, target, [f for f in files if f.is_file()])
                         for target, files in jobs]:
                done.result()
    except RuntimeError as e:
        return f"note: {e}; open the parts: the viewer shows them as one recording"
    return ""


def drop_segments(out_dir: Path, recording: str) -> None:
    """Remove the recording's parts (joined, or of a run started anew)."""
    for path in _segment_files(out_dir, recording):
        path.unlink(missing_ok=True)
