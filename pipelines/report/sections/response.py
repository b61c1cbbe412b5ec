"""Response: each measured quantity against each swept parameter (the
report's first figure), a line per method: the scene's physical responses
(``scene.responses``) first, then the costs; a log axis where the sweep is
geometric; response.csv."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from mpm.responses import QUANTITIES, REDUCTIONS

from ..common import (add_image, geometric, md_table, natural_key, num, parameter_label, positive, pyplot, total,
                      write_csv)
from ..jobs import RESOLUTION_KEYS, Job
from ..registry import section

# (name, title, unit, the job's value); a response without a value in any job is left out
RESPONSES = [
    ("error_displacement", "position error", "m", lambda j: j.error_displacement),
    ("error_velocity", "velocity error", "m/s", lambda j: j.error_velocity),
    ("step_time_ms", "time per step", "ms", lambda j: j.num("step_time_ms")),
    ("dt", "mean time step", "s", lambda j: j.num("dt")),
    ("energy_change", "energy change (less the boundaries' work)", "of the energy scale",
     lambda j: j.num("energy_change")),
    ("updates_per_1e4_steps", "configuration updates", "per 10⁴ steps", lambda j: j.num("updates_per_1e4_steps")),
    ("fracture", "pairs torn apart", "fraction", lambda j: total(j.metrics.get("fracture"))),
]
SKIPPED = ("hydra", "log.", "run.force", "run.device", "run.progress")


def scene_responses(jobs: list[Job]) -> list[tuple]:
    """The physical responses the jobs' scenes declare (``scene.responses``,
    metrics.json ``responses``), as :data:`RESPONSES` entries, by name."""
    found: dict[str, str] = {}
    for j in jobs:
        for name, r in (j.metrics.get("responses") or {}).items():
            found.setdefault(name, r.get("unit", ""))

    def getter(name: str):
        return lambda j: num(scene_response(j, name).get("value"))

    return [(name, name.replace('_', ' '), unit, getter(name)) for name, unit in found.items()]


def scene_response(j: Job, name: str) -> dict:
    """Job ``j``'s metrics.json entry of scene response ``name`` ({} if none)."""
    return (j.metrics.get("responses") or {}).get(name) or {}


def not_reached(j: Job, name: str) -> bool:
    """Whether the run ended before it reached response ``name``'s extremum
    (``mpm.responses.reached``): its value is a bound."""
    return scene_response(j, name).get("reached") is False


def definitions(jobs: list[Job], names: list[str]) -> list[str]:
    """A line per scene response: what it measures, in words."""
    out = []
    for name in names:
        r = next((scene_response(j, name) for j in jobs if scene_response(j, name)), {})
        quantity = str(r.get("quantity", "?"))
        what = QUANTITIES.get(quantity, quantity).split(" [")[0]
        body = "every body's particles" if r.get("body") == "all" else f"the {r.get('body')}"
        out.append(f"- *{name.replace('_', ' ')}* [{r.get('unit', '')}]: {what} of {body}, "
                   f"{REDUCTIONS.get(r.get('reduce', ''), r.get('reduce'))}.")
    return out


def swept_parameters(jobs: list[Job]) -> dict[str, dict]:
    """Numeric overrides whose value varies across the jobs: key -> {job rel: value}."""
    keys = sorted({k for j in jobs for k in j.overrides if not k.startswith(SKIPPED)})
    out = {}
    for key in keys:
        values = {j.rel: num(j.overrides.get(key)) for j in jobs if key in j.overrides}
        if len(values) >= 2 and all(v is not None for v in values.values()) and len(set(values.values())) > 1:
            out[key] = values
    return out


def concurrent(jobs: list[Job]) -> int:
    """How many of ``jobs`` ran while another did: each job's wall-clock span
    ends when its metrics.json was last written and lasted ``wall_time_s``."""
    spans = []
    for j in jobs:
        wall = j.num("wall_time_s")
        try:
            end = (j.path / "metrics.json").stat().st_mtime
        except OSError:
            continue
        if wall is not None:
            spans.append((end - wall, end))
    return sum(any(a < d and c < b for k, (c, d) in enumerate(spans) if k != i) for i, (a, b) in enumerate(spans))


def line_label(j: Job, key: str) -> str:
    """The job's label without the swept parameter (its line)."""
    return " · ".join(p for p in j.label.split(" · ") if not p.startswith(f"{key}=")) or j.scheme or "runs"


@section(order=15)
def section_response(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """The responses against each swept parameter; nothing when no numeric parameter varies."""
    params = swept_parameters(jobs)
    done = [j for j in jobs if j.completed]
    if not params or not done:
        return []
    # the scenes' physical responses first, then the costs; a response with a value in some job and
    # not zero in all (a plot with something to show)
    responses = [r for r in scene_responses(done) + RESPONSES if any(r[3](j) is not None for j in done)
                 and any(r[3](j) for j in done if r[3](j) is not None)]
    # one value in every job (EMPM's update at every step): a sentence, not a flat line
    constant = [r for r in responses if len(done) > 1 and all(r[3](j) is not None for j in done)
                and len({r[3](j) for j in done}) == 1]
    responses = [r for r in responses if r not in constant]
    if not responses:
        return []
    plt = pyplot()
    lines = ["## Response against the swept parameters", ""]
    rows = []
    for key, values in params.items():
        xs = [values[j.rel] for j in done if j.rel in values]
        log_x = geometric(xs)
        n = len(responses)
        cols = min(n, 3)
        fig, axes = plt.subplots((n + cols - 1) // cols, cols, figsize=(4.2 * cols, 3.4 * ((n + cols - 1) // cols)),
                                 squeeze=False)
        for ax in axes.flat[n:]:
            ax.set_visible(False)
        for ax, (name, title, unit, get) in zip(axes.flat, responses):
            by_line = defaultdict(list)
            for j in done:
                if j.rel in values and get(j) is not None:
                    by_line[line_label(j, key)].append((values[j.rel], get(j), j))
            for label in sorted(by_line, key=natural_key):
                pts = sorted(by_line[label], key=lambda p: p[0])
                colour, marker = style.get(pts[0][2].label, ("C0", "o"))
                ax.plot([p[0] for p in pts], [p[1] for p in pts], marker=marker, color=colour, label=label)
                bounds = [p for p in pts if not_reached(p[2], name)]  # hollow: the run ended first
                if bounds:
                    ax.plot([p[0] for p in bounds], [p[1] for p in bounds], linestyle="none", marker=marker,
                            markersize=9, markerfacecolor="white", markeredgecolor=colour)
                rows += [[key, p[0], label, name, p[1], p[2].rel] for p in pts]
            ys = [p[1] for pts in by_line.values() for p in pts]
            if log_x:
                ax.set_xscale("log")
            if ys and all(positive(y) for y in ys) and max(ys) > 20 * min(ys):
                ax.set_yscale("log")
            ax.set_title(title, fontsize=10)
            ax.set_xlabel(parameter_label(key))
            ax.set_ylabel(f"[{unit}]")
            ax.grid(True, which="both", alpha=0.3)
        handles, labels = axes.flat[0].get_legend_handles_labels()
        if len(labels) > 1:
            fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8, frameon=False)
            fig.tight_layout(rect=(0, 0.08, 1, 1))
        else:
            fig.tight_layout()
        name = f"response_{key.replace('/', '_').replace('.', '_')}.png"
        fig.savefig(out / name, dpi=120)
        plt.close(fig)
        add_image(lines, name, f"responses against {key}")
        lines += [f"Swept: `{key}` = {', '.join(f'{v:g}' for v in sorted(set(xs)))}"
                  + (" (geometric: log axis)" if log_x else "")
                  + ("; the resolution in cells across the domain" if key in RESOLUTION_KEYS else "") + ".", ""]
    if constant:
        lines += ["The same in every job: " + "; ".join(
            f"{title} {r3(done[0]):.4g}{' ' + unit if unit else ''}" for _, title, unit, r3 in constant) + ".", ""]
    physical = [r[0] for r in responses if r[0] in {n for n, *_ in scene_responses(done)}]
    if physical:
        lines += ["The scene's responses (`scene.responses`, each job's metrics.json):", ""]
        lines += definitions(done, physical) + [""]
        late = {n: [j.rel for j in done if not_reached(j, n)] for n in physical}
        for n, rels in ((n, rels) for n, rels in late.items() if rels):
            lines += [f"Not reached: *{n.replace('_', ' ')}* in job{'s' * (len(rels) > 1)} "
                      f"{', '.join(sorted(rels, key=natural_key))} (hollow markers): the quantity was still moving "
                      "towards it at the run's last state, so the value is a bound, not the response; a longer "
                      "run (`run.duration`) reaches it.", ""]
    shared = concurrent(done)
    if shared and any(r[0] == "step_time_ms" for r in responses):
        lines += [f"{shared} of the {len(done)} jobs ran while another did (their wall-clock spans overlap): "
                  "they shared the machine's cores, so their times per step are no benchmark "
                  "(`hydra.launcher.n_jobs=1` runs one at a time).", ""]
    write_csv(out / "response.csv", ["parameter", "value", "line", "response", "response_value", "dir"], rows)
    lines += ["Every point in [response.csv](response.csv).", ""]
    lines += md_table(["parameter", "values", "lines"],
                      [[k, len(set(v.values())), len({line_label(j, k) for j in done if j.rel in v})]
                       for k, v in params.items()])
    return lines
