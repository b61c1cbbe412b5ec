"""Where a run's data goes. The runner talks to a :class:`Sink`; the solver
never does.

A sink receives: static run metadata once (:meth:`Sink.start`), particles
(positions, the per-particle dJ field and, with plastic materials, their named
per-particle fields) on logged steps, a row of scalars every step, events
(text plus machine-readable values) and, apart from all these, wall-clock
timings: the physics of two identical runs is identical, their timings are not.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pathlib import Path

import numpy as np


def timings_path(recording: str | Path) -> Path:
    """The wall-clock companion of a recording: ``x.rrd`` -> ``x.timings.rrd``."""
    recording = Path(recording)
    return recording.with_name(recording.stem + ".timings.rrd")


@dataclass
class RunMeta:
    """Static description of a run for the recording."""

    name: str
    dim: int
    domain: tuple[float, ...]
    wall_cells: int
    dx: float
    body_names: list[str]
    particle_body: np.ndarray  # body index per particle
    particle_radius: float  # [m]
    properties: dict = field(default_factory=dict)  # name -> {key: value}: how to reproduce the run
    run_properties: dict = field(default_factory=dict)  # name -> {key: value}: when, where, which command
    scalar_groups: dict = field(default_factory=dict)  # view name -> scalar names
    colliders: list = field(default_factory=list)  # mpm.colliders.Collider (drawn by the sink)
    color: str = "body"  # what colours the particles: body, dJ or a per-particle field
    color_range: tuple = (None, "")  # ((low, high) or None: the run's own, where it comes from)
    # log.channels: field -> ((low, high) or None, where it comes from), each an extra particle entity
    # /channels/<field> coloured by the field, hidden in the blueprint (:func:`channel_ranges`)
    channels: dict = field(default_factory=dict)
    field_notes: dict = field(default_factory=dict)  # field -> what to know when reading it (the legend)
    # the rigid bodies (mpm.rigid): (name, its shape at rest, a Collider), each drawn under /rigid/<name> and
    # placed at its pose at every particle frame (:meth:`Sink.particles`' ``rigid``)
    rigid_bodies: list = field(default_factory=list)


class Sink:
    """Interface (and a sink that drops everything)."""

    def start(self, meta: RunMeta) -> None:
        pass

    def particles(self, step: int, t: float, x: np.ndarray, dJ: np.ndarray | None,
                  fields: dict[str, np.ndarray] | None = None, index: np.ndarray | None = None,
                  rigid: list | None = None) -> None:
        """Particles of a logged frame; ``index``: their numbers, when some were removed; ``rigid``: per
        rigid body of ``RunMeta.rigid_bodies``, its pose then as (rotation (3, 3), translation (3,)), which
        takes a point of its shape at rest to its place (x -> R x + b)."""

    def scalars(self, step: int, t: float, values: dict[str, float]) -> None:
        pass

    def event(self, step: int, t: float, text: str, level: str = "INFO", **values) -> None:
        pass

    def timings(self, step: int, t: float, values: dict[str, float]) -> None:
        """Wall-clock figures of a step [ms]: never part of the physics."""

    def flush(self) -> None:
        pass

    def sync(self) -> dict[str, int]:
        """Everything handed over so far written to disk (a checkpoint's moment): each file's name and
        size [bytes] then, from which a run killed later is continued; {}: nothing on disk."""
        return {}

    def close(self) -> None:
        pass
