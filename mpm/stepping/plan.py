"""What a solver's step does, stage by stage, and the kernels each stage
launches: what a scene compiles (an absent stage is work it does not need)."""

from __future__ import annotations

from ..launch import kernel_name


def plan(solver, driver=None) -> list[tuple[str, list[str]]]:
    """The stages of one step of ``solver`` (mpm.Solver), in order, each with
    the names of the kernels it launches; with ``driver`` (mpm.Driver) its
    policy and read-back too."""
    def names(*ks):
        return [kernel_name(k) for k in ks if k is not None]

    s, sch = solver, solver.scheme
    tr, cond = s.transfers, s.conditions
    lattice = sch.name == "empm"
    stages = [("clear the grid", [])]
    if tr.forcing is not None:
        stages.append(("body force of the closed-form solution (host)", []))
    positions = ("node positions on the lattice" if lattice else
                 "node positions summed only in steps near a wall" if s.free_flight else
                 "node positions summed")
    stages.append((f"P2G ({len(tr.p2g)} material group(s); stencils "
                   f"{'located on the fly' if s.fused else 'from the cache'}; {positions})",
                   names(*[k for k, _ in tr.p2g])))
    stages.append(("grid update: velocities, gravity, walls" + (", regions" if cond.regions else "")
                   + (", colliders" if cond.collider_kinds else ""), names(cond.grid_update)))
    if s.implicit is not None:
        stages.append(("implicit solve: Newton, CG", names(cond.constraints, *s.implicit.kernels())))
    if s.contact is not None:
        stages.append(("contact between bodies", names(s.contact.splat, s.contact.correct, s.contact.clear)))
    if cond.boundary is not None:
        stages.append(("boundary after contact", names(cond.boundary)))
    g2p = "G2P" + (", removal at open walls" if cond.open else "") + (
        ", energy and speed for the detection" if s.options.track_energy else "") + (
        ", the configuration update" if s.g2p_commits else "")
    stages.append((g2p, names(tr.g2p)))
    stages.append(("criterion (device, one thread): configuration updates, particles left, node positions "
                   "needed, grids that must follow", names(s.criterion.kernel)))
    update = {"empm": "every step", "tlmpm": "never (initial reference)"}.get(
        sch.name, f"when the criterion fires (epsilon {getattr(sch, 'epsilon', 0):g})")
    where = ("on the device where the grid covers the new reference, else the host refits first"
             if s.device_moves else "the host refits the grids and launches it")
    if s.g2p_commits:
        update = "every step, in G2P; the grids follow (host); the update kernel only at the start"
        where = ""
    update = f"{update}; {where}" if where and sch.name != "tlmpm" else update
    kernels = s.references.gated if s.device_moves else s.references.update
    stages.append((f"configuration update: {update}", sorted(set(names(*kernels)))))
    if driver is not None:
        stages.append(("policy (device, one thread): time, blow-up detection, next step, end, history row",
                       names(driver.device_policy.kernel)))
        stages.append((f"read-back of the history: every {driver.k} step(s)"
                       + (", the k steps as a CUDA graph" if driver.graph else ""), []))
    stages.append(("diagnostics, fracture measure" + (", particles inside colliders" if cond.inside else "")
                   + " (at logging cadence)", names(s.diagnostics.kernel, s.fracture.kernel, cond.inside)))
    return stages
