#!/usr/bin/env python3
"""Fails on a source file too long to read as one job (issue 15's bound).

Every C and C++ source file (.hpp, .cpp, .h, .c, .def, .ipp) under
channels/, routing/, actors/ and apps/, the benchmarks (apps/bench/)
aside, has at most MAX_LINES lines. A file past it mixes jobs: split it by
job, as routing/agent_tick.cpp and actors/asl_bindings.cpp were split off
their actors' files (docs/architecture.md, "Type IDs and errors",
which lists the tree's rules).

usage: check_file_sizes.py SOURCE_DIR | --self-test
Prints every file over the bound as file: N lines, and exits 1 if there is
one. --self-test checks the checker on a small tree.
"""

import sys
from pathlib import Path

MAX_LINES = 900
DIRS = ["channels", "routing", "actors", "apps"]
EXEMPT = ["apps/bench"]
SOURCES = {".hpp", ".cpp", ".h", ".c", ".def", ".ipp"}


def too_long(root: Path) -> list[str]:
    bad = []
    for top in DIRS:
        for path in sorted((root / top).rglob("*")):
            rel = path.relative_to(root).as_posix()
            if (path.suffix not in SOURCES or not path.is_file()
                    or any(rel.startswith(e + "/") for e in EXEMPT)):
                continue
            with path.open("rb") as f:
                n = sum(1 for _ in f)
            if n > MAX_LINES:
                bad.append(f"{rel}: {n} lines (at most {MAX_LINES})")
    return bad


def self_test() -> int:
    import tempfile
    files = {
        "channels/ok.cpp": MAX_LINES,
        "routing/long.cpp": MAX_LINES + 1,          # too long
        "actors/x/long.hpp": MAX_LINES + 50,        # too long, nested
        "apps/tool/main.c": MAX_LINES + 1,          # too long
        "apps/bench/bench.cpp": MAX_LINES * 2,      # exempt
        "actors/notes.md": MAX_LINES * 2,           # not source
        "tests/long_test.cpp": MAX_LINES * 2,       # not checked
    }
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for name, lines in files.items():
            path = root / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text("x\n" * lines)
        got = sorted(line.split(":")[0] for line in too_long(root))
    want = ["actors/x/long.hpp", "apps/tool/main.c", "routing/long.cpp"]
    if got != want:
        print(f"self-test failed: found {got}, expected {want}")
        return 1
    print("self-test passed: the three long files found, nothing else")
    return 0


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    if sys.argv[1] == "--self-test":
        return self_test()
    bad = too_long(Path(sys.argv[1]))
    for line in bad:
        print(line)
    if not bad:
        print(f"no source file under {', '.join(DIRS)} over {MAX_LINES} lines "
              f"({', '.join(EXEMPT)} aside)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
