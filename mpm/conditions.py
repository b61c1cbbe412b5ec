"""The boundary conditions of a model on the device: walls, kinematic regions
and rigid colliders (their rules: mpm.grid, mpm.colliders).

:class:`Conditions` packs them once and launches the passes that apply them:
inside the grid update (:meth:`update_grid`), as a pass of their own after
contact or the implicit solve (:meth:`apply`), and as the implicit solve's
constraints (:meth:`constrain`). Only what the scene holds is compiled: no
regions, no colliders, no separate pass unless needed. The scene's rigid
bodies (mpm.rigid) are colliders after its own, placed at their pose before
the grid update (``rigid``, mpm.rigid_coupling.Coupler).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .collider_device import build_meshes, make_inside_count, scene_kinds
from .collider_shapes import pack
from .colliders import INSIDE_DEPTH
from .rigid import solids
from .rigid_coupling import Coupler
from .grid import make_boundary, make_boundary_data, make_constraints, make_grid_update, region_types
from .scene import WALL_TYPES
from .surface import pack_profile, reach

OPEN = WALL_TYPES.index("open")


def needs_gradients(scene) -> bool:
    """Whether the boundary conditions read the nodes' velocity gradients
    (summed in P2G): the surface rule with a collider that holds a body's
    surface tangentially (friction, or sticky), mpm.surface."""
    return scene.boundary_rule == "surface" and any((c.friction > 0 and c.boundary != "elastic")
                                                     or c.boundary == "sticky" for c in solids(scene))


class Conditions:
    """``model``'s walls, regions and colliders. ``separate``: they act after
    contact or the implicit solve rather than in the grid update;
    ``implicit``: also compile the solve's constraints; ``lattice``: the
    nodes sit on the lattice (the Eulerian scheme; no summed positions).
    ``gradients``: the nodes' velocity gradients are summed in P2G
    (:func:`needs_gradients`)."""

    def __init__(self, model, launch, control, separate: bool, implicit: bool, lattice: bool,
                 batched: bool = False):
        t, scene = model.types, model.scene
        self.model, self.launch, self.control = model, launch, control
        self.regions = len(scene.regions) > 0
        self.solids = solids(scene)  # the colliders, then the rigid bodies' shapes (mpm.rigid)
        self.collider_kinds = scene_kinds(scene)
        rule, self.gradients = scene.boundary_rule, needs_gradients(scene)
        self.band = (scene.wall_cells - 0.5) * model.dx  # [m] the node rule's walls act on nodes this close
        # [m] walls act on nodes closer than this to the domain's face (a node the kernel's reach from a face)
        self.wall_reach = self.band if rule == "nodes" else (scene.wall_cells + reach(model.kernel)) * model.dx
        self.closed = (np.array(model.wall_codes[0]) != OPEN, np.array(model.wall_codes[1]) != OPEN)
        self.open = not (self.closed[0].all() and self.closed[1].all())  # particles leave at open faces
        rules = dict(rule=rule, gradients=self.gradients)
        self.grid_update = make_grid_update(t, not separate, self.regions, self.collider_kinds,
                                            lattice=lattice, n_grids=model.kernel.n_grids, batched=batched, **rules)
        self.boundary = (make_boundary(t, self.regions, self.collider_kinds, batched, **rules)
                         if separate else None)
        self.constraints = (make_constraints(t, self.regions, self.collider_kinds,
                                             any(c.friction > 0 for c in self.solids), **rules,
                                             first=len(scene.colliders) if scene.rigid_bodies else 0)
                            if implicit else None)
        self.inside = make_inside_count(t, self.collider_kinds) if self.solids else None
        # particles put back out of the solids in G2P (mpm.keep_out)
        self.keep_out = rule == "surface" and bool(self.solids or self.closed[0].any() or self.closed[1].any())
        self.collider_speed = max([c.speed(scene.domain) for c in scene.colliders], default=0.0)  # [m/s]
        with wp.ScopedDevice(model.device):
            self._meshes = build_meshes(self.solids, model.device)  # kept alive for their ids
            self.data = self._pack()
            self._inside_counts = wp.zeros(max(len(self.solids), 1), dtype=wp.int32)
        # the rigid bodies: placed before the grid update, advanced after G2P (mpm.rigid_coupling)
        self.rigid = Coupler(model, self, control) if scene.rigid_bodies else None

    def kernels(self) -> list:
        return ([k for k in (self.grid_update, self.boundary, self.constraints, self.inside) if k is not None]
                + (self.rigid.kernels() if self.rigid is not None else []))

    def _pack(self):
        """Walls and kinematic regions (velocity, velocity gradient, centre,
        (start, end) per region) and the colliders, for the kernels."""
        m = self.model
        t, d = m.types, m.dim
        rows = [(tuple(reg.velocity or (0.0,) * d), reg.gradient(d),
                 tuple(reg.center if reg.center is not None else 0.5 * np.add(*reg.select.bounds())),
                 (reg.start, reg.end)) for reg in m.scene.regions]
        if not rows:  # placeholders: the kernels compile the regions out
            rows = [((0.0,) * d, np.zeros((d, d)), (0.0,) * d, (0.0, 0.0))]
        data = make_boundary_data(t)()
        data.domain = t.vec(*m.domain)
        data.band = t.scalar(self.band)
        face = m.scene.wall_cells * m.dx
        data.face_lo = t.vec(*([face] * d))
        data.face_hi = t.vec(*[L - face for L in m.domain])
        data.profile = pack_profile(t, m.kernel, m.dx, m.device)
        data.rest_mass = wp.array([b.material.rho * m.dx**d for b in m.scene.bodies], dtype=t.scalar,
                                  device=m.device)
        data.wall_lo = t.ivec(*m.wall_codes[0])
        data.wall_hi = t.ivec(*m.wall_codes[1])
        dtype = np.float32 if t.precision == "float32" else np.float64
        tables = [wp.array(np.array([r[k] for r in rows], dtype=dtype), dtype=T)
                  for k, T in enumerate(region_types(t))]
        data.region_u, data.region_gradient, data.region_center, data.region_window = tables
        data.colliders = pack(self.solids, t, self._meshes, m.device, len(m.scene.rigid_bodies or ()))
        return data

    def speed(self) -> float:
        """The fastest collider or kinematic region [m/s] (a region's rotation
        and stretch bounded over the domain's diagonal)."""
        scene = self.model.scene
        diagonal = float(np.linalg.norm(scene.domain))
        regions = [float(np.linalg.norm(r.velocity if r.velocity is not None else 0.0))
                   + float(np.linalg.norm(r.gradient(scene.dim), 2)) * diagonal for r in scene.regions]
        return max([self.collider_speed] + regions)

    # ------------------------------------------------------------ passes
    def place(self, status) -> None:
        """The rigid bodies' colliders at their pose (mpm.rigid_coupling), at the step's start: the elastic
        colliders' springs (mpm.elastic_contact), the grid rule and the keep-out read them."""
        if self.rigid is not None:
            self.rigid.place(status)

    def update_grid(self, grid, layout, const, status) -> None:
        """Grid momentum to velocity, gravity over the device's step, and
        (unless separate) the conditions at the nodes' current positions."""
        self.launch(self.grid_update, layout.n_nodes, [
            grid.lattice, const.gravity, const.grid_offsets, self.control, self.data, status])

    def apply(self, grid, layout, status) -> None:
        """The conditions as a pass of their own (after contact), at the step's start."""
        self.launch(self.boundary, layout.n_nodes, [grid.lattice, self.control, self.data, status])

    def constrain(self, grid, n: int, time, free, friction, friction_u, friction_n, friction_shift,
                  contact_id) -> None:
        """The implicit solve's constraints on the first ``n`` nodes: the
        constrained velocity in ``grid.v``, the projector onto the free
        velocities in ``free`` and, with friction, its coefficient, the
        collider's velocity and normal per node and the extrapolation to
        its surface, and the collider in contact per node ``contact_id``
        (mpm.grid.make_constraints)."""
        wp.launch(self.constraints, n, device=self.model.device, inputs=[
            grid.lattice, time, self.data, free, friction, friction_u, friction_n, friction_shift, contact_id])

    def inside_colliders(self, x, time: float) -> np.ndarray:
        """Per collider, the particles of ``x`` deeper inside it than
        INSIDE_DEPTH cells at ``time`` [s]."""
        m = self.model
        if self.inside is None:
            return np.zeros(0, np.int64)
        self._inside_counts.zero_()
        wp.launch(self.inside, m.n_particles, device=m.device, inputs=[
            x, m.types.scalar(time), m.types.scalar(INSIDE_DEPTH * m.dx), self.data.colliders,
            self._inside_counts])
        return self._inside_counts.numpy()[:len(self.solids)].astype(np.int64)


class Removals:
    """The particles removed at open faces (G2P gives them mass 0): per body
    those left (``counts``, what A-ULMPM's criterion divides by) and those
    removed so far (``removed``), and the particles left by number
    (``kept``; None: all of them)."""

    def __init__(self, model):
        self.model = model
        self.counts = np.array([c for _, c in model.body_ranges])
        self.removed = np.zeros(len(model.body_ranges), np.int64)
        self.kept: np.ndarray | None = None
        self._stale = False

    def add(self, report) -> None:
        """A step's removals (``report.removed``, per body, or None)."""
        if report.removed is not None:
            self.removed += report.removed
            self.counts = self.counts - report.removed
            self._stale = True

    def refresh(self) -> None:
        """``kept`` from the masses, after removals (a read-back)."""
        if self._stale:
            self.kept = np.flatnonzero(self.model.mass.numpy() > 0)
            self._stale = False
