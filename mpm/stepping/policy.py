"""The driver's step policy on the device (mpm.stepping.driver): after every step, one
thread advances the clock, applies the blow-up detection (mpm.stepping.detection),
chooses the next step (mpm.stepping.timestep) and decides whether the steps may go
on without the host, so that k steps run with one read-back.

Per step, in order (:func:`make_policy`), mirroring the host's rules with
the same float64 arithmetic:

1. the step count and the time advance by the step taken;
2. the detection checks the state the step started from (energy) and the
   new state (speed, inversion); a trip with action ``stop`` halts
   (``DETECTION``);
3. a non-finite value or a particle outside the domain halts (``NONFINITE``,
   ``OUTSIDE``);
4. at the end (a number of steps or a simulated time) the steps halt
   (``DONE``); otherwise the next step is chosen - the explicit rule of every
   body from this step's figures capped by ``dt_max``, the implicit
   displacement limit times the halvings' factor, or a fixed step - and
   lands on the end; a step below ``dt_collapse`` of the first, or one that
   is not a positive finite number, halts (``COLLAPSE``); a configuration
   update the device cannot do (mpm.stepping.criterion) halts for the host
   (``REGRID``); an observer's request (a particle frame, say) pauses
   (``PAUSE``);
5. the centre of the angular momentum scale follows the state's centre of
   mass when the diagnostics were measured;
6. the whole step buffer (mpm.stepping.status) is written into row (step - 1) mod k of
   the history, and the following steps of the batch are skipped once a
   halt is set.
"""


import functools
import math

import numpy as np
import warp as wp

from ..diagnostics import diagnostic_names
from ..launch import warp_kernel
from .detection import DetectParams, detect_params, make_detection
from .status import (CONTROL, COLLAPSE, DETECTION, DONE, NONFINITE, OUTSIDE, PAUSE, REGRID, StepControl,
                     StepStatus)
from .timestep import BINDINGS, BodyLaws, body_laws, make_step_rule, pymax, pymin, wave_speed

WAVE, VISCOUS, STRAIN, DT_MAX, FIXED, DISPLACEMENT = range(len(BINDINGS))


@wp.struct
class PolicyParams:
    """The step policy's constants (float64; inf where unset)."""

    cfl: wp.float64
    dt_max: wp.float64  # [s]
    dt_collapse: wp.float64
    dt_fixed: wp.float64  # [s] (0: adaptive)
    steps_end: wp.float64  # (inf: the end is a time)
    t_end: wp.float64  # [s] (inf: the end is a number of steps)
    dx: wp.float64  # [m]
    collider_speed: wp.float64  # [m/s]
    displacement: wp.float64  # implicit: cells per step at the fastest speed


@functools.cache
def make_rule(dim: int, n_bodies: int, implicit: bool):
    """``rule(control, status, laws, params, first, v0) -> (dt, fresh,
    factor, binding)``: the rule's next step [s], the step a fresh reference
    allows, the reference factor and the binding term, from this step's
    figures or (``first``) the fastest initial particle ``v0`` [m/s]: the
    implicit displacement limit times the halvings' factor, or the explicit
    rule of every body."""
    f64 = wp.float64
    inf = f64(math.inf)
    limits = make_step_rule(dim)

    @wp.func
    def body_limits(status: StepStatus, laws: BodyLaws, params: PolicyParams, b: int, first: bool, speed: f64):  # pyright: ignore[reportGeneralTypeIssues]
        """Body b's wave, viscous and strain limits and its fresh step [s]."""
        J = f64(1.0)
        s = f64(1.0)
        stiffening = f64(1.0)
        rate = f64(0.0)
        if not first:
            if wp.isfinite(status.min_J[b]):
                J = status.min_J[b]
            s2 = wp.sqrt(status.min_stretch2[b])
            if wp.isfinite(s2):
                s = s2
            if status.stiffening[b] > f64(0.0) and wp.isfinite(status.stiffening[b]):
                stiffening = status.stiffening[b]
            rate = wp.sqrt(status.max_rate2[b])
        c = wave_speed(laws, b, pymin(pymax(J, f64(1.0e-3)), f64(1.0))) * wp.sqrt(stiffening)
        wave, viscous, strain, fresh = limits(params.dx, pymin(pymax(s, f64(1.0e-3)), f64(1.0)), c, speed,
                                              params.cfl, laws.nu[b], rate)
        return wave, viscous, strain, fresh

    @wp.func
    def explicit(status: StepStatus, laws: BodyLaws, params: PolicyParams, first: bool, speed: f64):  # pyright: ignore[reportGeneralTypeIssues]
        """The smallest body limit, its fresh step and term; the reference factor."""
        best = f64(inf)  # pyright: ignore[reportArgumentType]
        best_fresh = f64(inf)  # pyright: ignore[reportArgumentType]
        binding = int(WAVE)
        fresh = f64(inf)  # pyright: ignore[reportArgumentType]
        factor = f64(1.0)
        for b in range(n_bodies):
            wave, viscous, strain, fresh_b = body_limits(status, laws, params, b, first, speed)
            dt_b = pymin(pymin(wave, viscous), strain)
            if b == 0 or dt_b < best:
                best = dt_b
                best_fresh = fresh_b
                binding = int(WAVE)
                if viscous < wave:
                    binding = int(VISCOUS)
                if strain < pymin(wave, viscous):
                    binding = int(STRAIN)
            fresh = wp.where(b == 0, fresh_b, pymin(fresh, fresh_b))
        if best_fresh > f64(0.0):
            factor = best / best_fresh
        fresh = pymin(params.dt_max, fresh)
        return best, fresh, factor, binding

    @wp.func
    def rule(control: StepControl, status: StepStatus, laws: BodyLaws, params: PolicyParams, first: bool,  # pyright: ignore[reportGeneralTypeIssues]
             v0: f64):
        speed = v0
        if not first:
            speed = wp.sqrt(status.max_v2[0])
        speed = pymax(speed, params.collider_speed)
        best = f64(inf)  # pyright: ignore[reportArgumentType]
        binding = int(WAVE)
        fresh = f64(inf)  # pyright: ignore[reportArgumentType]
        factor = f64(1.0)
        if wp.static(implicit):
            limit = f64(inf)  # pyright: ignore[reportArgumentType]
            if speed > f64(0.0):
                limit = params.displacement * params.dx / speed
            best = control.scale[0] * limit
            fresh = best
            binding = int(DISPLACEMENT)
        else:
            best, fresh, factor, binding = explicit(status, laws, params, first, speed)
        return best, fresh, factor, binding

    return rule


@functools.cache
def make_choose(dim: int, n_bodies: int, implicit: bool):
    """``choose(control, status, laws, params, first, v0) -> collapsed``: the
    next step into the control block (the rule's, :func:`make_rule`, capped
    by ``dt_max``, or the fixed one, landing on the end); True when the run
    cannot take it (COLLAPSE)."""
    f64 = wp.float64
    inf = f64(math.inf)
    rule = make_rule(dim, n_bodies, implicit)

    @wp.func
    def choose(control: StepControl, status: StepStatus, laws: BodyLaws, params: PolicyParams, first: bool,  # pyright: ignore[reportGeneralTypeIssues]
               v0: f64):
        limit, fresh, factor, binding = rule(control, status, laws, params, first, v0)
        dt = params.dt_fixed
        if params.dt_fixed > f64(0.0):
            binding = FIXED
        else:
            dt = pymin(params.dt_max, limit)
            if params.dt_max <= limit:
                binding = DT_MAX
            if control.dt0_set[0] == f64(0.0):
                control.dt0[0] = dt
                control.dt0_set[0] = f64(1.0)
        control.dt_limit[0] = dt
        if wp.isfinite(params.t_end):
            dt = pymin(dt, params.t_end - control.t[0])
        control.dt[0] = dt
        control.dt_request[0] = dt
        control.dt_fresh[0] = fresh
        control.factor[0] = factor
        control.binding[0] = f64(binding)
        collapsed = bool(False)
        if params.dt_fixed == f64(0.0) and control.dt0_set[0] != f64(0.0):
            if not (control.dt_limit[0] >= params.dt_collapse * control.dt0[0]):  # NaN and 0 included
                collapsed = True
        if not (dt > f64(0.0) and dt < inf):  # a step of 0 would never end the run
            collapsed = True
        return collapsed

    return choose


@functools.cache
def make_policy(dim: int, n_bodies: int, implicit: bool, detect: bool, energy_on: bool, stop: bool,
                measured: bool, batched: bool):
    """The policy kernel (module docstring) and the ``initial`` kernel that
    chooses the first step from the fastest initial particle ``v0`` [m/s];
    ``detect``: the detection runs (``stop``: a trip halts, else it is a
    warning); ``measured``: the diagnostics are summed every step;
    ``batched``: nothing in a step the driver skips."""
    f64 = wp.float64
    choose = make_choose(dim, n_bodies, implicit)
    energy, step_trips = make_detection(energy_on)
    iC = diagnostic_names(dim).index("center_of_mass_x")

    @wp.func
    def failure(control: StepControl, status: StepStatus, laws: BodyLaws, detection: DetectParams):  # pyright: ignore[reportGeneralTypeIssues]
        """Why the step failed (DETECTION, NONFINITE, OUTSIDE), or 0."""
        nonfinite = status.nonfinite[0] > f64(0.0)
        halt = int(0)
        if wp.static(detect):
            energy(control, status, detection)
            if nonfinite:
                status.trips[0] = f64(0.0)  # the failure names the cause
            else:
                step_trips(control, status, laws, detection, n_bodies)
                if wp.static(stop):
                    if status.trips[0] > f64(0.0):
                        halt = DETECTION
        if halt == 0 and nonfinite:
            halt = NONFINITE
        if halt == 0 and status.outside[0] > f64(0.0):
            halt = OUTSIDE
        return halt

    @wp.func
    def going_on(control: StepControl, status: StepStatus, laws: BodyLaws, params: PolicyParams, n: f64, t: f64):  # pyright: ignore[reportGeneralTypeIssues]
        """After a sound step: DONE at the end, else the next step is chosen
        (COLLAPSE), REGRID for the host, PAUSE for an observer, or 0."""
        halt = int(0)
        done = bool(False)
        if wp.isfinite(params.steps_end):
            done = n >= params.steps_end
        else:
            done = t >= params.t_end * f64(1.0 - 1e-12)
        if done:
            halt = DONE
        elif choose(control, status, laws, params, False, f64(0.0)):
            halt = COLLAPSE
        else:
            for b in range(n_bodies):
                if control.regrid[b] != f64(0.0):
                    halt = REGRID
            if halt == 0 and (n >= control.stop_step[0] or t >= control.stop_time[0] * f64(1.0 - 1e-9)):
                halt = PAUSE
        return halt

    @warp_kernel
    def initial(control: StepControl, status: StepStatus, laws: BodyLaws, params: PolicyParams, v0: f64):  # pyright: ignore[reportGeneralTypeIssues]
        control.halt[0] = f64(0.0)
        if choose(control, status, laws, params, True, v0):
            control.halt[0] = f64(COLLAPSE)
        control.skip[0] = wp.where(control.halt[0] != f64(0.0), f64(1.0), f64(0.0))

    @warp_kernel
    def policy(status: StepStatus, control: StepControl, laws: BodyLaws, params: PolicyParams,  # pyright: ignore[reportGeneralTypeIssues]
               detection: DetectParams, flat: wp.array(dtype=f64), history: wp.array2d(dtype=f64)):  # pyright: ignore[reportGeneralTypeIssues]
        if wp.static(batched):
            if control.skip[0] != f64(0.0):
                return
        dt = control.dt[0]
        n = control.step[0] + f64(1.0)
        t = control.t[0] + dt
        control.step[0] = n
        control.t[0] = t
        control.dt_step[0] = dt
        control.fresh_step[0] = control.dt_fresh[0]
        control.factor_step[0] = control.factor[0]
        control.landing_step[0] = wp.where(control.dt_request[0] < control.dt_limit[0], f64(1.0), f64(0.0))
        halt = failure(control, status, laws, detection)
        if halt == 0:
            halt = going_on(control, status, laws, params, n, t)
        control.halt[0] = f64(halt)
        if wp.static(measured):  # (a failed step's state is not measured on the host either)
            if control.host_update[0] == f64(0.0) and halt != DETECTION and halt != NONFINITE and halt != OUTSIDE:
                M = status.diagnostics[0]
                for d in range(wp.static(dim)):
                    control.center[d] = wp.where(M > f64(0.0), status.diagnostics[iC + d] / M, f64(0.0))
        row = (int(n) - 1) % history.shape[0]
        for i in range(flat.shape[0]):
            history[row, i] = flat[i]
        control.skip[0] = wp.where(halt != 0, f64(1.0), f64(0.0))

    return initial, policy


class Policy:
    """The step policy of one driver (mpm.stepping.driver) on the device: its
    constants, the history of ``rows`` steps, and the kernels.
    ``detection``: mpm.stepping.detection.Detection (its action off: none)."""

    def __init__(self, solver, step_policy, detection, rows: int, measured: bool, batched: bool):
        m = solver.model
        self.solver, self.buffer = solver, solver.buffer
        implicit = solver.implicit is not None
        detect = detection.action != "off"
        energy_on = not getattr(m.scene.solution, "has_body_force", False)
        self.initial, self.kernel = make_policy(m.dim, len(m.scene.bodies), implicit, detect, energy_on,
                                                detection.action == "stop", measured, batched)
        self.laws = body_laws([b.material for b in m.scene.bodies], m.device)
        p = self.params = PolicyParams()
        sp = step_policy
        p.cfl, p.dt_max, p.dt_collapse = sp.cfl, sp.dt_max, sp.dt_collapse
        p.dt_fixed = sp.dt if sp.dt is not None else 0.0
        p.steps_end = float(sp.steps) if sp.steps is not None else math.inf
        p.t_end = sp.duration if sp.duration is not None else math.inf
        p.dx, p.collider_speed = m.dx, solver.conditions.collider_speed
        p.displacement = solver.options.integrator.displacement if implicit else 0.0
        self.detection = DetectParams()
        self.detection.check_J = wp.zeros(len(m.scene.bodies), dtype=wp.float64, device=m.device)
        with wp.ScopedDevice(m.device):
            self.history = wp.full((rows, self.buffer.size), np.nan, dtype=wp.float64)

    def kernels(self) -> list:
        return [self.initial, self.kernel]

    def start(self, v0: float, detector=None) -> None:
        """The first step, from the fastest initial particle ``v0`` [m/s], and
        the detection's constants (``detector``: mpm.stepping.detection.Detector)."""
        m, b = self.solver.model, self.buffer
        b.set(**{f.name: b.initial[b.slices[f.name]] for f in CONTROL  # a new run's clock and detection
                 if f.name not in ("alive", "positions", "center", "kinetic_last", "potential_last")})
        if detector is not None:
            self.detection = detect_params(detector, m.device)
            b.set(escale=detector.scale)
        wp.launch(self.initial, 1, device=m.device, inputs=[b.control, b.status, self.laws, self.params, float(v0)])

    def record(self) -> None:
        """After a step: the policy kernel (module docstring)."""
        b = self.buffer
        self.solver.launch(self.kernel, 1, [b.status, b.control, self.laws, self.params, self.detection, b.flat,
                                            self.history])
