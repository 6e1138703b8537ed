"""The package as a user meets it: every native function has a type stub,
every public name a docstring, and the installed wheel carries its stubs."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import mdtf
from mdtf import _mdtf


def test_every_native_function_has_a_stub_with_its_parameters() -> None:
    stub = Path(mdtf.__file__).with_name("_mdtf.pyi")
    assert stub.is_file(), "the wheel ships _mdtf.pyi"
    assert Path(mdtf.__file__).with_name("py.typed").is_file()
    tree = ast.parse(stub.read_text())
    stubs = {f.name: [a.arg for a in f.args.args] for f in tree.body if isinstance(f, ast.FunctionDef)}
    native = {n: f for n, f in vars(_mdtf).items() if callable(f) and not isinstance(f, type)}
    assert set(stubs) == set(native)
    for name, f in native.items():
        params = list(inspect.signature(f).parameters)
        assert stubs[name] == params, f"{name}: stub {stubs[name]}, native {params}"


def test_every_public_name_is_documented() -> None:
    for name in mdtf.__all__:
        obj = getattr(mdtf, name)
        assert (obj.__doc__ or "").strip(), f"mdtf.{name} has no docstring"
    assert mdtf.__version__.count(".") == 2
