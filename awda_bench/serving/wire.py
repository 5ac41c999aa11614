"""The wire format of a served policy: messages as msgpack maps, NumPy arrays inside them as
``{"__ndarray__": True, "dtype": str, "shape": [...], "data": bytes}``.

Why this pair of libraries: `websockets <https://websockets.readthedocs.io>`_ carries the
messages (framing, ping/pong keep-alive, a closing handshake that tells a dropped connection
from a finished one, and a synchronous client and server, so the harness's worker and the policy
server stay plain blocking Python), and `msgpack <https://msgpack.org>`_ serializes them (binary,
no pickle: a server cannot run code in the harness, and either side can be another language).
openpi's websocket policy server and client use the same pair, and encode arrays the same way
(dtype, shape, raw bytes), so a 240x320x3 frame costs 230 kB plus a few bytes and no copy beyond
``tobytes``.

Values an :class:`~awda_bench.episode.Observations` call returns cross as themselves: arrays,
numbers, lists (a tuple comes back as a list), and the two observation records
(:class:`~awda_bench.episode.WristDepth`, :class:`~awda_bench.episode.Proprioception`) as
``{"__record__": name, field: value, ...}``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import msgpack
import numpy as np

from awda_bench.episode import Proprioception, WristDepth
from awda_bench.errors import RemotePolicyError

RECORDS: dict[str, type] = {"WristDepth": WristDepth, "Proprioception": Proprioception}
"""Observation records that cross the wire by name."""

_ARRAY_KINDS = "biuf"
"""NumPy dtype kinds that cross the wire (bool, ints, unsigned, floats); never objects."""


def _encode(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in _ARRAY_KINDS:
            raise TypeError(f"cannot send an array of dtype {value.dtype} (numbers and bools only)")
        contiguous = np.ascontiguousarray(value)
        return {
            "__ndarray__": True,
            "dtype": contiguous.dtype.str,
            "shape": list(contiguous.shape),
            "data": contiguous.tobytes(),
        }
    if isinstance(value, np.generic):
        return value.item()
    if dataclasses.is_dataclass(value) and type(value).__name__ in RECORDS:
        fields = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
        return {"__record__": type(value).__name__, **fields}
    raise TypeError(f"cannot send a {type(value).__name__}")


def _decode(value: dict[Any, Any]) -> Any:
    if value.get("__ndarray__") is True:
        dtype = np.dtype(value["dtype"])
        if dtype.kind not in _ARRAY_KINDS:
            raise TypeError(f"refusing an array of dtype {dtype}")
        return np.frombuffer(value["data"], dtype=dtype).reshape(value["shape"]).copy()
    name = value.get("__record__")
    if name is not None:
        record = RECORDS.get(name)
        if record is None:
            raise TypeError(f"unknown record {name!r}")
        return record(**{k: v for k, v in value.items() if k != "__record__"})
    return value


def pack(message: dict[str, Any]) -> bytes:
    """One message (a dict of plain values, arrays and observation records) as bytes."""
    return msgpack.packb(message, default=_encode, use_bin_type=True)


def unpack(data: bytes | str, *, peer: str) -> dict[str, Any]:
    """The message in ``data`` from ``peer`` (named in the error when it is not one of ours)."""
    if isinstance(data, str):
        raise RemotePolicyError(
            f"{peer} sent a text frame; a policy server speaks msgpack binary frames "
            "(is this `python -m awda_bench serve`?)"
        )
    try:
        message = msgpack.unpackb(data, object_hook=_decode, raw=False)
    except (ValueError, TypeError, msgpack.UnpackException) as exc:
        raise RemotePolicyError(
            f"{peer} sent a message that is not ours ({type(exc).__name__}: {exc}); "
            "check that both sides run the same awda_bench version"
        ) from exc
    if not isinstance(message, dict) or "type" not in message:
        raise RemotePolicyError(
            f"{peer} sent a message without a type; check that both sides run the same "
            "awda_bench version"
        )
    return message
