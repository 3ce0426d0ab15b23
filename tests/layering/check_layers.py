#!/usr/bin/env python3
"""Fails on a back-edge between HERM's layers (docs/architecture.md, "Layers").

The layers, lowest first: channels/ (Network Interface Layer), routing/
(Network Adaptation Layer), actors/ (Application Support Layer and the
module's set-up). A file may include its own layer's headers and those of
the layers below, never a higher layer's, apps/ or tests/. The libraries'
CMake files obey the same order in what they link.

usage: check_layers.py SOURCE_DIR | --self-test
Prints every offending line as file:line: text, and exits 1 if there is one.
--self-test checks the checker on a small tree with one back-edge of each kind.
"""

import re
import sys
from pathlib import Path

LAYERS = ["channels", "routing", "actors"]
# Which top-level folders each layer may include from.
ALLOWED = {layer: set(LAYERS[: i + 1]) for i, layer in enumerate(LAYERS)}
# What a lower layer's libraries must not link (a higher layer's targets).
TARGETS = {
    "channels": ["herm_routing", "herm_runtime", "herm_system", "herm_asl",
                 "herm_marshal", "herm_module", "herm_config", "herm_control"],
    "routing": ["herm_runtime", "herm_system", "herm_asl", "herm_marshal",
                "herm_module", "herm_config", "herm_control"],
}
INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"/]+)/')
SOURCES = {".hpp", ".cpp", ".h", ".c", ".def", ".ipp"}


def check_includes(root: Path, layer: str) -> list[str]:
    bad = []
    for path in sorted((root / layer).rglob("*")):
        if path.suffix not in SOURCES or not path.is_file():
            continue
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
        for number, line in enumerate(lines, 1):
            match = INCLUDE.match(line)
            if not match:
                continue
            top = match.group(1)
            if top in ALLOWED[layer] or not (root / top).is_dir():
                continue
            bad.append(f"{path.relative_to(root)}:{number}: {line.strip()} "
                       f"({layer}/ may include only "
                       f"{', '.join(sorted(ALLOWED[layer]))})")
    return bad


def check_links(root: Path, layer: str) -> list[str]:
    bad = []
    for path in sorted((root / layer).rglob("CMakeLists.txt")):
        text = path.read_text(encoding="utf-8")
        for match in re.finditer(r"target_link_libraries\(([^)]*)\)", text):
            words = set(re.split(r"\s+", match.group(1)))
            for target in TARGETS.get(layer, []):
                if target in words:
                    number = text.count("\n", 0, match.start()) + 1
                    bad.append(f"{path.relative_to(root)}:{number}: links "
                               f"{target}, a higher layer's library")
    return bad


def find_back_edges(root: Path) -> list[str]:
    bad = []
    for layer in LAYERS:
        bad += check_includes(root, layer) + check_links(root, layer)
    return bad


def self_test() -> int:
    import tempfile
    files = {
        "channels/a.hpp": '#include "channels/b.hpp"\n#include "caf/atom.hpp"\n',
        "channels/b.cpp": '#include "routing/r.hpp"\n',           # back-edge
        "channels/CMakeLists.txt": "target_link_libraries(x PUBLIC herm_system)\n",
        "routing/r.hpp": '#include "channels/a.hpp"\n',
        "routing/r.cpp": '  #  include "actors/x.hpp"\n',          # back-edge
        "actors/x.hpp": '#include "routing/r.hpp"\n#include "apps/y.hpp"\n',
        "apps/y.hpp": "",
    }
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for name, text in files.items():
            (root / name).parent.mkdir(parents=True, exist_ok=True)
            (root / name).write_text(text)
        found = sorted(line.split(":")[0] for line in find_back_edges(root))
    expected = ["actors/x.hpp", "channels/CMakeLists.txt", "channels/b.cpp",
                "routing/r.cpp"]
    if found != expected:
        print(f"self-test: found {found}, expected {expected}")
        return 1
    print("self-test: every planted back-edge found, nothing else")
    return 0


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__.strip().splitlines()[-3], file=sys.stderr)
        return 2
    if sys.argv[1] == "--self-test":
        return self_test()
    root = Path(sys.argv[1])
    bad = find_back_edges(root)
    for line in bad:
        print(line)
    if bad:
        print(f"{len(bad)} back-edge(s) between layers", file=sys.stderr)
        return 1
    print("layers in order: no back-edges in "
          + ", ".join(f"{layer}/" for layer in LAYERS))
    return 0


if __name__ == "__main__":
    sys.exit(main())
