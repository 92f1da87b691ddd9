"""`missionctl review DB`: the console at any instant of a recorded mission,
or its plan-against-actual report (`--report [--json]`).

DB is a server's journal (`--db` of `missionctl server`), live or a copy:
it is opened read-only and never written. The telemetry archive beside it
(`mission.telemetry.db` for `mission.db`) is read when there is one.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK

CLOCK_HELP = (
    "ground: what the ground knew at each instant (journal order and times, the default); "
    "robot: what the robots reported happened at each instant (their reports' own times)"
)


def register(sub: argparse._SubParsersAction) -> None:
    r = sub.add_parser(
        "review",
        help="the console, read-only, at any instant of a recorded mission (or --report)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    r.add_argument("db", metavar="DB", help="a mission server's journal (--db), or a copy of it")
    r.add_argument(
        "--telemetry",
        metavar="FILE",
        help="its telemetry archive (default: DB's .telemetry.db beside it, when there is one)",
    )
    r.add_argument(
        "--library",
        metavar="FILE",
        help="the skill library (default: the one the journal names, else the mission's "
        "next to DB)",
    )
    r.add_argument("--at", metavar="TIME", help="start at 14:32, 14:32:05 or #REVISION")
    r.add_argument("--clock", choices=("ground", "robot"), default="ground", help=CLOCK_HELP)
    r.add_argument(
        "--report",
        action="store_true",
        help="print the plan against what happened (per skill, failures and retries, "
        "waivers, refusals, who did what) instead of opening the console",
    )
    r.add_argument("--json", action="store_true", help="with --report: one JSON object")
    r.add_argument("--theme", metavar="T", help="the console's theme")
    r.add_argument("--config", metavar="FILE", help="the console's settings file")
    r.set_defaults(func=run_review)


def _fail(message: str) -> int:
    print(f"missionctl review: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


def run_review(args: argparse.Namespace) -> int:
    from backend.core.records import RecordError
    from backend.files.record.journal import JournalReader
    from backend.files.record.report import plan_against_actual, report_text

    if args.json and not args.report:
        return _fail("--json goes with --report")
    try:
        journal = JournalReader(args.db)
    except RecordError as e:
        return _fail(str(e))
    try:
        if args.report:
            report = plan_against_actual(journal)
            if args.json:
                print(json.dumps(report.model_dump(mode="json"), indent=1))
            else:
                sys.stdout.write(report_text(report))
            return EXIT_OK
        return _console(args, journal)
    except RecordError as e:
        return _fail(str(e))
    finally:
        journal.close()


def _console(args: argparse.Namespace, journal) -> int:
    from backend.core.records import RecordError
    from backend.protocol.archive import ArchiveReader, archive_path
    from console.config import load_config
    from console.options import known_binding_ids
    from console.review.app import ReviewApp
    from console.state.replay import Replay

    library, problem = _library(args, journal)
    if library is None:
        return _fail(problem)
    path = Path(args.telemetry) if args.telemetry else archive_path(journal.path)
    archive = None
    notices = []
    if path.exists() or args.telemetry:
        archive = ArchiveReader(path)  # RecordError: the caller says it
    else:
        notices.append(
            f"no telemetry archive beside {journal.path} ({path.name}): robots' positions, "
            "battery and link, alerts and presence are not shown"
        )
    try:
        at = _start_at(args, journal)
    except ValueError as e:
        return _fail(f"--at: {e}")

    def make_replay(model):
        replay = Replay(model, journal, library, archive)
        replay.cursor.clock = args.clock
        return replay

    cfg = load_config(args.config, known_ids=known_binding_ids())
    if journal.gap:
        notices.append(
            f"this journal keeps what came after revision {journal.base} only: its older "
            "snapshots were not kept (a server before review kept its last three)"
        )
    app = ReviewApp(
        make_replay, what=journal.path.name, at=at, theme=args.theme, config=cfg, notices=notices
    )
    try:
        app.run()
    except RecordError as e:
        return _fail(str(e))
    finally:
        if archive is not None:
            archive.close()
    return EXIT_OK


def _start_at(args: argparse.Namespace, journal) -> float | None:
    """The instant --at names in --clock (None: the end); ValueError saying why not."""
    from console.state.replay import parse_goto

    if not args.at:
        return None
    kind, value = parse_goto(args.at, journal.start_time() or 0.0)
    if kind == "time":
        return value
    i = int(value) - journal.base - 1
    if not 0 <= i < len(journal):
        raise ValueError(
            f"no revision {int(value)} (this journal holds {journal.base + 1} to {journal.last})"
        )
    return float(journal.order(args.clock).keys[i])


def _library(args: argparse.Namespace, journal):
    """The skill library: --library, the journal's (as recorded, then beside
    DB), the base mission's next to DB. (library, "") or (None, why)."""
    from backend.files.diagnostics import FileProblems
    from backend.files.missions import load_library

    named = journal.library
    candidates = [Path(args.library)] if args.library else []
    if named:
        candidates += [Path(named), journal.path.parent / Path(named).name]
    candidates.append(journal.path.parent / journal.snapshot(journal.base).library)
    tried = []
    for c in candidates:
        if c.is_file():
            try:
                return load_library(c), ""
            except FileProblems as e:
                return None, "; ".join(str(i) for i in e.issues)
        tried.append(str(c))
    return None, (
        f"cannot find the skill library (tried {', '.join(tried)}): give it with --library FILE"
    )
