"""The events that open a run's recording: what the scheme and the integrator
do, in words, with their parameters; and the views of its scalars."""

from __future__ import annotations

IMPLICIT_SCALARS = ["newton_iterations", "cg_iterations", "newton_residual", "solve_rounds", "unsettled"]


def scalar_groups(dim: int, marked: list[str], error: bool = False, implicit: bool = False) -> dict:
    """Time-series views of the recording's blueprint: scalar names, or entity
    paths (the wall-clock timings, in the timings file)."""
    momentum = (["momentum_x", "momentum_y", "angular_momentum"] if dim == 2 else
                ["momentum_x", "momentum_y", "momentum_z", "angular_momentum_x",
                 "angular_momentum_y", "angular_momentum_z"])
    groups = {
        "energy": ["kinetic_energy", "elastic_energy", "potential_energy", "total_energy"],
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
