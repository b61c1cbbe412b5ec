"""What the registries and a run's provenance know of models defined outside
``mpm`` (mpm.kernels.registry, mpm.materials.registry, mpm.factories,
pipelines.config.plugins): a copy of a built-in kernel is the user's, a
built-in's name cannot be taken over, the config hash follows the modules a
plugin uses, and a factory broken in 3D, in float64 or returning the wrong
number of values is refused when registered, in one line naming it."""

from __future__ import annotations

import dataclasses
import importlib
import sys

import pytest

import mpm
from mpm.kernels import KERNELS, register_kernel
from mpm.materials import register_material
from pipelines.config import plugins

HELPER = """
def shear_modulus_factor():
    return {factor}
"""

PLUGIN = '''
import dataclasses
import functools

import warp as wp

import mpm
from mpm.materials import register_material
from mpm.materials.neo_hookean import NeoHookean

import {helper}


@dataclasses.dataclass
class Scaled(NeoHookean):
    name = "{name}"

    def packed(self):
        mu, lam = super().packed()
        return (mu * {helper}.shear_modulus_factor(), lam)


Q2 = dataclasses.replace(mpm.QUADRATIC, name="{kernel}", margin=2.0)


@functools.cache
def three_values(t):
    S = t.scalar

    @wp.func
    def stress_energy(F: t.mat, L: t.mat, params: t.params):
        return F, S(0.0), S(1.0)

    return stress_energy


@dataclasses.dataclass
class ThreeValues(NeoHookean):
    name = "{name}_three"
    stress_energy = staticmethod(three_values)


@functools.cache
def planar_only(t):
    if t.dim == 3:
        raise ValueError("only 2D")
    return mpm.QUADRATIC.weights(t)


PLANAR = dataclasses.replace(mpm.QUADRATIC, name="{kernel}_planar", weights=planar_only)


@functools.cache
def single_only(t):
    if t.precision == "float64":
        raise ValueError("float32 only")
    return mpm.QUADRATIC.weights(t)


SINGLE = dataclasses.replace(mpm.QUADRATIC, name="{kernel}_single", weights=single_only)
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """A plugin module (and the helper module it imports) written to a
    folder on sys.path under names of its own; ``write(factor)`` rewrites
    the helper."""
    tag = tmp_path.name.replace("-", "_")[-24:]
    names = {"helper": f"helper_{tag}", "name": f"scaled_{tag}", "kernel": f"q2_{tag}"}
    folder = tmp_path / "plug"
    folder.mkdir()
    monkeypatch.syspath_prepend(str(folder))
    module = f"plugin_{tag}"
    (folder / f"{module}.py").write_text(PLUGIN.format(**names))

    def write(factor):
        (folder / f"{names['helper']}.py").write_text(HELPER.format(factor=factor))
        importlib.invalidate_caches()
        sys.modules.pop(names["helper"], None)
        sys.modules.pop(module, None)
        return importlib.import_module(module)

    yield write, module, names
    for name in (module, names["helper"]):
        sys.modules.pop(name, None)
    for registry in (mpm.MATERIALS, KERNELS):  # the registries are the process's: leave them as found
        for name in [n for n in registry if tag in n]:
            del registry[name]
    for group in plugins.GROUPS:
        for path in [p for p in plugins.ALIASES[group] if p.startswith(module + ".")]:
            del plugins.ALIASES[group][path]


def scene(material) -> mpm.Scene:
    return mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16,
                     bodies=[mpm.Body(mpm.Box((0.5, 0.5), (0.1, 0.1)), material)])


def test_a_built_in_kernels_name_cannot_be_taken_by_a_copy():
    """register_kernel of a copy of mpm.QUADRATIC under its own name (whose
    weights are defined where the built-in's are) is refused in one line;
    the built-in stays (it replaced it silently for the process before)."""
    copy = dataclasses.replace(mpm.QUADRATIC, margin=2.0)
    with pytest.raises(ValueError) as caught:
        register_kernel(copy)
    assert "\n" not in str(caught.value) and "name 'quadratic' is taken by" in str(caught.value)
    assert KERNELS["quadratic"] is mpm.QUADRATIC


def test_a_copy_of_a_built_in_kernel_is_recorded_and_hashed(plugin):
    """``kernel=<module>.Q2`` (dataclasses.replace(mpm.QUADRATIC, name=...,
    margin=2.0)) is the user's: the run's provenance names the module that
    holds it, and the config hash takes its parameters (two margins, two
    hashes) and its module's file (it counted as built in, and escaped both)."""
    write, module, names = plugin
    loaded = write(1.0)
    assert plugins.resolve("kernel", f"{module}.Q2") == names["kernel"]
    s = scene(mpm.FixedCorotated(E=1e4))
    assert plugins.origins(s, loaded.Q2) == {f"kernel {names['kernel']}": f"{module}.Q2"}
    first = plugins.sources(s, loaded.Q2)
    assert f"module {module}" in first and f"kernel {names['kernel']}" in first
    other = dataclasses.replace(loaded.Q2, margin=3.0)
    assert plugins.sources(s, other)[f"kernel {names['kernel']}"] != first[f"kernel {names['kernel']}"]
    assert plugins.origins(s, mpm.QUADRATIC) == {} and plugins.sources(s, mpm.QUADRATIC) == {}


def test_the_hash_follows_the_modules_a_plugin_imports(plugin):
    """A material whose module imports a helper module of the user's: the
    run's sources hash both files, and editing the helper alone changes the
    hash (only the defining file was hashed: a sweep reused a stale result)."""
    write, module, names = plugin
    loaded = write(1.0)
    assert plugins.resolve("material", f"{module}.Scaled") == names["name"]
    s = scene(loaded.Scaled(E=1e4))
    before = plugins.sources(s, mpm.QUADRATIC)
    assert set(before) == {f"module {module}", f"module {names['helper']}"}
    loaded = write(2.0)
    after = plugins.sources(scene(loaded.Scaled(E=1e4)), mpm.QUADRATIC)
    assert after[f"module {module}"] == before[f"module {module}"]
    assert after[f"module {names['helper']}"] != before[f"module {names['helper']}"]


@pytest.mark.parametrize("attribute,said", [
    ("ThreeValues", "stress_energy(types) gives a Warp function returning 3 value(s); accepted: 2 (P, psi)"),
    ("PLANAR", "weights(types) fails in 3D float32 (ValueError: only 2D)"),
    ("SINGLE", "weights(types) fails in 2D float64 (ValueError: float32 only)"),
])
def test_a_factory_broken_in_3d_float64_or_its_return_count_is_refused_when_registered(plugin, attribute, said):
    """Factories are called for 2D and 3D in float32 and float64 and their
    functions' return statements counted: each mistake is one line naming
    the class or kernel when registered (a material returning three values
    failed at the first step with a 96-line Warp error that never named it;
    a 3D-only or float64-only failure registered and failed in the run)."""
    write, module, _ = plugin
    obj = getattr(write(1.0), attribute)
    with pytest.raises(ValueError) as caught:
        register_material(obj) if isinstance(obj, type) else register_kernel(obj)
    message = str(caught.value)
    assert "\n" not in message and said in message, message
    assert message.startswith(("material ", "kernel ")) and (module in message or obj.name in message), message


def test_the_built_in_models_pass_every_check():
    """No built-in model or kernel trips the checks (every type, return counts)."""
    from mpm.kernels.registry import kernel_problem
    from mpm.materials.registry import material_problem
    for cls in mpm.MATERIALS.values():
        assert material_problem(cls) is None, cls
    for kernel in KERNELS.values():
        assert kernel_problem(kernel) is None, kernel.name
