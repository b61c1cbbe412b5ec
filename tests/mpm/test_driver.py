"""The driver (mpm.stepping.driver) and its policy on the device (mpm.stepping.policy,
mpm.stepping.criterion): batches of k steps give the run of k = 1 bit for bit on the
CPU, read back about once per k steps, stop a blow-up at the same step
before any value is non-finite, and choose the step the host's rule
(mpm.stepping.timestep.StepRule) and blow-up detection (mpm.stepping.detection.Detector)
choose from the same figures."""

import math

import numpy as np
import pytest

import mpm
from mpm.launch import Counter
from mpm.materials import MATERIALS
from mpm.stepping.status import REGRID

pytestmark = pytest.mark.bitwise


class Steps(mpm.Observer):
    """Every report, the events, and the steps at which the state was current."""

    def __init__(self, wants=(math.inf, math.inf)):
        self.reports, self.events, self.current, self._wants = [], [], [], wants

    def on_step(self, driver, report):
        self.reports.append(report)
        if driver.current:
            self.current.append((driver.step, driver.time))

    def on_event(self, driver, event):
        self.events.append(event.text)

    def wants(self, driver):
        return self._wants


def ball(dim=2, velocity=1.0, E=1.0e5, material=None, center=None):
    center = center or ((0.5, 0.3) if dim == 2 else (0.5, 0.3, 0.5))
    return mpm.Scene(dim=dim, domain=(1.0,) * dim, resolution=48 if dim == 2 else 20,
                     gravity=(0.0, -9.81, 0.0)[:dim],
                     bodies=[mpm.Body(mpm.Sphere(center, 0.1), material or mpm.FixedCorotated(E=E, nu=0.3),
                                      velocity=(velocity,) + (0.0,) * (dim - 1))])


def drive(scene, scheme, k, kernel="quadratic", policy=None, observers=(), measure=True, detection=None,
          device="cpu"):
    model, state = mpm.build(scene, mpm.KERNELS[kernel], "float32", device)
    solver = mpm.Solver(model, scheme, mpm.SolverOptions(track_energy=True, track_J=True, batched=k > 1))
    steps = Steps() if not observers else observers[0]
    driver = mpm.Driver(solver, state, policy or mpm.StepPolicy(duration=0.25), detection,
                        [steps, *observers[1:]], sync_every=k, measure=measure)
    solver.load()
    driver.run()
    return driver, steps, state


def same_reports(a, b):
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        assert (ra.step, ra.dt, ra.dt_fresh, ra.max_speed, ra.kinetic, ra.elastic, ra.updated) == \
               (rb.step, rb.dt, rb.dt_fresh, rb.max_speed, rb.kinetic, rb.elastic, rb.updated)
        np.testing.assert_array_equal(ra.diagnostics, rb.diagnostics)


@pytest.mark.parametrize("scheme", ["empm", "tlmpm", "aulmpm"])
@pytest.mark.parametrize("kernel", ["quadratic", "compact"])
def test_batches_give_the_steps_of_one_at_a_time(scheme, kernel, device):
    """k = 10 and k = 1: the same steps, figures, diagnostics and state, bit
    for bit (the same kernels in the same order; only the host reads less);
    a droplet with A-ULMPM's fluid defaults updates its references on the
    device and on the host."""
    scenes = [ball()]
    if scheme == "aulmpm":
        scenes.append(mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=48, gravity=(0.0, -9.81),
                                bodies=[mpm.Body(mpm.Sphere((0.5, 0.25), 0.12), mpm.Fluid(K=2e4))]))
    for scene in scenes:
        one, a, sa = drive(scene, mpm.SCHEMES[scheme](), 1, kernel, device=device)
        ten, b, sb = drive(scene, mpm.SCHEMES[scheme](), 10, kernel, device=device)
        assert one.outcome.status == ten.outcome.status == "completed"
        same_reports(a.reports, b.reports)
        for name in ("x", "v", "C", "F0s", "Fsn", "X"):
            np.testing.assert_array_equal(getattr(sa, name).numpy(), getattr(sb, name).numpy())
        assert one.summary() == ten.summary()
        if scene is scenes[-1] and scheme == "aulmpm":
            assert sum(bool(r.updated) for r in a.reports) > 5  # the fluid does update


def test_a_run_of_n_steps_reads_back_about_n_over_k_times(device):
    """With no observer asking for the state, n steps read back once per
    batch: ceil(n / k) times, plus once for each time the ball outran the
    room its grid was given (REGRID, a batch cut short: the host refits it);
    the kernels launched per step are those of k = 1."""
    counts, regrids, syncs = {}, {}, {}
    for k in (1, 10):
        model, state = mpm.build(ball(), mpm.KERNELS["quadratic"], "float32", device)
        solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(track_energy=True, track_J=True, batched=k > 1))
        steps = Steps()
        driver = mpm.Driver(solver, state, mpm.StepPolicy(steps=200), observers=[steps], sync_every=k)
        solver.load()
        driver.start()
        with Counter() as c:
            while driver.running:
                driver.advance()
        counts[k] = c
        regrids[k] = sum(r.halt == REGRID for r in steps.reports)
        assert driver.step == 200
        assert math.ceil(200 / k) <= driver.syncs <= math.ceil(200 / k) + regrids[k]
        syncs[k] = driver.syncs
    assert regrids[10] <= 2  # the room for k steps is mostly enough
    # every read: the history once per batch, and nothing else per step
    assert counts[10].reads <= math.ceil(200 / 10) + regrids[10]
    assert counts[1].reads >= 200
    # the same kernels per step (a batch cut short launches its remaining steps, which do nothing)
    assert counts[10].launches == counts[1].launches // 200 * 10 * syncs[10]


def test_the_detection_stops_a_blow_up_at_the_same_step_in_a_batch(device):
    """A fixed step far above the stable one blows the ball up: with k = 10
    the energy criterion stops it at the same step as with k = 1, the steps
    after it in the batch did nothing, and no value is non-finite yet."""
    policy = mpm.StepPolicy(steps=60, dt=1e-3)
    scene = ball(E=1e7)
    one, _, s1 = drive(scene, mpm.EMPM(), 1, policy=policy, device=device)
    ten, _, s10 = drive(scene, mpm.EMPM(), 10, policy=policy, device=device)
    assert one.outcome.status == ten.outcome.status == "unstable"
    assert one.outcome.criterion == ten.outcome.criterion == "energy"
    assert one.outcome.step == ten.outcome.step < 10 and one.outcome.reason == ten.outcome.reason
    for name in ("x", "v", "Fsn"):
        a, b = getattr(s1, name).numpy(), getattr(s10, name).numpy()
        np.testing.assert_array_equal(a, b)
        assert np.isfinite(b).all()


def test_warnings_and_failures_are_reported_from_the_batch(device):
    """detect.action = warn: the trips become warnings at the step they
    happened, then the run fails on its non-finite values - the same events
    and outcome with k = 10 as with k = 1."""
    policy = mpm.StepPolicy(steps=60, dt=1e-3)
    runs = [drive(ball(E=1e7), mpm.EMPM(), k, policy=policy, detection=mpm.Detection(action="warn"),
                  device=device) for k in (1, 10)]
    (one, a, _), (ten, b, _) = runs
    assert a.events == b.events and any("stability warning" in e for e in a.events)
    assert one.outcome.criterion == ten.outcome.criterion in ("nonfinite", "outside")
    assert one.outcome.step == ten.outcome.step


def test_a_batch_ends_where_an_observer_wants_the_state(device):
    """An observer asking for the state at step 37 and at t = 0.1 s gets the
    state (driver.current) at exactly those steps: the first step at or past
    each, as with k = 1."""
    class Frames(Steps):
        def wants(self, driver):
            return (37.0 if driver.step < 37 else math.inf), (0.1 if driver.time < 0.1 else math.inf)

    driver, obs, _ = drive(ball(), mpm.EMPM(), 10, observers=[Frames()], device=device)
    current = [s for s, _ in obs.current]
    assert 37 in current
    first_past = next(r.step for r in obs.reports if r.time >= 0.1 * (1 - 1e-9))
    assert first_past in current
    assert len(current) < driver.step / 5  # otherwise batches of 10


def test_the_device_chooses_the_hosts_step(device):
    """The step the device chose after every step equals the host's rule on
    that step's figures (mpm.stepping.timestep.StepRule: wave speed at the most
    compressed particle, stretch, viscosity, strain rate; dt_max; landing),
    and its detection the host's (mpm.stepping.detection.Detector) - two
    implementations of one rule, on a viscous fluid (c grows with
    compression; in A-ULMPM the viscous term shrinks with the reference
    cell) and an A-ULMPM solid."""
    fluid = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=48, gravity=(0.0, -9.81),
                      bodies=[mpm.Body(mpm.Sphere((0.5, 0.25), 0.12), MATERIALS["viscous"](K=2e4, viscosity=5.0))])
    for scene, scheme in ((fluid, mpm.EMPM()), (fluid, mpm.AULMPM()), (ball(), mpm.AULMPM())):
        driver, obs, _ = drive(scene, scheme, 1, device=device)
        solver, p = driver.solver, driver.policy
        detector = mpm.Detector(driver.detection, solver.model.scene, solver.conditions.speed(), driver.v0,
                                solver.model.kernel.n_grids, float(solver.model.mass.numpy().astype(np.float64).sum()))
        names = solver.diagnostics.names
        energies = tuple(driver.initial[names.index(k)] for k in ("kinetic_energy", "potential_energy"))
        t = 0.0
        dt = min(p.dt_max, solver.timestep.stable_dt(p.cfl, None, driver.v0))
        for r in obs.reports:
            assert r.dt == min(dt, p.duration - t)
            assert detector.energy(energies[0], r.elastic, energies[1]) == []
            assert detector.step(r) == []
            energies = (r.kinetic, r.potential)
            t = r.time
            dt = min(p.dt_max, solver.timestep.stable_dt(p.cfl, r))
        assert detector.growth == driver.detector.growth and detector.scale == driver.detector.scale
        assert detector.work == driver.detector.work


def test_steps_by_hand_on_a_batched_solver_update_as_the_driver_does(device):
    """Solver.advance on a solver compiled for batches: the criterion's
    configuration updates happen (the device moves a covered reference, the
    host the others), as on an unbatched solver: the same state bit for bit
    (EMPM with the compact kernel: an update pass every step, X = x after it)."""
    states = []
    for batched in (False, True):
        model, state = mpm.build(ball(), mpm.KERNELS["compact"], "float32", device)
        solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(batched=batched))
        solver.prepare(state)
        for _ in range(20):
            report = solver.advance(state, 4e-4)
            assert report.updated == [0]
            np.testing.assert_array_equal(state.X.numpy(), state.x.numpy())
        states.append(state.numpy())
    for name in ("x", "v", "C", "F0s"):
        np.testing.assert_array_equal(states[0][name], states[1][name])


def test_a_second_driver_starts_its_own_clock(device):
    """A driver on a solver that has run before starts from step 0 and t = 0
    with the detection's state reset: it takes its own number of steps."""
    model, state = mpm.build(ball(), mpm.KERNELS["quadratic"], "float32", device)
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(track_energy=True, track_J=True))
    for _ in range(2):
        driver = mpm.Driver(solver, state, mpm.StepPolicy(steps=3))
        assert driver.run().status == "completed"
        assert driver.step == 3 and 0.0 < driver.time < 3 * 1e-3


def test_advance_before_prepare_says_what_to_call():
    """A solver stepped before it took its reference configurations says so
    (instead of failing inside the grid's arrays)."""
    model, state = mpm.build(mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, gravity=(0.0, -9.81), bodies=[
        mpm.Body(mpm.Sphere((0.5, 0.5), 0.1), mpm.NeoHookean())]), mpm.KERNELS["quadratic"], "float32", "cpu")
    with pytest.raises(RuntimeError, match=r"Solver.prepare\(state\)"):
        mpm.Solver(model).advance(state, 1e-4)
