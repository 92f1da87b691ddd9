"""A site relay (`missionctl router`): a Zenoh router at the site (e.g. on the
lander) that the site's robots and consoles connect to, linked to the
ground's mission server over the long link.

It holds no mission state: Zenoh routes through it. What stays at the site
keeps working while the ground is unreachable — robots meet at barriers
(liveliness tokens) and ask each other (world queries) through the relay —
and the ground link is retried by Zenoh itself (every 1 s, backing off to
4 s). What waits for the ground waits in the robots (their downlink outbox)
and in the server (their uplink), as on any link.

Security, as at the server (docs/deployment.md):
- the site logs in here: `accounts` (the site's accounts, with the same
  names and roles as on the ground) become the relay's logins and
  access-control rules, so each account may do here what it may at the
  ground;
- the relay logs in at the ground with an account of role `relay`, which
  the ground lets carry everything of the protocol;
- the relay tells the ground's link from the site's by the common name of
  the ground's TLS certificate (`ground_cert_names`): a relay with accounts
  needs a tls/ link to the ground.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from backend.server.accounts import Accounts, zenoh_dictionary
from backend.server.acl import acl_config
from backend.transport import TransportChange, relay_config, transport_events
from backend.transport.session import close_session, open_session

log = logging.getLogger(__name__)

# what `missionctl certs` names the server's certificate
DEFAULT_GROUND_CERT_NAME = "missionctl server"


class SiteRelay:
    def __init__(
        self,
        *,
        listen: list[str],
        connect: list[str],
        zenoh_extra: dict[str, Any] | None = None,
        accounts: Accounts | None = None,
        ground_cert_names: list[str] | None = None,
        on_ground: Callable[[bool], object] | None = None,
    ):
        if accounts is not None and not any(e.startswith("tls/") for e in connect):
            raise ValueError(
                "a relay with --accounts needs a tls/ --connect endpoint: it tells the "
                "ground's link from the site's by the ground's certificate"
            )
        self.listen = list(listen)
        self.connect = list(connect)
        self.zenoh_extra = dict(zenoh_extra or {})
        self.accounts = accounts
        self.ground_cert_names = ground_cert_names or [DEFAULT_GROUND_CERT_NAME]
        self.on_ground = on_ground  # called on the loop: the ground link is up / down
        self.ground_up = False
        self.ground_links = 0  # how often the ground link came up (tests, logs)
        self._session: Any = None
        self._listener: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._grounds: set[str] = set()  # zids of the routers we are linked to

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._session = await asyncio.to_thread(self._open)
        self._listener = transport_events(self._session, self._on_transport, history=True)

    def _open(self) -> Any:
        extra = dict(self.zenoh_extra)
        if self.accounts is None:
            cfg = relay_config(self.listen, self.connect, extra=extra)
            return open_session(cfg, what="the relay's listen endpoint")
        mtls = bool(extra.get("transport/link/tls/enable_mtls"))
        extra["access_control"] = acl_config(
            self.accounts, cert_names=mtls, ground_cert_names=self.ground_cert_names
        )
        with zenoh_dictionary(self.accounts) as dictionary:
            extra["transport/auth/usrpwd/dictionary_file"] = dictionary
            cfg = relay_config(self.listen, self.connect, extra=extra)
            return open_session(cfg, what="the relay's listen endpoint")

    async def stop(self) -> None:
        self._listener = None
        session, self._session = self._session, None
        if session is not None:
            await asyncio.to_thread(close_session, session)

    async def __aenter__(self) -> SiteRelay:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    def _on_transport(self, change: TransportChange) -> None:  # a Zenoh thread
        if change.whatami != "router" or self._loop is None:
            return  # the site's robots and consoles come and go
        try:
            self._loop.call_soon_threadsafe(self._ground_changed, change)
        except RuntimeError:  # the loop is closed: stopping
            pass

    def _ground_changed(self, change: TransportChange) -> None:
        if change.connected:
            self._grounds.add(change.zid)
        else:
            self._grounds.discard(change.zid)
        up = bool(self._grounds)
        if up == self.ground_up:
            return
        self.ground_up = up
        if up:
            self.ground_links += 1
        if self.on_ground is not None:
            self.on_ground(up)
