"""Bad input to the library (mpm.build, the registries, Solver, StepPolicy,
Driver), tried as a new user would: each is refused with one line naming
the argument and what is accepted, raised before any Warp module is
compiled or loaded by it (the command line's counterpart is
tests/pipelines/test_fuzz_inputs.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import warp._src.context as warp_context

import mpm
from helpers import DEVICE

REFUSALS = (ValueError, TypeError, KeyError, RuntimeError)


def body(**keys) -> mpm.Body:
    args = dict(shape=mpm.Box((0.5, 0.5), (0.1, 0.1)), material=mpm.FixedCorotated(E=1e4))
    args.update(keys)
    return mpm.Body(**args)


def scene(bodies=None, **keys) -> mpm.Scene:
    args = dict(dim=2, domain=(1.0, 1.0), resolution=16, bodies=bodies or [body()])
    args.update(keys)
    return mpm.Scene(**args)


def built(**keys):
    return mpm.build(scene(**keys), mpm.QUADRATIC, "float32", DEVICE)


def solver(*args):
    return mpm.Solver(built()[0], *args)


def driver(policy=None, **keys):
    model, state = built()
    return mpm.Driver(mpm.Solver(model, mpm.EMPM()), state, policy or mpm.StepPolicy(steps=2), **keys)


def ended():
    d = driver()
    assert d.run().status == "completed"
    return d


# (case, the call, a fragment its message must name)
CASES = [
    # mpm.build and the scene
    ("kernel name misspelt", lambda: mpm.build(scene(), "quadratc"), "kernel 'quadratc'"),
    ("kernel of another type", lambda: mpm.build(scene(), 3), "kernel"),
    ("precision float16", lambda: mpm.build(scene(), mpm.QUADRATIC, "float16"), "precision"),
    ("scene a dict", lambda: mpm.build({"dim": 2}, mpm.QUADRATIC), "scene"),
    ("dim 4", lambda: mpm.build(dataclasses.replace(scene(), dim=4), mpm.QUADRATIC), "dim"),
    ("domain negative", lambda: mpm.build(scene(domain=(1.0, -1.0)), mpm.QUADRATIC), "domain"),
    ("resolution 2", lambda: mpm.build(scene(resolution=2), mpm.QUADRATIC), "resolution"),
    ("gravity in 3D for 2D", lambda: mpm.build(scene(gravity=(0.0, -9.8, 0.0)), mpm.QUADRATIC), "gravity"),
    ("gravity nan", lambda: mpm.build(scene(gravity=(0.0, float("nan"))), mpm.QUADRATIC), "gravity"),
    ("boundary rule unknown", lambda: mpm.build(scene(boundary_rule="faces"), mpm.QUADRATIC), "boundary_rule"),
    ("walls unknown", lambda: mpm.build(scene(walls=("slip",) * 3 + ("glue",)), mpm.QUADRATIC), "walls"),
    ("ppc 0", lambda: mpm.build(scene(ppc=0), mpm.QUADRATIC), "ppc"),
    ("jitter 2", lambda: mpm.build(scene(jitter=2.0), mpm.QUADRATIC), "jitter"),
    ("no bodies", lambda: mpm.build(dataclasses.replace(scene(), bodies=[]), mpm.QUADRATIC), "bodies"),
    ("a material class", lambda: mpm.build(scene([body(material=mpm.FixedCorotated)]), mpm.QUADRATIC),
     "bodies[0].material"),
    ("a material name", lambda: mpm.build(scene([body(material="fixed_corotated")]), mpm.QUADRATIC),
     "bodies[0].material"),
    ("E negative", lambda: mpm.build(scene([body(material=mpm.FixedCorotated(E=-1.0))]), mpm.QUADRATIC),
     "bodies[0].material.E"),
    ("nu 0.6", lambda: mpm.build(scene([body(material=mpm.FixedCorotated(E=1e4, nu=0.6))]), mpm.QUADRATIC),
     "bodies[0].material.nu"),
    ("a shape class", lambda: mpm.build(scene([body(shape=mpm.Box)]), mpm.QUADRATIC), "bodies[0].shape"),
    ("no shape", lambda: mpm.build(scene([body(shape=None)]), mpm.QUADRATIC), "bodies[0].shape"),
    ("no material", lambda: mpm.build(scene([body(material=None)]), mpm.QUADRATIC), "bodies[0].material"),
    ("a shape outside the domain", lambda: mpm.build(scene([body(shape=mpm.Box((0.95, 0.5), (0.1, 0.1)))]),
                                                     mpm.QUADRATIC), "bodies[0]"),
    ("velocity of shape (2, 1)", lambda: mpm.build(scene([body(velocity=np.zeros((2, 1)))]), mpm.QUADRATIC),
     "bodies[0].velocity"),
    ("velocity in 3D for 2D", lambda: mpm.build(scene([body(velocity=(1.0, 0.0, 0.0))]), mpm.QUADRATIC),
     "bodies[0].velocity"),
    ("velocity nan", lambda: mpm.build(scene([body(velocity=(float("nan"), 0.0))]), mpm.QUADRATIC),
     "bodies[0].velocity"),
    ("velocity text", lambda: mpm.build(scene([body(velocity="fast")]), mpm.QUADRATIC), "bodies[0].velocity"),
    ("angular velocity a 3-vector in 2D", lambda: mpm.build(scene([body(angular_velocity=(0.0, 0.0, 1.0))]),
                                                            mpm.QUADRATIC), "bodies[0].angular_velocity"),
    ("deformation 3x3 in 2D", lambda: mpm.build(scene([body(deformation=np.eye(3))]), mpm.QUADRATIC),
     "bodies[0].deformation"),
    ("deformation inverted", lambda: mpm.build(scene([body(deformation=[[-1.0, 0.0], [0.0, 1.0]])]),
                                               mpm.QUADRATIC), "bodies[0].deformation"),
    ("body ppc 0", lambda: mpm.build(scene([body(ppc=0)]), mpm.QUADRATIC), "bodies[0].ppc"),
    ("collider friction negative", lambda: mpm.build(scene(colliders=[
        mpm.Collider.half_space((0.5, 0.1), (0.0, 1.0), friction=-1.0)]), mpm.QUADRATIC), "colliders[0]"),
    # the registries
    ("KERNELS misspelt", lambda: mpm.KERNELS["quadratc"], "kernel 'quadratc'"),
    ("SCHEMES unknown", lambda: mpm.SCHEMES["ulmpm"], "scheme 'ulmpm'"),
    ("MATERIALS unknown", lambda: mpm.MATERIALS["rubber"], "material 'rubber'"),
    ("INTEGRATORS unknown", lambda: mpm.INTEGRATORS["rk4"], "integrator 'rk4'"),
    # Solver
    ("a scheme class", lambda: solver(mpm.EMPM), "scheme"),
    ("a scheme name", lambda: solver("empm"), "scheme"),
    ("a model of another type", lambda: mpm.Solver("model", mpm.EMPM()), "model"),
    ("options a class", lambda: solver(mpm.EMPM(), mpm.SolverOptions), "options"),
    ("transfer unknown", lambda: solver(mpm.EMPM(), mpm.SolverOptions(transfer="mlss")), "transfer"),
    ("flip 2", lambda: solver(mpm.EMPM(), mpm.SolverOptions(flip=2.0)), "flip"),
    ("integrator a class", lambda: solver(mpm.EMPM(), mpm.SolverOptions(integrator=mpm.Implicit)),
     "options.integrator"),
    ("newton_tol 2", lambda: solver(mpm.EMPM(), mpm.SolverOptions(integrator=mpm.Implicit(newton_tol=2.0))),
     "newton_tol"),
    ("epsilon negative", lambda: solver(mpm.AULMPM(epsilon=-1.0)), "scheme.epsilon"),
    # StepPolicy and Driver
    ("steps -5", lambda: driver(mpm.StepPolicy(steps=-5)), "policy.steps"),
    ("steps 2.5", lambda: driver(mpm.StepPolicy(steps=2.5)), "policy.steps"),
    ("dt negative", lambda: driver(mpm.StepPolicy(steps=3, dt=-1e-3)), "policy.dt"),
    ("cfl nan", lambda: driver(mpm.StepPolicy(steps=3, cfl=float("nan"))), "policy.cfl"),
    ("cfl 2", lambda: driver(mpm.StepPolicy(steps=3, cfl=2.0)), "policy.cfl"),
    ("duration -1", lambda: driver(mpm.StepPolicy(duration=-1.0)), "policy.duration"),
    ("steps and duration", lambda: driver(mpm.StepPolicy(steps=3, duration=1.0)), "policy.steps"),
    ("neither steps nor duration", lambda: driver(mpm.StepPolicy()), "policy.steps"),
    ("dt_max 0", lambda: driver(mpm.StepPolicy(steps=3, dt_max=0.0)), "policy.dt_max"),
    ("policy a dict", lambda: driver({"steps": 3}), "policy"),
    ("detection unknown", lambda: driver(detection=mpm.Detection(action="explode")), "detection.action"),
    ("sync_every 2 unbatched", lambda: driver(sync_every=2), "sync_every"),
    ("advance before start", lambda: driver().advance(), "advance"),
    ("advance after the end", lambda: ended().advance(), "advance"),
]


def loaded() -> int:
    """Warp modules loaded (compiled or from the cache) in this process."""
    return sum(len(m.execs) for m in warp_context.user_modules.values())


@pytest.mark.parametrize("name,call,fragment", [pytest.param(n, c, f, id=n) for n, c, f in CASES])
def test_bad_library_input_is_refused_in_one_line_before_compiling(name, call, fragment):
    """One exception of a refusal type (no AttributeError, IndexError or a
    Warp error from deeper in), one line naming the argument and saying
    what is accepted; no Warp module loaded on the way (but for the advance
    after a run, and those a valid model and solver need, done first)."""
    solver()  # mpm.build's and the Solver's own loads (mpm.surface's profile table)
    before = loaded() if name != "advance after the end" else None
    with pytest.raises(REFUSALS) as caught:
        call()
    message = str(caught.value)
    assert "\n" not in message and fragment in message and "accepted" in message, message
    assert type(caught.value).__module__.split(".")[0] in ("builtins", "mpm"), type(caught.value)
    if before is not None:
        assert loaded() == before


def test_the_library_fuzz_covers_at_least_45_cases():
    assert len(CASES) >= 45 and len({n for n, _, _ in CASES}) == len(CASES)


def test_build_takes_a_kernel_by_name():
    """``mpm.build(scene, "quadratic")`` is mpm.build(scene, mpm.QUADRATIC)."""
    by_name, _ = mpm.build(scene(), "quadratic", "float32", DEVICE)
    assert by_name.kernel is mpm.QUADRATIC
