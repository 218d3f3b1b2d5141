"""Specification of the package layout, read from the source with ``ast`` (nothing is imported).

Every ``import`` statement counts, also those inside functions and under ``TYPE_CHECKING``:
a lazy import is still a dependency, and a circle of them is still a circle. The layers are
physrelight (the physics core) -> synth, learned -> validation; the core imports none of the
others, except the command line's entry module, which loads each stage's CLI.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("physrelight", "synth", "learned", "validation")
UPPER = ("synth", "learned", "validation")
CLI_ENTRY = "physrelight.cli"


def _modules() -> dict[str, tuple[Path, bool]]:
    """``{dotted name: (file, is a package __init__)}`` of every module of the four packages."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_pkg = parts[-1] == "__init__"
            out[".".join(parts[:-1] if is_pkg else parts)] = (path, is_pkg)
    return out


def _targets(module: str, is_pkg: bool, node: ast.Import | ast.ImportFrom, known: set[str]) -> set[str]:
    """The project modules an import statement loads (``from pkg import sub`` counts as ``pkg.sub``)."""
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    else:
        if node.level:  # relative: from the module's package, up level - 1
            base = module.split(".") if is_pkg else module.split(".")[:-1]
            base = base[:len(base) - (node.level - 1)]
            prefix = ".".join(base + ([node.module] if node.module else []))
        else:
            prefix = node.module or ""
        names = [f"{prefix}.{a.name}" if f"{prefix}.{a.name}" in known else prefix for a in node.names]
    return {n for n in names if n in known}


def import_graph() -> dict[str, set[str]]:
    """``{module: the project modules it imports}``, from every import statement of its source."""
    modules = _modules()
    known = set(modules)
    graph = {}
    for name, (path, is_pkg) in modules.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        deps: set[str] = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                deps |= _targets(name, is_pkg, node, known)
        graph[name] = deps - {name}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    comp.append(m)
                    if m == node:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def test_01_the_graph_sees_lazy_and_relative_imports() -> None:
    graph = import_graph()
    # a function-level import, a relative one and a from-package-import-module one
    assert "validation.relight_demo" in graph["physrelight.cli"]
    assert "learned.checkpoint" in graph["learned.networks"]
    assert "synth.writer" in graph["synth.dataset"]
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": set()}) == []


def test_02_no_import_circles() -> None:
    found = circles(import_graph())
    assert not found, "import circles: " + "; ".join(" <-> ".join(c) for c in found)


def test_03_the_physics_core_imports_no_stage_but_through_the_cli_entry() -> None:
    graph = import_graph()
    bad = {m: sorted(d for d in deps if d.split(".")[0] in UPPER)
           for m, deps in graph.items() if m.split(".")[0] == "physrelight" and m != CLI_ENTRY}
    bad = {m: d for m, d in bad.items() if d}
    assert not bad, f"physrelight/ reaches up outside {CLI_ENTRY}: {bad}"


@pytest.mark.parametrize("lower, upper", [("synth", "learned"), ("synth", "validation"), ("learned", "validation")])
def test_04_layers_point_down(lower: str, upper: str) -> None:
    graph = import_graph()
    bad = {m: sorted(d for d in deps if d.split(".")[0] == upper)
           for m, deps in graph.items() if m.split(".")[0] == lower}
    assert not {m: d for m, d in bad.items() if d}


SKY_MASK_CORE = "physrelight.sky_mask"
SKY_MASK_NAMES = ("display_noise_sigma", "grow_sky_by_colour", "is_monochrome", "label_components", "log_noise_sigma",
                  "plausible_sky", "refine_sky_boundary", "resized_noise_roughness", "sky_colour_model", "sky_roughness")


def _defined_and_exported(path: Path) -> tuple[set[str], set[str]]:
    """The top-level functions and classes a module defines, and the names of its ``__all__``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    defined = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    exported: set[str] = set()
    for n in tree.body:
        if isinstance(n, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets):
            exported = {e.value for e in n.value.elts if isinstance(e, ast.Constant)}
    return defined, exported


def test_05_the_sky_masks_classical_processing_lives_in_the_core_once() -> None:
    """The plausibility test, the boundary by colour, the growth by colour and the components are image processing
    (issue 41): defined in :mod:`physrelight.sky_mask` only, which imports nothing but the core, and not re-exported
    by the segmenter's module."""
    modules = _modules()
    assert not {d for d in import_graph()[SKY_MASK_CORE] if d.split(".")[0] != "physrelight"}
    for name, (path, _) in modules.items():
        defined, exported = _defined_and_exported(path)
        if name == SKY_MASK_CORE:
            assert set(SKY_MASK_NAMES) <= defined and set(SKY_MASK_NAMES) <= exported
        else:
            assert not (defined | exported) & set(SKY_MASK_NAMES), f"{name} defines or exports {SKY_MASK_NAMES}"


def test_06_one_gaussian_blur() -> None:
    """The segmenter's camera softening, SkyGAN's smoothed sky and SSIM's window are one function,
    :func:`physrelight.filters.gaussian_blur` (issue 41): no other module defines a blur or a Gaussian kernel."""
    found = {}
    for name, (path, _) in _modules().items():
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.FunctionDef) and ("blur" in node.name.lower()
                                                      or "gaussian_1d" in node.name or "gaussian_filter" in node.name
                                                      or "gaussian_kernel" in node.name):
                found.setdefault(name, []).append(node.name)
    assert found == {"physrelight.filters": ["gaussian_kernel1d", "gaussian_blur"]}, found


# What is not learned lives in the core (issue 41): each name in its core module, none of them defined again in the
# relighter (which imports them).
CORE_HOMES = {
    "physrelight.image_input": ("as_batch", "as_image", "as_radiance", "give_back", "as_mask", "as_rotation"),
    "physrelight.target_lighting": ("sun_sky_map", "sun_lighting", "sky_map_kind", "sun_rgb",
                                    "clear_sky_sun", "overcast_level", "rotate_azimuth", "turned_camera",
                                    "target_lighting", "target_sun", "camera_target", "as_lighting_batch",
                                    "read_target"),
    "physrelight.sky_view": ("target_sky", "fitted_sky", "rendered_sky"),
    "physrelight.horizon": ("estimate_pitch", "pitch_from_verticals", "estimate_camera_pitch", "photo_camera"),
    "physrelight.exposure": ("dc_luminance", "exposure_scale", "match_exposure", "exposure_gain"),
    "physrelight.full_resolution": ("resize_short_side", "working_resolution", "transfer_to_full_resolution"),
}


def _defined(module: str) -> set[str]:
    """The functions, classes and methods a module defines (at any depth), read with ``ast``."""
    path, _ = _modules()[module]
    return {n.name for n in ast.walk(ast.parse(path.read_text()))
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))}


def test_07_the_non_learned_steps_live_in_the_core_and_the_relighter_imports_them() -> None:
    graph = import_graph()
    relighter = _defined("learned.relighter")
    for module, names in CORE_HOMES.items():
        assert not {d for d in graph[module] if d.split(".")[0] in UPPER}, module
        missing = set(names) - _defined(module)
        assert not missing, f"{module} lacks {sorted(missing)}"
        again = set(names) & relighter
        assert not again, f"learned.relighter defines {sorted(again)} again (their home is {module})"
    assert {"physrelight.target_lighting", "physrelight.sky_view", "physrelight.full_resolution"} <= graph[
        "learned.relighter"]
