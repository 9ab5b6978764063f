"""The layout: every import points one way, no module imports itself round a circle, and the
source tree runs without installing.

Layers, lowest first: kernel (``ilcdob/*.py``) <- vehicles (``ilcdob.vehicles``) <-
identification <- design <- validation <- application (``ilcdob.app``). A module may import
its own layer and the layers below it, never one above (lazy imports inside functions
included). Within a layer the imports form no circle either, counting every import statement
(lazy ones and those for type checking too): a circle means a primitive sits in the wrong
module. The README's layout table states the same.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: folder (relative to the repository) -> (package name, layer rank)
PACKAGES = {"ilcdob": ("ilcdob", 0), "ilcdob/vehicles": ("ilcdob.vehicles", 1),
            "identification": ("ilcdob.identification", 2), "design": ("ilcdob.design", 3),
            "validation": ("ilcdob.validation", 4), "ilcdob/app": ("ilcdob.app", 5)}
LAYERS = sorted(((pkg, rank) for pkg, rank in PACKAGES.values()), key=lambda x: -len(x[0]))


def _rank(module: str) -> int | None:
    """Layer of a dotted ilcdob module name (None: not ilcdob)."""
    if module == "ilcdob.__main__":  # ``python -m ilcdob``: the application's entry point
        return PACKAGES["ilcdob/app"][1]
    for pkg, rank in LAYERS:
        if module == pkg or module.startswith(pkg + "."):
            return rank
    return None


def _modules() -> list[tuple[Path, str]]:
    out = []
    for folder, (pkg, _) in PACKAGES.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT / folder).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            if folder == "ilcdob" and parts and parts[0] in ("vehicles", "app"):
                continue  # their own layers
            out.append((path, ".".join([pkg, *parts])))
    return out


def _imports(path: Path, module: str) -> list[tuple[int, str]]:
    """Every imported ilcdob module name (absolute), with its line."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            found.append((node.lineno, name))
            found += [(node.lineno, f"{name}.{a.name}") for a in node.names]  # `from ilcdob import app`
    return [(line, name) for line, name in found if name == "ilcdob" or name.startswith("ilcdob.")]


def _upward() -> list[str]:
    bad = []
    for path, module in _modules():
        own = _rank(module)
        for line, name in _imports(path, module):
            target = _rank(name)
            if target is not None and target > own and not name.endswith(("__version__",)):
                bad.append(f"{path.relative_to(ROOT)}:{line}: {module} imports {name}")
    return bad


def test_every_import_points_down_the_layers():
    assert _modules(), "no module found"
    assert _upward() == []


def _graph() -> dict[str, set[str]]:
    """Module -> the ilcdob modules it imports (an imported name resolved to its module)."""
    modules = {module: path for path, module in _modules()}
    graph = {}
    for module, path in modules.items():
        deps = set()
        for _, name in _imports(path, module):
            while name and name not in modules:  # `from .x import f` gives `...x.f`: its module is `...x`
                name = name.rpartition(".")[0]
            if name and name != module:
                deps.add(name)
        graph[module] = deps
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles: strongly connected sets of two or more modules (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                out.append(sorted(part))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_circle():
    circles = _circles(_graph())
    assert circles == [], "import circles: " + "; ".join(" <-> ".join(c) for c in circles)


def test_the_circle_finder_sees_a_circle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}}
    assert _circles(graph) == [["a", "b", "c"]]


def test_the_checker_sees_an_upward_import():
    # the kernel importing the application layer, absolute and relative, is caught
    assert _rank("ilcdob.app.cli") == 5 and _rank("ilcdob.fleet") == 0 and _rank("ilcdob.vehicles.quadrotor") == 1
    tree = "from .app import cli\nimport ilcdob.validation.compare\n"
    fake = ROOT / "ilcdob" / "_layout_probe_never_committed.py"
    try:
        fake.write_text(tree)
        names = [n for _, n in _imports(fake, "ilcdob._layout_probe_never_committed")]
    finally:
        fake.unlink()
    assert "ilcdob.app" in names and "ilcdob.validation.compare" in names


@pytest.mark.parametrize("code", ["import ilcdob.design, ilcdob.identification.loaders, ilcdob.validation.campaign; "
                                  "print(ilcdob.design.__file__)"])
def test_the_source_tree_imports_without_installing(code, tmp_path):
    # run from the repository root, no -P: the source tree is what Python finds first
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert Path(run.stdout.strip()) == ROOT / "design" / "__init__.py"
    run = subprocess.run([sys.executable, "-m", "ilcdob", "--version"], cwd=ROOT, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0 and run.stdout.startswith("ilcdob "), run.stderr[-2000:]


#: The design's rooms, lowest first (the README's layout table): a room imports its own and lower rooms only.
#: Modules directly in design/ (the package, ``pair``: the design verb) sit above every room.
DESIGN_ROOMS = ("filters", "maps", "sets", "law", "methods", "checks", "export")


def _room(module: str) -> int | None:
    """Rank of a design module's room (None: not in design)."""
    prefix = "ilcdob.design"
    if not (module == prefix or module.startswith(prefix + ".")):
        return None
    room = module[len(prefix) + 1:].split(".")[0]
    return DESIGN_ROOMS.index(room) if room in DESIGN_ROOMS else len(DESIGN_ROOMS)


def test_the_design_rooms_import_downwards():
    bad = []
    for path, module in _modules():
        own = _room(module)
        if own is None:
            continue
        for line, name in _imports(path, module):
            target = _room(name)
            if target is not None and target > own:
                bad.append(f"{path.relative_to(ROOT)}:{line}: {module} ({DESIGN_ROOMS[own]}) imports {name}")
    assert bad == []
    assert {p.name for p in (ROOT / "design").iterdir() if p.is_dir() and (p / "__init__.py").is_file()} \
        == set(DESIGN_ROOMS), "a design folder that is not a room (or a room without its folder)"


def test_every_package_folder_is_installed() -> None:
    """``pip install .`` (not editable) installs only the packages pyproject.toml lists: a
    sub-package folder missing there imports from the source tree but not once installed."""
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    dirs = {name: Path(folder) for name, folder in config["package-dir"].items()}
    found = set()
    for init in ROOT.rglob("__init__.py"):
        rel = init.parent.relative_to(ROOT)
        for name, folder in dirs.items():
            if rel == folder or folder in rel.parents:
                found.add(".".join([name, *rel.relative_to(folder).parts]))
    assert found - listed == set(), f"package folders not in pyproject.toml: {found - listed}"


def test_every_ilcdob_import_resolves() -> None:
    """Every ``from ilcdob... import name`` in the repository's Python files (lazy ones, benchmarks and
    examples included) names a module or an attribute that exists: a moved module breaks an import that
    only runs in a worker process or a benchmark."""
    import importlib

    bad = []
    for path in sorted(p for p in ROOT.rglob("*.py") if not {".git", "build"} & set(p.parts)):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not (isinstance(node, ast.ImportFrom) and node.level == 0 and node.module
                    and (node.module == "ilcdob" or node.module.startswith("ilcdob."))):
                continue
            try:
                module = importlib.import_module(node.module)
            except ImportError as exc:
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: {exc}")
                continue
            for alias in node.names:
                if alias.name == "*" or hasattr(module, alias.name):
                    continue
                try:
                    importlib.import_module(f"{node.module}.{alias.name}")
                except ImportError:
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.module} has no {alias.name}")
    assert bad == []


def test_committed_reports_are_what_their_runs_wrote() -> None:
    """Every file a committed report's manifest lists has the digest its run recorded: a generated report is
    regenerated, never edited by hand (or by a rename across the tree)."""
    import hashlib
    import json

    manifests = sorted((ROOT / "reports").rglob("manifest.json"))
    assert manifests, "no committed report found"
    bad = []
    for manifest in manifests:
        for name, digest in json.loads(manifest.read_text(encoding="utf-8")).get("files", {}).items():
            path = manifest.parent / name
            if not path.is_file() or hashlib.sha256(path.read_bytes()).hexdigest() != digest:
                bad.append(str(path.relative_to(ROOT)))
    assert bad == [], f"differ from their manifests: {bad}"
