"""Physical responses of a run: a quantity of a body's particles (its lowest
point, its height, its front, its centre) followed over the states of a run
and reduced to one number (its minimum, its rebound, its final value, its
largest fractional drop). A scene's responses name what a sweep over it is
about - a ball's peak compression and rebound, a dam break's front - beside
what it costs.

    tracker = Tracker([Response("rebound", "bottom", body=0, reduce="max_after_min")], model)
    tracker.update(state.x.numpy(), t)   # every state, e.g. from an mpm.Observer
    tracker.values()                     # {"rebound": 0.31}
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

QUANTITIES = {
    "bottom": "the lowest particle's height (coordinate along y) [m]",
    "top": "the highest particle's height [m]",
    "height": "top minus bottom [m]",
    "width": "the extent along x [m]",
    "front": "the largest x [m]",
    "back": "the smallest x [m]",
    "center_x": "the mass-weighted mean x [m]",
    "center_y": "the mass-weighted mean y [m]",
}
"""What a response follows, per state, over a body's particles (or all)."""

REDUCTIONS = {
    "min": "the smallest value over the run",
    "max": "the largest value over the run",
    "final": "the value at the last state",
    "max_after_min": "the largest value after the smallest (a rebound's height)",
    "drop": "(initial - smallest) / initial, a fraction (a compression)",
    "acceleration": "twice the t^2 coefficient of a parabola fitted to the states from a quarter of the run on "
                    "(m/s^2 of a length: a body sliding or rolling)",
}
"""How a response reduces its quantity over the states of a run."""


@dataclass(frozen=True)
class Response:
    """A named response: ``quantity`` (:data:`QUANTITIES`) of body ``body``'s
    particles (None: every body's), reduced over the run by ``reduce``
    (:data:`REDUCTIONS`)."""

    name: str
    """the response's name (metrics.json, a sweep report)"""
    quantity: str
    """what is followed per state (:data:`QUANTITIES`)"""
    body: int | None = None
    """the body's index; None: every body's particles"""
    reduce: str = "max"
    """how it is reduced over the run (:data:`REDUCTIONS`)"""

    def __post_init__(self):
        if self.quantity not in QUANTITIES:
            raise ValueError(f"response {self.name}: quantity {self.quantity!r}; accepted: {', '.join(QUANTITIES)}")
        if self.reduce not in REDUCTIONS:
            raise ValueError(f"response {self.name}: reduce {self.reduce!r}; accepted: {', '.join(REDUCTIONS)}")

    @property
    def unit(self) -> str:
        return {"drop": "-", "acceleration": "m/s^2"}.get(self.reduce, "m")


def quantity(name: str, x: np.ndarray, m: np.ndarray) -> float:
    """:data:`QUANTITIES` ``name`` of positions ``x`` [m] (n x d) with masses ``m`` [kg]."""
    if name == "bottom":
        return float(x[:, 1].min())
    if name == "top":
        return float(x[:, 1].max())
    if name == "height":
        return float(x[:, 1].max() - x[:, 1].min())
    if name == "width":
        return float(x[:, 0].max() - x[:, 0].min())
    if name == "front":
        return float(x[:, 0].max())
    if name == "back":
        return float(x[:, 0].min())
    axis = {"center_x": 0, "center_y": 1}[name]
    return float(m @ x[:, axis].astype(np.float64) / m.sum())


class Tracker:
    """The responses of one model's run: :meth:`update` with every state's
    positions, :meth:`values` at the end (NaN before any update)."""

    def __init__(self, responses: list[Response], model):
        self.responses = list(responses)
        names = [r.name for r in self.responses]
        if len(set(names)) != len(names):
            raise ValueError(f"responses: a name twice in {names}")
        n = len(model.body_ranges)
        for r in self.responses:
            if r.body is not None and not 0 <= r.body < n:
                raise ValueError(f"response {r.name}: body {r.body}; accepted: 0 to {n - 1}, or None (every body)")
        mass = model.mass.numpy().astype(np.float64)
        self._slices = [slice(None) if r.body is None else slice(model.body_ranges[r.body][0],
                                                                  sum(model.body_ranges[r.body]))
                        for r in self.responses]
        self._mass = [mass[s] for s in self._slices]
        self.series: list[list[tuple[float, float]]] = [[] for _ in self.responses]  # (t [s], value)

    def update(self, x: np.ndarray, t: float, kept: np.ndarray | None = None) -> None:
        """Record each response's quantity at the state with positions ``x`` [m]
        at time ``t`` [s]; ``kept``: the indices of the particles still in the
        domain (None: all), once some were removed at open walls (NaN for a
        body with none left)."""
        alive = None
        if kept is not None:
            alive = np.zeros(len(x), bool)
            alive[kept] = True
        for r, s, m, out in zip(self.responses, self._slices, self._mass, self.series):
            xs = x[s]
            if alive is not None:
                xs, m = xs[alive[s]], m[alive[s]]
            out.append((float(t), quantity(r.quantity, xs, m) if len(xs) else float("nan")))

    def values(self) -> dict[str, float]:
        """Each response's reduction over the states recorded so far."""
        return {r.name: reduce(r.reduce, np.array([v for _, v in series]), np.array([t for t, _ in series]))
                for r, series in zip(self.responses, self.series)}

    def reached(self) -> dict[str, bool]:
        """Each response's :func:`reached` over the states recorded so far."""
        return {r.name: reached(r.reduce, np.array([v for _, v in series]))
                for r, series in zip(self.responses, self.series)}

    def summary(self, body_names: list[str]) -> dict[str, dict]:
        """metrics.json ``responses``: per name its value (None when not
        finite), unit, quantity, reduction, body (a name, or "all") and
        whether the run reached it (:func:`reached`)."""
        return {r.name: {"value": v if np.isfinite(v) else None, "unit": r.unit, "quantity": r.quantity,
                         "reduce": r.reduce, "body": "all" if r.body is None else body_names[r.body],
                         "reached": ok}
                for r, v, ok in zip(self.responses, self.values().values(), self.reached().values())}


def reduce(kind: str, values: np.ndarray, times: np.ndarray | None = None) -> float:
    """:data:`REDUCTIONS` ``kind`` of a quantity's values over a run's states
    at ``times`` [s] (needed by "acceleration")."""
    if kind == "acceleration":
        if times is None:
            raise ValueError("reduce: 'acceleration' needs the states' times")
        return _acceleration(values, times)
    values = values[np.isfinite(values)]  # states where the body had no particle left
    if len(values) == 0:
        return float("nan")
    if kind == "min":
        return float(values.min())
    if kind == "max":
        return float(values.max())
    if kind == "final":
        return float(values[-1])
    lowest = int(np.argmin(values))
    if kind == "max_after_min":
        return float(values[lowest:].max())
    return float((values[0] - values[lowest]) / values[0])  # drop


def _acceleration(values: np.ndarray, times: np.ndarray) -> float:
    """d^2 q / dt^2 of q(t) = a t^2 / 2 + b t + c fitted by least squares to
    the finite states from a quarter of the run on (a body's load settles
    first); NaN with fewer than four."""
    use = np.isfinite(values) & (times >= times[-1] / 4) if len(values) else np.zeros(0, bool)
    if use.sum() < 4:
        return float("nan")
    return float(2.0 * np.polyfit(times[use], values[use], 2)[0])


def reached(kind: str, values: np.ndarray) -> bool:
    """Whether the run reached the extremum that ``kind`` reduces to: False
    when it lies at the last state (the quantity still moving towards it
    when the run ended, e.g. a ball still sinking into the floor or still
    rising: the value is a bound, not the response); "final" always."""
    values = values[np.isfinite(values)]
    if kind in ("final", "acceleration") or len(values) == 0:
        return kind in ("final", "acceleration")
    last = len(values) - 1
    if kind == "max":
        return int(np.argmax(values)) < last
    lowest = int(np.argmin(values))
    if kind == "max_after_min":
        return lowest + int(np.argmax(values[lowest:])) < last
    return lowest < last  # min, drop
