"""Particle-to-grid and grid-to-particle transfers, in each body's reference
configuration, on every grid of the kernel: P2G in mpm.p2g, G2P in mpm.g2p,
and :class:`Transfers`, which compiles them for a model and launches them.

Notation (A-ULMPM paper, eq. 10-33): ``X_p`` reference
particle positions, ``X_i`` reference node positions, ``r = X_i - X_p``,
``W_ip`` kernel weights (cached at the last configuration update),
``K_p = I / (moment dx^2)`` the MLS moment inverse, ``F^{0s}`` the deformation
gradient at the last update, ``F^{sn}`` the deformation since then,
``F^{0n} = F^{sn} F^{0s}``.
"""

from dataclasses import dataclass

import numpy as np
import warp as wp

from .collider_device import scene_kinds
from .g2p import make_g2p
from .body_springs import BodySprings
from .elastic_contact import Springs, elastic
from .loads import Loads
from .p2g import make_p2g
from .scene import WALL_TYPES

TRANSFERS = ("mls", "apic", "pic", "flip")
"""mls: affine momentum with C, MLS force K_p r w (Hu et al. 2018); apic:
affine momentum, force and F from the kernel gradient (Jiang et al. 2015);
pic: no affine term, force and F from the kernel gradient; flip: as pic, and
G2P blends the particle's own velocity updated by the grid's change (FLIP,
Brackbill & Ruppel 1986) into PIC's (``SolverOptions.flip``, Zhu & Bridson
2005's PIC/FLIP blend)."""
AFFINE_FREE = ("pic", "flip")
"""the transfers without an affine term C (no MLS moment read)"""


@dataclass(frozen=True)
class GridConstants:
    """The discretisation's constants as the kernels take them (Warp values)."""

    dx: object  # [m] cell width
    inv_dx: object  # [1/m]
    K: object  # MLS moment inverse 1 / (moment dx^2) [1/m^2] (0: per particle)
    grid_offsets: object  # per kernel grid, its offset [cells]
    gravity: object  # [m/s^2]

    @classmethod
    def of(cls, model) -> "GridConstants":
        t, k = model.types, model.kernel
        S = t.scalar
        return cls(dx=S(model.dx), inv_dx=S(1.0 / model.dx),
                   K=S(1.0 / (k.moment * model.dx**2) if k.moment is not None else 0.0),
                   grid_offsets=wp.types.vector(k.n_grids, S)(*k.grids), gravity=t.vec(*model.gravity))


class Transfers:
    """P2G for every material group of ``model`` and one G2P, compiled for
    what the run needs, and launched on the solver's grid.

    ``lagrangian``: the reference may lag behind the particles (not EMPM);
    ``fused``: stencils located in the transfers instead of cached
    (mpm.stencil.fuse); ``commit``: G2P does the configuration update too;
    ``with_stress`` False: P2G leaves the stress to the implicit solve;
    ``forcing``: a manufactured solution's body force (mpm.analytic), set on
    the host; the model's external loads (mpm.loads) set it on the device;
    ``bound_reach``: G2P bounds |F^sn|_inf (walls-only Lagrangian scenes);
    ``removal``: particles leave at open faces; ``marks``: count dJ >=
    epsilon; ``epsilon``: the criterion's threshold; ``compensate``: G2P keeps
    x and F as compensated sums (mpm.g2p; the state's ``xc`` and ``Fc``);
    ``rigid``: the scene's rigid bodies, which take the step's impulse after G2P."""

    def __init__(self, model, launch, buffer, transfer: str, *, lagrangian: bool, fused: bool, commit: bool,
                 with_stress: bool, regions: bool, forcing, record_dJ: bool, marks: bool, epsilon: float,
                 track_energy: bool, track_J: bool, removal: bool, bound_reach: bool, project=None,
                 batched: bool = False, flip: float = 0.0, compensate: bool = False, gradients: bool = False,
                 boundary=None, keep_out: bool = False, rigid=None):
        t, k = model.types, model.kernel
        self.model, self.launch, self.buffer = model, launch, buffer
        self.rigid = rigid  # the rigid bodies, advanced after G2P (mpm.rigid_coupling.Coupler; None: none)
        self.flip = t.scalar(flip if transfer == "flip" else 0.0)  # the FLIP share of G2P's velocity
        self.forcing = forcing
        springs = elastic(model.scene)  # colliders acting through springs on the particles (mpm.elastic_contact)
        touching = model.scene.contact == "elastic" and len(model.scene.bodies) > 1  # mpm.body_springs
        body_force = forcing is not None or model.loads is not None or springs or touching
        # the factor of F whose sum G2P compensates (mpm.g2p): F^0s with the commit of an unprojected
        # F^0s, F^sn without a commit, none with a projected commit
        compensated = "" if not compensate else ("sn" if not commit else ("0s" if project is None else ""))
        self.p2g = [(make_p2g(t, k, transfer, g.cls, regions, body_force, lagrangian=lagrangian,
                              with_stress=with_stress, fused=fused, batched=batched, gradients=gradients,
                              compensated=compensated), g)
                    for g in model.groups]
        self.g2p = make_g2p(t, k, transfer, record_dJ, marks, lagrangian=lagrangian,
                            track_compression=any(b.material.stiffens for b in model.scene.bodies),
                            track_energy=track_energy, track_inversion=track_J, removal=removal, fused=fused,
                            bound_reach=bound_reach, commit=commit, project=project, batched=batched,
                            loads=model.loads is not None, compensate=compensate, keep_out=keep_out,
                            colliders=scene_kinds(model.scene) if keep_out else ())
        self.boundary = boundary  # the walls and colliders, for keep_out (mpm.grid)
        margin = k.margin * model.dx
        open_code = WALL_TYPES.index("open")
        self.inside_lo = t.vec(*([margin] * t.dim))
        self.inside_hi = t.vec(*[L - margin for L in model.domain])
        self.open_lo = t.vec(*[float(c == open_code) for c in model.wall_codes[0]])
        self.open_hi = t.vec(*[float(c == open_code) for c in model.wall_codes[1]])
        self.epsilon = t.scalar(epsilon if np.isfinite(epsilon) else 0.0)
        with wp.ScopedDevice(model.device):
            # body force per unit mass [m/s^2] of a manufactured solution, set every step
            # or of the external loads, set at every step's start
            self.body_force = wp.zeros(model.n_particles if body_force else 1, dtype=t.vec)
        self.loads = Loads(model, launch, buffer, self.body_force) if model.loads is not None else None
        self.springs = None  # the elastic colliders' springs (their records: the conditions')
        if springs:
            assert boundary is not None, "a scene with colliders packs them (mpm.conditions)"
            self.springs = Springs(model, launch, buffer, self.body_force, scene_kinds(model.scene), boundary.colliders)
        self.touching = BodySprings(model, launch, buffer, self.body_force) if touching else None  # between bodies
        self.forced = body_force  # a body force at each step's start (apply_forcing)
        # zeroed first unless a pass writes every particle's: a manufactured solution, or the colliders'
        # springs without loads (the loads write their particles only; the bodies' springs add to it)
        self.zero_first = forcing is None and (self.touching is not None or self.springs is not None) \
            and not (self.springs is not None and self.loads is None)

    def kernels(self) -> list:
        return ([k for k, _ in self.p2g] + [self.g2p] + (self.loads.kernels() if self.loads else [])
                + (self.springs.kernels() if self.springs else []) + (self.touching.kernels() if self.touching else []))

    def apply_forcing(self, state, X0: np.ndarray, time: float) -> None:
        """The body force of the step: the external loads' at the device's
        step start, or the manufactured solution's at the initial positions
        ``X0`` [m] and ``time`` [s] (host)."""
        if self.zero_first:
            self.body_force.zero_()
        if self.loads is not None:
            self.loads.apply(state)
        if self.forcing is not None:
            b = self.forcing.body_force(X0, time)
            self.body_force.assign(b.astype(np.float32 if self.model.types.precision == "float32" else np.float64))
        if self.springs is not None:
            self.springs.apply(state)
        if self.touching is not None:
            self.touching.apply(state)

    def rasterize(self, state, grid, layout, const, write: bool) -> None:
        """P2G over the device's step: the plastic return mapping (stored when
        ``write``; else a state's stored energy, no step), mass, momentum with
        the stress impulse, node positions, the elastic energy into the
        step's status."""
        m, b = self.model, self.buffer
        for kernel, g in self.p2g:
            self.launch(kernel, g.count, [
                m.mass, m.volume, m.body, m.body_params, layout.shape_d, state.x, state.v, state.C,
                state.F0s, state.Fsn, self.body_force, state.history, state.Fc, state.stencils, const.dx, const.K,
                g.start, int(write), grid.m, grid.v, grid.q, grid.p0, grid.G, m.region, grid.kin, grid.kin_id,
                b.status, b.control])

    def interpolate(self, state, grid, layout, const) -> None:
        """G2P over the device's step: velocities, affine matrices, positions,
        F^sn, the criterion's counts and the step's figures."""
        m, b = self.model, self.buffer
        self.launch(self.g2p, m.n_particles, [
            m.body, layout.shape_d, grid.v, grid.m, grid.p0, self.flip, state.stencils, const.dx, const.K, b.control,
            self.epsilon,
            self.inside_lo, self.inside_hi, state.x, state.v, state.C, state.Fsn, state.F0s, state.dJ, b.status,
            m.mass, const.gravity, m.volume, self.open_lo, self.open_hi, m.body_params, self.body_force,
            state.xc, state.Fc, self.boundary])
        if self.rigid is not None:  # the rigid bodies take the step's impulse (mpm.rigid_coupling)
            self.rigid.push(b.status)
