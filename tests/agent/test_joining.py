"""A robot under a new name (issue 30): the server announces it and answers
`joining`; the agent keeps registering, without raising, until an operator
adds it."""

from __future__ import annotations

import pytest

from .conftest import Harness


async def test_a_joining_robot_registers_again_until_it_is_added(harness: Harness) -> None:
    async with harness as h:
        lru3 = h.name("lru3")
        h.server.refuse_code = "joining"
        h.server.refuse = f"robot '{lru3}' (rover) is not part of this mission yet"
        a = h.agent(lru3)
        await a.start()
        # not refused for good: still waiting, and saying why
        with pytest.raises(TimeoutError, match="is not part of this mission yet"):
            await a.wait_registered(0.3)
        h.server.refuse = None  # an operator added it
        await a.wait_registered(10)
        assert a.last_register_reply is not None and a.last_register_reply.accepted
