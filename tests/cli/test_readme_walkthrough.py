"""README.md's "Three terminals: a mission from plan to log", replayed from
the README itself: its sh block is parsed and run (server and robots in the
background, each `missionctl ctl` command as its own process, exit code 0),
and what its comments say the operator sees is waited for and asserted. A
change to the README or to the code that breaks the walk-through fails here.

What the test changes, and only that: the endpoint tcp/127.0.0.1:7447 (the
robots' `--connect`, the server's and ctl's default) becomes a free loopback
port (`--listen` for the server, $MISSIONCTL_CONNECT for ctl), the server's
`--db` a temporary file, `missionctl` this interpreter's CLI
(`python -m backend.cli`) and `python` this interpreter.

PROMISES below maps each commented README line to what the test checks."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from backend.cli.ctl.args import DEFAULT_CONNECT

from .helpers import CTL_TIMEOUT, ROOT, Robots, Server, env, ok_json, until

README = ROOT / "README.md"
HEADING = "## Three terminals: a mission from plan to log"
README_ENDPOINT = "tcp/127.0.0.1:7447"  # what the README's commands use; replaced by a free port
WAIT = 20.0  # seconds for any one promised state
CLI = [sys.executable, "-m", "backend.cli"]
EXECUTABLES = {  # the README's executables -> this checkout's, run by this interpreter
    "missionctl": CLI,
    ".venv/bin/missionctl": CLI,
    "python": [sys.executable],
    "python3": [sys.executable],
    ".venv/bin/python": [sys.executable],
}


# ---------------------------------------------------------------- the README


@dataclass
class Line:
    """One command line of the block: its `&&`-joined commands (argv each) and
    its trailing comment."""

    lineno: int  # in README.md
    text: str
    commands: list[list[str]]
    comment: str

    def where(self) -> str:
        return f"README.md:{self.lineno} `{self.text}`"

    def ctl_args(self) -> list[str]:
        """The arguments after `missionctl ctl` of the first command."""
        argv = self.commands[0]
        return argv[2:] if len(argv) > 1 and argv[1] == "ctl" else []


def split_comment(line: str) -> tuple[str, str]:
    """`code  # comment` -> (code, comment); a # inside quotes or a word is code."""
    quote = None
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i].strip(), line[i + 1 :].strip()
    return line.strip(), ""


def walkthrough() -> dict[int, list[Line]]:
    """The block's command lines by terminal (`# N. …` comment lines)."""
    text = README.read_text()
    start = text.find(HEADING)
    assert start >= 0, f"README.md: heading {HEADING!r} not found"
    end = text.find("\n## ", start + len(HEADING))
    m = re.compile(r"^```sh\n(.*?)^```", re.M | re.S).search(
        text, start, end if end >= 0 else len(text)
    )
    assert m, f"README.md: no ```sh block under {HEADING!r}"
    first = text.count("\n", 0, m.start(1)) + 1
    terminals: dict[int, list[Line]] = {}
    current: list[Line] | None = None
    for lineno, raw in enumerate(m[1].splitlines(), first):
        code, comment = split_comment(raw)
        if not code:
            heading = re.fullmatch(r"(\d+)\.\s.*", comment)
            if heading:
                current = terminals.setdefault(int(heading[1]), [])
            continue
        where = f"README.md:{lineno} `{raw.strip()}`"
        assert current is not None, f"{where}: a command before the `# 1. …` terminal comment"
        assert not code.endswith("\\"), (
            f"{where}: the test reads one command per line (no `\\` continuations)"
        )
        tokens = shlex.split(code)
        odd = [t for t in tokens if t in ("|", "||", ";", "&", ">", "<") or t.endswith(";")]
        assert not odd, f"{where}: the test replays commands joined by `&&` only, not {odd}"
        commands: list[list[str]] = [[]]
        for t in tokens:
            if t == "&&":
                commands.append([])
            else:
                commands[-1].append(t)
        assert all(commands), f"{where}: an empty command around `&&`"
        current.append(Line(lineno, raw.strip(), commands, comment))
    return terminals


# ---------------------------------------------------------------- what the comments promise


class View:
    """The mission as `ctl state --json` shows it (and `ctl robots --json`,
    fetched only when a condition asks for a robot's mode)."""

    def __init__(self, endpoint: str, names: dict[str, str]):
        self.endpoint, self.names = endpoint, names
        self.state = ok_json(endpoint, "state")
        self._robots: dict | None = None

    def skill(self, sid: str) -> dict | None:
        return next((s for t in self.state["tasks"].values() for s in t if s["id"] == sid), None)

    def labelled(self, robot: str, label: str) -> dict | None:
        found = [s for s in self.state["tasks"].get(robot, []) if s["label"] == label]
        assert len(found) <= 1, (
            f"{robot} has {len(found)} skills labelled {label!r}: the README's label is ambiguous"
        )
        return found[0] if found else None

    def want(
        self, sid: str, status: str, attempt: int | None = None, info: str | None = None
    ) -> list[str]:
        s = self.skill(sid)
        if s is None:
            return [f"no skill {sid}"]
        out = [] if s["status"] == status else [f"{sid} is {s['status']} (want {status})"]
        if attempt is not None and s["attempt"] != attempt:
            out.append(f"{sid} is attempt {s['attempt']} (want {attempt})")
        if info is not None and info not in (s["status_info"] or ""):
            out.append(f"{sid} says {s['status_info']!r} (want it to mention {info!r})")
        return out

    def want_label(self, robot: str, label: str, status: str) -> list[str]:
        s = self.labelled(robot, label)
        if s is None:
            return [f"{robot} has no skill labelled {label!r}"]
        return (
            []
            if s["status"] == status
            else [f"{s['id']} ({label!r}) is {s['status']} (want {status})"]
        )

    def want_mode(self, robot: str, mode: str) -> list[str]:
        if self._robots is None:
            self._robots = ok_json(self.endpoint, "robots")["robots"]
        t = (self._robots.get(robot) or {}).get("telemetry")
        have = t["mode"] if t else None
        return [] if have == mode else [f"{robot}'s mode is {have} (want {mode})"]

    def statuses(self) -> dict[str, str]:
        return {s["id"]: s["status"] for t in self.state["tasks"].values() for s in t}


Condition = Callable[[View], list[str]]  # what is not (yet) as promised; [] when it all is


def failed_and_halted(v: View) -> list[str]:
    """# lru1-3 failed and lru1 halted; lru2-5 waits (synchwaiting) for lru1"""
    n = v.names
    return [
        *v.want(n["flaky"], "failure"),
        *v.want_mode(n["halted"], "halted"),  # its queue holds, not run:
        *v.want(n["meet1"], "idle_synchronized"),  # the next skill does not start
        *v.want(n["meet2"], "synchwaiting", info=n["halted"]),
    ]


def retried_then_met(v: View) -> list[str]:
    """# lru1-3.2 (attempt 2) succeeds, then both meet"""
    n = v.names
    return [
        *v.want(n["retried"], "success", attempt=int(n["attempt"])),
        *v.want(n["flaky"], "failure"),  # the failed attempt stays in the log
        *v.want(n["meet1"], "success"),
        *v.want(n["meet2"], "success"),
    ]


def hold_started(v: View) -> list[str]:
    """# lru2 is still in run mode: it starts "hold" at once"""
    n = v.names
    return [
        *v.want_label(n["robot"], n["hold"], "running"),
        *v.want_label(n["robot"], n["later"], "idle_synchronized"),
    ]


def later_back_hold_stays(v: View) -> list[str]:
    """# "later" comes back to the plan; "hold" stays"""
    n = v.names
    return [
        *v.want_label(n["robot"], n["later"], "idle"),
        *v.want_label(n["robot"], n["hold"], "running"),
    ]


@dataclass
class Promise:
    """A README line whose first command is `missionctl ctl PREFIX…` ({name}
    stands for a skill the comments named); its comment must match `comment`
    (named groups bind names: every line naming one must agree); ctl's output
    must match `printed` ({name} substituted); `condition` is polled until it
    holds: after the line ran, or for a `state` line (whose comment says what
    it shows) before it runs."""

    prefix: str
    comment: str | None = None
    printed: str | None = None
    condition: Condition | None = None


# README line (its ctl command, {name}: a name bound by a comment) -> what its
# comment must say (named groups bind names) -> what ctl must print -> the
# condition polled (see failed_and_halted … above).
PROMISES = [
    Promise(
        "add lru1 recharge",
        comment=r"^(?P<flaky>lru1-\d+): fails once\b",
        printed=r"^added {flaky} \(recharge\) to lru1 ",
    ),
    Promise(
        "add lru1 identify_stone",
        comment=r"^(?P<meet1>lru1-\d+)$",
        printed=r"^added {meet1} \(identify_stone\) to lru1 ",
    ),
    Promise(
        "add lru2 identify_stone",
        comment=r"^(?P<meet2>lru2-\d+)$",
        printed=r"^added {meet2} \(identify_stone\) to lru2 ",
    ),
    Promise("barrier {meet1} {meet2}", printed=r"^created barrier \S+ \({meet1}, {meet2}\) "),
    Promise(
        "state",
        comment=r"^(?P<flaky>\S+) failed and (?P<halted>lru\d+) halted; "
        r"(?P<meet2>\S+) waits \(synchwaiting\) for (?P=halted)$",
        condition=failed_and_halted,
    ),
    Promise(
        "retry {flaky}",
        comment=r"^(?P<retried>\S+) \(attempt (?P<attempt>\d+)\) succeeds, then both meet$",
        printed=r"^retrying {flaky} as {retried} ",
        condition=retried_then_met,
    ),
    Promise(
        "add {robot} recharge --label {hold}",
        comment=r"^runs until released\b",
        printed=r"^added {robot}-\d+ \(recharge\) to {robot} ",
    ),
    Promise(
        "add {robot} recharge --label {later}",
        printed=r"^added {robot}-\d+ \(recharge\) to {robot} ",
    ),
    Promise(
        "sync {robot}",
        comment=r'^(?P<robot>lru2) is still in run mode: it starts "(?P<hold>[^"]+)" at once$',
        printed=r"^synchronized .* to {robot} ",
        condition=hold_started,
    ),
    Promise(
        "unsync {robot}",
        comment=r'^"(?P<later>[^"]+)" comes back to the plan; "(?P<hold>[^"]+)" stays$',
        printed=r"^unsynchronized .* from {robot} ",
        condition=later_back_hold_stays,
    ),
]


def fill(template: str, names: dict[str, str], regex: bool) -> str:
    def one(m: re.Match) -> str:
        return re.escape(names[m[1]]) if regex else names[m[1]]

    return re.sub(r"\{(\w+)\}", one, template)


def claim(lines: list[Line]) -> tuple[dict[int, Promise], dict[str, str]]:
    """Each promise's line (in order: line index -> promise) and the names the
    comments bind; fails, before anything starts, when the block changed shape."""
    claimed: dict[int, Promise] = {}
    names: dict[str, str] = {}
    named_at: dict[str, Line] = {}
    pos = 0
    for p in PROMISES:
        want = shlex.split(p.prefix)
        for i in range(pos, len(lines)):
            args = lines[i].ctl_args()
            if len(args) >= len(want) and all(
                w.startswith("{") or w == a for w, a in zip(want, args, strict=False)
            ):
                claimed[i], pos = p, i + 1
                break
        else:
            after = f" after {lines[pos - 1].where()}" if pos else ""
            raise AssertionError(
                f"README.md walk-through: no line `missionctl ctl {p.prefix} …`{after}; "
                "the walk-through changed shape: update the README or PROMISES in this test"
            )
        line = lines[pos - 1]
        if p.comment is None:
            continue
        m = re.search(p.comment, line.comment)
        assert m, f"{line.where()}: the comment should match /{p.comment}/, it is {line.comment!r}"
        for name, value in m.groupdict().items():
            if name in names and names[name] != value:
                raise AssertionError(
                    f"{line.where()}: the comment names {value} where "
                    f"{named_at[name].where()} named {names[name]} (`{name}`)"
                )
            names[name], named_at[name] = value, line
    for i, p in claimed.items():  # the ids a command uses are the ones the comments named
        want, args = shlex.split(p.prefix), lines[i].ctl_args()
        for w, a in zip(want, args, strict=False):
            if w.startswith("{"):
                assert w[1:-1] in names, f"PROMISES: {w} of `{p.prefix}` is named by no comment"
                assert a == names[w[1:-1]], (
                    f"{lines[i].where()}: uses {a} where the comments named "
                    f"{names[w[1:-1]]} ({named_at[w[1:-1]].where()})"
                )
    unchecked = [ln.where() for i, ln in enumerate(lines) if ln.comment and i not in claimed]
    assert not unchecked, f"comments the test does not check (add them to PROMISES): {unchecked}"
    return claimed, names


# ---------------------------------------------------------------- running it


def local(argv: list[str], line: Line, endpoint: str) -> list[str]:
    """A README command as this checkout runs it: the executable, and the endpoint."""
    exe = EXECUTABLES.get(argv[0])
    assert exe, (
        f"{line.where()}: the test knows no executable {argv[0]!r} (known: {sorted(EXECUTABLES)})"
    )
    return [*exe, *(a.replace(README_ENDPOINT, endpoint) for a in argv[1:])]


def server_command(line: Line) -> Callable[[str, Path], list[str]]:
    argv = line.commands[0]
    assert len(line.commands) == 1 and argv[1:2] == ["server"], (
        f"{line.where()}: terminal 1 should be one `missionctl server …` command"
    )
    assert "--db" in argv, f"{line.where()}: no --db (the test replaces it with a temporary file)"
    listen = [argv[i + 1] for i, a in enumerate(argv) if a == "--listen"]
    assert listen in ([], [README_ENDPOINT]), (
        f"{line.where()}: the test replaces {README_ENDPOINT} only, not {listen}"
    )

    def command(endpoint: str, db: Path) -> list[str]:
        out = local(argv, line, endpoint)
        out[out.index("--db") + 1] = str(db)
        return out if listen else [*out, "--listen", endpoint]  # the default, on another port

    return command


def robots_command(line: Line) -> tuple[list[str], list[str]]:
    argv = line.commands[0]
    assert len(line.commands) == 1 and any(a.endswith("trivial_robots.py") for a in argv), (
        f"{line.where()}: terminal 2 should be one "
        "`python docs/examples/trivial_robots.py …` command"
    )
    assert f"--connect {README_ENDPOINT}" in shlex.join(argv), (
        f"{line.where()}: the robots should connect to {README_ENDPOINT} (the test replaces it)"
    )
    return argv, [a for a in argv if re.fullmatch(r"\w+:\w+", a)]


def shown_statuses(output: str, line: Line) -> dict[str, str]:
    """skill id -> status of `ctl state`'s human output, read with its own legend."""
    lines = output.strip().splitlines()
    legend = re.fullmatch(r"\((.*)\)", lines[-1] if lines else "")
    assert legend, f"{line.where()}: no legend line at the end of:\n{output}"
    pairs = [pair.split(" ", 1) for pair in legend[1].split(", ")]
    glyphs = dict(pairs)
    assert len(glyphs) == len(pairs), (
        f"{line.where()}: the legend gives one glyph to several statuses: {lines[-1]}"
    )
    return {
        m[2]: glyphs[m[1]]
        for ln in lines
        if (m := re.match(r"^  (\S) (\S+)", ln)) and m[1] in glyphs
    }


@dataclass
class Run:
    endpoint: str
    server: Server
    robots: Robots
    names: dict[str, str]

    def ctl_env(self) -> dict[str, str]:
        return {
            **env(),
            "MISSIONCTL_CONNECT": self.endpoint,
        }  # the default endpoint, on the free port

    def context(self) -> str:
        tail = "".join(self.robots.lines[-30:])
        return (
            f"\nthe robots' last output:\n{tail}\nthe server's log:\n{self.server.output()[-3000:]}"
        )

    def execute(self, line: Line) -> str:
        out = []
        for argv in line.commands:
            r = subprocess.run(
                local(argv, line, self.endpoint),
                cwd=ROOT,
                env=self.ctl_env(),
                capture_output=True,
                text=True,
                timeout=CTL_TIMEOUT,
            )
            assert r.returncode == 0 and "Traceback" not in r.stderr, (
                f"{line.where()}: `{shlex.join(argv)}` exited with {r.returncode}\n"
                f"stdout: {r.stdout}\nstderr: {r.stderr}{self.context()}"
            )
            out.append(r.stdout)
        return "".join(out)

    def wait(self, line: Line, condition: Condition) -> View:
        deadline = time.monotonic() + WAIT
        while True:
            view = View(self.endpoint, self.names)
            unmet = condition(view)
            if not unmet:
                return view
            if time.monotonic() > deadline:
                raise AssertionError(
                    f"{line.where()}: the comment promises {line.comment!r}; "
                    f"not so within {WAIT:g} s: "
                    f"{'; '.join(unmet)}\nstatuses: {view.statuses()}{self.context()}"
                )
            time.sleep(0.1)


@pytest.fixture
def processes():
    """Server and robots started by the test; stopped in teardown whatever
    happened (SIGTERM, then SIGKILL), robots first."""
    started: list[Any] = []
    yield started
    for proc in reversed(started):
        proc.stop()


@pytest.mark.timeout(120)
def test_the_readme_walkthrough_works_as_written(tmp_path, processes):
    terminals = walkthrough()
    assert sorted(terminals) == [1, 2, 3], (
        f"README.md walk-through: terminals {sorted(terminals)}, want 1, 2, 3"
    )
    assert len(terminals[1]) == 1 and len(terminals[2]) == 1, (
        "README.md walk-through: one command in terminals 1 and 2"
    )
    operator = terminals[3]
    for line in operator:
        assert all(
            a[:1] in (["missionctl"], [".venv/bin/missionctl"]) and a[1:2] == ["ctl"]
            for a in line.commands
        ), f"{line.where()}: the operator's lines should be `missionctl ctl …` commands"
    # the ctl lines name no endpoint: they rely on the default, the server's and the robots' one
    assert DEFAULT_CONNECT == README_ENDPOINT, (
        f"ctl's default endpoint is {DEFAULT_CONNECT}, the README's {README_ENDPOINT}"
    )
    promises, names = claim(operator)  # the block's shape, checked before anything starts
    make_server = server_command(terminals[1][0])
    robots_argv, robot_specs = robots_command(terminals[2][0])

    server = Server(tmp_path, command=make_server)
    processes.append(server)
    endpoint = server.endpoint
    robots = Robots(endpoint, *robot_specs, command=local(robots_argv, terminals[2][0], endpoint))
    processes.append(robots)
    until(
        endpoint,
        lambda st: all(st["robots"][r.split(":")[0]]["online"] for r in robot_specs),
        what="robots online",
    )
    run = Run(endpoint, server, robots, names)

    for i, line in enumerate(operator):
        p = promises.get(i)
        is_state = line.ctl_args()[:1] == ["state"]
        view = None
        if (
            p and p.condition and is_state
        ):  # what the state line will show: the robots get there in time
            view = run.wait(line, p.condition)
        elif is_state:
            view = View(endpoint, names)
        out = run.execute(line)
        if p and p.printed:
            printed = fill(p.printed, names, regex=True)
            assert re.search(printed, out, re.M), (
                f"{line.where()}: ctl printed {out!r}, the README expects /{printed}/"
            )
        if is_state:  # every status visible: what it printed is what the mission is
            shown = json.loads(out)["tasks"] if "--json" in line.ctl_args() else None
            statuses = (
                {s["id"]: s["status"] for t in shown.values() for s in t}
                if shown is not None
                else shown_statuses(out, line)
            )
            assert statuses == view.statuses(), (
                f"{line.where()}: shows statuses {statuses}, "
                f"the mission has {view.statuses()}\n{out}"
            )
        if p and p.condition and not is_state:  # what the command leads to
            run.wait(line, p.condition)
