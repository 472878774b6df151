"""The house has floors: no import cycle between the top-level Rust modules of src/, nor between
the files of one Rust folder, nor between the Python modules of the package (function-local
imports included)."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "python" / "scenesample"


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in list(edges):
        if v not in index:
            visit(v)
    return out


def rust_graph() -> dict[str, set[str]]:
    src = ROOT / "src"
    mods = {p.stem for p in src.iterdir() if p.suffix == ".rs" and p.stem != "lib"}
    mods |= {p.name for p in src.iterdir() if p.is_dir() and p.name != "py"}
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for m in mods:
        files = list((src / m).rglob("*.rs")) if (src / m).is_dir() else [src / f"{m}.rs"]
        for f in files:
            text = re.sub(r"//.*", "", f.read_text())
            for g in re.findall(r"crate::(\{[^}]*\}|\w+)", text):
                names = re.findall(r"(?:^|[{,]\s*)(\w+)", g) if g.startswith("{") else [g]
                edges[m] |= {n for n in names if n in mods and n != m}
    return edges


def sibling_graph(folder: Path) -> dict[str, set[str]]:
    """Which files of one Rust folder name which others (`super::x`, `crate::<folder>::x`,
    tests included). The folder's `mod.rs` is its facade, which re-exports and which every
    file may lean on, so it is left out."""
    files = {p.stem: p for p in folder.glob("*.rs") if p.stem not in ("mod", "lib")}
    path = "::".join(folder.relative_to(ROOT / "src").parts)
    edges: dict[str, set[str]] = {m: set() for m in files}
    for m, f in files.items():
        text = re.sub(r"//.*", "", f.read_text())
        text = re.sub(r"(?m)^\s*(pub(\([^)]*\))?\s+)?mod\s+\w+\s*;", "", text)
        groups = re.findall(r"\bsuper::(\{[^}]*\}|\w+)", text)
        if path:
            groups += re.findall(r"\bcrate::" + re.escape(path) + r"::(\{[^}]*\}|\w+)", text)
        for g in groups:
            names = re.findall(r"(?:^|[{,]\s*)(\w+)", g) if g.startswith("{") else [g]
            edges[m] |= {n for n in names if n in files and n != m}
    return edges


def python_graph() -> dict[str, set[str]]:
    names = {
        ".".join(p.relative_to(PACKAGE.parent).with_suffix("").parts): p
        for p in PACKAGE.rglob("*.py")
    }
    names = {k.removesuffix(".__init__"): v for k, v in names.items()}
    names["scenesample._core"] = PACKAGE / "_core.pyi"  # the native module, through its stub
    edges: dict[str, set[str]] = {k: set() for k in names}
    for mod, path in names.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.ImportFrom):
                base = package
                for _ in range(node.level - 1):
                    base = base.rpartition(".")[0]
                stem = (
                    (base + "." + node.module if node.module else base)
                    if node.level
                    else (node.module or "")
                )
                # A submodule imports that module; any other name is an attribute of the stem
                # (for the package itself, an import from its facade).
                targets = [
                    f"{stem}.{a.name}" if f"{stem}.{a.name}" in names else stem for a in node.names
                ]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            for t in targets:
                if t in names and t != mod:
                    edges[mod].add(t)
    return edges


#: One Rust room and one Python subpackage per paper's method.
ROOMS = {"nonredundant", "epr", "visibility_field", "impostors"}
#: The floors below the rooms, which no paper owns.
FLOORS = {"scene", "trace", "gpu", "image", "calibration", "shading", "shadow_rays", "types"}


def test_rust_modules_form_no_cycle():
    edges = rust_graph()
    assert ROOMS | FLOORS <= set(edges)
    assert cycles(edges) == []
    # The shared types sit below every room; the scene names none of its users.
    assert edges["types"] <= {"camera", "error", "scene"}
    assert edges["scene"] <= {"camera", "error"}


def test_each_paper_has_one_room_over_shared_floors():
    """No room reaches into another paper's room, and no floor into any room: what two papers
    share lives on a floor."""
    edges = rust_graph()
    for room in ROOMS:
        assert edges[room] & ROOMS == set(), room
    for floor in set(edges) - ROOMS:
        assert edges[floor] & ROOMS == set(), floor
    py = python_graph()
    rooms = {f"scenesample.{r}" for r in ROOMS}
    assert rooms <= set(py)
    for mod, targets in py.items():
        own = next((r for r in rooms if mod == r or mod.startswith(r + ".")), None)
        other = {t for t in targets for r in rooms - {own} if t == r or t.startswith(r + ".")}
        # The package's facade, the verbs and the tools dispatch to the rooms; rooms and the
        # shared modules below them do not lean on another paper's room.
        if own is not None:
            assert other == set(), (mod, other)


def test_the_files_of_each_rust_folder_form_no_cycle():
    folders = [p for p in (ROOT / "src").rglob("*") if p.is_dir()]
    found = {str(f.relative_to(ROOT)): c for f in folders if (c := cycles(sibling_graph(f)))}
    assert found == {}
    # The graph sees the edges it must: the raster rule takes its rays from `pixels`.
    image = sibling_graph(ROOT / "src" / "image")
    assert "pixels" in image["raster_rule"]
    assert "raster_rule" not in image["pixels"]


def test_python_modules_form_no_cycle():
    edges = python_graph()
    assert "scenesample._api" in edges and "scenesample.methods" in edges
    assert cycles(edges) == []


def test_the_cycle_finder_finds_cycles():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []
