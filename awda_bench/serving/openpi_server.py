"""``OpenpiServer``: a method's policy behind openpi's websocket policy protocol (``python -m
awda_bench serve --protocol openpi``), for ``openpi_client.websocket_client_policy.
WebsocketClientPolicy``, or ``run --method remote --protocol openpi``, to query.

It speaks as openpi's ``WebsocketPolicyServer`` does: the metadata on connect
(:func:`~.openpi_schema.server_metadata`: the method, its snapshot hash, the observation keys it
reads), then one reply per request, ``server_timing`` (``infer_ms``, ``prev_total_ms``) added;
when the policy raises, its traceback as a text frame, and the connection closed (1011). Each
connection plays on an :class:`~.openpi_adapter.OpenpiAdapter` over a policy of its own (the
pool and start-up checks of :class:`~.server.PolicyServer`, whose conversation this replaces).
"""

from __future__ import annotations

import sys
import time
import traceback
from collections.abc import Callable
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.frames import CloseCode
from websockets.sync.server import ServerConnection

from awda_bench.episode import Policy
from awda_bench.serving.openpi_adapter import OpenpiAdapter
from awda_bench.serving.openpi_schema import DEFAULT_DEMO_FRAMES, SERVER_TIMING
from awda_bench.serving.protocol import ServerInfo
from awda_bench.serving.server import PolicyServer
from awda_bench.serving.wire import decode, pack_openpi

CLIENT = "the client"
"""How the server names its peer in errors."""


class OpenpiServer(PolicyServer):
    """Serve policies built by ``make_policy`` as ``info`` over openpi's protocol on
    ``ws://host:port`` (port 0: any free port; :attr:`url` says which)."""

    def __init__(
        self,
        make_policy: Callable[[], Policy],
        info: ServerInfo,
        host: str = "127.0.0.1",
        port: int = 0,
        demo_frames: int = DEFAULT_DEMO_FRAMES,
    ) -> None:
        super().__init__(make_policy, info, host, port)  # listens; serves once serve_forever runs
        self.demo_frames = demo_frames
        self.metadata: dict[str, Any] = OpenpiAdapter(
            self._idle[0], info=info, demo_frames=demo_frames
        ).metadata
        """What every connection is sent first."""

    def _handle(self, connection: ServerConnection) -> None:
        policy = self._take_policy()
        adapter = OpenpiAdapter(policy, info=self.info, demo_frames=self.demo_frames)
        try:
            connection.send(pack_openpi(self.metadata))
            previous_total_s: float | None = None
            for data in connection:
                start = time.monotonic()
                try:
                    if isinstance(data, str):
                        raise ValueError("a text frame; an openpi client sends msgpack binary")
                    request = decode(data, peer=CLIENT, hint="an openpi client sends msgpack")
                    reply = adapter.infer(request)
                    timing = {"infer_ms": (time.monotonic() - start) * 1e3}
                    if previous_total_s is not None:
                        timing["prev_total_ms"] = previous_total_s * 1e3
                    reply[SERVER_TIMING] = timing
                    encoded = pack_openpi(reply)
                except Exception:  # openpi's way: the traceback as text, then close
                    text = traceback.format_exc()
                    print(
                        f"served policy {self.info.method!r} raised:\n{text}",
                        file=sys.stderr,
                        flush=True,
                    )
                    connection.send(text)
                    connection.close(
                        CloseCode.INTERNAL_ERROR,
                        "Internal server error. Traceback included in previous frame.",
                    )
                    return
                connection.send(encoded)
                previous_total_s = time.monotonic() - start
        except ConnectionClosed:
            pass  # the client went away (finished, killed, or timed out): nothing to answer
        finally:
            self._give_back(policy)
