"""Friction between bodies against closed forms (``+experiment=incline``,
conf/scene/incline_2d.yaml; ``+experiment=incline_disk``,
conf/scene/incline_disk_2d.yaml): a block sliding on an inclined plane at
g (sin theta - mu cos theta), at rest where tan theta <= mu, and a solid
disk rolling at (2/3) g sin theta, per scheme, integrator and grid, from
the response "acceleration" of each job's metrics.json (incline.csv,
rolling.csv)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from mpm.inclines import rolling, sliding

from ..common import absent, fmt, md_table, write_csv
from ..jobs import Job
from ..registry import section

BLOCK, DISK = "incline_2d", "incline_disk_2d"


def resolved(job: Job, key: str) -> Any:
    """The job's composed config at ``key`` ("scene.gravity") with its
    interpolations resolved (the scenes pick theta by ``scene.size``); None
    if missing or unresolvable."""
    try:
        from omegaconf import OmegaConf

        value = OmegaConf.select(OmegaConf.create(job.config or {}), key)
        return OmegaConf.to_container(value, resolve=True) if OmegaConf.is_config(value) else value
    except Exception:
        return None


def incline(job: Job) -> dict | None:
    """theta [deg] (from the tilted gravity), mu, the moving body's initial
    speed [m/s] and its measured acceleration [m/s^2] (None: not measured);
    None when the job's config lacks them."""
    try:
        gx, gy = (float(x) for x in resolved(job, "scene.gravity"))
        speed = float((resolved(job, "scene.bodies.1.velocity") or [0.0])[0])
        mu = float(resolved(job, "scene.contact_friction") or 0.0)
    except (TypeError, ValueError, IndexError):
        return None
    response = (job.metrics.get("responses") or {}).get("acceleration") or {}
    return {"theta": math.degrees(math.atan2(gx, -gy)), "g": math.hypot(gx, gy), "mu": mu, "speed": speed,
            "a": response.get("value")}


def _rows(have: list[Job], closed) -> list[list]:
    rows = []
    for j in have:
        c = incline(j)
        if c is None:
            continue
        ref = closed(c)
        a = c["a"] if j.completed else None
        # at rest in the closed form the error is the fitted acceleration itself [m/s^2]
        err = None if a is None else (a - ref if ref == 0.0 else 100.0 * (a / ref - 1.0))
        rows.append([j.scheme, j.integrator, j.resolution, fmt(c["theta"], 3), fmt(c["mu"], 3),
                     fmt(c["speed"], 3), j.status, fmt(a, 4), fmt(ref, 4),
                     fmt(err, 3) + ("" if ref != 0.0 or err is None else " m/s^2")])
    return sorted(rows, key=lambda r: (r[0], r[1], float(r[3]), float(r[4]), r[2] or 0))


HEADERS = ["scheme", "integrator", "cells", "theta [deg]", "mu", "speed [m/s]", "status",
           "acceleration [m/s^2]", "closed form", "error [%]"]


def _section(jobs: list[Job], out: Path, scene: str, experiment: str, title: str, csv: str, closed,
             what: str) -> list[str]:
    """A section's lines and its csv: the jobs of ``scene`` against ``closed(incline(job))``."""
    have = [j for j in jobs if j.scene == scene]
    if not have:
        return absent(title, f"no {scene} job (+experiment={experiment})")
    rows = _rows(have, closed)
    write_csv(out / csv, HEADERS, rows)
    return [f"## {title}", "", f"{what} ([{csv}]({csv})).", ""] + md_table(HEADERS, rows)


@section(order=67)
def section_incline(jobs: list[Job], out: Path) -> list[str]:
    """incline.csv: a block on an inclined plane against g (sin - mu cos)."""
    return _section(jobs, out, BLOCK, "incline", "Friction between bodies: a block on an incline", "incline.csv",
                    lambda c: sliding(c["theta"], c["g"], c["mu"], c["speed"]),
                    "A block's acceleration down a plane inclined at theta with Coulomb friction mu between it "
                    "and the plane's body (the parabola fitted to its centre from a quarter of the run on), "
                    "against g (sin theta - mu cos theta) while it slides; from rest where tan theta <= mu the "
                    "closed form is rest and the error column gives the fitted acceleration itself")


@section(order=68)
def section_rolling(jobs: list[Job], out: Path) -> list[str]:
    """rolling.csv: a solid disk rolling down a plane against (2/3) g sin theta."""
    return _section(jobs, out, DISK, "incline_disk", "Friction between bodies: a disk rolling down an incline",
                    "rolling.csv", lambda c: rolling(c["theta"], c["g"], c["mu"]),
                    "A solid disk's acceleration down a plane inclined at theta (its centre's parabola from a "
                    "quarter of the run on), against rolling without slipping, (2/3) g sin theta where "
                    "mu >= tan theta / 3, per grid")
