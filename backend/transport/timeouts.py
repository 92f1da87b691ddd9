"""Every timeout of a connection from one number: the link's expected one-way
delay D (`--link-delay-hint`), in seconds.

A long link (the Moon: D = 1.3 s; a relay pass: D = several seconds) breaks
Zenoh's LAN defaults: its handshake takes about three round trips (TCP, TLS,
Zenoh's init and open exchanges), which at D = 5 s no longer fit in the
10 s open/accept timeouts, and the first keep-alive reaches the far end
2 D + lease/4 after it started counting. With RTT = 2 D:

    open and accept timeouts    10 s + 4 RTT          Zenoh's 10 s at D = 0
    interests timeout           10 s + 4 RTT          (a client's discovery, one round trip)
    lease                       10 s + 2 RTT          a robot's own lease at least this
    keep-alive                  4 per lease           Zenoh's default (every lease / 4)
    a protocol query's timeout  its LAN value + 2 RTT (a query and its reply cross the
                                                       link once each; as much again for
                                                       jitter and the far side's queue)
    waiting for the far end     its LAN value + 6 RTT (its handshake, then a query:
    at start (registering)                             `startup_s`)

D = 0 changes nothing: every process keeps its LAN defaults (a robot's 1 s
lease, the client's 10 s, the robot's 5 s). The same D goes to every process
of a deployment (server, relay, robots, consoles, ctl): a process on a
short link behind a relay still waits for answers from across the long one.
"""

from __future__ import annotations

from typing import Any

ZENOH_DEFAULT_S = 10.0  # Zenoh's open/accept/interests timeouts and its lease
KEEP_ALIVES_PER_LEASE = 4


def rtt(delay_s: float) -> float:
    return 2.0 * max(0.0, delay_s)


def handshake_s(delay_s: float) -> float:
    """Open and accept timeouts (also the interests timeout)."""
    return ZENOH_DEFAULT_S + 4.0 * rtt(delay_s)


def lease_s(delay_s: float) -> float:
    return ZENOH_DEFAULT_S + 2.0 * rtt(delay_s)


def query_timeout(base_s: float, delay_s: float) -> float:
    """A protocol query's timeout: `base_s` on a LAN, plus two round trips."""
    return base_s + 2.0 * rtt(delay_s)


def startup_s(base_s: float, delay_s: float) -> float:
    """How long to wait at start for the far end (a robot's registration):
    `base_s` on a LAN, plus the long link's handshake and a query."""
    return base_s + 6.0 * rtt(delay_s)


def robot_lease_ms(base_ms: int, delay_s: float) -> int:
    """A robot's lease: its own (short: a hung robot shows soon) on a LAN,
    at least `lease_s(D)` on a long link."""
    if delay_s <= 0:
        return base_ms
    return max(base_ms, round(lease_s(delay_s) * 1000))


def zenoh_options(delay_s: float, *, lease: bool = True) -> dict[str, Any]:
    """The Zenoh config options for D (nothing at D = 0: Zenoh's defaults).
    `lease=False` leaves the lease to the caller (a robot sets its own)."""
    if delay_s <= 0:
        return {}
    handshake_ms = round(handshake_s(delay_s) * 1000)
    out: dict[str, Any] = {
        "transport/unicast/open_timeout": handshake_ms,
        "transport/unicast/accept_timeout": handshake_ms,
        "routing/interests/timeout": handshake_ms,
        "transport/link/tx/keep_alive": KEEP_ALIVES_PER_LEASE,
    }
    if lease:
        out["transport/link/tx/lease"] = round(lease_s(delay_s) * 1000)
    return out


def describe(delay_s: float) -> str:
    """One line for a process's start-up message."""
    if delay_s <= 0:
        return "LAN timeouts"
    return (
        f"link delay hint {delay_s:g} s: open/accept {handshake_s(delay_s):g} s, "
        f"lease {lease_s(delay_s):g} s, queries +{2 * rtt(delay_s):g} s"
    )
