"""Every public name has a numpydoc docstring: a summary, and Parameters / Returns sections that
name what the signature takes and says what it gives back.

Public names: ``hystid.__all__``, and in every public module (no part of its dotted name starts
with ``_``) the names of its ``__all__`` (or, without one, the functions and classes defined
there whose name does not start with ``_``), and the public methods and properties of those
classes. A class documents its constructor's parameters (``Parameters``, or ``Attributes`` for
a record-like class); a function or method documents each parameter and, when it returns a
value, has a ``Returns`` (or ``Yields``) section.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import re
import textwrap

import pytest

import hystid

SECTION = re.compile(r"^(\w[\w ]*)\n-{3,}\s*$", re.MULTILINE)
NO_VALUE = {"None", "NoReturn", "Never"}


def _public_modules() -> list[str]:
    names = ["hystid"]
    for info in pkgutil.walk_packages(hystid.__path__, "hystid."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


def _public_objects() -> dict[str, object]:
    found: dict[str, object] = {}
    for modname in _public_modules():
        module = importlib.import_module(modname)
        names = getattr(module, "__all__", None)
        if names is None:
            names = [n for n, obj in vars(module).items() if not n.startswith("_")
                     and (inspect.isfunction(obj) or inspect.isclass(obj))
                     and getattr(obj, "__module__", None) == modname]
        for name in names:
            obj = getattr(module, name)
            if not (inspect.isfunction(obj) or inspect.isclass(obj)):
                continue  # constants are documented by their comments
            home = f"{obj.__module__}.{obj.__qualname__}"
            found.setdefault(home, obj)
            if inspect.isclass(obj):
                for attr, member in vars(obj).items():
                    if attr.startswith("_"):
                        continue
                    if isinstance(member, staticmethod | classmethod):
                        member = member.__func__
                    if inspect.isfunction(member) or isinstance(member, property):
                        found.setdefault(f"{home}.{attr}", member)
    return found


def _sections(doc: str) -> dict[str, str]:
    doc = inspect.cleandoc(doc)
    heads = list(SECTION.finditer(doc))
    return {m.group(1).strip(): doc[m.end(): (heads[i + 1].start() if i + 1 < len(heads)
                                               else len(doc))]
            for i, m in enumerate(heads)}


def _documented_names(section: str) -> set[str]:
    names: set[str] = set()
    for line in textwrap.dedent(section.strip("\n")).splitlines():
        if line and not line[0].isspace():
            head = line.split(" : ")[0].rstrip(":").strip()
            names.update(n.strip().lstrip("*") for n in head.split(","))
    return names


def _parameters(func) -> list[str]:
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        return []
    return [p.name for p in sig.parameters.values() if p.name not in ("self", "cls")]


def _returns_value(func) -> bool:
    annotation = func.__annotations__.get("return")
    if annotation is not None:
        text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")
        return text not in NO_VALUE
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(func)))
    except (OSError, TypeError, SyntaxError):
        return False
    body = tree.body[0]
    nested = {id(n) for node in ast.walk(body) if node is not body and isinstance(
        node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda) for n in ast.walk(node)}
    return any(isinstance(n, ast.Return | ast.Yield) and getattr(n, "value", None) is not None
               and id(n) not in nested for n in ast.walk(body))


def _problems(name: str, obj) -> list[str]:
    doc = obj.__doc__ if not isinstance(obj, property) else obj.fget.__doc__
    if inspect.isclass(obj) and obj.__doc__ and obj.__doc__ is type.__doc__:
        doc = None
    if not doc or not doc.strip():
        return [f"{name}: no docstring"]
    if isinstance(obj, property):
        return []
    sections = _sections(doc)
    out = []
    if inspect.isclass(obj):
        if getattr(obj, "_is_protocol", False) or (
                "__init__" not in vars(obj) and not hasattr(obj, "__dataclass_fields__")):
            return []  # a protocol has no constructor; an inherited one is documented there
        params = _parameters(obj)
        documented = _documented_names(sections.get("Parameters", "")) | _documented_names(
            sections.get("Attributes", ""))
    else:
        params = _parameters(obj)
        documented = _documented_names(sections.get("Parameters", ""))
        if _returns_value(obj) and not {"Returns", "Yields"} & sections.keys():
            out.append(f"{name}: returns a value but has no Returns section")
    missing = [p for p in params if p not in documented]
    if missing:
        out.append(f"{name}: parameters not documented: {', '.join(missing)}")
    return out


PUBLIC = _public_objects()


def test_the_walk_finds_the_public_api():
    # the test itself: it sees the package's public names, methods and properties
    assert "hystid.sandwich.Sandwich.simulate" in PUBLIC
    assert "hystid.model.DuhemSandwich.rest_state" in PUBLIC
    assert "hystid.compensate.compensator.feedforward" in PUBLIC
    assert "hystid.response.SandwichResponse" in PUBLIC
    assert not any(".tests." in n or n.split(".")[-1].startswith("_") for n in PUBLIC)
    assert len(PUBLIC) > 200


def test_the_checker_catches_what_it_should():
    def bare(a, b=1):
        return a + b

    def partial(a, b=1):
        """Add.

        Parameters
        ----------
        a : int
            One.
        """
        return a + b

    def complete(a: int, *args: int, b: int = 1) -> int:
        """Add.

        Parameters
        ----------
        a, b : int
            Two numbers.
        *args : int
            More.

        Returns
        -------
        int
            The sum.
        """
        return a + b + sum(args)

    assert _problems("bare", bare) == ["bare: no docstring"]
    assert _problems("partial", partial) == [
        "partial: returns a value but has no Returns section",
        "partial: parameters not documented: b",
    ]
    assert _problems("complete", complete) == []


@pytest.mark.parametrize("modname", _public_modules())
def test_public_names_have_numpydoc_docstrings(modname):
    module = importlib.import_module(modname)
    problems = [] if (module.__doc__ or "").strip() else [f"{modname}: no module docstring"]
    for name, obj in PUBLIC.items():
        owner = name.rsplit(".", 2 if _is_member(name) else 1)[0]
        if owner == modname:
            problems += _problems(name, obj)
    assert not problems, "\n".join(problems)


def _is_member(name: str) -> bool:
    parts = name.split(".")
    return len(parts) > 2 and inspect.isclass(PUBLIC.get(".".join(parts[:-1])))
