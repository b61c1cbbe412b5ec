"""After an implicit solve: what its solution changes in the step's
active sets, for another solve from it (mpm.implicit.solve's rounds).

* Coulomb friction between bodies (mpm.contact.friction ``classify``): a
  stuck bin whose tangential reaction leaves the cone slides, a sliding
  one whose slip the load turned round sticks, one whose bodies pull lets
  go, and a sliding bin's load follows its new normal reaction (settled
  within FRICTION_TOL of mu lambda_n).
* Coulomb friction at the colliders (mpm.implicit.rough ``classify``): a
  stuck node whose tangential reaction leaves the cone slides, a sliding
  one whose slip its load turned round sticks, and a sliding node's load
  follows its new normal reaction (settled within FRICTION_TOL of
  mu R_n); a node whose normal reaction pulls slides without load (a
  separating collider then lets it go in the one-sided rounds).
* The one-sided boundary conditions under the surface rule (a separating
  collider, a slip wall: they hold a node only while the body moves into
  them): the conditions classify the velocity without their reaction,
  v - reaction, as they classified the predictor at the step's start; a
  held node whose reaction pushes stays held, one whose constraint pulls
  is let go, and a free node the solution moves into the solid is held.

Friction between bodies is settled first, then at the colliders, then
the one-sided conditions (a node they let go leaves friction, one they
newly hold starts stuck). With ``commit``
False (the last solve the step allows) a round only counts the changes
and leaves the solve's solution and active sets as they were.
"""

import warp as wp

from .system import make_side_kernels

FRICTION_TOL = 1.0e-2  # a sliding bin's load settled: it moved by less than this fraction of mu lambda_n


class Rounds:
    """The rounds of an :class:`mpm.implicit.solve.ImplicitSolve` (its arrays:
    the solution, the projectors Pi, the reaction, the bins, the collider
    nodes' states)."""

    def __init__(self, solve):
        self.solve = solve
        m = solve.solver.model
        # the one-sided conditions' rounds: the surface rule's; the node rule as it was
        self.sides = make_side_kernels(solve.t) if m.scene.boundary_rule == "surface" else None
        with wp.ScopedDevice(m.device):
            self.bstate_kept = wp.full(m.n_nodes if solve.sliding else 1, -1, dtype=wp.int32)
            self.side_changes = wp.zeros(1, dtype=wp.int32)
        self.kept: tuple = ()

    def grow(self, n: int) -> None:
        """Room for the last solve's classification of ``n`` nodes."""
        s = self.solve
        k = n if self.sides is not None else 1
        with wp.ScopedDevice(s.solver.model.device):
            self.kept = (wp.zeros(k, dtype=s.t.vec), wp.zeros(k, dtype=s.t.mat), wp.zeros_like(s.friction),
                         wp.zeros_like(s.friction_u), wp.zeros_like(s.friction_n),
                         wp.zeros_like(s.friction_shift), wp.zeros_like(s.contact_id), wp.zeros_like(s.cstate),
                         wp.zeros_like(s.cload), wp.zeros_like(s.held),
                         wp.zeros(k if s.rough else 1, dtype=s.t.vec))  # (v*, with collider friction)

    def changes(self, commit: bool = True) -> int:
        """The bins, else the nodes, whose state the solution changes (0:
        settled); with ``commit``, the next solve's start and active sets."""
        changed = self.friction(commit) if self.solve.sliding else 0
        if not changed and self.solve.rough:
            changed = self.rough(commit)
        if not changed and self.sides is not None:
            changed = self.one_sided(commit)
        return changed

    def friction(self, commit: bool = True) -> int:
        """Friction between bodies: each frictional bin's next state and load
        from the reaction at the solution; where any changed and ``commit``,
        v* with the new loads and grid_v projected onto the new constraints
        (else the bins' states stay as the solve had them). The bins that changed."""
        s = self.solve
        solver, m = s.solver, s.solver.model
        n = solver.layout.n_nodes
        sums, _, classify, load = s.sliding[1:5]
        # (the last residual evaluation, at the solution, left its projection sums in contact_num, _den)
        s.rel.zero_()
        s.rel_den.zero_()
        wp.launch(sums, n, device=m.device, inputs=[
            0, s.cbin, s.coef, s.bnormal, s.free, solver.grid.m, s.inv_diag, solver.grid.v,
            s.rel, s.rel_den])  # V_a - V_c per bin
        if not commit:
            wp.copy(self.bstate_kept, s.bstate)
        s.changed.zero_()
        wp.launch(classify, m.n_nodes, device=m.device, inputs=[
            s.bnormal, s.bstate, s.bmu, s.contact_num, s.contact_den, s.rel, s.force,
            s.t.scalar(FRICTION_TOL), s.force_after, s.changed])
        changed = int(s.changed.numpy()[0])
        if not commit:
            wp.copy(s.bstate, self.bstate_kept)
        if changed == 0 or not commit:  # (the loads stay those the solution carries)
            return changed
        s.force, s.force_after = s.force_after, s.force
        wp.launch(load, n, device=m.device, inputs=[
            s.cbin, s.coef, s.bnormal, s.bstate, s.force, s.free, solver.grid.m, s.v_star0, s.v_base])
        if s.rough:  # (v_base is v* without collider friction) and the colliders' loads on it
            s.hold()
        s.project(0, solver.grid.v)
        return changed

    def rough(self, commit: bool = True) -> int:
        """Friction at the colliders (mpm.implicit.rough ``classify``): each
        node's next state and load from the reaction at the solution; where
        any changed and ``commit``, the nodes held or freed accordingly, v*
        with the new loads (and grid_v projected onto the contact
        constraints). The nodes that changed."""
        s = self.solve
        solver, m = s.solver, s.solver.model
        n = solver.layout.n_nodes
        self.side_changes.zero_()
        wp.launch(s.rough[1], n, device=m.device, inputs=[
            solver.grid.m, s.friction, s.friction_u, s.friction_n, s.friction_shift, s.held, s.reaction,
            solver.grid.v, s.cstate, s.cload, s.t.scalar(FRICTION_TOL), s.cstate_after, s.cload_after,
            self.side_changes])
        changed = int(self.side_changes.numpy()[0])
        if changed == 0 or not commit:
            return changed
        s.cstate, s.cstate_after = s.cstate_after, s.cstate
        s.cload, s.cload_after = s.cload_after, s.cload
        s.hold()
        if s.contact is not None:
            s.project(0, solver.grid.v)
        return changed

    def one_sided(self, commit: bool = True) -> int:
        """The one-sided conditions (module docstring): where a node's
        projector changed and ``commit``, grid_v starts the next solve from
        v - reaction, constrained anew (projected onto the contact
        constraints between bodies); else the solve's solution and
        classification stay. The nodes that changed."""
        s = self.solve
        solver, m = s.solver, s.solver.model
        n = solver.layout.n_nodes
        assert self.sides is not None, "called under the surface rule only (changes)"
        unconstrained, changed = self.sides
        arrays = (solver.grid.v, s.free, s.friction, s.friction_u, s.friction_n, s.friction_shift, s.contact_id,
                  s.cstate, s.cload, s.held, s.v_star)
        for kept, a in zip(self.kept, arrays):
            if a.shape[0] >= n and kept.shape[0] >= n:
                wp.copy(kept, a, count=n)
        wp.launch(unconstrained, n, device=m.device, inputs=[solver.grid.m, s.reaction, solver.grid.v])
        solver.conditions.constrain(solver.grid, n, solver.step_time, s.free, s.friction, s.friction_u,
                                    s.friction_n, s.friction_shift, s.contact_id)
        if s.rough:  # a node let go leaves friction, one newly held starts stuck
            s.hold(fresh=True)
        self.side_changes.zero_()
        wp.launch(changed, n, device=m.device, inputs=[s.free, self.kept[1], self.side_changes])
        count = int(self.side_changes.numpy()[0])
        if count == 0 or not commit:
            for kept, a in zip(self.kept, arrays):
                if a.shape[0] >= n and kept.shape[0] >= n:
                    wp.copy(a, kept, count=n)
            return count
        if s.contact is not None:
            s.project(0, solver.grid.v)
        return count
