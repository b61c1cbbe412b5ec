"""The public API (``mpm.__all__``): every name is there after ``import mpm``
and documented (a docstring of its own; for a dataclass, every field
documented; for a constant, the string literal that follows its
assignment), and the code blocks of docs/library.md run as written."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import importlib.util
import inspect
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import pytest

import mpm

ROOT = Path(__file__).resolve().parents[2]


def own_doc(obj) -> str:
    """The object's own docstring: a class's from its body (a dataclass without
    one gets its signature as __doc__, which documents nothing)."""
    if inspect.isclass(obj):
        doc = vars(obj).get("__doc__") or ""
        return "" if doc.startswith(f"{obj.__name__}(") else doc
    return getattr(obj, "__doc__", None) or ""


def attribute_docs(tree: ast.AST) -> dict[str, str]:
    """name -> the string literal right after ``name = ...`` / ``name: T = ...``
    among the statements of a module or class body."""
    out = {}
    body = tree.body
    for a, b in zip(body, body[1:]):
        target = (a.targets[0] if isinstance(a, ast.Assign) and len(a.targets) == 1 else
                  a.target if isinstance(a, ast.AnnAssign) else None)
        if isinstance(target, ast.Name) and isinstance(b, ast.Expr) and isinstance(b.value, ast.Constant) \
                and isinstance(b.value.value, str):
            out[target.id] = b.value.value
    return out


def constant_doc(obj) -> str:
    """The attribute docstring of a constant, found in the mpm module that defines it."""
    for info in pkgutil.walk_packages(mpm.__path__, "mpm."):
        module = importlib.import_module(info.name)
        names = [n for n, v in vars(module).items() if v is obj and not n.startswith("_")]
        if not names:
            continue
        docs = attribute_docs(ast.parse(inspect.getsource(module)))
        for n in names:
            if docs.get(n):
                return docs[n]
    return ""


def field_docs(cls) -> dict[str, bool]:
    """field -> documented (param metadata, an attribute docstring, or named as
    ``field`` in the class docstring), for a dataclass."""
    docs = {}
    for klass in reversed(cls.__mro__):
        if dataclasses.is_dataclass(klass) and klass is not object:
            tree = ast.parse(inspect.getsource(klass).lstrip()) if klass.__module__.startswith("mpm") else None
            if tree is not None:
                docs.update(attribute_docs(tree.body[0]))
    text = own_doc(cls)
    return {f.name: bool(f.metadata.get("doc") or docs.get(f.name) or f"``{f.name}``" in text)
            for f in dataclasses.fields(cls)}


@pytest.mark.parametrize("name", mpm.__all__)
def test_every_public_name_is_documented(name):
    obj = getattr(mpm, name)
    if inspect.ismodule(obj) or inspect.isclass(obj) or callable(obj):
        assert own_doc(obj).strip(), f"mpm.{name} has no docstring of its own"
        if inspect.isclass(obj) and dataclasses.is_dataclass(obj):
            missing = [f for f, ok in field_docs(obj).items() if not ok]
            assert not missing, f"mpm.{name}: fields without a doc: {missing}"
    else:
        assert constant_doc(obj).strip(), f"mpm.{name}: no docstring after its assignment"


def test_the_api_names_what_a_researcher_reaches_for():
    """Every material class, the collider, the driver and the plan are public names."""
    for cls in mpm.MATERIALS.values():
        assert getattr(mpm, cls.__name__) is cls, cls
    for name in ("Collider", "Driver", "plan", "Load", "Solver", "SolverOptions", "StepPolicy", "Detection"):
        assert name in mpm.__all__ and hasattr(mpm, name)
    assert sorted(mpm.__all__) == sorted(set(mpm.__all__))
    assert all(hasattr(mpm, n) for n in mpm.__all__)


def test_every_name_the_library_page_shows_is_public():
    """docs/library.md says every ``mpm.<name>`` it shows is in mpm.__all__
    (mpm.precision.resolution was not) or a module of mpm, and a dotted one
    is its module's."""
    text = (ROOT / "docs" / "library.md").read_text()
    names = set(re.findall(r"`mpm\.([A-Za-z_][A-Za-z0-9_.]*)", text))
    assert names
    for name in sorted(n for n in names if not n.startswith("__")):
        if "." not in name and importlib.util.find_spec(f"mpm.{name}") is None:  # (a module of mpm: its own)
            assert name in mpm.__all__, f"mpm.{name} is shown in docs/library.md but is not in mpm.__all__"
            continue
        obj, path = mpm, "mpm"
        for part in name.split("."):  # an attribute, else a submodule
            path += "." + part
            obj = getattr(obj, part) if hasattr(obj, part) else importlib.import_module(path)


def test_the_check_finds_an_undocumented_field():
    @dataclasses.dataclass
    class Bare:
        """A class."""

        a: float = 1.0
        b: float = 2.0
        """documented"""

    # not from mpm: only the class docstring counts
    assert field_docs(Bare) == {"a": False, "b": False}
    assert own_doc(dataclasses.make_dataclass("NoDoc", [("x", int)])) == ""


def library_blocks() -> list[str]:
    text = (ROOT / "docs" / "library.md").read_text()
    return re.findall(r"```python\n(.*?)```", text, re.S)


def test_the_library_guides_code_runs(tmp_path):
    """Every ```python block of docs/library.md (at least the three the
    page shows), run in order in one fresh interpreter (a later block may
    use an earlier one's names), as written, on the CPU, printing what the
    page says it prints."""
    assert len(library_blocks()) >= 3
    code = "\n\n".join(library_blocks())
    script = tmp_path / "guide.py"
    script.write_text(code)
    p = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=900, cwd=tmp_path,
                       env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    out = p.stdout
    # what the blocks print: the run completed in steps; the centre of mass from the particles (m x / M)
    # equals the solver's diagnostics (two sums of the same state); the resting disc's lowest centre of
    # mass lies below its start (0.3 m) and above the floor's band (radius 0.1 m over 3 cells of 1/32 m)
    assert int(re.search(r"^completed (\d+) steps$", out, re.M).group(1)) >= 10, out
    assert re.search(r"^completed t = 0\.\d+ s$", out, re.M), out
    com = [float(v) for v in re.search(r"centre of mass \[m\]: \[([^\]]+)\]", out).group(1).split()]
    diag = ast.literal_eval(re.search(r"^(\{'center_of_mass_x'.*\})$", out, re.M).group(1))
    assert com == pytest.approx([diag["center_of_mass_x"], diag["center_of_mass_y"]], abs=2e-6), out
    lowest = float(re.search(r"lowest centre of mass ([\d.]+) m", out).group(1))
    assert 3 / 32 + 0.1 - 0.01 < lowest < 0.3, out
