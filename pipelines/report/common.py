"""Helpers every report section shares: numbers read from the metrics,
markdown tables, CSV files, plots and the Pareto front."""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import numpy as np

MAX_TABLE_ROWS = 60  # rows of a markdown table before it is cut short


def num(value) -> float | None:
    """``value`` as a float, None if it is missing or not a number."""
    if isinstance(value, bool) or value is None:
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def total(value) -> float | None:
    """The "total" entry of a per-body dict (or the value itself if a number)."""
    if isinstance(value, dict):
        return num(value.get("total"))
    return num(value)


def as_int(value) -> int | None:
    """A count as an int, None if missing."""
    v = num(value)
    return None if v is None or not math.isfinite(v) else int(round(v))


def positive(value: float | None) -> bool:
    """A finite number above zero."""
    return value is not None and math.isfinite(value) and value > 0


NUMBER = re.compile(r"((?:(?<=[=,])-)?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)")


def natural_key(text: str) -> list:
    """Sort key that orders numbers by value: "2" before "10", "5e4" before
    "1e5", "E=-1" before "E=0"."""
    return [(0, float(t)) if i % 2 else (1, t) for i, t in enumerate(NUMBER.split(text))]


def fmt(value, digits: int = 4) -> str:
    """A table cell: numbers to ``digits`` significant digits, None as empty."""
    if value is None:
        return ""
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        return f"{value:.{digits}g}"
    return str(value).replace("|", "\\|").replace("\n", " ")


def md_table(headers: list[str], rows: list[list]) -> list[str]:
    """Markdown table lines, cut short after MAX_TABLE_ROWS rows."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(fmt(c) for c in row) + " |" for row in rows[:MAX_TABLE_ROWS]]
    if len(rows) > MAX_TABLE_ROWS:
        lines.append(f"\n({len(rows) - MAX_TABLE_ROWS} more rows in the CSV file)")
    return lines + [""]


def write_csv(path: Path, headers: list[str], rows: list[list]) -> None:
    """CSV with full-precision numbers; None as an empty cell."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(headers)
        for row in rows:
            w.writerow(["" if c is None else repr(c) if isinstance(c, float) else c for c in row])


def pyplot():
    """matplotlib.pyplot drawing into files (no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def label_styles(labels: list[str]) -> dict[str, tuple]:
    """A (colour, marker) per label, the same in every figure."""
    markers = "osD^v<>ph*X"
    colours = [f"C{i}" for i in range(10)]
    return {lab: (colours[i % 10], markers[(i // 10 + i) % len(markers)]) for i, lab in enumerate(labels)}


def add_image(lines: list[str], name: str, caption: str) -> None:
    """Append the markdown of the image ``name`` to ``lines``."""
    lines += [f"![{caption}]({name})", ""]


def absent(title: str, why: str) -> list[str]:
    """A section's lines when the sweep lacks its data: the title and why."""
    return [f"## {title}", "", f"Not available: {why}.", ""]


def is_absent(lines: list[str]) -> bool:
    """Whether ``lines`` are a section's :func:`absent` note."""
    return len(lines) > 2 and lines[2].startswith("Not available")


def bar_chart(path: Path, groups: list[str], values: dict[tuple[str, str], float], style: dict,
              ylabel: str, log: bool = False, title: str | None = None) -> None:
    """Bars of ``values[(group, label)]``, one cluster per group, one colour
    per label (in natural order), with the axis label (and unit) ``ylabel``."""
    plt = pyplot()
    labels = sorted({lab for _, lab in values}, key=natural_key)
    width = 0.8 / max(len(labels), 1)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.2 + len(groups) * len(labels) * 0.35), 4.5))
    for k, label in enumerate(labels):
        xs = [i + (k - (len(labels) - 1) / 2) * width for i, g in enumerate(groups) if (g, label) in values]
        ys = [values[(g, label)] for g in groups if (g, label) in values]
        ax.bar(xs, ys, width=width, color=style[label][0], label=label)
    ax.set_xticks(range(len(groups)))
    tilt = len(groups) > 3
    ax.set_xticklabels(groups, rotation=20 if tilt else 0, ha="right" if tilt else "center")
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    if log:
        ax.set_yscale("log")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def pareto_front(times, errors) -> np.ndarray:
    """Boolean mask of the points no other point dominates, i.e. none is at
    least as fast and as accurate and strictly better in one; non-finite
    points are never on the front."""
    t, e = np.asarray(times, dtype=np.float64), np.asarray(errors, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(e)
    front = np.zeros(t.shape, dtype=bool)
    for i in np.flatnonzero(ok):
        dominated = ok & (t <= t[i]) & (e <= e[i]) & ((t < t[i]) | (e < e[i]))
        front[i] = not dominated.any()
    return front


# units of swept parameters, by the last part of their key
PARAMETER_UNITS = {"E": "Pa", "K": "Pa", "rho": "kg/m³", "nu": "-", "dt": "s", "dt_max": "s", "duration": "s",
                   "resolution": "cells", "particle_resolution": "cells", "epsilon": "-", "eta": "-", "cfl": "-",
                   "steps": "steps", "viscosity": "Pa s", "yield_stress": "Pa", "friction_angle": "deg",
                   "flip": "-", "ppc": "particles per cell", "gravity": "m/s²", "dJ_max": "-"}


def parameter_label(key: str) -> str:
    """An axis label for a swept override: its key and unit, e.g. ``material.E [Pa]``."""
    unit = PARAMETER_UNITS.get(key.rsplit(".", 1)[-1])
    return f"{key} [{unit}]" if unit else key


def geometric(values) -> bool:
    """Whether a sweep's values are better read on a log axis: positive,
    distinct values that grow by factors within 2.5 times of one another and
    not by a constant step (1, 2, 4, 8 and 1, 2, 5, 10 are; 1, 2, 3 is not),
    or two values tenfold apart or more."""
    v = np.unique(np.asarray([x for x in values if x is not None], dtype=np.float64))
    if len(v) < 2 or v[0] <= 0:
        return False
    if len(v) == 2:
        return bool(v[1] / v[0] >= 10.0)
    ratios = v[1:] / v[:-1]
    steps = np.diff(v)
    arithmetic = np.ptp(steps) <= 0.05 * steps.mean()
    return bool(not arithmetic and ratios.max() <= 2.5 * ratios.min())
