"""The import graph: every dependency points down the layers, and no two modules import each other (even lazily).

Read from the source files (every ``import`` statement, at module level or inside a function), so the check also
covers imports that never run in the tests. A new module must be placed in a layer here.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "fourierf_plugin"
MAPPED = {  # folders at the top of the repository installed inside the package (pyproject.toml's package-dir)
    REPO / "method_configs": f"{PACKAGE}.method_configs",
    REPO / "data" / "parsers": f"{PACKAGE}.data.parsers",
}

LAYERS: dict[str, int] = {
    # foundations
    PACKAGE: 0,
    f"{PACKAGE}.utils": 0,
    f"{PACKAGE}.configs": 0,
    # the method's pure pieces, and what a scene is
    f"{PACKAGE}.cameras": 1,
    f"{PACKAGE}.field_components": 1,
    f"{PACKAGE}.model_components": 1,
    f"{PACKAGE}.data.scene_effects": 1,
    f"{PACKAGE}.data.dataparser_base": 2,
    f"{PACKAGE}.data.dataparser_transforms": 1,
    f"{PACKAGE}.data.images": 1,
    f"{PACKAGE}.data.poses": 1,
    f"{PACKAGE}.data.capture": 1,
    f"{PACKAGE}.data.colmap_model": 1,
    f"{PACKAGE}.data.view_selection": 1,
    f"{PACKAGE}.synthetic": 1,
    # the field, and the fast forms of its operations
    f"{PACKAGE}.fields": 2,
    f"{PACKAGE}.accel": 3,
    f"{PACKAGE}.data.parsers": 3,
    f"{PACKAGE}.data.nerfstudio_writer": 3,  # reads LLFF scenes through data.parsers.llff
    f"{PACKAGE}.sfm": 3,
    f"{PACKAGE}.models": 4,
    f"{PACKAGE}.data.datamanager": 4,
    f"{PACKAGE}.data": 4,  # the package itself (its __init__)
    f"{PACKAGE}.pipelines": 5,
    f"{PACKAGE}.exporter": 5,
    # running, saving and loading a run
    f"{PACKAGE}.engine": 6,
    # presets and the finished config
    f"{PACKAGE}.method_configs": 7,
    f"{PACKAGE}.vis": 7,  # training observers: TensorBoard
    f"{PACKAGE}.viewer": 8,  # the web viewer (loads runs, exports meshes)
    f"{PACKAGE}.scripts": 9,
}


def module_name(path: Path) -> str:
    for folder, prefix in MAPPED.items():
        if folder in path.parents:
            rel = path.relative_to(folder).with_suffix("")
            return ".".join([prefix, *rel.parts]).removesuffix(".__init__")
    rel = path.relative_to(REPO).with_suffix("")
    return ".".join(rel.parts).removesuffix(".__init__")


def source_files() -> list[Path]:
    files = sorted((REPO / PACKAGE).rglob("*.py"))
    for folder in MAPPED:
        files += sorted(folder.rglob("*.py"))
    return files


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in source_files()}


def layer_of(module: str) -> int:
    """The layer of the longest prefix that names ``module``."""
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        prefix = ".".join(parts[:n])
        if prefix in LAYERS:
            return LAYERS[prefix]
    raise KeyError(module)


def imports_of(module: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The project modules ``module`` imports anywhere in its file (``from pkg import sub`` counts as ``pkg.sub``)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*anchor, *([base] if base else [])])
            for alias in node.names:
                candidate = f"{base}.{alias.name}"
                found.add(candidate if candidate in known else base)
    return {m for m in found if m == PACKAGE or m.startswith(f"{PACKAGE}.")} - {module}


def graph() -> dict[str, set[str]]:
    known = modules()
    return {m: {i for i in imports_of(m, p, known) if i in known} for m, p in known.items()}


def test_every_module_has_a_layer() -> None:
    unplaced = []
    for m in modules():
        try:
            layer_of(m)
        except KeyError:
            unplaced.append(m)
    assert not unplaced, f"place these modules in LAYERS: {unplaced}"


def test_every_dependency_points_down() -> None:
    upward = [
        f"{m} (layer {layer_of(m)}) imports {i} (layer {layer_of(i)})"
        for m, deps in graph().items()
        for i in sorted(deps)
        if layer_of(i) > layer_of(m)
    ]
    assert not upward, "\n".join(upward)


def test_no_import_cycles() -> None:
    g = graph()
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    cycles: list[list[str]] = []

    def visit(m: str, path: list[str]) -> None:
        state[m] = 1
        for dep in sorted(g[m]):
            if state.get(dep) == 1:
                cycles.append([*path[path.index(dep) :], dep])
            elif dep not in state:
                visit(dep, [*path, dep])
        state[m] = 2

    for m in sorted(g):
        if m not in state:
            visit(m, [m])
    assert not cycles, "\n".join(" -> ".join(c) for c in cycles)


@pytest.mark.parametrize(
    ("module", "forbidden"),
    [
        (f"{PACKAGE}.engine.trainer", f"{PACKAGE}.method_configs"),
        (f"{PACKAGE}.configs.base", f"{PACKAGE}.method_configs"),
        (f"{PACKAGE}.fields.fourier_tensorf_field", f"{PACKAGE}.accel"),
    ],
)
def test_the_reviewed_upward_arrows_are_gone(module: str, forbidden: str) -> None:
    deps = graph()[module]
    assert not any(d == forbidden or d.startswith(forbidden + ".") for d in deps), sorted(deps)
