#!/usr/bin/env python3
"""Docs quote compiled code: every fenced block in docs/*.md and README.md
that follows a marker line

    <!-- quote: path/to/file.cpp region -->

must equal the lines between `// [region]` and `// [region-end]` in that
file (indentation common to all of them removed). With --fix, the blocks are
rewritten from the code instead. Exit 1 names every block that differs."""
import pathlib
import re
import sys

MARK = re.compile(r"^<!-- quote: (\S+) (\S+) -->\s*$")


def region(root, path, name):
    lines = (root / path).read_text().splitlines()
    try:
        begin = next(i for i, l in enumerate(lines) if l.strip() == f"// [{name}]")
        end = next(i for i, l in enumerate(lines)
                   if i > begin and l.strip() == f"// [{name}-end]")
    except StopIteration:
        raise SystemExit(f"{path}: no region '// [{name}]' ... '// [{name}-end]'")
    body = lines[begin + 1:end]
    indent = min((len(l) - len(l.lstrip()) for l in body if l.strip()), default=0)
    return [l[indent:] for l in body]


def main():
    root = pathlib.Path(__file__).resolve().parents[2]
    fix = "--fix" in sys.argv
    docs = sorted((root / "docs").glob("*.md")) + [root / "README.md"]
    bad, quotes = [], 0
    for doc in docs:
        lines = doc.read_text().splitlines()
        out, i = [], 0
        while i < len(lines):
            out.append(lines[i])
            m = MARK.match(lines[i])
            i += 1
            if not m:
                continue
            quotes += 1
            if i >= len(lines) or not lines[i].startswith("```"):
                raise SystemExit(f"{doc.name}:{i}: a quote marker must precede a fenced block")
            out.append(lines[i])
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            want = region(root, m.group(1), m.group(2))
            if lines[i + 1:j] != want:
                bad.append(f"{doc.name}:{i + 1}: differs from {m.group(1)} [{m.group(2)}]")
            out.extend(want)
            i = j
        if fix:
            doc.write_text("\n".join(out) + "\n")
    for b in bad:
        print(b)
    print(f"{quotes} quotes checked, {len(bad)} differ" + (" (fixed)" if fix and bad else ""))
    return 1 if bad and not fix else 0


if __name__ == "__main__":
    sys.exit(main())
