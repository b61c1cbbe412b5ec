"""Materials and kernels defined outside ``mpm`` (docs/extending.md,
examples/my_models.py): the copies of neo_hookean and the quadratic B-spline
give the built-ins' bits; registration checks what it is given and says what
is wrong in one line; the guide quotes the example file it describes.

Every test leaves the registries as it found them (the example registers at
import, and other tests enumerate mpm.MATERIALS and mpm.KERNELS)."""

import dataclasses
import importlib
import re
import sys
from pathlib import Path

import pytest
import warp as wp

import mpm
from mpm.kernels import KERNELS, register_kernel
from mpm.materials import MATERIALS, register_material
from mpm.params import param

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = "examples.my_models"  # the name the command line imports it by (from the checkout's root)


@pytest.fixture(autouse=True)
def registries():
    saved = dict(MATERIALS), dict(KERNELS)
    yield
    for registry, before in zip((MATERIALS, KERNELS), saved):
        registry.clear()
        registry.update(before)
    sys.modules.pop(EXAMPLE, None)  # imported afresh (and registered) by the next test that needs it


@pytest.fixture
def example():
    return importlib.import_module(EXAMPLE)


@pytest.mark.bitwise
def test_the_copies_give_the_built_ins_bits(example, device):
    """48 steps of a disc bouncing off the floor (|F - I| reaches 0.4) with
    my_neo_hookean and with my_quadratic: positions, velocities, affine
    matrices and deformation gradients equal the built-ins' bit for bit."""
    assert example.compare(steps=48, resolution=24, device=device) == {"my_neo_hookean": [], "my_quadratic": []}


def test_the_example_registers_its_copies_once(example):
    assert MATERIALS["my_neo_hookean"] is example.MyNeoHookean
    assert KERNELS["my_quadratic"] is example.MY_QUADRATIC
    before = dict(MATERIALS), dict(KERNELS)
    assert register_material(example.MyNeoHookean) is example.MyNeoHookean  # again: nothing changes
    assert register_kernel(example.MY_QUADRATIC) is example.MY_QUADRATIC
    assert (dict(MATERIALS), dict(KERNELS)) == before
    assert list(MATERIALS)[:9] == ["fixed_corotated", "neo_hookean", "fluid", "viscous", "snow", "sand",
                                   "von_mises", "nacc", "viscoplastic"]


def _material(example, name="bad", base=None, **attrs):
    """A dataclass material like the example's, with ``attrs`` changed."""
    cls = type("Bad", (base or example.MyNeoHookean,), {"name": name, **attrs})
    return dataclasses.dataclass(cls)


def _string_annotation(t):
    @wp.func
    def stress_energy(F: "t.mat", L: "t.mat", params: "t.params"):  # noqa: F821 - as with annotations postponed
        return F, F[0, 0]

    return stress_energy


BAD_MATERIALS = [
    (lambda ex: int, "not a subclass of mpm.Material"),
    (lambda ex: _material(ex, ""), "name ''; accepted: a class attribute name"),
    (lambda ex: _material(ex, "a-b"), "name 'a-b'"),
    (lambda ex: _material(ex, "neo_hookean"),
     "name 'neo_hookean' is taken by mpm.materials.neo_hookean.NeoHookean; accepted: a name not in"),
    (lambda ex: _material(ex, base=mpm.Material), "stress_energy, principal missing or not callable"),
    (lambda ex: _material(ex, principal=None), "principal missing or not callable"),
    (lambda ex: _material(ex, stress_energy=staticmethod(_string_annotation)),
     "stress_energy(types) fails (NameError: name 't' is not defined); a file that defines Warp functions cannot "
     "use `from __future__ import annotations`"),
    (lambda ex: _material(ex, principal=staticmethod(lambda t: None)),
     "principal(types) gives a NoneType; accepted: a Warp function"),
    (lambda ex: _material(ex, packed=lambda self: (1.0,) * 9),
     "packed() gives 9 values; accepted: at most N_MATERIAL_PARAMS = 8"),
    (lambda ex: _material(ex, base=mpm.Material, stress_energy=ex.MyNeoHookean.stress_energy,
                          principal=ex.MyNeoHookean.principal), "packed() is not defined"),
    (lambda ex: _material(ex, wave_speed=lambda self, J=1.0: 0.0), "wave_speed() = 0.0; accepted: a finite speed > 0"),
    (lambda ex: _material(ex, viscosity_param=2), "viscosity_param 2; accepted: None or an index into packed()"),
    (lambda ex: _material(ex, plastic=True), "plastic = True in a class that is not an mpm.materials.Plastic"),
    (lambda ex: type("Bad", (ex.MyNeoHookean,), {"name": "bad", "__annotations__": {"K": float}, "K": 1.0}),
     "K: not dataclass fields; accepted: the class decorated with @dataclasses.dataclass"),
    (lambda ex: dataclasses.dataclass(type("Bad", (ex.MyNeoHookean,), {
        "name": "bad", "__annotations__": {"K": float}, "K": dataclasses.field(kw_only=True)})),
     "cannot be made from its defaults (TypeError: "),
]


@pytest.mark.parametrize("make, message", BAD_MATERIALS, ids=[m for _, m in BAD_MATERIALS])
def test_a_bad_material_is_refused_in_one_line(example, make, message):
    cls = make(example)
    before = dict(MATERIALS)
    with pytest.raises(ValueError) as e:
        register_material(cls)
    text = str(e.value)
    assert "\n" not in text and message in text, text
    assert text.startswith("material ")
    assert dict(MATERIALS) == before


def test_the_decorator_and_a_reloaded_class(example):
    def define():  # the same module and qualified name each time: a reloaded module's class
        @register_material()
        @dataclasses.dataclass
        class Stiffer(example.MyNeoHookean):
            name = "stiffer"
            E: float = param(1.0e7, "Young's modulus [Pa]", gt=0.0)

        return Stiffer

    first, second = define(), define()
    assert first is not second and MATERIALS["stiffer"] is second and second().E == 1.0e7


def _kernel(example, **changes):
    return dataclasses.replace(example.MY_QUADRATIC, **{"name": "bad", **changes})


BAD_KERNELS = [
    (lambda ex: object(), "not an mpm.Kernel (object)"),
    (lambda ex: _kernel(ex, name="quadratic"), "kernel quadratic: name 'quadratic' is taken by "
                                               "mpm.kernels.quadratic.QUADRATIC; accepted: a name not in"),
    (lambda ex: _kernel(ex, name=""), "name ''"),
    (lambda ex: _kernel(ex, support=0), "support 0; accepted: an integer >= 1"),
    (lambda ex: _kernel(ex, moment=-1.0), "moment -1.0"),
    (lambda ex: _kernel(ex, margin=float("nan")), "margin nan"),
    (lambda ex: _kernel(ex, grids=[0.0]), "grids [0.0]; accepted: a non-empty tuple"),
    (lambda ex: _kernel(ex, gradients=None), "gradients missing or not callable"),
    (lambda ex: _kernel(ex, phase=ex.my_weights), "phase given; accepted: phase, weights_at and gradients_at"),
    (lambda ex: _kernel(ex, weights=lambda t: 1.0), "weights(types) gives a float; accepted: a Warp function"),
]


@pytest.mark.parametrize("make, message", BAD_KERNELS, ids=[m for _, m in BAD_KERNELS])
def test_a_bad_kernel_is_refused_in_one_line(example, make, message):
    kernel = make(example)
    before = dict(KERNELS)
    with pytest.raises(ValueError) as e:
        register_kernel(kernel)
    text = str(e.value)
    assert "\n" not in text and message in text, text
    assert dict(KERNELS) == before


def test_registering_compiles_nothing(example, monkeypatch):
    """Registration calls a model's and a kernel's factories (Warp functions
    are made) but loads no Warp module: they compile in a run that uses them."""
    loads = []
    real = type(wp.get_module(EXAMPLE)).load

    def counted(module, *args, **kwargs):
        loads.append(module.name)
        return real(module, *args, **kwargs)

    monkeypatch.setattr(type(wp.get_module(EXAMPLE)), "load", counted)
    reloaded = importlib.reload(example)  # a reloaded module's classes replace their earlier selves
    assert MATERIALS["my_neo_hookean"] is reloaded.MyNeoHookean and KERNELS["my_quadratic"] is reloaded.MY_QUADRATIC
    assert loads == []


def test_the_guide_quotes_the_example_file():
    """Every Python block of docs/extending.md is a verbatim part of
    examples/my_models.py (the file the tests above run), and every
    ``examples.my_models.<name>`` its commands name exists there; the guide is
    linked from the user guide's index and from the library page."""
    guide = (ROOT / "docs" / "extending.md").read_text()
    source = (ROOT / "examples" / "my_models.py").read_text()
    blocks = re.findall(r"```python\n(.*?)```", guide, re.S)
    assert len(blocks) >= 4
    for block in blocks:
        assert block in source, block
    module = importlib.import_module(EXAMPLE)
    names = set(re.findall(r"examples\.my_models\.(\w+)", guide))
    assert {"MyNeoHookean", "MY_QUADRATIC"} <= names
    assert all(hasattr(module, n) for n in names - {"nosuch"}), names
    for page in ("README.md", "library.md"):
        assert "(extending.md)" in (ROOT / "docs" / page).read_text(), page
