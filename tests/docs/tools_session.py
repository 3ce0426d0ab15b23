#!/usr/bin/env python3
"""The user guide's worked session ("Tools"), run for real and compared.

  tools_session.py --bin DIR [--root DIR] [--keep]

DIR holds the built hermd, hermctl and herm-example-calculator. The script
reads docs/user-guide.md's chapter "Tools": its three configuration blocks
(`# NAME.yaml` on their first line) become the files of three real
modules, and every block marked `<!-- session: STEP -->` is a step below.
Each `$ ` command of a step is run as the chapter says (in the background
where it says `&`, ends with `^C` or `...`, or runs "while" another
command runs) and what it prints, standard output and standard error as
they came, must equal the lines the block shows under it.

What differs from run to run is masked on both sides before they are
compared (MASKS: times, rates, sizes, the number of values a 10 Hz
publisher managed in three seconds); everything else must match to the
character: tables, values, sequence numbers, types, errors. /tmp/herm-tools
is replaced by a fresh temporary folder; the modules use UDP ports
47400..47402 on loopback (the test holds a CTest resource lock on them).
Exit status 0 when every step matched, 1 with a diff otherwise.
"""
import argparse
import os
import pathlib
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

DOC = "docs/user-guide.md"
CHAPTER = "## Tools"
DOC_DIR = "/tmp/herm-tools"
MARK = re.compile(r"^<!-- ([a-z]+)(?::\s*(.*?))?\s*-->\s*$")

# (pattern, replacement) applied to every line of both sides.
MASKS = [
    (re.compile(r'"time_ns":\d+'), '"time_ns":#'),
    (re.compile(r"as APO \d+"), "as APO #"),
    (re.compile(r"average rate: [\d.]+"), "average rate: #"),
    (re.compile(r"min: [\d.]+s max: [\d.]+s std dev: [\d.]+s window: \d+"),
     "min: #s max: #s std dev: #s window: #"),
    (re.compile(r"^(Bag size: +)\d+ B$"), r"\1# B"),
    (re.compile(r"^(Duration: +)[\d.]+s$"), r"\1#s"),
    (re.compile(r"^(Start: +|End: +)[\d-]+ [\d:.]+$"), r"\1#"),
    (re.compile(r"^(Messages: +)\d+$"), r"\1#"),
    (re.compile(r"(recorded|played) \d+ messages"), r"\1 # messages"),
    (re.compile(r"(Topic: sensors\.range .*Count: )\d+"), r"\1#"),
]


class Failed(Exception):
    pass


def mask(line):
    for pattern, repl in MASKS:
        line = pattern.sub(repl, line)
    return line


# -- the chapter -------------------------------------------------------------

def chapter_blocks(root):
    """(markers, body lines) of every fenced block of the Tools chapter."""
    lines = (root / DOC).read_text().splitlines()
    start = lines.index(CHAPTER)
    end = next((i for i in range(start + 1, len(lines))
                if lines[i].startswith("## ")), len(lines))
    i = start
    while i < end:
        if not lines[i].startswith("```"):
            i += 1
            continue
        markers, k = {}, i - 1
        while k >= 0 and MARK.match(lines[k]):
            m = MARK.match(lines[k])
            markers[m.group(1)] = m.group(2) or ""
            k -= 1
        j = i + 1
        while not lines[j].startswith("```"):
            j += 1
        yield markers, lines[i + 1:j]
        i = j + 1


def commands(body):
    """[(command, [expected lines])] of a block of `$ ` lines."""
    steps = []
    for line in body:
        if line.startswith("$ "):
            steps.append((line[2:], []))
        elif not steps:
            raise Failed(f"a session block starts with '{line}', not a `$ ` command")
        else:
            steps[-1][1].append(line.rstrip())
    return steps


# -- processes ---------------------------------------------------------------

class Proc:
    """A process whose merged output is read line by line as it comes."""

    def __init__(self, argv, env, cwd, stdout=None):
        self.argv = argv
        self.lines = []
        self.cond = threading.Condition()
        out = stdout if stdout is not None else subprocess.PIPE
        self.p = subprocess.Popen(argv, env=env, cwd=cwd, stdout=out,
                                  stderr=subprocess.STDOUT, text=True)
        if stdout is None:
            threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.p.stdout:
            with self.cond:
                self.lines.append(line.rstrip("\n").rstrip())
                self.cond.notify_all()

    def wait_lines(self, n, timeout):
        with self.cond:
            if not self.cond.wait_for(lambda: len(self.lines) >= n, timeout):
                raise Failed(f"'{shlex.join(self.argv)}' printed "
                             f"{len(self.lines)} line(s) in {timeout} s, "
                             f"expected {n}: {self.lines}")
            return list(self.lines[:n])

    def interrupt(self, timeout=10):
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGINT)
        try:
            self.p.wait(timeout)
        except subprocess.TimeoutExpired:
            self.p.kill()
            self.p.wait()
            raise Failed(f"'{shlex.join(self.argv)}' did not end on SIGINT")
        time.sleep(0.05)  # the reader thread takes the last lines
        with self.cond:
            return list(self.lines)

    def wait(self, timeout):
        try:
            self.p.wait(timeout)
        except subprocess.TimeoutExpired:
            self.p.kill()
            raise Failed(f"'{shlex.join(self.argv)}' did not end in {timeout} s")
        time.sleep(0.05)
        with self.cond:
            return self.p.returncode, list(self.lines)


class Session:
    def __init__(self, bindir, tmp):
        self.bindir = pathlib.Path(bindir).resolve()
        self.tmp = pathlib.Path(tmp)
        self.env = {k: v for k, v in os.environ.items()
                    if not k.startswith("HERM_")}
        self.env["PATH"] = f"{self.bindir}:{self.env.get('PATH', '')}"
        self.procs = []
        self.checked = 0

    def subst(self, text):
        return text.replace(DOC_DIR, str(self.tmp))

    def argv(self, cmd):
        argv = [self.subst(a) for a in shlex.split(cmd)]
        name = argv[0]
        if name.startswith("build/bin/"):
            argv[0] = str(self.bindir / name[len("build/bin/"):])
        elif name in ("hermd", "hermctl"):
            argv[0] = str(self.bindir / name)
        else:
            raise Failed(f"the session runs hermd, hermctl and build/bin/ "
                         f"programs, not '{name}'")
        return argv

    def spawn(self, cmd):
        argv = self.argv(cmd.rstrip(" &"))
        log = None
        if ">" in argv:
            k = argv.index(">")
            log = open(argv[k + 1], "w")
            argv = argv[:k]
        p = Proc(argv, self.env, self.tmp, stdout=log)
        self.procs.append(p)
        return p

    def run(self, cmd, timeout=30, expect_ok=None):
        p = Proc(self.argv(cmd), self.env, self.tmp)
        status, lines = p.wait(timeout)
        if expect_ok is not None and (status == 0) != expect_ok:
            raise Failed(f"'{cmd}' exited with {status}: {lines}")
        return lines

    def same(self, cmd, want, got):
        self.checked += 1
        w = [mask(line) for line in want]
        g = [mask(line.replace(str(self.tmp), DOC_DIR)) for line in got]
        if w != g:
            raise Failed(f"'{cmd}' printed:\n    " + "\n    ".join(got)
                         + "\n  the guide shows:\n    " + "\n    ".join(want))

    def check(self, cmd, want, timeout=30):
        self.same(cmd, want, self.run(cmd, timeout))

    def check_each(self, cmds):
        for cmd, want in cmds:
            self.check(cmd, want)

    def stop(self):
        for p in self.procs:
            if p.p.poll() is None:
                p.p.send_signal(signal.SIGINT)
        for p in self.procs:
            try:
                p.p.wait(5)
            except subprocess.TimeoutExpired:
                p.p.kill()
                p.p.wait()

    def calc(self, a, b, op):
        value = f'{{"a":{a},"b":{b},"op":"{op}"}}'
        self.run(shlex.join(["hermctl", "call", "calculator", value,
                             "-t", "calc_request"]), expect_ok=True)


def expect_commands(step, cmds, *prefixes):
    got = [c for c, _ in cmds]
    if len(got) != len(prefixes) or not all(
            c.startswith(p) for c, p in zip(got, prefixes)):
        raise Failed(f"step '{step}': the guide's commands changed "
                     f"({got}); tools_session.py runs {list(prefixes)}")


def until(what, predicate, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.2)
    raise Failed(f"{what} within {timeout} s")


# -- the steps, in the chapter's order ----------------------------------------

def step_start(s, cmds):
    expect_commands("start", cmds, "hermd ", "hermd ",
                    "build/bin/herm-example-calculator serve", "export ",
                    "hermctl modules", "hermctl topic list")
    for cmd, want in cmds[:3]:
        p = s.spawn(cmd)
        if want:
            s.same(cmd, want, p.wait_lines(len(want), 30))
    for assignment in shlex.split(cmds[3][0])[1:]:
        key, value = assignment.split("=", 1)
        s.env[key] = s.subst(value)
    for sock in ("alpha", "beta", "calculator"):
        until(f"{sock}.sock appears", (s.tmp / f"{sock}.sock").exists, 20)
    # A person types slower than routes settle; the script waits for them.
    until("alpha routes to 0x41 and 0x42",
          lambda: all(m in " ".join(s.run("hermctl routes"))
                      for m in ("0x41", "0x42")), 30)
    # ... and for each module's herm.info to answer a discovery (routes
    # back to alpha; on a loaded machine a little after alpha's own).
    until("the three modules answer alpha's discovery",
          lambda: re.search(r'"modules": *3\b',
                            "".join(s.run("hermctl --json topic list"))),
          30)
    s.check_each(cmds[4:])


def step_calls(s, cmds):
    expect_commands("calls", cmds, *["hermctl call "] * 4)
    s.check_each(cmds)


def step_listen(s, cmds):
    expect_commands("listen", cmds, "hermctl topic echo calculator.results",
                    "hermctl topic echo calculator.results -n 1")
    cmd, want = cmds[0]
    if want[-1] != "^C":
        raise Failed(f"'{cmd}' is ended by ^C in the guide")
    echo = s.spawn(cmd)
    echo.wait_lines(1, 20)
    s.calc(3, 5, "*")
    s.calc(9, 4, "-")
    echo.wait_lines(len(want) - 1, 20)
    s.same(cmd, want[:-1], echo.interrupt())
    s.check(*cmds[1])


def step_publish(s, cmds):
    expect_commands("publish", cmds, "hermctl topic pub greeting",
                    "hermctl topic pub sensors.range")
    s.check(*cmds[0])
    cmd, want = cmds[1]
    if want[-1] != "...":
        raise Failed(f"'{cmd}' goes on ('...') in the guide")
    s.publisher = s.spawn(cmd)
    s.same(cmd, want[:-1], s.publisher.wait_lines(len(want) - 1, 20))


def step_rates(s, cmds):
    expect_commands("rates", cmds, "hermctl --name beta topic hz",
                    "hermctl topic list")
    s.check_each(cmds)


def step_record(s, cmds):
    expect_commands("record", cmds, "hermctl record -o run.db -d 3",
                    "hermctl record --info run.db")
    cmd, want = cmds[0]
    rec = s.spawn(cmd)
    rec.wait_lines(1, 20)  # "recording 2 topic(s)": it has subscribed
    time.sleep(0.5)
    s.calc(12, 4, "/")
    status, got = rec.wait(20)
    if status != 0:
        raise Failed(f"'{cmd}' exited with {status}: {got}")
    s.same(cmd, want, got)
    s.check(*cmds[1])


def step_replay(s, cmds):
    expect_commands("replay", cmds,
                    "hermctl --name beta topic echo replay.range -n 3",
                    "hermctl --name beta topic echo replay.results",
                    "hermctl play run.db")
    s.publisher.interrupt()
    first = s.spawn(cmds[0][0])
    second = s.spawn(cmds[1][0])
    if cmds[1][1][-1] != "^C":
        raise Failed(f"'{cmds[1][0]}' is ended by ^C in the guide")

    def subscribed():
        rows = " ".join(s.run("hermctl --name beta topic list"))
        return "replay.range" in rows and "replay.results" in rows
    until("beta lists both replay topics as subscribed", subscribed, 20)
    s.check(cmds[2][0], cmds[2][1], timeout=60)
    status, got = first.wait(20)
    s.same(cmds[0][0], cmds[0][1], got)
    want = cmds[1][1][:-1]
    second.wait_lines(len(want), 20)
    s.same(cmds[1][0], want, second.interrupt())


STEPS = {"start": step_start, "calls": step_calls, "listen": step_listen,
         "publish": step_publish, "rates": step_rates, "record": step_record,
         "replay": step_replay}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    ap.add_argument("--root",
                    default=str(pathlib.Path(__file__).resolve().parents[2]))
    ap.add_argument("--keep", action="store_true",
                    help="keep the temporary folder (logs, run.db)")
    args = ap.parse_args()
    root = pathlib.Path(args.root)
    tmp = tempfile.mkdtemp(prefix="herm-tools-")
    s = Session(args.bin, tmp)
    done = []
    try:
        steps = []
        for markers, body in chapter_blocks(root):
            if "session" in markers:
                steps.append((markers["session"], commands(body)))
            elif "config" in markers and body and body[0].startswith("# "):
                name = body[0][2:].split(":")[0]
                (s.tmp / name).write_text(s.subst("\n".join(body) + "\n"))
        names = [n for n, _ in steps]
        if names != list(STEPS):
            raise Failed(f"the chapter's session steps are {names}, "
                         f"tools_session.py runs {list(STEPS)}")
        for name, cmds in steps:
            STEPS[name](s, cmds)
            done.append(name)
    except (Failed, OSError) as e:
        print(f"tools_session: step {len(done) + 1} "
              f"({(list(STEPS) + ['?'])[len(done)]}): {e}", file=sys.stderr)
        for log in sorted(s.tmp.glob("*.log")):
            tail = log.read_text().splitlines()[-15:]
            print(f"--- {log.name}\n" + "\n".join(tail), file=sys.stderr)
        return 1
    finally:
        s.stop()
        if args.keep:
            print(f"tools_session: kept {tmp}", file=sys.stderr)
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    print(f"tools_session: {len(done)} steps, {s.checked} outputs match the guide")
    return 0


if __name__ == "__main__":
    sys.exit(main())
