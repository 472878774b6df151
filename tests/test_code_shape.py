"""Functions that fit on a screen and files that hold one concern: no function in src/ or the
package over 100 lines of code (docstrings, comments and blank lines aside), no file in src/,
python/ or scripts/ over 800 lines (tests aside: a Rust module's tests live in a `*_tests.rs`
or `tests.rs` file beside it once they would push it past), and no block nested more than 5
deep (the function's body is level 1) in the visibility field's room, whose views were the
hardest code in the house to follow."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 100
FILE_LIMIT = 800
DEPTH = 5
FN = re.compile(r"^\s*(pub(\([^)]*\))?\s+)?(const\s+)?(unsafe\s+)?(extern \"C\"\s+)?fn\s+(\w+)")


def _code(line: str) -> str:
    """A line without its comment, string and char literals (so braces in them do not count)."""
    line = re.sub(r'"([^"\\]|\\.)*"', '""', line)
    line = re.sub(r"'([^'\\]|\\.)'", "' '", line)
    return line.split("//")[0]


def rust_functions(path: Path) -> list[tuple[str, int, int, int]]:
    """(name, first line, lines of code, deepest block) of each Rust function in ``path``,
    nested functions counted on their own and within their parent."""
    lines = path.read_text().splitlines()
    out = []
    for i, line in enumerate(lines):
        m = FN.match(line)
        if not m:
            continue
        depth, started, code, deepest = 0, False, 0, 0
        for text in lines[i:]:
            stripped = text.strip()
            if stripped and not stripped.startswith("//"):
                code += 1
            for ch in _code(text):
                if ch == "{":
                    depth += 1
                    started = True
                    deepest = max(deepest, depth)
                elif ch == "}":
                    depth -= 1
            if started and depth == 0:
                break
            if not started and stripped.endswith(";"):
                break
        if started:
            out.append((m.group(6), i + 1, code, deepest))
    return out


def python_functions(path: Path) -> list[tuple[str, int, int]]:
    """(name, first line, lines of code) of each Python function, docstring aside."""
    src = path.read_text()
    lines = src.splitlines()
    out = []
    for node in ast.walk(ast.parse(src)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        start = node.body[0].lineno
        first = node.body[0]
        if isinstance(first, ast.Expr) and isinstance(getattr(first, "value", None), ast.Constant):
            start = first.end_lineno + 1
        body = lines[start - 1 : node.end_lineno]
        code = sum(1 for t in body if t.strip() and not t.strip().startswith("#"))
        out.append((node.name, node.lineno, code))
    return out


def test_no_function_is_over_100_lines():
    long = [
        f"{p.relative_to(ROOT)}:{line} {name} ({n} lines)"
        for p in sorted((ROOT / "src").rglob("*.rs"))
        for name, line, n, _ in rust_functions(p)
        if n > LIMIT
    ]
    long += [
        f"{p.relative_to(ROOT)}:{line} {name} ({n} lines)"
        for folder in ("python", "scripts")
        for p in sorted((ROOT / folder).rglob("*.py"))
        for name, line, n in python_functions(p)
        if n > LIMIT
    ]
    assert long == []


def code_files() -> list[Path]:
    """Every Rust and Python file of src/, python/ and scripts/, tests aside."""
    files = [p for p in (ROOT / "src").rglob("*.rs") if not p.name.endswith("tests.rs")]
    files += [p for folder in ("python", "scripts") for p in (ROOT / folder).rglob("*.py")]
    return sorted(files)


def test_no_file_is_over_800_lines():
    files = code_files()
    assert len(files) > 100
    long = [
        f"{p.relative_to(ROOT)} ({n} lines)"
        for p in files
        if (n := len(p.read_text().splitlines())) > FILE_LIMIT
    ]
    assert long == []


def test_the_field_nests_no_deeper_than_five():
    deep = [
        f"{p.relative_to(ROOT)}:{line} {name} (depth {d})"
        for p in sorted((ROOT / "src" / "visibility_field").glob("*.rs"))
        for name, line, _, d in rust_functions(p)
        if d > DEPTH
    ]
    assert deep == []


def test_the_measures_see_length_and_depth(tmp_path):
    body = "\n".join(f"    let x{i} = {i};" for i in range(120))
    deep = "fn deep() {\n    for a in b {\n        if c {\n            match d {\n" + (
        "                e => {\n                    if f {\n                        g();\n"
        "                    }\n                }\n            }\n        }\n    }\n}\n"
    )
    f = tmp_path / "x.rs"
    f.write_text(f"pub fn long() {{\n{body}\n}}\n// fn not_one() {{\n{deep}")
    found = {name: (n, d) for name, _, n, d in rust_functions(f)}
    assert found["long"][0] == 122 and found["deep"][1] == 6 and "not_one" not in found
