"""A TCP relay that delays every byte by D seconds in each direction: the
delay in the network rather than in the robot SDK (`agent.link.delay_s`).
Runs its own event loop on a thread, so the measured process's loop cannot
hold it up.

    with DelayProxy(upstream_port, delay=2.0) as proxy:
        connect to tcp/127.0.0.1:{proxy.port}
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

from backend.transport import free_port

CHUNK = 65536


class DelayProxy:
    def __init__(self, upstream_port: int, delay: float, host: str = "127.0.0.1"):
        self.upstream = (host, upstream_port)
        self.delay = delay
        self.host = host
        self.port = free_port()
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True)
        self._server: asyncio.Server | None = None
        self._conns: set[asyncio.Task[Any]] = set()

    def __enter__(self) -> DelayProxy:
        self._thread.start()
        asyncio.run_coroutine_threadsafe(self._start(), self._loop).result(10)
        return self

    def __exit__(self, *exc: object) -> None:
        asyncio.run_coroutine_threadsafe(self._stop(), self._loop).result(10)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10)
        self._loop.close()

    async def _start(self) -> None:
        self._server = await asyncio.start_server(self._accept, self.host, self.port)

    async def _stop(self) -> None:
        assert self._server is not None
        self._server.close()
        for task in list(self._conns):
            task.cancel()
        await asyncio.gather(*self._conns, return_exceptions=True)

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._conns.add(task)
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.upstream)
            await asyncio.gather(self._pump(reader, up_writer), self._pump(up_reader, writer))
        except (OSError, asyncio.CancelledError):
            pass
        finally:
            self._conns.discard(task)
            writer.close()

    async def _pump(self, src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
        """Bytes from `src` reach `dst` `delay` seconds after they arrived, in order."""
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[tuple[float, bytes] | None] = asyncio.Queue()

        async def feed() -> None:
            while data := await src.read(CHUNK):
                queue.put_nowait((loop.time() + self.delay, data))
            queue.put_nowait(None)

        async def drain() -> None:
            while (item := await queue.get()) is not None:
                due, data = item
                if (wait := due - loop.time()) > 0:
                    await asyncio.sleep(wait)
                dst.write(data)
                await dst.drain()
            dst.close()

        await asyncio.gather(feed(), drain())
