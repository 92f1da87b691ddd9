"""A recorded mission, read-only: the server's journal.

The server writes it (backend/server/journal.py); this package only reads
it, never writes (SQLite `mode=ro`), so it works on a copy of a live
server's journal as on the live file itself. What reads it: `missionctl
review` (the console at any instant, in ground or robot time), its
`--report` (plan against actual) and the server's answer to `ctl history`.
The telemetry archive beside it is read by backend/protocol/archive.py.
"""
