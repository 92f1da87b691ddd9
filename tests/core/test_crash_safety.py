"""Crash safety: a journaling process killed with SIGKILL at random moments
comes back with a consistent mission equal to a prefix of what it applied.

The worker (crash_worker.py, a subprocess: never a fork of the test process)
applies a long deterministic stream of operations, one journal transaction
each, snapshotting every 50 revisions, and prints each revision once it is
committed. For half the seeds it checkpoints the journal on a thread every
16 batches, as the server does (every 512), so kills land during those too.
The test reads k lines (k random), kills the worker right away and reopens
the journal. The kill moments are set by the worker's own output, not
by sleeping.

Checks after each kill:
- the mission loads and is consistent (section order per robot, unique ids,
  barrier rules);
- its revision R is the last printed one or the one after it (committed, killed
  before printing): nothing committed is lost;
- it equals the mission the same stream gives in-process at revision R (a
  prefix of the applied operations, never part of one), request ids included;
- the journal takes the next batch after the crash.
"""

from __future__ import annotations

import random
import subprocess
import sys
import time
from pathlib import Path

from backend.core.events import EventBatch
from backend.core.model import Mission
from backend.server.journal import Journal

sys.path.insert(0, str(Path(__file__).parent))
from crash_worker import OpGenerator, mission_problems, start_engine  # noqa: E402

WORKER = Path(__file__).with_name("crash_worker.py")
ROOT = Path(__file__).resolve().parents[2]
SEEDS = (101, 202, 303, 404)
BACKGROUND_CHECKPOINTS = (202, 404)
KILLS_PER_SEED = 6
N_STEPS = 6000  # about 4,500 revisions: the worker is killed long before the end
SNAPSHOT_EVERY = 50
MAX_LINES = 2500


def run_and_kill(db: Path, seed: int, k: int, err: Path) -> tuple[list[int], bool, int]:
    """Start the worker, read k lines, SIGKILL it; every revision it printed
    (also those still in the pipe), whether it finished, its return code."""
    with err.open("w") as errf:
        proc = subprocess.Popen(
            [
                sys.executable,
                str(WORKER),
                str(db),
                str(seed),
                str(N_STEPS),
                str(SNAPSHOT_EVERY),
                # half the seeds checkpoint on a thread as the server does, half leave it to SQLite
                "background" if seed in BACKGROUND_CHECKPOINTS else "sqlite",
            ],
            stdout=subprocess.PIPE,
            stderr=errf,
            stdin=subprocess.DEVNULL,
            text=True,
            cwd=ROOT,
        )
        lines: list[str] = []
        try:
            while len(lines) < k:
                line = proc.stdout.readline()
                if not line:
                    break
                lines.append(line.strip())
        finally:
            proc.kill()  # SIGKILL: no cleanup, no atexit, no flush
            rc = proc.wait()
            lines += proc.stdout.read().split()
            proc.stdout.close()
    done = "done" in lines
    return [int(x) for x in lines if x != "done"], done, rc


def reference_states(seed: int, wanted: set[int]) -> dict[int, tuple[str, list, str | None]]:
    """The same stream in-process: at each wanted revision, the mission's JSON,
    the (client, request_id, revision) so far and that revision's batch JSON."""
    engine = start_engine()
    out: dict[int, tuple[str, list, str | None]] = {}
    requests: list[tuple[str, str, int]] = []
    if 0 in wanted:
        out[0] = (engine.mission.model_dump_json(), [], None)

    def capture(st) -> None:
        rev = st.applied.revision
        requests.append((st.client, st.request_id, rev))
        if rev in wanted:
            out[rev] = (
                engine.mission.model_dump_json(),
                list(requests),
                st.applied.batch(st.client).model_dump_json(),
            )

    gen = OpGenerator(engine, seed, on_step=capture)
    top = max(wanted)
    for _ in range(N_STEPS):
        if engine.mission.revision >= top:
            break
        gen.step()
    return out


def test_sigkill_at_random_moments_recovers_a_consistent_prefix(tmp_path):
    t0 = time.monotonic()
    rng = random.Random(20240611)
    runs: list[tuple[int, int, Path, list[int], bool]] = []
    n = 0
    for seed in SEEDS:
        for i in range(KILLS_PER_SEED):
            # small k (before/around the first snapshots) as well as large ones
            k = (
                rng.choice((0, 1, 2))
                if (n == 0)
                else rng.randint(1, 60)
                if i == 0
                else rng.randint(1, MAX_LINES)
            )
            db = tmp_path / f"s{seed}-{i}.db"
            err = tmp_path / f"s{seed}-{i}.err"
            printed, done, rc = run_and_kill(db, seed, k, err)
            problem = err.read_text()
            assert not problem.strip(), f"worker (seed {seed}) failed:\n{problem}"
            assert done or rc == -9, f"worker exited with {rc}"
            assert printed == list(range(1, len(printed) + 1)), "revisions are consecutive from 1"
            assert done or len(printed) >= k
            runs.append((seed, k, db, printed, done))
            n += 1

    recovered: list[tuple[int, int, Path, list[int], bool, int | None]] = []
    for seed, k, db, printed, done in runs:
        last_printed = printed[-1] if printed else 0
        with Journal.open(db) as j:
            mission, requests = j.load()
            if mission is None:
                # killed before the base snapshot was committed: nothing was
                assert not printed
                assert requests == []
                recovered.append((seed, k, db, printed, done, None))
                continue
            info = j.load_info
            r = mission.revision
            assert last_printed <= r <= last_printed + (0 if done else 1), (
                f"seed {seed}, k={k}: recovered revision {r}, last printed {last_printed}"
            )
            assert j.last_revision() == r
            assert info.replayed <= SNAPSHOT_EVERY
            assert len(j.snapshot_revisions()) <= 3
            problems = mission_problems(mission)
            assert not problems, f"seed {seed}, k={k}, revision {r}: {problems}"
        recovered.append((seed, k, db, printed, done, r))

    by_seed: dict[int, set[int]] = {}
    for seed, _, _, _, _, r in recovered:
        if r is not None:
            by_seed.setdefault(seed, set()).update({r, r + 1})
    for seed, wanted in by_seed.items():
        ref = reference_states(seed, wanted)
        for s, k, db, _, _, r in recovered:
            if s != seed or r is None:
                continue
            want_json, want_requests, _ = ref[r]
            with Journal.open(db) as j:
                mission, requests = j.load()
                assert mission.model_dump_json() == want_json, (
                    f"seed {seed}, k={k}: revision {r} differs from the in-process run"
                )
                assert mission == Mission.model_validate_json(want_json)
                assert [r[:3] for r in requests] == want_requests  # (client, id, revision)
                # the journal goes on after the crash: the next batch of the stream
                if r + 1 in ref:
                    nxt_json, _, batch_json = ref[r + 1]
                    j.append(EventBatch.model_validate_json(batch_json))
                    again, _ = j.load()
                    assert again.model_dump_json() == nxt_json

    revisions = sorted(r for *_, r in recovered if r is not None)
    assert len(recovered) >= 20
    assert len(set(revisions)) >= 15, f"kill moments were not varied: {revisions}"
    assert any(r > 3 * SNAPSHOT_EVERY for r in revisions), "no kill after several snapshots"
    elapsed = time.monotonic() - t0
    print(f"\n{len(recovered)} kills, recovered revisions {revisions}, {elapsed:.1f} s")
