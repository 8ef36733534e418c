"""A TCP relay that holds every byte for a fixed time in each direction: added latency where ``tc netem`` is absent.

``python delay_relay.py DELAY_MS LISTEN_HOST:PORT=TARGET_HOST:PORT ...`` listens on each LISTEN address and
forwards each connection to its TARGET, every chunk delivered ``DELAY_MS`` after it was read, in order; a side
that closes is closed on the other side after the same delay. Prints ``relay listening on ...`` once every
address listens and runs until it is killed. A test helper (tests/integration/test_netns.py), not installed.
"""

from __future__ import annotations

import asyncio
import contextlib
import sys


async def pump(reader: asyncio.StreamReader, writer: asyncio.StreamWriter, delay_s: float) -> None:
    """Copy ``reader`` to ``writer``, each chunk ``delay_s`` after it was read; then close ``writer``."""
    loop = asyncio.get_running_loop()
    held: asyncio.Queue[tuple[float, bytes]] = asyncio.Queue()

    async def read() -> None:
        with contextlib.suppress(ConnectionError):
            while data := await reader.read(65536):
                held.put_nowait((loop.time() + delay_s, data))
        held.put_nowait((loop.time() + delay_s, b""))

    reading = asyncio.ensure_future(read())
    try:
        while True:
            due, data = await held.get()
            await asyncio.sleep(max(0.0, due - loop.time()))
            if not data:
                return
            writer.write(data)
            await writer.drain()
    except ConnectionError:
        return
    finally:
        reading.cancel()
        writer.close()


async def serve(delay_s: float, routes: list[tuple[str, int, str, int]]) -> None:
    """Listen on every route's address and relay each connection to its target."""

    def handler(host: str, port: int):
        async def relay(down_r: asyncio.StreamReader, down_w: asyncio.StreamWriter) -> None:
            try:
                up_r, up_w = await asyncio.open_connection(host, port)
            except OSError:
                down_w.close()
                return
            await asyncio.gather(pump(down_r, up_w, delay_s), pump(up_r, down_w, delay_s))

        return relay

    servers = [await asyncio.start_server(handler(th, tp), lh, lp) for lh, lp, th, tp in routes]
    print(f"relay listening on {', '.join(f'{lh}:{lp}' for lh, lp, _, _ in routes)}", flush=True)
    await asyncio.gather(*(s.serve_forever() for s in servers))


def parse(text: str) -> tuple[str, int, str, int]:
    """``LISTEN_HOST:PORT=TARGET_HOST:PORT`` as (listen host, port, target host, port)."""
    listen, _, target = text.partition("=")
    lh, _, lp = listen.rpartition(":")
    th, _, tp = target.rpartition(":")
    return lh, int(lp), th, int(tp)


if __name__ == "__main__":
    asyncio.run(serve(float(sys.argv[1]) / 1000.0, [parse(a) for a in sys.argv[2:]]))
