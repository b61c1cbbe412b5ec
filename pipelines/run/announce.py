"""The events that open a run's recording: what the scheme and the integrator
do, in words, with their parameters; the views of its scalars; and the run's static
description for its recording (RunMeta)."""

from __future__ import annotations

from . import rigid_track, run_metrics
from ..recording.sinks import RunMeta

IMPLICIT_SCALARS = ["newton_iterations", "cg_iterations", "newton_residual", "solve_rounds", "unsettled"]


def scalar_groups(dim: int, marked: list[str], error: bool = False, implicit: bool = False,
                  rigid: bool = False) -> dict:
    """Time-series views of the recording's blueprint: scalar names, or entity
    paths (the wall-clock timings, in the timings file); ``rigid``: the
    scene has rigid bodies, whose energy joins the energy view
    (pipelines.run.rigid_track)."""
    momentum = (["momentum_x", "momentum_y", "angular_momentum"] if dim == 2 else
                ["momentum_x", "momentum_y", "momentum_z", "angular_momentum_x",
                 "angular_momentum_y", "angular_momentum_z"])
    groups = {
        "energy": ["kinetic_energy", "elastic_energy", "potential_energy", "total_energy"]
        + (["rigid_energy", "system_energy"] if rigid else []),
        "momentum": momentum + [f"boundary_impulse_{a}" for a in "xyz"[:dim]],
        "step": ["dt", "dt_fresh", "max_speed"],
        "wall clock [ms]": ["/timings/step_time_ms", "/timings/update_ms"],
        "configuration updates": ["config_updates", "fracture", "fragments"] + marked,
    }
    if error:
        groups["error"] = ["error/displacement", "error/velocity"]
    if implicit:
        groups["implicit solve"] = IMPLICIT_SCALARS
    return groups


def rigid_groups(dim: int, names: list[str]) -> dict:
    """Per rigid body (pipelines.run.rigid_track), the time-series view of its series (one plot per unit)."""
    axes = "xyz"[:dim]
    turn = ["angle", "angular_velocity", "torque"] if dim == 2 else [
        f"{q}_{a}" for q in ("rotation", "angular_velocity", "torque") for a in axes]
    return {f"rigid {n}": [f"rigid/{n}/{q}_{a}" for q in ("position", "velocity", "force") for a in axes]
            + [f"rigid/{n}/{q}" for q in turn]
            + [f"rigid/{n}/{q}_energy" for q in ("kinetic", "rotational", "potential")] for n in names}


def opening_events(scheme, integrator=None, dt: float | None = None) -> list[tuple[str, dict]]:
    """(text, parameters) of the scheme's event and, for an implicit run
    (``integrator`` given; ``dt`` the fixed step [s] or None), the
    integrator's."""
    s = scheme
    if s.name == "empm":
        text = ("empm: every body's reference configuration is updated at every step (s = n); "
                "the cumulative count is the scalar config_updates")
    elif s.name == "tlmpm":
        text = "tlmpm: the reference configuration is the initial one (s = 0), never updated"
    else:
        text = (f"aulmpm ({s.criterion} criterion): a body is updated when the fraction of its "
                f"particles with dJ >= {s.epsilon:g} reaches {s.eta:g}")
        if s.criterion == "distortion":
            text += (f", or a particle has dJ >= {max(s.dJ_max, s.epsilon):g} or a reference cell "
                     f"is squeezed below {s.stretch_min:g} of its width")
        text += f"; affine matrix: {s.affine}"
    events = [(text, {"scheme": s.name, **{k: v for k, v in vars(s).items() if isinstance(v, (int, float, str))}})]
    if integrator is not None:
        i = integrator
        step = (f"fixed step {dt:g} s" if dt is not None else
                f"adaptive step: at most {i.displacement:g} cell per step, halved up to {i.halvings} "
                "times after a failed solve")
        kind = ("the semi-implicit update (one Newton step)" if i.newton_max == 1 else
                f"Newton to {i.newton_tol:g} of the initial residual in at most {i.newton_max} iterations")
        events.append((f"implicit: backward Euler, {kind}; CG to {i.cg_tol:g} in at most {i.cg_max} iterations; "
                       f"{step}", {k: v for k, v in vars(i).items() if isinstance(v, (int, float, str))}))
    return events


def run_meta(run) -> RunMeta:
    """The static description of the run of a Recorder ``run`` (pipelines.run.recorder) for its recording."""
    spec, scene, model = run.spec, run.spec.scene, run.model
    ppc = [b.ppc or scene.ppc for b in scene.bodies]
    groups = scalar_groups(
        scene.dim, (run.marked_names if run.scheme.tracks_marks() else [])
        + (run.stretch_names if run.scheme.name != "empm" else []),
        run.solution is not None or spec.run.reference is not None, run.implicit, bool(scene.rigid_bodies))
    groups.update(rigid_groups(scene.dim, rigid_track.names(scene)))
    return RunMeta(
        name=f"{spec.scene_name} / {run.scheme.name} / {spec.kernel.name} ({spec.transfer})",
        dim=scene.dim, domain=model.domain, wall_cells=scene.wall_cells, dx=model.dx,
        body_names=[b.name for b in scene.bodies], particle_body=model.body.numpy(),
        particle_radius=0.5 * scene.particle_dx / max(ppc) ** (1.0 / scene.dim),
        color=spec.log.color, color_range=run_metrics.color_range(spec),
        channels=run_metrics.channel_ranges(spec.log), field_notes=run_metrics.field_notes(run.scheme.name),
        properties={k: v for k, v in run.properties.items() if k != "run"},
        run_properties={"run": run.properties["run"]}, colliders=list(scene.colliders), scalar_groups=groups,
        rigid_bodies=[(n, b.shape) for n, b in zip(rigid_track.names(scene), scene.rigid_bodies)])
