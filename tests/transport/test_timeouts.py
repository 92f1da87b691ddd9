"""One delay setting derives every timeout (backend/transport/timeouts.py)."""

from __future__ import annotations

import argparse
import json

import pytest

from backend.client.client import MissionClient
from backend.transport import client_config, timeouts
from backend.transport.login import Login, add_login_arguments, login_from_args


def test_a_lan_keeps_zenohs_defaults_and_ours():
    assert timeouts.zenoh_options(0.0) == {}
    assert timeouts.query_timeout(5.0, 0.0) == 5.0
    assert timeouts.robot_lease_ms(1000, 0.0) == 1000  # a hung robot still shows within 1 s


@pytest.mark.parametrize("delay", [1.3, 5.0, 6.0])
def test_the_handshake_and_the_lease_outlast_the_round_trips(delay):
    rtt = 2 * delay
    # Zenoh's open exchange is ~3 round trips (TCP, TLS, init, open): 10 s failed at D = 5
    assert timeouts.handshake_s(delay) > 3 * rtt + 10
    # the far end hears the first keep-alive 2 D + lease / 4 after it started counting
    lease = timeouts.lease_s(delay)
    assert lease > rtt + lease / timeouts.KEEP_ALIVES_PER_LEASE
    assert timeouts.query_timeout(5.0, delay) >= 5.0 + rtt
    assert timeouts.robot_lease_ms(1000, delay) == round(lease * 1000)
    options = timeouts.zenoh_options(delay)
    assert options["transport/unicast/accept_timeout"] == round(timeouts.handshake_s(delay) * 1000)
    assert options["transport/link/tx/lease"] == round(lease * 1000)
    assert "transport/link/tx/lease" not in timeouts.zenoh_options(delay, lease=False)


def test_zenoh_takes_every_option_the_hint_sets():
    cfg = client_config(["tcp/127.0.0.1:7447"], extra=timeouts.zenoh_options(6.0))
    assert json.loads(cfg.get_json("transport/unicast/open_timeout")) == 58_000
    assert json.loads(cfg.get_json("routing/interests/timeout")) == 58_000
    assert json.loads(cfg.get_json("transport/link/tx/lease")) == 34_000


def _args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_login_arguments(p)
    return p.parse_args(list(argv))


@pytest.mark.parametrize(("text", "seconds"), [("6s", 6.0), ("1.3", 1.3), ("500ms", 0.5)])
def test_the_hint_reads_like_every_duration(text, seconds):
    login = login_from_args(_args("--link-delay-hint", text))
    assert login.link_delay_hint == seconds
    assert login.zenoh_options() == timeouts.zenoh_options(seconds)


def test_a_bad_hint_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exited:
        _args("--link-delay-hint", "soon")
    assert exited.value.code == 2
    assert "not a delay: 'soon' (examples: 6s" in capsys.readouterr().err


def test_a_client_waits_two_round_trips_more():
    c = MissionClient("tcp/127.0.0.1:7447", login=Login(link_delay_hint=6.0), timeout=10.0)
    assert c.timeout == 10.0 + 24.0
    assert c.zenoh_extra["transport/unicast/open_timeout"] == 58_000
