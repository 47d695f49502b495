#!/usr/bin/env python3
"""Functions and files over a size limit in the workspace's Rust code, outside tests.

    scripts/room_sizes.py [--fn-max 150] [--file-max 800] [--all] [PATH ...]

Counts, for every `.rs` file under `src/`, `crates/*/src/`, `benches/` and `examples/` (or the
paths given), the lines of each `fn` body (from the line of `fn` to its closing brace) and the
lines of the file outside `#[cfg(test)]` modules. Test code is left out: files under a `tests/`
directory, files named `tests.rs`, and `#[cfg(test)] mod … { … }` blocks. Prints every function
over `--fn-max` lines and every file over `--file-max` lines (all of them with `--all`) and exits
1 when there is one, so it can run in CI.

The brace matching skips string literals, char literals and comments; it is a line counter, not
a parser, so a macro that opens more braces than it closes would confuse it (none does here).
"""

import argparse
import re
import sys
from pathlib import Path

FN = re.compile(r"^\s*(pub(\([^)]*\))?\s+)?((const|async|unsafe|extern\s+\"C\")\s+)*fn\s+(\w+)")
CFG_TEST = re.compile(r"^\s*#\[cfg\(test\)\]\s*$")
MOD_OPEN = re.compile(r"^\s*(pub(\([^)]*\))?\s+)?mod\s+\w+\s*\{")


def strip(line, state):
    """The line's code with strings, chars and comments blanked; `state` carries an open block
    comment or raw string across lines."""
    out = []
    i, n = 0, len(line)
    while i < n:
        if state["block"]:
            j = line.find("*/", i)
            if j < 0:
                return "".join(out)
            state["block"] = False
            i = j + 2
            continue
        if state["str"]:
            if line[i] == "\\" and not state["raw"]:
                i += 2
                continue
            if line[i] == '"' and line.startswith('"' + "#" * state["hashes"], i):
                state["str"] = False
                i += 1 + state["hashes"]
                continue
            i += 1
            continue
        c = line[i]
        if line.startswith("//", i):
            break
        if line.startswith("/*", i):
            state["block"] = True
            i += 2
            continue
        m = re.match(r'r(#*)"', line[i:])
        if m and (i == 0 or not (line[i - 1].isalnum() or line[i - 1] == "_")):
            state.update(str=True, raw=True, hashes=len(m.group(1)))
            i += len(m.group(0))
            continue
        if c == '"':
            state.update(str=True, raw=False, hashes=0)
            i += 1
            continue
        if c == "'":
            m = re.match(r"'(\\.|\\u\{[0-9a-fA-F]+\}|[^\\'])'", line[i:])
            if m:
                i += len(m.group(0))
                continue
        out.append(c)
        i += 1
    return "".join(out)


def measure(path):
    """(code lines outside test modules, [(fn name, first line, length)])."""
    lines = path.read_text(encoding="utf-8").splitlines()
    state = {"block": False, "str": False, "raw": False, "hashes": 0}
    code = [strip(l, state) for l in lines]
    depth = 0
    test_until = None  # depth at which a #[cfg(test)] module closes
    pending_test = False
    open_fns = []  # (name, start line, depth before its body)
    fns = []
    test_lines = 0
    for no, (raw, c) in enumerate(zip(lines, code), start=1):
        in_test = test_until is not None
        if in_test:
            test_lines += 1
        if CFG_TEST.match(raw):
            pending_test = True
        elif pending_test and MOD_OPEN.match(c) and test_until is None:
            test_until = depth
            test_lines += 1
            pending_test = False
        elif raw.strip() and not raw.strip().startswith("#"):
            pending_test = False
        m = FN.match(c)
        if m and not in_test and "{" in c[m.end():] or (m and not in_test and ";" not in c):
            open_fns.append([m.group(5), no, depth, False])
        for ch in c:
            if ch == "{":
                depth += 1
                for f in open_fns:
                    if not f[3] and f[2] == depth - 1:
                        f[3] = True
            elif ch == "}":
                depth -= 1
                while open_fns and open_fns[-1][3] and open_fns[-1][2] == depth:
                    name, start, _, _ = open_fns.pop()
                    fns.append((name, start, no - start + 1))
                if test_until is not None and depth == test_until:
                    test_until = None
            elif ch == ";":
                # `fn f(...);` in a trait: no body.
                if open_fns and not open_fns[-1][3] and open_fns[-1][2] == depth:
                    open_fns.pop()
    return len(lines) - test_lines, fns


def rust_files(roots):
    for root in roots:
        p = Path(root)
        files = [p] if p.is_file() else sorted(p.rglob("*.rs"))
        for f in files:
            parts = f.parts
            if "tests" in parts or f.name == "tests.rs" or "target" in parts:
                continue
            yield f


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*")
    ap.add_argument("--fn-max", type=int, default=150)
    ap.add_argument("--file-max", type=int, default=800)
    ap.add_argument("--all", action="store_true", help="list every function and file, largest first")
    a = ap.parse_args()
    roots = a.paths or ["src", *map(str, sorted(Path("crates").glob("*/src"))), "benches", "examples"]
    over = 0
    rows_fn, rows_file = [], []
    for f in rust_files(roots):
        n, fns = measure(f)
        rows_file.append((n, str(f)))
        for name, start, length in fns:
            rows_fn.append((length, f"{f}:{start} {name}"))
    for n, f in sorted(rows_file, reverse=True):
        if a.all or n > a.file_max:
            print(f"file {n:5} lines  {f}")
            over += n > a.file_max
    for n, f in sorted(rows_fn, reverse=True):
        if a.all or n > a.fn_max:
            print(f"fn   {n:5} lines  {f}")
            over += n > a.fn_max
    print(f"{over} over the limits (functions > {a.fn_max} lines, files > {a.file_max} lines, tests left out)")
    sys.exit(1 if over else 0)


if __name__ == "__main__":
    main()
