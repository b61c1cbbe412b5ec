"""How a recording is shown: which way is up, where the 3D camera starts, and
the blueprint (a particle view beside time series, one unit per plot, on
the simulated-time timeline).

Scenes have y up (gravity along -y). Rerun's 3D views take the up axis
from the view coordinates logged at the root (``RIGHT_HAND_Y_UP``); its 2D
views draw y downwards and ignore view coordinates, so 2D recordings carry a
static transform that mirrors y (``FLIP_2D``) on the spatial entities
(``/particles``, ``/domain``, ``/colliders``, and ``/channels`` with
log.channels). The data themselves stay in
the scene's coordinates (what :mod:`pipelines.recording.recordings` reads);
the recording property ``view`` states the convention.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

if TYPE_CHECKING:
    from rerun.encodings import EntityPathLike

FLIP_2D = (1.0, -1.0, 1.0)  # scale of the 2D spatial entities: y up on the screen
SPATIAL_2D = ("particles", "domain", "colliders", "regions")  # the entities that carry the flip
ELEVATION, AZIMUTH = 25.0, 35.0  # the initial 3D camera: above the floor, in front and to the right [deg]
TIMELINE = "sim_time"  # the timeline the viewer opens on

# unit of each scalar (2D: per metre of depth); a name "a/b" takes the unit of "a"
_UNITS = {
    "mass": ("kg", "kg/m"), "kinetic_energy": ("J", "J/m"), "elastic_energy": ("J", "J/m"),
    "potential_energy": ("J", "J/m"), "total_energy": ("J", "J/m"), "rigid_energy": ("J", "J/m"),
    "system_energy": ("J", "J/m"),
    "momentum": ("kg m/s", "kg/s"), "angular_momentum": ("kg m²/s", "kg m/s"),
    "boundary_impulse": ("N s", "N s/m"),
    "contact_work": ("J", "J/m"),
    "center_of_mass": ("m", "m"), "dt": ("s", "s"), "dt_fresh": ("s", "s"), "max_speed": ("m/s", "m/s"),
    "step_time_ms": ("ms", "ms"), "update_ms": ("ms", "ms"),
    "error/displacement": ("m", "m"), "error/velocity": ("m/s", "m/s"),
    "config_updates": ("count", "count"), "fragments": ("count", "count"), "contact_nodes": ("count", "count"),
    "removed": ("count", "count"), "inside_colliders": ("count", "count"),
    "newton_iterations": ("count", "count"), "cg_iterations": ("count", "count"),
    "solve_rounds": ("count", "count"), "unsettled": ("count", "count"),
    "fracture": ("fraction", "fraction"), "marked_fraction": ("fraction", "fraction"),
    "min_stretch": ("ratio", "ratio"), "newton_residual": ("ratio", "ratio"),
}


# a series left out of the plots when it equals another at every step (EMPM: a fresh reference is the last step's)
SAME_AS = {"dt_fresh": "dt"}

WORDS = {"dt": "time step", "dt_fresh": "time step allowed now", "config_updates": "configuration updates"}


# unit of a rigid body's series rigid/<name>/<quantity>[_axis] (2D: per metre of depth)
_RIGID_UNITS = {
    "position": ("m", "m"), "velocity": ("m/s", "m/s"), "angular_velocity": ("rad/s", "rad/s"),
    "angle": ("rad", "rad"), "rotation": ("rad", "rad"), "force": ("N", "N/m"), "torque": ("N m", "N m/m"),
    "kinetic_energy": ("J", "J/m"), "rotational_energy": ("J", "J/m"), "potential_energy": ("J", "J/m"),
}


def unit(name: str, dim: int) -> str:
    """The unit of scalar ``name`` ("" when unknown)."""
    name = name.rsplit("/", 1)[-1] if name.startswith("/") else name
    if name.startswith("rigid/"):
        quantity = name.rsplit("/", 1)[-1]
        for key in (quantity, quantity[:-2] if quantity[-2:] in ("_x", "_y", "_z") else quantity):
            if key in _RIGID_UNITS:
                return _RIGID_UNITS[key][0 if dim == 3 else 1]
        return ""
    for key in (name, name.split("/")[0], name.rstrip("_xyz").rstrip("_"),
                name.split("/")[0].rstrip("_xyz").rstrip("_")):
        if key in _UNITS:
            return _UNITS[key][0 if dim == 3 else 1]
    return ""


def label(name: str, dim: int) -> str:
    """A series' name in the viewer: words and unit, e.g. ``kinetic energy [J/m]``."""
    u = unit(name, dim)
    words = name.rsplit("/", 1)[-1] if name.startswith("/") else name
    words = WORDS.get(words, words.removesuffix("_ms").replace("_", " "))
    return f"{words} [{u}]" if u and u not in ("count", "fraction", "ratio") else \
        f"{words} ({u})" if u else words


def view_coordinates(rec: rr.RecordingStream, dim: int, channels: bool = False, rigid: bool = False) -> None:
    """Declare the scene's up axis (static): y up in both 2D and 3D
    (``channels``: the /channels entities too, log.channels; ``rigid``: the
    /rigid entities too, a scene's rigid bodies)."""
    if dim == 3:
        rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Y_UP, static=True)
        rec.send_property("view", rr.AnyValues(up="+y", coordinates="RIGHT_HAND_Y_UP"))
    else:
        spatial = SPATIAL_2D + (("channels",) if channels else ()) + (("rigid",) if rigid else ())
        for path in spatial:
            rec.log(path, rr.Transform3D(scale=FLIP_2D), static=True)
        rec.send_property("view", rr.AnyValues(
            up="+y", flip=" ".join(f"/{p}" for p in spatial),
            note="2D views draw y down: the spatial entities carry a transform scaling y by -1; "
                 "their data are in the scene's coordinates (y up)"))


def camera(domain, floor: float) -> rrb.EyeControls3D:
    """An orbital camera above the floor (height ``floor`` [m]) looking at the
    domain's centre from (ELEVATION, AZIMUTH), far enough to frame it."""
    L = np.asarray(domain, float)
    target = L / 2
    el, az = np.radians(ELEVATION), np.radians(AZIMUTH)
    direction = np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
    position = target + 1.3 * float(np.linalg.norm(L)) * direction
    position[1] = max(position[1], floor + 0.5 * L[1])
    return rrb.EyeControls3D(position=position.tolist(), look_target=target.tolist(), eye_up=[0.0, 1.0, 0.0])


LEGEND_ROOM = 0.5  # a plot's y range above its data, for its legend: [min, max + LEGEND_ROOM (max - min)]


def y_range(members: list[str], extents: dict) -> tuple[float, float] | None:
    """The y range of a plot of ``members`` with room for its legend above
    the data, from the series' (min, max) in ``extents``; None unless every
    member has an extent."""
    spans = [e for e in (extents.get(m) for m in members) if e is not None]
    if not members or len(spans) < len(members):
        return None
    lo, hi = min(e[0] for e in spans), max(e[1] for e in spans)
    span = hi - lo if hi > lo else max(abs(hi), 1e-30)
    return lo - 0.05 * span, hi + LEGEND_ROOM * span


def series_views(groups: dict, dim: int, extents: dict | None = None, same: tuple = ()) -> list:
    """One time-series view per group and unit (named with the unit), the
    whole run in view, on the simulated-time timeline. A plot of several
    series has a legend in its top-left corner; with the series' extents
    (the run's (min, max) per scalar name, known once it has ended) its y
    range leaves the legend room above the data, where Rerun would
    otherwise draw it over the curves. A series in ``same`` is left out and
    named in the title of its twin's plot (:data:`SAME_AS`)."""
    views = []
    for group, names in groups.items():
        by_unit: dict[str, list[str]] = {}
        for n in (n for n in names if n not in same):
            by_unit.setdefault(unit(n, dim), []).append(n)
        for u, members in by_unit.items():
            title = group.split(" [")[0]
            if len(by_unit) > 1:  # the group's quantities apart: named by the first (less its axis)
                title = label(members[0], dim).split(" [")[0].split(" (")[0]
                title = title[:-2] if len(members) > 1 and title[-2:] in (" x", " y", " z") else title
            twins = [n for n in same if SAME_AS[n] in members]
            title += "".join(f" (= {WORDS.get(n, n)})" for n in twins)
            title = f"{title} [{u}]" if u else title
            room = y_range(members, extents or {}) if len(members) > 1 else None
            views.append(rrb.TimeSeriesView(
                name=title, origin="/",
                contents=[m if m.startswith("/") else f"/scalars/{m}" for m in members],
                axis_x=rrb.TimeAxis(view_range=rr.TimeRange(start=rr.TimeRangeBoundary.infinite(),
                                                            end=rr.TimeRangeBoundary.infinite())),
                axis_y=rrb.ScalarAxis(range=room) if room is not None else None,
                plot_legend=rrb.PlotLegend(corner="LeftTop", visible=len(members) > 1)))
    return views


def blueprint(dim: int, domain, wall: float, groups: dict, channels=(), extents: dict | None = None,
              title: str = "particles", same: tuple = (), rigid: bool = False):
    """The particle view (domain, floor and colliders drawn, y up; named
    ``title``, which says what the colours mean) with its colour key
    beside the domain, next to the colour legend, the time series (a tab
    each) and the events; ``channels`` (log.channels): their entities in
    the particle view, hidden (the user shows one in the viewer's blueprint
    panel); ``extents``: the series' (min, max), for the plots' y ranges
    (:func:`series_views`); ``same``: series left out, equal to their
    :data:`SAME_AS` at every step (one curve would hide the other);
    ``rigid``: the rigid bodies (/rigid) drawn too."""
    from .colour_key import extent

    L = np.asarray(domain, float)
    hidden = [f"/channels/{c}" for c in channels]
    contents = ["/particles", "/particles/key/**", "/domain", "/colliders/**", "/regions/**"] + [
        p for c in hidden for p in (c, f"{c}/key/**")] + (["/rigid/**"] if rigid else [])
    overrides: dict[EntityPathLike, rrb.EntityBehavior] | None = {
        path: rrb.EntityBehavior(visible=False) for path in hidden} or None
    if dim == 2:
        m = 0.05 * float(L.max())
        view = rrb.Spatial2DView(name=title, origin="/", contents=contents, overrides=overrides,
                                 visual_bounds=rrb.VisualBounds2D(x_range=[-m, extent(L, 1 + len(channels)) + m],
                                                                  y_range=[-L[1] - m, m]))
    else:
        view = rrb.Spatial3DView(
            name=title, origin="/", contents=contents, overrides=overrides, eye_controls=camera(L, wall),
            line_grid=rrb.LineGrid3D(visible=True, plane=rr.components.Plane3D((0.0, 1.0, 0.0), wall),
                                     spacing=float(10 ** np.floor(np.log10(L.max() / 4)))))
    series = series_views(groups, dim, extents, same)
    return rrb.Blueprint(
        rrb.Horizontal(
            view,
            rrb.Vertical(rrb.TextDocumentView(name="colour", origin="/legend"), rrb.Tabs(*series, name="time series"),
                         rrb.TextLogView(name="events", origin="/events"), row_shares=[2, 6, 2]),
            column_shares=[1, 1],
        ),
        rrb.TimePanel(timeline=TIMELINE),
        rrb.SelectionPanel(expanded=False),  # room for the plots: their time axes labelled at 1600 px
        collapse_panels=False,
    )


def declared(path) -> dict:
    """What a recording declares about its display, read back from the file:
    ``up`` (the ``view`` property), ``coordinates`` (the root's view
    coordinates, e.g. ``RUB``: x right, y up, z back), ``flip`` (entity ->
    static scale), ``views`` (name -> class: 2D, 3D, TimeSeries, ...),
    ``timeline`` (the time panel's), ``eye`` (the 3D camera: position,
    look_target, eye_up), ``grid`` (the 3D line grid's plane), ``hidden``
    (the entities a view's overrides hide, e.g. ``/channels/speed``),
    ``y_range`` and ``legend`` (per time-series view: its y range, when
    set, and its legend's corner), ``title`` (the particle view's name,
    listed in ``views`` as "particles"), all from the last blueprint sent."""
    from rerun.chunk import RrdReader

    reader = RrdReader(str(path))
    data = reader.stream().collect()
    static = data.reader(index=None, contents="/**").to_arrow_table()

    def first(table, col) -> Any:  # the column's last value (None: none)
        values = [v for v in table.column(col).to_pylist() if v is not None] if col in table.column_names else []
        return values[-1] if values else None

    props = data.reader(index=None, contents="/__properties/**").to_arrow_table()
    up = first(props, "property:view:up")
    out = {"up": up[0] if up else None, "coordinates": None, "flip": {}, "views": {}, "y_range": {}, "legend": {},
           "timeline": None, "eye": {}, "grid": None, "hidden": [], "title": None}
    xyz = first(static, "/:ViewCoordinates:xyz")
    if xyz is not None:  # Rerun's codes: 1 up, 2 down, 3 right, 4 left, 5 forward, 6 back
        out["coordinates"] = "".join("?UDRLFB"[int(c)] for c in np.ravel(xyz))
    for c in static.column_names:
        if c.endswith(":Transform3D:scale"):
            out["flip"][c[1:].split(":")[0]] = tuple(np.ravel(first(static, c)).tolist())
    tables = [reader.store(store=b).stream().collect().reader(index="blueprint", contents="/**").to_arrow_table()
              for b in reader.blueprints()]
    if tables:
        # the run's start sends a blueprint, its end another (the colour range, the plots' y ranges); the
        # reader does not keep their order, the viewer activates the last sent: the latest log time
        table = max(tables, key=lambda t: max(v for v in t.column("log_time").to_pylist() if v is not None)
                    if "log_time" in t.column_names else 0)
        for c in table.column_names:
            if c.endswith(":ViewBlueprint:class_identifier"):
                view = c.split(":")[0]
                name = first(table, f"{view}:ViewBlueprint:display_name")
                kind = first(table, c)[0]
                if kind in ("2D", "3D"):  # the particle view, named by what its colours mean
                    out["title"] = name[0] if name else None
                    name = ["particles"]
                out["views"][name[0] if name else view] = kind
            elif ":EyeControls3D:" in c:
                out["eye"][c.rsplit(":", 1)[1]] = np.ravel(first(table, c)).tolist()
            elif c.endswith(":ScalarAxis:range") or c.endswith(":PlotLegend:corner"):
                view = c.split("/ScalarAxis:")[0].split("/PlotLegend:")[0]
                name = first(table, f"{view}:ViewBlueprint:display_name")
                value = np.ravel(first(table, c)).tolist()
                if c.endswith("corner"):
                    out["legend"][name[0]] = rrb.components.Corner2D(int(value[0])).name
                else:
                    out["y_range"][name[0]] = tuple(value)
            elif c.endswith(":LineGrid3D:plane"):
                out["grid"] = np.ravel(first(table, c)).tolist()
            elif c.endswith(":EntityBehavior:visible") and "/ViewContents/overrides/" in c:
                if not bool(np.ravel(first(table, c))[0]):
                    entity = c.split("/ViewContents/overrides/", 1)[1].split(":")[0].removesuffix("/visualizers")
                    out["hidden"].append("/" + entity)
        timeline = first(table, "/time_panel:TimePanelBlueprint:timeline")
        out["timeline"] = timeline[0] if timeline else None
    return out
