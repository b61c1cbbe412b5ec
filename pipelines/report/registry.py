"""The report's sections and their order.

A section is a function that writes its tables and plots into the output
directory and returns its lines of ``report.md``. It takes, by name, any of

    jobs        the sweep's jobs, labelled and with their errors (pipelines.report.jobs)
    out         the output directory
    style       a (colour, marker) per label, the same in every figure
    duplicates  the number of jobs merged as copies of an identical configuration

and registers itself with :func:`section`; ``report.md`` lists the sections by
increasing ``order``. The report imports every module of
:mod:`pipelines.report.sections` (:func:`pipelines.report.load_sections`), so
that an experiment's section is one module there::

    @section(order=75)
    def section_bounce(jobs, out):
        ...
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Callable

ARGUMENTS = ("jobs", "out", "style", "duplicates")


@dataclass(frozen=True)
class Section:
    order: float  # place in report.md, increasing
    write: Callable[..., list[str]]
    document: str | None = None  # a markdown file of its own that also holds the section (when available)

    @property
    def name(self) -> str:
        return f"{self.write.__module__}.{self.write.__qualname__}"

    def __call__(self, **data) -> list[str]:
        """The section's lines, written from the arguments it names."""
        return self.write(**{k: data[k] for k in inspect.signature(self.write).parameters})


_SECTIONS: dict[str, Section] = {}


def section(order: float, document: str | None = None):
    """Register the decorated function as a report section at ``order``;
    ``document`` (e.g. ``"stability.md"``): a markdown file, titled after
    its name, that also gets the section's lines unless the section is not
    available."""

    def register(write: Callable[..., list[str]]) -> Callable[..., list[str]]:
        unknown = sorted(set(inspect.signature(write).parameters) - set(ARGUMENTS))
        if unknown:
            raise TypeError(f"section {write.__qualname__}: unknown argument(s) {', '.join(unknown)}; "
                            f"accepted: {', '.join(ARGUMENTS)}")
        new = Section(order, write, document)
        taken = next((s for s in _SECTIONS.values() if s.order == order and s.name != new.name), None)
        if taken is not None:
            raise ValueError(f"section {new.name}: order {order} is {taken.name}'s")
        _SECTIONS[new.name] = new
        return write

    return register


def registered() -> list[Section]:
    """The sections registered so far, in report order."""
    return sorted(_SECTIONS.values(), key=lambda s: s.order)
