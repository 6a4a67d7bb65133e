"""The module map of docs/design.md holds: no import runs up a layer, no import circle between
the library's files, the library never imports the packages built on it, and no module of it or
of the packages built on it passes MAX_MODULE_LINES.

Read from the source (every ``import`` and ``from ... import``, at module level or inside a
function), nothing is imported.
"""

from __future__ import annotations

import ast
from pathlib import Path

from conftest import REPO_ROOT

LIBRARY = REPO_ROOT / "frontiernet"

# docs/design.md, "Module map": layer of each top-level module or package of frontiernet/
LAYERS = {
    "errors": 1, "config_ranges": 1, "config": 1, "io": 1, "array_files": 1, "geometry": 1, "workers": 1, "registry": 1,
    "timing": 1, "allocator": 1,
    "model": 2, "depth": 2, "planning": 2, "scenes": 2,
    "simulator": 3,
    "mapping": 4,
    "frontiers": 5, "mapprediction": 5,
    "exploration": 6,
    "sequences": 7, "benchmark": 7,
    "cli": 8,
}
ABOVE_THE_LIBRARY = ("datagen", "train", "deploy")
MAX_MODULE_LINES = 450
"""docs/design.md, "Module map": a module longer than this holds more than one job (issue 29)."""


def _module_name(path: Path) -> str:
    parts = path.relative_to(REPO_ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """Absolute names of the modules `path` imports (relative imports resolved)."""
    package = _module_name(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            names.add(module)
            # `from . import x` / `from .pkg import mod`: the names may be modules themselves
            names |= {f"{module}.{alias.name}" for alias in node.names}
    return names


def _library_graph() -> dict[str, set[str]]:
    """frontiernet module file -> the module files it imports. An import of a package stands for
    the files its ``__init__.py`` imports (a package's face hands names on), so packages are no nodes."""
    files = {_module_name(path): path for path in LIBRARY.rglob("*.py")}
    direct = {name: {imported for imported in _imports(path) if imported in files and imported != name}
              for name, path in files.items()}
    faces = {name for name, path in files.items() if path.name == "__init__.py"}

    def behind(name: str, seen: frozenset = frozenset()) -> set[str]:
        if name not in faces:
            return {name}
        return set().union(*(behind(inner, seen | {name}) for inner in direct[name] - seen - {name}))

    return {name: set().union(*(behind(imported) for imported in imports)) - {name}
            for name, imports in direct.items() if name not in faces}


def _layer(module: str) -> int | None:
    parts = module.split(".")
    return LAYERS.get(parts[1]) if len(parts) > 1 else None


def test_every_part_of_the_library_has_its_layer():
    parts = {path.stem if path.is_file() else path.name for path in LIBRARY.iterdir()
             if (path.suffix == ".py" and path.stem != "__init__") or (path / "__init__.py").is_file()}
    assert parts == set(LAYERS), "docs/design.md's module map and LAYERS name every part of frontiernet/"


def test_no_import_runs_up_a_layer():
    up = [f"{module} (layer {_layer(module)}) imports {imported} (layer {_layer(imported)})"
          for module, imported_set in _library_graph().items() for imported in sorted(imported_set)
          if _layer(module) is not None and _layer(imported) is not None and _layer(imported) > _layer(module)]
    assert up == []


def test_the_library_never_imports_what_is_built_on_it():
    found = [f"{path.relative_to(REPO_ROOT)} imports {name}" for path in LIBRARY.rglob("*.py")
             for name in sorted(_imports(path)) if name.split(".")[0] in ABOVE_THE_LIBRARY]
    assert found == []


def test_no_import_circle_between_library_files():
    graph = _library_graph()
    state, circles = {}, []

    def visit(module: str, path: list[str]) -> None:
        state[module] = "open"
        for imported in sorted(graph[module]):
            if state.get(imported) == "open":
                circles.append(" -> ".join(path[path.index(imported):] + [imported]))
            elif imported not in state:
                visit(imported, path + [imported])
        state[module] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])
    assert circles == []


def test_no_module_is_longer_than_the_limit():
    long = [f"{path.relative_to(REPO_ROOT)}: {lines} lines" for folder in (LIBRARY, *(REPO_ROOT / name for name in ABOVE_THE_LIBRARY))
            for path in sorted(folder.rglob("*.py")) if (lines := len(path.read_text().splitlines())) > MAX_MODULE_LINES]
    assert long == []
