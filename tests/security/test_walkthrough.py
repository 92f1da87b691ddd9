"""docs/security.md's walk-through "From nothing to a TLS, password-protected
server (one machine)", replayed from the document itself: its sh block is
parsed and run by bash, so a change to the doc or to the code that breaks the
walk-through fails here.

What the test changes, and only that: `~` is a temporary HOME, `missionctl`
is this checkout's CLI (a shim on PATH), the port 7447 is a free loopback
port, and the two interactive consoles (steps 6, 7) become `missionctl ctl`
runs with the same login options."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml

from backend.transport import free_port

from .helpers import ROOT, env, stop_process

DOC = ROOT / "docs" / "security.md"
WHERE = "docs/security.md walk-through"
HEADING = "## From nothing to a TLS, password-protected server (one machine)"
DOC_ENDPOINT = "tls/127.0.0.1:7447"  # what the doc's commands connect to; replaced by a free port
WAIT = 20.0  # seconds for any one awaited line


# ---------------------------------------------------------------- the document


@dataclass
class Step:
    number: int
    title: str
    commands: list[str] = field(default_factory=list)
    comments: list[str] = field(default_factory=list)


def section(text: str) -> str:
    start = text.find(HEADING)
    assert start >= 0, f"{WHERE}: heading {HEADING!r} not found"
    end = text.find("\n## ", start + len(HEADING))
    return text[start:] if end < 0 else text[start:end]


def sh_block(sec: str) -> str:
    m = re.search(r"^```sh\n(.*?)^```", sec, re.M | re.S)
    assert m, f"{WHERE}: no ```sh block in the section"
    return m[1]


def parse_steps(block: str) -> dict[int, Step]:
    """The block's commands grouped by their `# N. title` comment: `\\`
    continuations joined, a heredoc kept with its command, other comment lines
    kept apart (they state what the commands should print)."""
    steps: dict[int, Step] = {}
    current: Step | None = None
    lines = iter(block.splitlines())
    for line in lines:
        text = line.strip()
        if not text:
            continue
        if text.startswith("#"):
            heading = re.fullmatch(r"#\s*(\d+)\.\s*(.*)", text)
            if heading:
                current = steps[int(heading[1])] = Step(int(heading[1]), heading[2])
            elif current is not None:
                current.comments.append(text.lstrip("# "))
            continue
        assert current is not None, f"{WHERE}: command before step 0: {text!r}"
        while text.endswith("\\"):
            text = text[:-1].rstrip() + " " + next(lines, "").strip()
        heredoc = re.search(r"<<-?\s*['\"]?(\w+)", text)
        if heredoc:
            body = []
            for body_line in lines:
                body.append(body_line)
                if body_line.strip() == heredoc[1]:
                    break
            text = "\n".join([text, *body])
        current.commands.append(text)
    return steps


def the_command(steps: dict[int, Step], number: int, what: str, prefix: str) -> str:
    step = steps.get(number)
    assert step is not None, f"{WHERE}: step {number} ({what}) not found"
    assert len(step.commands) == 1 and step.commands[0].startswith(prefix), (
        f"{WHERE}: step {number} ({what}) should be one `{prefix} …` command, found {step.commands}"
    )
    return step.commands[0]


def quoted(text: str, pattern: str, what: str) -> str:
    m = re.search(pattern, text)
    assert m, f"{WHERE}: {what} not found in {text!r}"
    return m[1]


def error_table(sec: str) -> dict[str, str]:
    """cause -> message of the "What goes wrong" table (messages in backticks)."""
    return dict(re.findall(r"^\| (.+?) \| `(.+)` \|$", sec, re.M))


def matches(message: str, line: str) -> bool:
    """`message` as the doc writes it, "…" standing for any text."""
    return re.search(".*".join(re.escape(part) for part in message.split("…")), line) is not None


# ---------------------------------------------------------------- processes


class Background:
    """A walk-through command run by bash in the background (`exec`: the pid is
    missionctl's own, so SIGTERM reaches it); its output lines, stdout and
    stderr together, can be awaited."""

    def __init__(self, command: str, cwd: Path, sh_env: dict[str, str]):
        self.command = command
        self.proc = subprocess.Popen(
            ["bash", "-c", f"exec {command}"],
            cwd=cwd,
            env=sh_env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            with self._cond:
                self.lines.append(line.rstrip("\n"))
                self._cond.notify_all()
        with self._cond:  # EOF: the process ended, waiters must not wait for the timeout
            self._cond.notify_all()

    def output(self) -> str:
        with self._cond:
            return "\n".join(self.lines)

    def wait_line(self, needle: str, timeout: float = WAIT) -> str:
        def found() -> str | None:
            return next((ln for ln in self.lines if needle in ln), None)

        with self._cond:
            self._cond.wait_for(lambda: found() is not None or not self._reader.is_alive(), timeout)
            line = found()
        if line is None:
            why = (
                f"within {timeout:g} s"
                if self.proc.poll() is None
                else f"(exited with {self.proc.returncode})"
            )
            raise AssertionError(
                f"no {needle!r} {why} from `{self.command}`; output:\n{self.output()}"
            )
        return line

    def stop(self) -> None:
        stop_process(self.proc)  # SIGTERM, then SIGKILL
        self._reader.join(10)
        self.proc.stdout.close()


@pytest.fixture
def background():
    """Starts Background commands; all of them are stopped in teardown,
    whatever happened (last started first)."""
    started: list[Background] = []

    def start(command: str, cwd: Path, sh_env: dict[str, str]) -> Background:
        started.append(Background(command, cwd, sh_env))
        return started[-1]

    yield start
    for proc in reversed(started):
        proc.stop()


def shell_env(tmp: Path) -> dict[str, str]:
    """HOME is the test's own (the doc writes ~/mc); `missionctl` on PATH runs
    this checkout's CLI with the test's interpreter."""
    home, bindir = tmp / "home", tmp / "bin"
    home.mkdir()
    bindir.mkdir()
    shim = bindir / "missionctl"
    shim.write_text(
        f"#!/bin/sh\nPYTHONPATH={shlex.quote(str(ROOT))} "
        f'exec {shlex.quote(sys.executable)} -m backend.cli "$@"\n'
    )
    shim.chmod(0o755)
    return {**env(), "HOME": str(home), "PATH": f"{bindir}{os.pathsep}{os.environ.get('PATH', '')}"}


def one_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected one line on stderr, got:\n{stderr}"
    return lines[0]


def option(argv: list[str], name: str, what: str) -> int:
    assert name in argv, f"{WHERE}: {what} has no {name} option: {shlex.join(argv)}"
    return argv.index(name)


# ---------------------------------------------------------------- the test


@pytest.mark.timeout(90)
def test_the_tls_accounts_walkthrough_works_as_written(tmp_path, background):
    sec = section(DOC.read_text())
    steps = parse_steps(sh_block(sec))
    for n in range(4):
        assert n in steps and steps[n].commands, f"{WHERE}: step {n} not found"
    server_cmd = the_command(steps, 4, "server", "missionctl server ")
    sim_cmd = the_command(steps, 5, "simulated fleet", "missionctl sim ")
    operator_cmd = the_command(steps, 6, "operator console", "missionctl console ")
    observer_cmd = the_command(steps, 7, "observer console", "missionctl console ")
    # the test replaces this endpoint only: anything else would bind or connect elsewhere
    assert re.findall(r"--listen\s+(\S+)", server_cmd) == [DOC_ENDPOINT], (
        f"{WHERE}: step 4 (server) should listen on {DOC_ENDPOINT} only: {server_cmd}"
    )
    for n, cmd in ((5, sim_cmd), (6, operator_cmd), (7, observer_cmd)):
        assert f"--connect {DOC_ENDPOINT}" in cmd, (
            f"{WHERE}: step {n} should connect to {DOC_ENDPOINT}: {cmd}"
        )
    server_says = quoted(
        " ".join(steps[4].comments), r'->\s*"([^"]+)"', 'step 4\'s promised output (-> "…")'
    )
    observer_sees = quoted(
        " ".join([steps[7].title, *steps[7].comments]),
        r'"(read-only[^"]*)"',
        "step 7's read-only message",
    )
    errors = error_table(sec)
    exit_code = int(
        quoted(sec, r"What goes wrong.*?exit code (\d+)", "the exit code of a refused connection")
    )

    # Steps 0-3 as written, in one shell (they share M, the umask and `cd ~/mc`);
    # then where they left us: the other terminals run there, with M set.
    sh_env = shell_env(tmp_path)
    setup = [c for n in range(4) for c in steps[n].commands]
    script = "\n".join(
        [
            "set -eu",
            "trap 'echo \"failed: $BASH_COMMAND\" >&2' ERR",
            *setup,
            'printf "%s\\n" "$PWD" "$M"',
        ]
    )
    r = subprocess.run(
        ["bash", "-c", script], cwd=ROOT, env=sh_env, capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 0, f"{WHERE}: steps 0-3 failed:\n{r.stderr}"
    workdir, mission = (Path(p) for p in r.stdout.splitlines()[-2:])
    assert workdir.is_relative_to(sh_env["HOME"]), (
        f"{WHERE}: step 0 should cd under ~, not {workdir}"
    )
    assert mission.is_file(), f"{WHERE}: M={mission} is not a mission file"
    sh_env["M"] = str(mission)

    # Step 4 in the background; another process may take the free port first (retried).
    for _attempt in range(3):
        endpoint = f"tls/127.0.0.1:{free_port()}"
        server = background(server_cmd.replace(DOC_ENDPOINT, endpoint), workdir, sh_env)
        try:
            logins = server.wait_line("logins required")
            break
        except AssertionError:
            if "cannot listen on" not in server.output():
                raise
            server.stop()
    else:
        raise AssertionError(f"the server found no free port:\n{server.output()}")
    assert server_says in logins, (
        f"{WHERE}: step 4 promises {server_says!r}; the server said {logins!r}"
    )

    def ctl_argv(console_cmd: str) -> list[str]:
        """A console line of the doc as `missionctl ctl` with the same options."""
        argv = shlex.split(console_cmd.replace(DOC_ENDPOINT, endpoint))
        argv[1] = "ctl"
        return argv

    def ctl(console_cmd: str, *op: str, drop: str | None = None, password_file: str | None = None):
        argv = ctl_argv(console_cmd)
        if drop:
            i = option(argv, drop, "a console line")
            del argv[i : i + 2]
        if password_file:
            argv[option(argv, "--password-file", "a console line") + 1] = password_file
        return subprocess.run(
            ["bash", "-c", shlex.join([*argv, *op])],
            cwd=workdir,
            env=sh_env,
            capture_output=True,
            text=True,
            timeout=30,
        )

    # The observer watches the fleet from before the simulator starts: its
    # "robot X online" lines tell when the robots have registered.
    watcher = background(shlex.join([*ctl_argv(observer_cmd), "watch"]), workdir, sh_env)
    watcher.wait_line("watching mission")

    # Step 5 in the background: the sim runs every robot of the mission on the
    # robot account, which (the doc says) lists them all.
    sim = background(sim_cmd.replace(DOC_ENDPOINT, endpoint), workdir, sh_env)
    sim.wait_line(f"connected to {endpoint}")
    sim_argv = shlex.split(sim_cmd)
    sim_user = sim_argv[option(sim_argv, "--user", "step 5 (sim)") + 1]
    accounts = yaml.safe_load((workdir / "accounts.yaml").read_text())["accounts"]
    assert sim_user in accounts, f"{WHERE}: step 5's --user {sim_user} is not an account of step 3"
    robots = accounts[sim_user]["robots"]
    assert sorted(robots) == sorted(yaml.safe_load(mission.read_text())["robots"]), (
        f"{WHERE}: step 3's robot account should list every robot of the mission"
    )
    try:
        for robot in robots:
            watcher.wait_line(f"robot {robot} online")
    except AssertionError as e:
        raise AssertionError(f"{e}\nthe sim's output:\n{sim.output()}") from None

    # Step 6, the operator: sees the robots online and may change the mission.
    r = ctl(operator_cmd, "robots")
    assert r.returncode == 0, r.stderr
    for robot in robots:
        assert re.search(rf"^{re.escape(robot)} \(.*\): online since", r.stdout, re.M), r.stdout
    r = ctl(observer_cmd, "state", "--json")
    assert r.returncode == 0, r.stderr
    before = json.loads(r.stdout)
    robot = next(name for name, tasks in before["tasks"].items() if tasks)
    r = ctl(
        operator_cmd, "sync", robot
    )  # sends the robot its skills: the server reaches it under its account
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"synchronized {robot}-"), r.stdout

    # Step 7, the observer: reads, and every change is refused with the doc's words.
    r = ctl(observer_cmd, "state", "--json")
    assert r.returncode == 0, r.stderr
    after = json.loads(r.stdout)
    assert after["revision"] > before["revision"], "the observer does not see the operator's sync"
    r = ctl(observer_cmd, "unsync", robot)
    assert r.returncode == 1, r.stderr
    assert observer_sees in one_line(r.stderr)
    assert json.loads(ctl(observer_cmd, "state", "--json").stdout)["revision"] == after["revision"]

    # What goes wrong: one line and the doc's exit code, with the doc's message.
    wrong = workdir / "secrets" / "wrong.pw"
    fd = os.open(wrong, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write("not-the-password\n")
    cases = [
        ("wrong password or unknown user", {"password_file": str(wrong.relative_to(workdir))}),
        ("no or wrong `--ca`", {"drop": "--ca"}),
    ]
    for cause, change in cases:
        assert cause in errors, f"{WHERE}: the error table has no row {cause!r}"
        r = ctl(operator_cmd, "state", **change)
        assert r.returncode == exit_code, (cause, r.returncode, r.stderr)
        message = errors[cause].replace(DOC_ENDPOINT, endpoint)
        assert matches(message, one_line(r.stderr)), (
            f"{cause}: the doc says {message!r}, ctl said {r.stderr!r}"
        )
