"""What a driver (mpm.stepping.driver) reports to its observers besides each
step's report: :class:`Event` (a warning, a halved step) and
:class:`Outcome` (how a run ended)."""

from __future__ import annotations

from dataclasses import dataclass, field

from .status import StepReport

STATUSES = ("running", "completed", "unstable")


@dataclass
class Event:
    """Something a person should read: a warning, a halved step."""

    step: int
    """the step it happened at"""
    time: float
    """[s]"""
    text: str
    """what happened, one line"""
    level: str = "INFO"
    """INFO | WARN | ERROR"""
    values: dict = field(default_factory=dict)
    """the figures behind it, by name"""
    kind: str = ""
    """"detection": a warning of the blow-up detection; "halving": an implicit step halved;
    "unsettled": an implicit step's contact rounds ran out (mpm.implicit.solve ROUNDS)"""


@dataclass
class Outcome:
    """How a run ended (``status`` running while it has not)."""

    status: str = "running"
    """one of STATUSES"""
    reason: str = ""
    """why the run stopped, one line (empty: completed)"""
    step: int = 0
    """steps completed"""
    time: float = 0.0
    """[s]"""
    criterion: str | None = None
    """nonfinite, outside, dt_collapse, newton, or a detection criterion"""
    body: str | None = None
    """the body it names, if any"""
    values: dict = field(default_factory=dict)
    """the criterion's figures, by name"""
    report: StepReport | None = None
    """the step that failed (None: none was taken)"""
