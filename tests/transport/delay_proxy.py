"""A TCP proxy that puts a long link's delay in the network, for tests and benchmarks.

    proxy = DelayProxy(("127.0.0.1", ground_port), delay=1.3).start()
    ... connect the site's relay to loopback_endpoint(proxy.port) ...
    proxy.cut(); ...; proxy.heal()
    proxy.close()

Every byte crosses `delay` seconds after it arrived, each way, in order (the
kernel's `netem` is not available on these machines). `cut()` is a radio
outage: nothing crosses and no new connection is accepted; what is in flight,
what is sent meanwhile (held back by TCP's flow control) and a side's close
arrive after `heal()`, as TCP would deliver them once the link is back.
`bytes_up` counts what went from the connecting side (the site) to the
listening one (the ground), `bytes_down` the other way.

It runs its own event loop on a thread of its own, so the test's loop (and
its waits) never add to the delay. As a program, for trying a deployment by
hand (docs/deployment.md):

    python tests/transport/delay_proxy.py --listen 7450 --to 127.0.0.1:7447 --delay 6
"""

from __future__ import annotations

import argparse
import asyncio
import threading
import time
from collections.abc import Callable
from typing import Any

_CHUNK = 65536
_CLOSE = b""  # queued after a side's last byte: close the other side in order


class _Pipe:
    """One direction of one connection: read, hold `delay`, write."""

    def __init__(
        self,
        proxy: DelayProxy,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        count: Callable[[int], None],
    ):
        self.proxy = proxy
        self.reader = reader
        self.writer = writer
        self.count = count
        self.queue: asyncio.Queue[tuple[float, bytes]] = asyncio.Queue()

    async def read(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            while True:
                await self.proxy.link_up.wait()  # cut: stop reading (TCP holds the sender)
                data = await self.reader.read(_CHUNK)
                self.queue.put_nowait((loop.time() + self.proxy.delay, data))
                if not data:
                    return
        except (ConnectionError, OSError):
            self.queue.put_nowait((loop.time() + self.proxy.delay, _CLOSE))

    async def write(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            while True:
                due, data = await self.queue.get()
                wait = due - loop.time()
                if wait > 0:
                    await asyncio.sleep(wait)
                await self.proxy.link_up.wait()
                if data is _CLOSE or not data:
                    break
                # counted first: the far end may read the bytes before write() returns
                self.count(len(data))
                self.writer.write(data)
                await self.writer.drain()
        except (ConnectionError, OSError):
            pass
        finally:
            self.writer.close()


class DelayProxy:
    def __init__(self, target: tuple[str, int], delay: float = 0.0, *, port: int = 0):
        self.target = target
        self.delay = float(delay)
        self.port = port  # 0: a free one, known after start()
        self.bytes_up = 0  # connecting side -> target (site -> ground)
        self.bytes_down = 0
        self.connections = 0  # accepted (and linked to the target) so far
        self.loop: asyncio.AbstractEventLoop | None = None
        self.link_up: asyncio.Event = None  # type: ignore[assignment]  # made on the loop
        self._server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[Any]] = set()
        self._thread: threading.Thread | None = None
        self._lock = threading.Condition()

    # ------------------------------------------------------------ from any thread

    def start(self) -> DelayProxy:
        ready = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(ready,), daemon=True)
        self._thread.start()
        if not ready.wait(10):
            raise RuntimeError("the delay proxy did not start")
        return self

    def cut(self) -> None:
        """The link goes down: nothing crosses, new connections are refused."""
        self._call(self._cut)

    def heal(self) -> None:
        """The link is back: what waited crosses (after the delay), connections are accepted."""
        self._call(self._heal)

    def close(self) -> None:
        if self.loop is None or self._thread is None:
            return
        self._call(self._close)
        self._thread.join(10)
        self.loop = None

    def wait_connections(self, n: int, timeout: float = 10.0) -> None:
        """Until `n` connections were accepted so far (their pipes run)."""
        with self._lock:
            if not self._lock.wait_for(lambda: self.connections >= n, timeout):
                raise TimeoutError(f"the delay proxy accepted {self.connections} of {n}")

    def counts(self) -> tuple[int, int]:
        """(bytes up, bytes down) so far."""
        with self._lock:
            return self.bytes_up, self.bytes_down

    def __enter__(self) -> DelayProxy:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------ on the proxy's loop

    def _run(self, ready: threading.Event) -> None:
        self.loop = asyncio.new_event_loop()
        self.loop.run_until_complete(self._listen())
        ready.set()
        self.loop.run_forever()
        self.loop.close()

    def _call(self, fn: Callable[[], Any]) -> None:
        loop = self.loop
        if loop is None:
            return
        done = threading.Event()

        async def run() -> None:
            try:
                result = fn()
                if asyncio.iscoroutine(result):
                    await result
            finally:
                done.set()

        asyncio.run_coroutine_threadsafe(run(), loop)
        done.wait(10)

    async def _listen(self) -> None:
        self.link_up = asyncio.Event()
        self.link_up.set()
        self._server = await asyncio.start_server(self._accept, "127.0.0.1", self.port)
        self.port = self._server.sockets[0].getsockname()[1]

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.target)
        except OSError:
            writer.close()  # nothing at the far end: the connecting side sees the close
            return
        up = _Pipe(self, reader, up_writer, self._count_up)
        down = _Pipe(self, up_reader, writer, self._count_down)
        for coro in (up.read(), up.write(), down.read(), down.write()):
            task = asyncio.create_task(coro)
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
        with self._lock:
            self.connections += 1
            self._lock.notify_all()

    def _count_up(self, n: int) -> None:
        with self._lock:
            self.bytes_up += n

    def _count_down(self, n: int) -> None:
        with self._lock:
            self.bytes_down += n

    async def _cut(self) -> None:
        self.link_up.clear()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
            self._server = None

    async def _heal(self) -> None:
        if self._server is None:
            self._server = await asyncio.start_server(self._accept, "127.0.0.1", self.port)
        self.link_up.set()

    async def _close(self) -> None:
        if self._server is not None:
            self._server.close()
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        assert self.loop is not None
        self.loop.call_soon(self.loop.stop)


def main() -> int:
    ap = argparse.ArgumentParser(description="a TCP proxy delaying every byte, each way")
    ap.add_argument("--listen", type=int, required=True, metavar="PORT", help="on 127.0.0.1")
    ap.add_argument("--to", required=True, metavar="HOST:PORT")
    ap.add_argument("--delay", type=float, default=0.0, metavar="S", help="one way, seconds")
    args = ap.parse_args()
    host, _, port = args.to.rpartition(":")
    proxy = DelayProxy((host, int(port)), args.delay, port=args.listen).start()
    print(
        f"delay proxy: 127.0.0.1:{proxy.port} -> {args.to}, {args.delay:g} s each way", flush=True
    )
    started = time.monotonic()
    try:
        while True:
            time.sleep(10)
            up, down = proxy.counts()
            wall = time.monotonic() - started
            print(
                f"delay proxy: {up / wall:.0f} B/s up, {down / wall:.0f} B/s down "
                f"({up} / {down} bytes in {wall:.0f} s)",
                flush=True,
            )
    except KeyboardInterrupt:
        pass
    finally:
        proxy.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
