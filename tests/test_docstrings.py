"""Meta-test: every public object of ilcdob has a numpydoc docstring that matches its signature.

Modelled on python-control's ``control/tests/docstrings_test.py``. The public modules are found
by walking the packages ``ilcdob``, ``ilcdob.design``, ``ilcdob.identification``,
``ilcdob.validation`` and ``ilcdob.vehicles`` with :mod:`pkgutil` (``ilcdob.app``, the
command-line front end, and private modules, any dotted component starting with ``_``, are
skipped). In each module every public function and class *defined there* (not imported), and
every public method, class method, static method and property defined in those classes, gets
one test, named ``module:qualname``:

* it has a docstring (a method may inherit its docstring from the class it overrides);
* properties need nothing more;
* for a function, a method or a class's constructor (``__init__``, else ``__new__``, when the
  class defines one itself), the numpydoc ``Parameters`` (and ``Other Parameters``) section
  names every parameter of the signature except ``self``/``cls`` and private ones (a leading
  underscore, e.g. a dataclass's internal cache field), and names nothing that is not in the
  signature. ``*args``/``**kwargs`` may be written with or without their stars;
  several names may share one line (``x, y : float``). A dataclass or named tuple may list its
  fields under ``Attributes`` instead of ``Parameters``.

The section is read with ``numpydoc.docscrape`` when numpydoc is installed, otherwise with the
small parser below (a section is a title line underlined by dashes; a parameter line is a line
at the section's own indentation, ``name : type`` or ``name``).

A module that does not import gets one failing test, ``module:<import>``, so a broken module
is reported instead of aborting the collection.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import inspect
import pkgutil
import re
import traceback
from typing import Any

import pytest

try:  # optional: the project does not depend on numpydoc
    from numpydoc.docscrape import NumpyDocString
except ImportError:  # pragma: no cover - depends on the environment
    NumpyDocString = None

#: Packages walked (``ilcdob.design`` etc. live outside ``ilcdob/`` on disk, so each is a root).
ROOTS = ("ilcdob", "ilcdob.design", "ilcdob.identification", "ilcdob.validation", "ilcdob.vehicles")
#: Modules and packages not checked (with everything under them).
SKIP = ("ilcdob.app",)


def _skipped(name: str) -> bool:
    if any(part.startswith("_") for part in name.split(".")):
        return True
    return any(name == s or name.startswith(s + ".") for s in SKIP)


def _walk(name: str, seen: dict[str, Any], broken: dict[str, str]) -> None:
    """Import package or module ``name`` and, for a package, everything public under it."""
    if name in seen or name in broken or _skipped(name):
        return
    try:
        module = importlib.import_module(name)
    except Exception:  # noqa: BLE001 - reported as a failing test
        broken[name] = traceback.format_exc(limit=3)
        return
    seen[name] = module
    for info in pkgutil.iter_modules(getattr(module, "__path__", None) or [], name + "."):
        _walk(info.name, seen, broken)


def public_modules() -> tuple[dict[str, Any], dict[str, str]]:
    """All public modules of ilcdob (name -> module) and the ones that failed to import."""
    seen: dict[str, Any] = {}
    broken: dict[str, str] = {}
    for root in ROOTS:
        _walk(root, seen, broken)
    return dict(sorted(seen.items())), broken


# --- what is checked ------------------------------------------------------------------------

def _is_function(obj: Any) -> bool:
    return inspect.isfunction(obj) or (callable(obj) and not inspect.isclass(obj)
                                       and inspect.isfunction(getattr(obj, "__wrapped__", None)))


def _constructor(cls: type) -> Any:
    """The class's own ``__init__`` (else ``__new__``), or None when it inherits one."""
    for name in ("__init__", "__new__"):
        member = cls.__dict__.get(name)
        if isinstance(member, staticmethod):
            member = member.__func__
        if inspect.isfunction(member):
            return member
    return None


def _is_record(cls: type) -> bool:
    """Dataclass or named tuple: its fields may be documented under ``Attributes``."""
    return dataclasses.is_dataclass(cls) or (issubclass(cls, tuple) and hasattr(cls, "_fields"))


def collect() -> list[Any]:
    """One ``pytest.param`` per checked object: (kind, object, drop_first, is_record)."""
    modules, broken = public_modules()
    params = [pytest.param("import", tb, False, False, id=f"{name}:<import>") for name, tb in broken.items()]
    for modname, module in modules.items():
        done: set[int] = set()
        for name, obj in sorted(vars(module).items()):
            if name.startswith("_") or id(obj) in done:
                continue
            if getattr(obj, "__module__", None) != modname:
                continue  # imported, or not a function/class
            if inspect.isclass(obj):
                done.add(id(obj))
                params.append(pytest.param("class", obj, True, _is_record(obj), id=f"{modname}:{name}"))
                for mname, member in sorted(vars(obj).items()):
                    if mname.startswith("_"):
                        continue
                    mid = f"{modname}:{name}.{mname}"
                    if isinstance(member, (property, functools.cached_property)):
                        params.append(pytest.param("property", member, False, False, id=mid))
                    elif isinstance(member, staticmethod):
                        params.append(pytest.param("function", member.__func__, False, False, id=mid))
                    elif isinstance(member, classmethod):
                        params.append(pytest.param("method", (obj, mname, member.__func__), True, False, id=mid))
                    elif inspect.isfunction(member):
                        params.append(pytest.param("method", (obj, mname, member), True, False, id=mid))
            elif _is_function(obj):
                done.add(id(obj))
                params.append(pytest.param("function", obj, False, False, id=f"{modname}:{name}"))
    return params


# --- reading the docstring ------------------------------------------------------------------

_SECTION = re.compile(r"^\s*-{3,}\s*$")


def _sections(doc: str) -> dict[str, list[str]]:
    """Section title -> its lines, for a numpydoc docstring (the summary is under '')."""
    lines = inspect.cleandoc(doc).splitlines()
    out: dict[str, list[str]] = {"": []}
    title = ""
    i = 0
    while i < len(lines):
        if i + 1 < len(lines) and lines[i].strip() and _SECTION.match(lines[i + 1]):
            title = lines[i].strip()
            out.setdefault(title, [])
            i += 2
            continue
        out[title].append(lines[i])
        i += 1
    return out


def _names_in(section: list[str]) -> list[str]:
    """Parameter names of a ``Parameters``-like section (``name : type`` lines, no indent)."""
    body = [line for line in section if line.strip()]
    if not body:
        return []
    indent = min(len(line) - len(line.lstrip()) for line in body)
    names: list[str] = []
    for line in body:
        if len(line) - len(line.lstrip()) != indent:
            continue
        head = line.strip().split(" : ", 1)[0].rstrip(":").strip()
        names += [n.strip() for n in head.split(",") if n.strip()]
    return names


def documented(doc: str, titles: tuple[str, ...]) -> list[str]:
    """Names listed in the given sections of a numpydoc docstring, stars stripped."""
    if NumpyDocString is not None:
        parsed = NumpyDocString(doc)
        raw = [n for title in titles for p in parsed[title] for n in p.name.split(",")]
    else:
        sections = _sections(doc)
        raw = [n for title in titles for n in _names_in(sections.get(title, []))]
    return [n.strip().lstrip("*") for n in raw if n.strip()]


def signature_names(func: Any, drop_first: bool) -> list[str]:
    """Parameter names of ``func`` (without ``self``/``cls`` when ``drop_first``; with private ones)."""
    params = list(inspect.signature(func).parameters.values())
    if drop_first and params and params[0].kind in (params[0].POSITIONAL_ONLY, params[0].POSITIONAL_OR_KEYWORD):
        params = params[1:]
    return [p.name for p in params]


def _check_parameters(label: str, doc: str, names: list[str], record: bool) -> None:
    given = documented(doc, ("Parameters", "Other Parameters"))
    fields = documented(doc, ("Attributes",)) if record else []
    missing = [n for n in names if n not in given and n not in fields and not n.startswith("_")]
    extra = [n for n in given if n not in names]
    problems = []
    if missing:
        problems.append(f"parameters not documented: {', '.join(missing)}")
    if extra:
        problems.append(f"documented but not in the signature: {', '.join(extra)}")
    assert not problems, f"{label}: " + "; ".join(problems)


@pytest.mark.parametrize("kind, obj, drop_first, record", collect())
def test_docstring(kind: str, obj: Any, drop_first: bool, record: bool) -> None:
    """The object has a docstring whose Parameters section matches its signature."""
    if kind == "import":
        pytest.fail(f"module does not import:\n{obj}")
    if kind == "property":
        getter = obj.fget if isinstance(obj, property) else obj.func
        assert inspect.getdoc(getter), f"property {getter.__qualname__} has no docstring"
        return
    if kind == "method":
        cls, name, func = obj
        doc = func.__doc__ or inspect.getdoc(getattr(cls, name))  # an override may inherit its docstring
        label = func.__qualname__
    else:
        func, doc, label = obj, obj.__doc__, obj.__qualname__
    assert doc and doc.strip(), f"{label} has no docstring"
    if kind == "class":
        init = _constructor(obj)
        if init is None:
            return  # inherited constructor: documented where it is defined
        names = signature_names(init, drop_first=True)
    else:
        names = signature_names(func, drop_first)
    _check_parameters(label, doc, names, record)


def test_walk_finds_the_packages() -> None:
    """The walk reaches every package (a mapping mistake would silently check nothing)."""
    modules, broken = public_modules()
    found = set(modules) | set(broken)
    for root in ROOTS:
        assert root in found
    assert "ilcdob.design.maps.closed_form" in found and "ilcdob.identification.tfest" in found
    assert not any(name.startswith("ilcdob.app") for name in found)
