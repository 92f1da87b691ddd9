"""The delay proxy the relay tests put between ground and site."""

from __future__ import annotations

import asyncio
import time

from delay_proxy import DelayProxy

D = 0.2  # seconds each way: short, injected


async def _echo_server() -> asyncio.Server:
    async def echo(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        while data := await reader.read(1024):
            writer.write(data)
            await writer.drain()
        writer.close()

    return await asyncio.start_server(echo, "127.0.0.1", 0)


async def test_every_byte_crosses_after_the_delay_each_way_in_order():
    server = await _echo_server()
    port = server.sockets[0].getsockname()[1]
    with DelayProxy(("127.0.0.1", port), D) as proxy:
        reader, writer = await asyncio.open_connection("127.0.0.1", proxy.port)
        sent = time.monotonic()
        writer.write(b"one ")
        writer.write(b"two")
        await writer.drain()
        got = await asyncio.wait_for(reader.readexactly(7), 5)
        assert got == b"one two"
        assert time.monotonic() - sent >= 2 * D
        assert proxy.counts() == (7, 7)
        writer.close()
    server.close()


async def test_a_cut_holds_everything_until_the_link_heals():
    server = await _echo_server()
    port = server.sockets[0].getsockname()[1]
    with DelayProxy(("127.0.0.1", port), D) as proxy:
        reader, writer = await asyncio.open_connection("127.0.0.1", proxy.port)
        await asyncio.to_thread(proxy.wait_connections, 1)  # linked before the cut
        proxy.cut()
        try:  # a new connection finds no link
            _r, w = await asyncio.open_connection("127.0.0.1", proxy.port)
            w.close()
            refused = False
        except ConnectionRefusedError:
            refused = True
        assert refused
        writer.write(b"held")
        await writer.drain()
        reply = asyncio.ensure_future(reader.readexactly(4))
        done, _ = await asyncio.wait([reply], timeout=4 * D)  # nothing comes back meanwhile
        assert not done and proxy.counts() == (0, 0)
        proxy.heal()
        assert await asyncio.wait_for(reply, 5) == b"held"  # nothing lost
        _r, w = await asyncio.open_connection("127.0.0.1", proxy.port)  # accepted again
        w.close()
        writer.close()
    server.close()
