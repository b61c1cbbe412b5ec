"""CUDA code generation of every kernel a configuration can compile, checked
for sm_90 on a machine without a GPU or a CUDA driver.

What is checked: that Warp generates the CUDA source of each kernel module
and that NVRTC compiles it to PTX for sm_90, by Warp's ahead-of-time
compilation, which needs NVRTC but no driver:
``wp.compile_aot_module(module, device=None, arch=90, use_ptx=True,
module_dir=...)``. A kernel that compiles for the CPU but not for CUDA (a
native snippet's CUDA branch, a builtin or an overload the CUDA headers
lack, a conversion CUDA rejects) fails here, named with its module and
NVRTC's log. What is not checked: anything that needs a GPU - launching a
kernel, its results, races between atomic updates, register and shared
memory limits (applied when the driver loads the PTX). The CPU path is
unchanged: ``test_cpu_load_after_aot`` loads a solver's modules on the CPU
(``Solver.load``, ``wp.force_load``) after compiling them for sm_90 and
takes a step.

Which modules. Every kernel is built by a cached factory, specialised
through closures and ``wp.static``, in a Warp module of its own
(``mpm.launch.warp_kernel``): a module is determined by its factory's
arguments, and identical specialisations share one - Warp's module hash is
the key, so arguments that generate the same code (two materials with the
same elastic law in the implicit integrator, say) compile once. The product
of the options (3 schemes x 4 kernels x 9 materials x 2 integrators x 3
transfers x 3 kinds of contact x regions x colliders x open walls x the
solver's options x 2D/3D x float32/float64) is far too large to compile,
but the factories' arguments act on the generated code independently: a
flag adds or removes a ``wp.static`` block, a material contributes its own
functions, a collider kind its own block of the signed distance. So a set
of solvers that passes every factory, per dimension and precision, every
value of each of its arguments compiles every block of every kernel family.
On top of that, the interpolation kernel and the transfer are paired in the
transfers (P2G, G2P), where MLS, APIC and PIC take different code with a
constant or a per-particle moment matrix and with the linear kernel's
gradient (the other factories reach the interpolation kernel only through
the stencil functions of ``mpm.stencil``, which the transfers and the
configuration update compile for every pair); the collider kinds are
compiled all together in every kernel that takes them (with and without
a turning collider, whose rotation is a block of its own), and each alone in
``make_inside_count``, which evaluates nothing but the signed distance (a
block that needed another would fail there).

:func:`cases` lists the solvers, small scenes built from Python; the kernel
factories are found in ``mpm`` (every cached function that defines a
``@warp_kernel``) and their calls recorded while the solvers (and the
material-point driver, for every material) are built.
``test_cases_reach_every_specialisation`` asserts that every factory is
called with every required value of each argument (:func:`required`; a new
factory, flag or material that no case reaches fails it) and that every
kernel ``Driver.kernels()`` returns (the solver's and its policy's) comes from a recorded call. Each
``test_compiles_for_sm90`` compiles the distinct modules of one factory
(and interpolation kernel) in one dimension and precision, each once per
process, into ``aot_sm90`` beside Warp's kernel cache. Compiled from
nothing, the module takes about 25 minutes of CPU time on this project's
2-core machine (NVRTC of CUDA 13.4), two thirds of it in 3D (the cubic
kernel's implicit ``evaluate`` alone about 110 s), so about 13 minutes with
``pytest -n auto``; its tests are marked ``slow``. Warp skips a module
whose PTX for the same hash is already in that directory, as its kernel
cache does for the CPU, so a run after a change compiles only the modules
whose generated code or options changed; what is skipped compiled before
from the identical source, and its PTX is read and checked again. The
directory grows as modules change; deleting it empties it
(``wp.clear_kernel_cache()`` removes only Warp's ``wp_*`` folders).
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import inspect
import itertools
import pkgutil
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import warp as wp

import mpm
from mpm.colliders import ELASTIC, KINDS, RIGID, TURNING, Collider
from mpm.kernels import Kernel
from mpm.loads import Load
from mpm.launch import kernel_name
from mpm.materials.point_driver import MaterialPoint
from mpm.meshes import MeshShape
from mpm.transfer import TRANSFERS
from mpm.types import PRECISIONS, Types, make_types

ARCH = 90  # sm_90 (Hopper)
DIMS = (2, 3)


# ------------------------------------------------------------------ factories
def _kernel_factories() -> dict[str, object]:
    """Every cached function in ``mpm`` whose body defines a Warp kernel, by
    name (``module.function``)."""
    found = {}
    for info in pkgutil.walk_packages(mpm.__path__, "mpm."):
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            f = getattr(obj, "__wrapped__", None)
            if f is None or not hasattr(obj, "cache_info") or obj.__module__ != module.__name__:
                continue
            if "@warp_kernel" in inspect.getsource(f):
                found[f"{module.__name__}.{name}"] = obj
    return found


FACTORIES = _kernel_factories()


def _mpm_modules():
    return [m for name, m in list(sys.modules.items()) if name == "mpm" or name.startswith("mpm.")]


@contextlib.contextmanager
def recording(calls: dict):
    """While inside, every call of a kernel factory (from anywhere in ``mpm``)
    is recorded: ``calls[(factory, ((argument, value), ...))] = kernels``,
    the arguments bound to the signature with defaults applied."""
    patched = []
    for qual, factory in FACTORIES.items():
        signature = inspect.signature(factory.__wrapped__)

        def record(*args, _factory=factory, _signature=signature, _qual=qual, **kwargs):
            out = _factory(*args, **kwargs)
            bound = _signature.bind(*args, **kwargs)
            bound.apply_defaults()
            kernels = out if isinstance(out, tuple) else (out,)
            calls[(_qual, tuple(bound.arguments.items()))] = tuple(k for k in kernels if isinstance(k, wp.Kernel))
            return out

        for module in _mpm_modules():
            for name, obj in list(vars(module).items()):
                if obj is factory:
                    patched.append((module, name, obj))
                    setattr(module, name, record)
    try:
        yield calls
    finally:
        for module, name, obj in patched:
            setattr(module, name, obj)


# ------------------------------------------------------------------ cases
@dataclass(frozen=True)
class _Forcing:
    """A manufactured solution at rest with a zero body force: P2G compiles
    the body-force term for any solution that has one, so this stands in for
    the configurations' one, the vortex (2D only), in both dimensions."""

    has_body_force = True

    def velocity(self, X, t):
        return np.zeros_like(X)

    def velocity_gradient(self, X, t):
        return np.zeros((len(X), X.shape[1], X.shape[1]))

    def body_force(self, X, t):
        return np.zeros_like(X)


@dataclass(frozen=True)
class Case:
    """One small scene and solver; what it sets is what the solver compiles."""

    scheme: str = "empm"  # empm | tlmpm | aulmpm (the scene kind's defaults) | aulmpm_paper | aulmpm_transform
    kernel: str = "linear"  # the quickest to compile
    transfer: str = "mls"
    materials: tuple[str, ...] = ("fixed_corotated",)  # one body each
    implicit: bool = False
    psd: bool = True
    contact: str = "frictionless"
    contact_friction: float = 0.0  # mu between the bodies (contact="friction")
    normal: str = "difference"  # the contact's normals (mpm.contact.lattice.NORMALS)
    regions: bool = False
    colliders: tuple[str, ...] = ()  # kinds
    friction: bool = False
    turning: bool = False  # the first collider turns (mpm.collider_motion: the kinds take TURNING)
    rigid: bool = False  # rigid bodies coupled through Newton (mpm.rigid_coupling: the kinds take RIGID)
    joints: bool = False  # the first rigid body hinged to the world (mpm.joints: the wrench kernel)
    open_walls: bool = False
    fuse: bool | None = None
    record_dJ: bool = False
    track_energy: bool = False
    track_J: bool = False
    forcing: bool = False
    loads: bool = False  # a point load, a traction and a body force (mpm.loads)
    batched: bool = False  # the driver runs 10 steps between read-backs (mpm.stepping.driver)
    detect: str | None = None  # the driver's blow-up detection: stop | warn | off (None: stop
    # with the step's energies, which the detection needs; off without them)
    measure: bool = False  # the driver measures the diagnostics every step
    compensate: bool | None = None  # compensated sums of x and F in G2P (None: where the estimate flags the scene)
    rule: str = "surface"  # where walls and colliders act (mpm.scene.BOUNDARY_RULES)
    elastic: bool = False  # the first collider acts through springs on the particles (mpm.elastic_contact)

    def label(self) -> str:
        default = Case()
        return ",".join(f"{k}={v}" for k, v in vars(self).items() if v != getattr(default, k)) or "base"


def _collider(kind: str, dim: int, friction: float, turning: bool = False, elastic: bool = False) -> Collider:
    def at(*c):
        return tuple(c[:dim])

    shapes = {
        "half_space": dict(point=at(0.5, 0.2, 0.5), normal=at(0.0, 1.0, 0.0)),
        "wedge": dict(point=at(0.5, 0.2, 0.5), normals=(at(-1.0, 1.0, 0.0), at(1.0, 1.0, 0.0))),
        "box": dict(center=at(0.5, 0.12, 0.5), half_size=at(0.1, 0.05, 0.1)),
        "sphere": dict(center=at(0.5, 0.5, 0.5), radius=0.45, inside=True),
        "cylinder": dict(center=at(0.2, 0.2, 0.5), radius=0.05, half_height=0.05, axis=1),
        "cup": dict(center=at(0.8, 0.25, 0.5), radius=0.05, depth=0.1, thickness=0.02, axis=1),
        "bowl": dict(center=at(0.5, 0.7, 0.5), radius=0.1, thickness=0.02, rim=0.05, axis=1),
        "mesh": dict(mesh=MeshShape("warp:cube", (0.5, 0.12, 0.5), 0.08)),
    }
    spin = None if not turning else (1.0 if dim == 2 else (0.0, 1.0, 0.5))
    return Collider(kind, friction=friction, angular_velocity=spin, boundary="elastic" if elastic else "slip",
                    **shapes[kind])


def scene(case: Case, dim: int) -> mpm.Scene:
    n = len(case.materials)
    centres = [0.5] if n == 1 else list(np.linspace(0.35, 0.65, n))
    bodies = [mpm.Body(mpm.Sphere((x,) + (0.5,) * (dim - 1), 0.1), mpm.MATERIALS[m]())
              for x, m in zip(centres, case.materials)]
    walls = ("slip",) * (2 * dim)
    if case.open_walls:
        walls = ("open", "sticky", "slip", "open", "slip", "open")[:2 * dim]
    regions = []
    if case.regions:
        regions = [mpm.KinematicRegion(body=0, select=mpm.Box((centres[0],) + (0.5,) * (dim - 1), (0.05,) * dim),
                                       velocity=(0.1,) + (0.0,) * (dim - 1))]
    colliders = [_collider(k, dim, 0.3 if case.friction and i == 0 else 0.0, case.turning and i == 0,
                           case.elastic and i == 0) for i, k in enumerate(case.colliders)]
    rigid = []
    if case.rigid:
        at = (lambda *c: tuple(c[:dim]))  # noqa: E731
        rigid = [mpm.RigidBody(Collider.box(at(0.3, 0.8, 0.5), at(0.05, 0.05, 0.05)), density=500.0),
                 mpm.RigidBody(Collider.sphere(at(0.7, 0.8, 0.5), 0.05, friction=0.3), density=500.0)]
        if dim == 3:
            rigid.append(mpm.RigidBody(Collider.cylinder((0.5, 0.8, 0.3), 0.05, 0.05, axis=0), mass=0.1))
    joints = [mpm.Joint(0, (0.3, 0.7, 0.5)[:dim], axis=None if dim == 2 else (0.0, 0.0, 1.0))] if case.joints else []
    loads = []
    if case.loads:
        c, f = (centres[0],) + (0.5,) * (dim - 1), (0.0, -1.0, 0.0)[:dim]
        loads = [Load("point", f, at=c, count=2), Load("body", f, ramp=0.1),
                 Load("traction", f, select=mpm.Box(c, (0.2,) * dim), normal=(1.0,) + (0.0,) * (dim - 1),
                      table=((0.0, 0.0), (0.1, 1.0), (0.2, 0.5)))]
    return mpm.Scene(dim=dim, domain=(1.0,) * dim, resolution=16, ppc=1, bodies=bodies,
                     gravity=(0.0, -9.81, 0.0)[:dim], walls=walls, contact=case.contact,
                     contact_friction=case.contact_friction, contact_normal=case.normal, regions=regions,
                     colliders=colliders, solution=_Forcing() if case.forcing else None, loads=loads,
                     boundary_rule=case.rule, rigid_bodies=rigid, joints=joints)


def scheme(case: Case):
    return {"empm": mpm.EMPM, "tlmpm": mpm.TLMPM, "aulmpm": mpm.AULMPM,
            "aulmpm_paper": lambda: mpm.AULMPM(criterion="paper", affine="keep"),
            "aulmpm_transform": lambda: mpm.AULMPM(affine="transform")}[case.scheme]()


def driver(case: Case, dim: int, precision: str) -> mpm.Driver:
    """The case's solver and the driver that steps it (its policy on the device)."""
    model, state = mpm.build(scene(case, dim), mpm.KERNELS[case.kernel], precision, "cpu")
    integrator = mpm.Implicit(psd=case.psd) if case.implicit else mpm.Explicit()
    options = mpm.SolverOptions(transfer=case.transfer, integrator=integrator, fuse=case.fuse,
                                record_dJ=case.record_dJ, track_energy=case.track_energy, track_J=case.track_J,
                                batched=case.batched, compensate=case.compensate)
    solver = mpm.Solver(model, scheme(case), options)
    detect = case.detect or ("stop" if case.track_energy else "off")
    return mpm.Driver(solver, state, mpm.StepPolicy(steps=1), mpm.Detection(action=detect),
                      sync_every=10 if case.batched else 1, measure=case.measure)


def kinds(dim: int) -> tuple[str, ...]:
    """The collider kinds of a dimension (mesh colliders are 3D only)."""
    return tuple(k for k in KINDS if dim == 3 or k != "mesh")


def cases(dim: int) -> list[Case]:
    """The solvers whose kernels are compiled (see the module docstring)."""
    materials = list(mpm.MATERIALS)
    two = ("fixed_corotated", "fluid")  # two bodies, two projections
    # every kernel with every transfer, with the stencils cached (total or adaptive
    # Lagrangian); the materials take turns
    out = [Case(scheme=("tlmpm", "aulmpm")[i % 2], kernel=k, transfer=tr, materials=(materials[i % 9],))
           for i, (k, tr) in enumerate(itertools.product(mpm.KERNELS, TRANSFERS))]
    # every kernel Eulerian with the stencils located in the transfers (a plastic model's
    # return mapping at F^sn = I, G2P committing the update, a fluid's projection), and
    # implicit: MLS with a per-particle and a constant moment, the kernel gradient
    for k, tr, m in [("linear", "mls", "snow"), ("quadratic", "apic", "fluid"), ("cubic", "pic", "fixed_corotated"),
                     ("compact", "mls", "viscoplastic")]:
        out.append(Case(kernel=k, transfer=tr, fuse=True, materials=(m,)))
    for k, tr in [("linear", "pic"), ("quadratic", "apic"), ("cubic", "mls"), ("compact", "mls")]:
        out.append(Case(scheme="tlmpm", kernel=k, transfer=tr, implicit=True))
    # every material implicit; the options; all on the linear kernel, the quickest to
    # compile (their code does not depend on the kernel)
    out += [Case(materials=(m,), transfer=TRANSFERS[i % len(TRANSFERS)], implicit=True) for i, m in enumerate(materials)]
    out += [
        Case(), Case(scheme="aulmpm_paper"), Case(scheme="aulmpm_transform"),
        Case(scheme="tlmpm", implicit=True, psd=False),
        # contact between bodies
        Case(materials=two), Case(materials=two, fuse=True), Case(scheme="tlmpm", materials=two),
        Case(materials=two, contact="shared"), Case(scheme="tlmpm", materials=two, contact="none"),
        Case(scheme="tlmpm", materials=two, implicit=True), Case(materials=two, implicit=True),
        # with Coulomb friction: explicit (binned and gathered), implicit, in batches; each normal rule
        Case(materials=two, contact="friction", contact_friction=0.3, normal="max_gradient"),
        Case(scheme="tlmpm", materials=two, contact="friction", contact_friction=0.3),
        Case(scheme="tlmpm", materials=two, contact="friction", contact_friction=0.3, normal="max_gradient"),
        Case(scheme="tlmpm", materials=two, implicit=True, contact="friction", contact_friction=0.3),
        Case(materials=two, implicit=True, contact="friction", contact_friction=0.3, normal="max_gradient"),
        Case(scheme="tlmpm", materials=two, contact="friction", contact_friction=0.3, normal="stiffer"),
        Case(materials=two, implicit=True, contact="friction", contact_friction=0.3, normal="stiffer"),
        Case(batched=True, materials=two, contact="friction", contact_friction=0.3),
        # springs between the bodies' particles (mpm.body_springs), with loads, in batches
        Case(materials=two, contact="elastic", contact_friction=0.3, loads=True),
        Case(batched=True, scheme="tlmpm", materials=two, contact="elastic"),
        # kinematic regions
        Case(regions=True), Case(scheme="tlmpm", regions=True), Case(materials=two, regions=True),
        Case(scheme="tlmpm", regions=True, implicit=True),
        # open walls, the solver's options, a manufactured solution's body force
        Case(open_walls=True, fuse=True), Case(scheme="tlmpm", open_walls=True),
        Case(record_dJ=True, track_energy=True, track_J=True, fuse=True),
        Case(scheme="tlmpm", record_dJ=True, track_energy=True, track_J=True),
        Case(forcing=True), Case(scheme="tlmpm", materials=("neo_hookean",), forcing=True),
        # compensated sums: of F^sn (restarted by the update), of F^0s in the Eulerian commit, in batches
        Case(scheme="tlmpm", compensate=True), Case(compensate=True), Case(kernel="compact", compensate=True),
        Case(batched=True, scheme="aulmpm", compensate=True),
        # external loads: explicit, implicit, in batches
        Case(loads=True), Case(scheme="tlmpm", loads=True, implicit=True), Case(batched=True, loads=True),
        # the driver: its detection warning or off; steps in batches (every stage's early exits,
        # the device's configuration updates, its diagnostics), Eulerian fused and cached,
        # Lagrangian, with contact, regions, colliders and open walls
        Case(detect="warn", track_energy=True, measure=True), Case(scheme="tlmpm", detect="off"),
        Case(batched=True, fuse=True, track_energy=True, measure=True), Case(batched=True, kernel="compact", measure=True),
        Case(batched=True, scheme="aulmpm", materials=("fluid",)), Case(batched=True, scheme="aulmpm_paper", track_energy=True),
        Case(batched=True, scheme="aulmpm_transform"),
        Case(batched=True, scheme="tlmpm", detect="warn", track_energy=True), Case(batched=True, scheme="tlmpm", detect="off"),
        Case(batched=True, materials=two, measure=True), Case(batched=True, materials=two, contact="shared"),
        Case(batched=True, scheme="tlmpm", materials=two, regions=True, colliders=kinds(dim)),
        Case(batched=True, scheme="tlmpm", open_walls=True, record_dJ=True, track_energy=True, track_J=True),
        Case(batched=True, open_walls=True, fuse=True, colliders=kinds(dim)),
    ]
    # colliders, all kinds together with friction and without: in the grid update, after
    # contact, as constraints of the implicit solve; each kind alone
    every = kinds(dim)
    for friction in (False, True):
        out += [Case(colliders=every, friction=friction), Case(materials=two, colliders=every, friction=friction),
                Case(scheme="tlmpm", colliders=every, friction=friction, implicit=True)]
    out += [Case(colliders=(k,)) for k in every]
    # a turning collider among them (the rotation compiled: the kinds end with TURNING)
    out += [Case(colliders=every, friction=True, turning=True), Case(colliders=every, friction=True, rigid=True),
            Case(rigid=True), Case(batched=True, rigid=True), Case(rigid=True, joints=True),
            Case(colliders=every, friction=True, rigid=True, implicit=True),
            Case(scheme="tlmpm", colliders=every, friction=True, implicit=True, turning=True)]
    # an elastic collider among them: its springs on the particles, alone, with loads, turning, with rigid bodies
    out += [Case(colliders=every, friction=True, elastic=True), Case(colliders=every, elastic=True, loads=True),
            Case(scheme="tlmpm", colliders=every, friction=True, turning=True, elastic=True, batched=True),
            Case(colliders=every, friction=True, rigid=True, elastic=True)]
    # the node rule of earlier versions (walls and colliders on the nodes inside them)
    out += [Case(rule="nodes", colliders=every, friction=True), Case(rule="nodes", materials=two, colliders=every),
            Case(rule="nodes", scheme="tlmpm", colliders=every, friction=True, implicit=True),
            Case(rule="nodes", colliders=every, friction=True, rigid=True, implicit=True)]
    return out


# ------------------------------------------------------------------ specialisations
@functools.cache
def specialisations(dim: int, precision: str) -> dict:
    """(factory, arguments) -> kernels, for every case and the material-point
    driver (every material) in one dimension and precision; checks on the way
    that every kernel a solver uses was recorded."""
    calls: dict = {}
    unrecorded = []
    with recording(calls):
        for case in cases(dim):
            d = driver(case, dim, precision)
            known = {id(k) for ks in calls.values() for k in ks}
            unrecorded += [f"{kernel_name(k)} ({case.label()})" for k in d.kernels() if id(k) not in known]
        for cls in mpm.MATERIALS.values():
            MaterialPoint(cls(), dim, precision)
    assert not unrecorded, f"kernels built outside the recorded factories: {unrecorded}"
    return calls


def describe(value) -> str:
    if isinstance(value, Types):
        return f"{value.dim}D {value.precision}"
    if isinstance(value, Kernel):
        return value.name
    if isinstance(value, tuple):
        return "+".join(value) or "none"
    if inspect.isclass(value):
        return value.__name__
    if callable(value):
        return getattr(value, "__qualname__", repr(value))
    return repr(value)


def _short(factory: str) -> str:
    return factory.split(".")[-1]


def call_name(factory: str, args) -> str:
    return f"{_short(factory)}({', '.join(f'{k}={describe(v)}' for k, v in args)})"


# factories whose code depends on the interpolation kernel and the transfer together
PAIRWISE = ("_make_p2g", "make_g2p")


def required(factory: str, parameter: inspect.Parameter, t: Types) -> set:
    """The values an argument must take in dimension and precision ``t``:
    every value it can take, except that a kernel's collider kinds are none
    and all, with and without TURNING (each kind alone only where the signed
    distance is all a kernel evaluates, ``make_inside_count``, which is
    built only with colliders)."""
    name, annotation = parameter.name, str(parameter.annotation)
    if name == "t":
        return {t}
    if name == "kernel":
        return set(mpm.KERNELS.values())
    if name == "transfer":
        return set(TRANSFERS)
    if name in ("material", "cls"):
        return set(mpm.MATERIALS.values())
    if name == "project":
        return {None} | {cls.project for cls in mpm.MATERIALS.values() if cls.project is not None}
    if name == "colliders":
        return {(), kinds(t.dim), kinds(t.dim) + (TURNING,)}
    if name == "elastic_kinds":  # the springs of elastic colliders (mpm.elastic_contact)
        return {kinds(t.dim) + (ELASTIC,), kinds(t.dim) + (TURNING, ELASTIC), kinds(t.dim) + (TURNING, ELASTIC, RIGID)}
    if name == "kinds":
        return {kinds(t.dim), kinds(t.dim) + (TURNING,)} | {(k,) for k in kinds(t.dim)}
    if name == "n_grids":
        return {k.n_grids for k in mpm.KERNELS.values()}
    if name == "dim":
        return {t.dim}
    if name == "n_bodies":  # the per-body loops of the criterion and the policy: one body and several
        return {1, 2}
    if name == "affine":  # C over a configuration update
        return set(mpm.schemes.AFFINE)
    if name == "normal":  # the contact's normals
        return set(mpm.CONTACT_NORMALS)
    if name == "kind":  # the scheme's update rule (mpm.schemes.rule_kind)
        return {"always", "never", "paper", "distortion"}
    if name == "rule":  # where walls and colliders act
        return set(mpm.scene.BOUNDARY_RULES)
    if name == "compensated":  # the factor of F whose sum G2P compensates (mpm.p2g's exact energy)
        return {"", "sn", "0s"}
    if name == "first":  # the first rigid body's collider: none before it, and after every kind
        return {0, len(kinds(t.dim))}
    if parameter.annotation in (bool, "bool") or isinstance(parameter.default, bool):
        return {False, True}
    raise AssertionError(f"{factory}: no values known for argument {name!r} ({annotation}); "
                         "add them to required() in tests/mpm/test_cuda_codegen.py")


TYPES = [make_types(d, p) for d in DIMS for p in PRECISIONS]


def _id(t: Types) -> str:
    return f"{t.dim}D-{t.precision}"


@pytest.mark.slow
@pytest.mark.parametrize("t", TYPES, ids=_id)
def test_cases_reach_every_specialisation(t):
    """Per dimension and precision, every kernel factory is called with each
    required value of each of its arguments (:func:`required`), the
    transfers with every pair of interpolation kernel and transfer, and
    every kernel a solver uses comes from a factory."""
    calls = specialisations(t.dim, t.precision)
    missing = [f"{name}: no such kernel factory" for name in PAIRWISE if name not in map(_short, FACTORIES)]
    for factory in FACTORIES:
        made = [dict(args) for (f, args) in calls if f == factory]
        if not made:
            missing.append(f"{factory}: never called")
            continue
        for parameter in inspect.signature(FACTORIES[factory].__wrapped__).parameters.values():
            lacking = required(factory, parameter, t) - {a[parameter.name] for a in made}
            if lacking:
                missing.append(f"{factory}({parameter.name}): {sorted(map(describe, lacking))}")
        if _short(factory) in PAIRWISE:
            lacking = set(itertools.product(mpm.KERNELS, TRANSFERS)) - {(a["kernel"].name, a["transfer"]) for a in made}
            if lacking:
                missing.append(f"{factory}: (kernel, transfer) {sorted(lacking)}")
    assert not missing, "never reached:\n" + "\n".join(missing)


# ------------------------------------------------------------------ compilation
def _with_kernel(factory: str) -> bool:
    return "kernel" in inspect.signature(FACTORIES[factory].__wrapped__).parameters


# heaviest first (the implicit integrator's particle kernels in 3D), so that
# pytest-xdist does not leave one for the end
ORDER = ["make_evaluate", "_make_p2g", "make_g2p", "make_apply", "make_update"]
GROUPS = [pytest.param(t, factory, kernel, id="-".join([_id(t), _short(factory)] + [kernel] * bool(kernel)))
          for t in sorted(TYPES, key=lambda t: -t.dim)
          for factory in sorted(FACTORIES, key=lambda f: ORDER.index(_short(f)) if _short(f) in ORDER else len(ORDER))
          for kernel in (mpm.KERNELS if _with_kernel(factory) else [None])]


@pytest.fixture(scope="session")
def ptx_dir():
    """Where the PTX goes: beside Warp's kernel cache, where Warp skips a
    module whose PTX and meta file for the same hash (of its generated code
    and options) are already there, as it does for the CPU."""
    wp.init()
    directory = Path(wp.config.kernel_cache_dir) / f"aot_sm{ARCH}"
    directory.mkdir(parents=True, exist_ok=True)
    return directory


_compiled: set[str] = set()  # module identifiers compiled in this process


class CompileError(Exception):
    pass


def compile_module(kernel, directory) -> str:
    """PTX for sm_90 of the kernel's module (once per process); its identifier."""
    module = kernel.module
    ident = module.get_module_identifier()
    if ident in _compiled:
        return ident
    try:
        paths = wp.compile_aot_module(module, device=None, arch=ARCH, use_ptx=True, module_dir=directory)
    except Exception as e:
        raise CompileError(f"{kernel_name(kernel)} (module {ident}) does not compile for sm_{ARCH}: {e}") from e
    _compiled.add(ident)
    ptx = paths[-1].read_text()
    assert f".target sm_{ARCH}" in ptx and kernel.get_mangled_name() in ptx, f"{ident}: no sm_{ARCH} entry point"
    return ident


needs_nvrtc = pytest.mark.skipif(ARCH not in wp.get_cuda_supported_archs(),
                                 reason=f"this Warp build cannot compile for sm_{ARCH} (no NVRTC)")


@pytest.mark.slow
@needs_nvrtc
@pytest.mark.parametrize("t,factory,kernel", GROUPS)
def test_compiles_for_sm90(t, factory, kernel, ptx_dir, capfd):
    """Every distinct module of ``factory`` (with interpolation kernel
    ``kernel``) in dimension and precision ``t`` compiles for sm_90 PTX."""
    calls = specialisations(t.dim, t.precision)
    selected = {}
    for (f, args), kernels in calls.items():
        a = dict(args)
        if f == factory and (kernel is None or a["kernel"].name == kernel):
            for k in kernels:
                selected.setdefault(id(k), (k, call_name(f, args)))
    assert selected, f"{factory} is never called with kernel {kernel}"
    failures = []
    for k, call in selected.values():
        capfd.readouterr()
        try:
            compile_module(k, ptx_dir)
        except CompileError as e:
            failures.append(f"{e}\n  built by {call}\n{capfd.readouterr().err.strip()}")  # NVRTC's log
    assert not failures, "\n\n".join(failures)


def _broken_kernel():
    """A kernel that compiles for the CPU but not for CUDA."""
    snippet = """
    #if defined(__CUDA_ARCH__)
        not_a_cuda_function(x);
    #endif
        return x;
    """

    @wp.func_native(snippet)
    def identity(x: float) -> float: ...

    @wp.kernel(enable_backward=False, module="unique")
    def cuda_only_error(y: wp.array(dtype=float)):
        i = wp.tid()
        y[i] = identity(y[i])

    return cuda_only_error


@needs_nvrtc
def test_cuda_only_error_fails_with_its_name(tmp_path, capfd):
    """The check can fail: a kernel whose error only CUDA sees fails to
    compile for sm_90, and the error names the kernel and its module."""
    k = _broken_kernel()
    with pytest.raises(CompileError, match=r"cuda_only_error \(module wp_\w*cuda_only_error_\w+\)"):
        compile_module(k, tmp_path)
    assert "not_a_cuda_function" in capfd.readouterr().err  # NVRTC's log


@pytest.mark.slow
@needs_nvrtc
def test_cpu_load_after_aot(tmp_path):
    """Compiling for sm_90 leaves the CPU path as it was: the same modules
    then load on the CPU (``Solver.load``, ``wp.force_load``) and a step runs."""
    case = Case(scheme="tlmpm", regions=True)
    model, state = mpm.build(scene(case, 2), mpm.KERNELS[case.kernel], "float32", "cpu")
    s = mpm.Solver(model, scheme(case))
    for k in s.kernels():
        compile_module(k, tmp_path)
    s.load()
    s.prepare(state)
    report = s.advance(state, 1e-4)
    assert report.reason is None and report.max_speed > 0.0
