#!/usr/bin/env python3
"""Docs that cannot rot: every fenced block is checked against what builds.

A marker is an HTML comment on the line(s) directly above a fenced block
(several may stack). What each one means:

  <!-- quote: PATH REGION -->   the block equals the lines between
      `// [REGION]` and `// [REGION]-end` (or `# [REGION]` ... for YAML,
      CMake, shell) in PATH, indentation common to all of them removed.
      --fix rewrites such blocks from the code.
  <!-- excerpt: PATH -->        every non-blank line of the block, stripped,
      is a line of PATH, in the same order (PATH's lines in between, such as
      comments, may be left out). For code in files the doc may not mark.
  <!-- config: valid [with BASE] -->
  <!-- config: invalid "TEXT" [with BASE] -->
      the block (appended to the file BASE when given: a fragment) is fed to
      `hermd --check`: it must exit 0, or exit non-zero printing TEXT.
  <!-- run: DIR -->              each `$ hermd ...` / `$ hermctl ...` line is
      run (no shell) in DIR with the built binaries; its standard output then
      standard error must equal the lines that follow it, up to the next `$`.
  <!-- usage -->                 command lines (with or without `$ `, `sudo`):
      hermd and hermctl lines may use only options their `--help` lists (a
      hermctl subcommand's own options from `hermctl SUB --help`) and only
      subcommands `hermctl --help` lists; `build/bin/NAME` must be a built
      program. Other programs' lines are not checked; at least one must be.
  <!-- json: PATH... -->          every `"key":` (and every `"cmd"` value) in
      the block appears as a string literal "key" in one of the PATHs.
  <!-- test: NAME -->             checked by tests/docs/doc_examples_test.cpp,
      whose case NAME compares the block with what the code produces (wire
      bytes, decoder errors); this checker only makes sure NAME is there.
  <!-- session: STEP -->          a step of the user guide's worked session
      ("Tools"): tests/docs/tools_session.py starts its modules, runs the
      step's commands and compares what they print with the block (times
      and rates masked); this checker only makes sure STEP is there.
  <!-- unchecked: REASON -->      deliberately not checked (a prose diagram,
      a standard tool's command line); REASON says why.

In STRICT docs every fenced block needs a marker; elsewhere (other docs,
README.md) only marked blocks are checked.

usage: check_quotes.py [--fix] [--hermd PATH --hermctl PATH] [--root DIR]
       check_quotes.py --self-test
Without --hermd/--hermctl the config, run and usage markers are refused (the
suite always passes them). Exit 1 names every block that differs.
"""
import os
import pathlib
import re
import shlex
import subprocess
import sys
import tempfile

STRICT = ["docs/architecture.md", "docs/protocol.md", "docs/user-guide.md"]
MARK = re.compile(r"^<!-- ([a-z]+)(?::\s*(.*?))?\s*-->\s*$")
KINDS = {"quote", "excerpt", "config", "run", "usage", "json", "test",
         "session", "unchecked"}
NEEDS_BINARIES = {"config", "run", "usage"}
DOC_TEST = "tests/docs/doc_examples_test.cpp"
SESSION = "tests/docs/tools_session.py"
RUN_TIMEOUT = 20  # seconds per command; a daemon that does not stop fails


class Mismatch(Exception):
    """A block that does not match; the message says how."""


# -- the sources ----------------------------------------------------------

def region(root, path, name):
    lines = (root / path).read_text().splitlines()
    starts = (f"// [{name}]", f"# [{name}]")
    ends = (f"// [{name}-end]", f"# [{name}-end]")
    try:
        begin = next(i for i, l in enumerate(lines) if l.strip() in starts)
        end = next(i for i, l in enumerate(lines)
                   if i > begin and l.strip() in ends)
    except StopIteration:
        raise Mismatch(f"{path}: no region '// [{name}]' ... '// [{name}-end]'")
    body = lines[begin + 1:end]
    indent = min((len(l) - len(l.lstrip()) for l in body if l.strip()), default=0)
    return [l[indent:] for l in body]


def check_excerpt(root, path, block):
    source = [l.strip() for l in (root / path).read_text().splitlines()]
    at = 0
    for line in (l.strip() for l in block if l.strip()):
        try:
            at = source.index(line, at) + 1
        except ValueError:
            raise Mismatch(f"line '{line}' is not in {path} (in this order)")


def check_json(root, paths, block):
    text = "".join((root / p).read_text() for p in paths)
    body = "\n".join(block)
    # Module ids used as keys ("seqs": {"0x42": 3}) are data, not names.
    words = {w for w in re.findall(r'"(\w+)"\s*:', body)
             if not re.fullmatch(r"0x[0-9a-fA-F]+", w)}
    words |= set(re.findall(r'"cmd"\s*:\s*"(\w+)"', body))
    missing = sorted(w for w in words if f'"{w}"' not in text)
    if missing:
        raise Mismatch(f"keys not in {' '.join(paths)}: {', '.join(missing)}")


def check_test_name(root, name):
    if f'"{name}"' not in (root / DOC_TEST).read_text():
        raise Mismatch(f"{DOC_TEST} has no case \"{name}\"")


def check_session_step(root, name):
    if f'"{name}": step_{name}' not in (root / SESSION).read_text():
        raise Mismatch(f"{SESSION} has no step \"{name}\"")


# -- the binaries ---------------------------------------------------------

class Binaries:
    def __init__(self, hermd, hermctl):
        self.paths = {"hermd": hermd, "hermctl": hermctl}
        self.bin_dir = pathlib.Path(hermd).parent
        self.helps = {}

    def help(self, *args):
        if args not in self.helps:
            out = subprocess.run([self.paths[args[0]], *args[1:], "--help"],
                                 capture_output=True, text=True,
                                 timeout=RUN_TIMEOUT)
            self.helps[args] = out.stdout + out.stderr
        return self.helps[args]

    def run(self, argv, cwd):
        argv = [self.paths.get(argv[0], argv[0])] + argv[1:]
        try:
            out = subprocess.run(argv, cwd=cwd, capture_output=True, text=True,
                                 timeout=RUN_TIMEOUT)
        except subprocess.TimeoutExpired:
            raise Mismatch(f"'{' '.join(argv)}' ran for {RUN_TIMEOUT} s")
        return out.returncode, out.stdout + out.stderr


def options_of(help_text):
    """Option name -> whether it takes a value, from a CLI11 help text."""
    found = {}
    for m in re.finditer(r"^\s+((?:-\w,)?--[\w-]+)( [A-Z])?", help_text, re.M):
        for name in m.group(1).split(","):
            found[name] = bool(m.group(2))
    return found


def subcommands_of(help_text):
    part = help_text.split("Subcommands:", 1)
    if len(part) < 2:
        return set()
    names = set()
    for line in part[1].splitlines():
        m = re.match(r"^  ([^\s,]+(?:,\s*[^\s,]+)*)\s", line)
        if m:
            names |= {n.strip() for n in m.group(1).split(",")}
    return names


def check_command(bins, argv, where):
    """True when argv is a command this checker knows and it is valid."""
    prog = argv[0]
    if prog.startswith("build/bin/"):
        if not (bins.bin_dir / prog[len("build/bin/"):]).exists():
            raise Mismatch(f"{where}: {prog} is not a built program")
        return True
    if prog not in ("hermd", "hermctl"):
        return False
    opts = options_of(bins.help(prog))
    sub = []  # the subcommand and its own subcommands (topic echo)
    i = 1
    while i < len(argv):
        word = argv[i]
        name = word.split("=", 1)[0]
        if word.startswith("-"):
            if name not in opts:
                raise Mismatch(f"{where}: {' '.join([prog] + sub)} "
                               f"has no option {name}")
            if opts[name] and "=" not in word:
                i += 1
        elif prog == "hermctl" and not sub:
            if word not in subcommands_of(bins.help("hermctl")):
                raise Mismatch(f"{where}: hermctl has no subcommand {word}")
            sub = [word]
            opts = dict(opts, **options_of(bins.help("hermctl", *sub)))
        elif prog == "hermctl" and word in subcommands_of(
                bins.help("hermctl", *sub)):
            sub.append(word)
            opts = dict(opts, **options_of(bins.help("hermctl", *sub)))
        i += 1
    return True


def commands(line):
    """The command lines of one shell line: split at && ; | &, comments cut."""
    line = line.strip()
    if line.startswith("$ "):
        line = line[2:]
    lexer = shlex.shlex(line, posix=True, punctuation_chars="&;|")
    lexer.whitespace_split = True
    lexer.commenters = "#"
    out, cur = [], []
    for token in lexer:
        if set(token) <= set("&;|"):
            out.append(cur)
            cur = []
        else:
            cur.append(token)
    out.append(cur)
    for argv in out:
        while argv and argv[0] in ("sudo", "exec"):
            argv.pop(0)
    return [a for a in out if a]


def check_usage(bins, block):
    dollar = any(l.startswith("$ ") for l in block)
    checked = 0
    for n, line in enumerate(block, 1):
        if dollar and not line.startswith("$ "):
            continue  # output
        for argv in commands(line):
            checked += check_command(bins, argv, f"line {n}")
    if not checked:
        raise Mismatch("no hermd, hermctl or build/bin/ command to check")


def check_run(root, bins, cwd, block):
    steps, cmd, want = [], None, []
    for line in block + ["$ "]:
        if line.startswith("$ ") or line == "$":
            if cmd is not None:
                steps.append((cmd, want))
            cmd, want = line[2:], []
        elif cmd is None:
            raise Mismatch("a run block starts with a `$ ` command")
        else:
            want.append(line.rstrip())
    for cmd, want in steps:
        argv = shlex.split(cmd)
        if argv[0] not in ("hermd", "hermctl"):
            raise Mismatch(f"run: only hermd and hermctl are run, not {argv[0]}")
        check_command(bins, argv, cmd)
        _, out = bins.run(argv, root / cwd)
        got = [l.rstrip() for l in out.splitlines()]
        if got != want:
            raise Mismatch(f"'{cmd}' printed:\n    " + "\n    ".join(got))


def check_config(root, bins, args, block):
    m = re.fullmatch(r'(valid|invalid "([^"]*)")(?: with (\S+))?', args)
    if not m:
        raise Mismatch(f"config marker '{args}': expected valid or "
                       'invalid "TEXT", optionally "with BASE"')
    text = "\n".join(block) + "\n"
    if m.group(3):
        text = (root / m.group(3)).read_text() + text
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "doc.yaml"
        path.write_text(text)
        status, out = bins.run(["hermd", "--check", str(path)], tmp)
    if m.group(1) == "valid" and status != 0:
        raise Mismatch(f"hermd --check refused it: {out.strip()}")
    if m.group(1) != "valid" and (status == 0 or m.group(2) not in out):
        raise Mismatch(f"hermd --check (status {status}) did not say "
                       f"'{m.group(2)}': {out.strip()}")


# -- the docs -------------------------------------------------------------

def blocks(lines):
    """(markers, index of the opening fence, index of the closing fence)."""
    i = 0
    while i < len(lines):
        if not lines[i].startswith("```"):
            i += 1
            continue
        markers, k = [], i - 1
        while k >= 0 and MARK.match(lines[k]):
            m = MARK.match(lines[k])
            markers.insert(0, (m.group(1), m.group(2) or ""))
            k -= 1
        j = i + 1
        while j < len(lines) and not lines[j].startswith("```"):
            j += 1
        yield markers, i, j
        i = j + 1


def check_block(root, bins, kind, args, body):
    """Returns the lines the block should hold (for --fix), or None."""
    if kind in NEEDS_BINARIES and bins is None:
        raise Mismatch(f"'{kind}' needs --hermd and --hermctl")
    if kind == "quote":
        path, name = args.split()
        want = region(root, path, name)
        if body != want:
            raise Mismatch(f"differs from {path} [{name}]", want)
    elif kind == "excerpt":
        check_excerpt(root, args, body)
    elif kind == "json":
        check_json(root, args.split(), body)
    elif kind == "test":
        check_test_name(root, args)
    elif kind == "session":
        check_session_step(root, args)
    elif kind == "usage":
        check_usage(bins, body)
    elif kind == "run":
        check_run(root, bins, args, body)
    elif kind == "config":
        check_config(root, bins, args, body)
    elif kind == "unchecked" and not args:
        raise Mismatch("unchecked needs a reason")


def check_doc(root, doc, bins, fix, counts):
    rel = doc.relative_to(root).as_posix()
    lines = doc.read_text().splitlines()
    bad, fixes = [], {}
    for markers, i, j in blocks(lines):
        where = f"{rel}:{i + 1}"
        if not markers and rel in STRICT:
            bad.append(f"{where}: a fenced block without a marker "
                       "(see tests/docs/check_quotes.py)")
        for kind, args in markers:
            if kind not in KINDS:
                bad.append(f"{where}: unknown marker '{kind}'")
                continue
            counts[kind] = counts.get(kind, 0) + 1
            try:
                check_block(root, bins, kind, args, lines[i + 1:j])
            except Mismatch as e:
                bad.append(f"{where}: {kind}: {e.args[0]}")
                if len(e.args) > 1:
                    fixes[(i, j)] = e.args[1]
    if fix and fixes:
        for (i, j), want in sorted(fixes.items(), reverse=True):
            lines[i + 1:j] = want
        doc.write_text("\n".join(lines) + "\n")
    return bad


def check_tree(root, bins, fix=False):
    docs = sorted((root / "docs").glob("*.md")) + [root / "README.md"]
    counts, bad = {}, []
    for doc in docs:
        if doc.exists():
            bad += check_doc(root, doc, bins, fix, counts)
    return bad, counts


# -- self-test ------------------------------------------------------------

FAKE_HERMD = r"""#!/bin/sh
case "$1" in
  --help) printf 'Usage: hermd [OPTIONS] config\nOptions:\n  -h,--help  help\n  --check  validate\n  --log-level TEXT  level\n'; exit 0;;
  --check) if grep -q bad "$2"; then echo "hermd: $2:1: module.id: bad" >&2; exit 2; fi; exit 0;;
  *) echo "hermd: ran $1" >&2; exit 1;;
esac
"""
FAKE_HERMCTL = r"""#!/bin/sh
if [ "$1" = --help ]; then printf 'Options:\n  --module TEXT  m\n  --json  j\nSubcommands:\n  info  i\n  ping  p\n  topic  t\n'; exit 0; fi
if [ "$2" = --help ]; then printf 'Options:\n  -c,--count UINT  n\nSubcommands:\n  echo  e\n'; exit 0; fi
if [ "$3" = --help ]; then printf 'Options:\n  -n,--times UINT  n\n'; exit 0; fi
echo "$@"
"""
GOOD = {
    "src/a.cpp": "int x;\n  // [r]\n  int f() { return 1; }\n  // [r-end]\n"
                 "// note\nint g();\nint h();\n",
    "src/j.cpp": 'j = {{"cmd", 0}, {"ok", 1}, {"result", 2}, {"info", 3}};\n',
    "src/base.yaml": "module: { id: 1 }\n",
    "tests/docs/doc_examples_test.cpp": 'case("golden")\n',
    "tests/docs/tools_session.py": 'STEPS = {"start": step_start}\n',
    "tests/docs/fixtures/.keep": "",
}
BLOCKS = [  # (marker, good block, the same block planted with a mismatch)
    ("quote: src/a.cpp r", "int f() { return 1; }", "int f() { return 2; }"),
    ("excerpt: src/a.cpp", "int g();\nint h();", "int h();\nint g();"),
    ("config: valid", "module: { id: 1 }", "module: { id: bad }"),
    ('config: invalid "module.id: bad" with src/base.yaml', "bad: 1",
     "fine: 1"),
    ("run: tests/docs/fixtures", "$ hermctl info\ninfo", "$ hermctl info\nhello"),
    ("usage", "$ hermctl --module 0x31 ping 0x32 -c 3\nout\nhermd --check x",
     "hermd --log-levels debug x.yaml"),
    ("usage", "hermctl --json info", "hermctl --json neighbours"),
    ("usage", "hermctl topic echo x -n 3 --json", "hermctl topic echo x --rate 3"),
    ("usage", "build/bin/hermd x.yaml", "build/bin/herm-gone x.yaml"),
    ("json: src/j.cpp", '{"cmd": "info"}\n{"ok": true, "result": 1}',
     '{"ok": true, "results": 1}'),
    ("test: golden", "01 02", None),
    ("session: start", "$ hermctl modules", None),
    ("unchecked: a diagram", "a | b", None),
]


def self_test():
    with tempfile.TemporaryDirectory() as tmp:
        root = pathlib.Path(tmp)
        for name, text in GOOD.items():
            (root / name).parent.mkdir(parents=True, exist_ok=True)
            (root / name).write_text(text)
        bins = []
        for name, text in (("hermd", FAKE_HERMD), ("hermctl", FAKE_HERMCTL)):
            path = root / "bin" / name
            path.parent.mkdir(exist_ok=True)
            path.write_text(text)
            path.chmod(0o755)
            bins.append(str(path))
        binaries = Binaries(*bins)
        doc = root / "docs" / "protocol.md"
        doc.parent.mkdir()

        def fenced(marker, body):
            return f"<!-- {marker} -->\n```\n{body}\n```\n\n"

        doc.write_text("".join(fenced(m, g) for m, g, _ in BLOCKS))
        bad, _ = check_tree(root, binaries)
        if bad:
            print("self-test: good blocks refused:\n  " + "\n  ".join(bad))
            return 1
        planted = [(m, b) for m, _, b in BLOCKS if b is not None]
        planted += [("test: gone", "01"), ("unchecked", "x"),
                    ("quotes: src/a.cpp r", "x")]
        failures = []
        for marker, body in planted:
            doc.write_text(fenced(marker, body))
            if not check_tree(root, binaries)[0]:
                failures.append(marker)
        doc.write_text("```\nno marker\n```\n")
        if not check_tree(root, binaries)[0]:
            failures.append("(no marker)")
        doc.write_text(fenced("quote: src/a.cpp r", "stale"))
        check_tree(root, binaries, fix=True)
        if check_tree(root, binaries)[0]:
            failures.append("--fix")
    if failures:
        print("self-test: planted mismatches not found: " + ", ".join(failures))
        return 1
    print(f"self-test: all {len(planted) + 2} planted mismatches found, "
          f"{len(BLOCKS)} good blocks pass")
    return 0


def main():
    args = sys.argv[1:]
    if args == ["--self-test"]:
        return self_test()

    def value(flag):
        if flag in args:
            return args[args.index(flag) + 1]
        return None

    root = pathlib.Path(value("--root") or pathlib.Path(__file__).resolve().parents[2])
    bins = None
    if value("--hermd") and value("--hermctl"):
        bins = Binaries(os.path.abspath(value("--hermd")),
                        os.path.abspath(value("--hermctl")))
    fix = "--fix" in args
    bad, counts = check_tree(root, bins, fix)
    for b in bad:
        print(b)
    summary = ", ".join(f"{n} {k}" for k, n in sorted(counts.items()))
    print(f"markers checked: {summary}; {len(bad)} problem(s)"
          + (" (quotes fixed)" if fix and bad else ""))
    return 1 if bad and not fix else 0


if __name__ == "__main__":
    sys.exit(main())
