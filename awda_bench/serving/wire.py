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

openpi's websocket policy protocol (:mod:`.openpi_schema`) uses the same array encoding with
*binary* keys (``b"__ndarray__"``, ``b"data"``, ``b"dtype"``, ``b"shape"``: its
``openpi_client.msgpack_numpy`` packs them as msgpack bin, and reads only those), and NumPy scalars
as ``{b"__npgeneric__": True, b"data": value, b"dtype": str}``. :func:`pack_openpi` writes that
flavour; the decoder reads either key flavour (and ``__npgeneric__``), so one decoder serves both
protocols. Either way only bool and numeric dtypes cross (openpi's own decoder would build an
object array from a peer's message; this one refuses it).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import msgpack
import numpy as np

from awda_bench.episode import Proprioception, WristDepth
from awda_bench.errors import RemotePolicyError

NOT_OURS = "check that both sides run the same awda_bench version"
"""The fix named when a native peer's message cannot be read."""

RECORDS: dict[str, type] = {"WristDepth": WristDepth, "Proprioception": Proprioception}
"""Observation records that cross the wire by name."""

_ARRAY_KINDS = "biuf"
"""NumPy dtype kinds that cross the wire (bool, ints, unsigned, floats); never objects."""


def _array(value: np.ndarray, key: Any) -> dict[Any, Any]:
    """``value`` as the array map, its keys made by ``key`` (``str`` or ``str.encode``)."""
    if value.dtype.kind not in _ARRAY_KINDS:
        raise TypeError(f"cannot send an array of dtype {value.dtype} (numbers and bools only)")
    contiguous = np.ascontiguousarray(value)
    return {
        key("__ndarray__"): True,
        key("dtype"): contiguous.dtype.str,
        key("shape"): list(contiguous.shape),
        key("data"): contiguous.tobytes(),
    }


def _encode(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return _array(value, str)
    if isinstance(value, np.generic):
        return value.item()
    if dataclasses.is_dataclass(value) and type(value).__name__ in RECORDS:
        fields = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
        return {"__record__": type(value).__name__, **fields}
    raise TypeError(f"cannot send a {type(value).__name__}")


def _encode_openpi(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return _array(value, str.encode)
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot send a {type(value).__name__}")


def _field(value: dict[Any, Any], name: str) -> Any:
    """``value[name]`` under a text or a binary key."""
    return value[name] if name in value else value[name.encode()]


def _numeric_dtype(value: dict[Any, Any]) -> np.dtype:
    dtype = np.dtype(_field(value, "dtype"))
    if dtype.kind not in _ARRAY_KINDS:
        raise TypeError(f"refusing an array of dtype {dtype}")
    return dtype


def _decode(value: dict[Any, Any]) -> Any:
    if value.get("__ndarray__") is True or value.get(b"__ndarray__") is True:
        dtype = _numeric_dtype(value)
        data, shape = _field(value, "data"), _field(value, "shape")
        return np.frombuffer(data, dtype=dtype).reshape(shape).copy()
    if value.get(b"__npgeneric__") is True or value.get("__npgeneric__") is True:
        return _numeric_dtype(value).type(_field(value, "data"))
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


def pack_openpi(message: Any) -> bytes:
    """``message`` (plain values and arrays) as openpi's ``msgpack_numpy`` packs it."""
    return msgpack.packb(message, default=_encode_openpi, use_bin_type=True)


def decode(data: bytes, *, peer: str, hint: str) -> Any:
    """The msgpack value in ``data`` from ``peer``, its arrays decoded (either key flavour);
    a one-line error ending in ``hint`` when it is not msgpack."""
    try:
        return msgpack.unpackb(data, object_hook=_decode, raw=False)
    except (ValueError, TypeError, KeyError, msgpack.UnpackException) as exc:
        raise RemotePolicyError(
            f"{peer} sent a message that is not ours ({type(exc).__name__}: {exc}); {hint}"
        ) from exc


def unpack(data: bytes | str, *, peer: str) -> dict[str, Any]:
    """The message in ``data`` from ``peer`` (named in the error when it is not one of ours)."""
    if isinstance(data, str):
        raise RemotePolicyError(
            f"{peer} sent a text frame; a policy server speaks msgpack binary frames "
            "(is this `python -m awda_bench serve`?)"
        )
    message = decode(data, peer=peer, hint=NOT_OURS)
    if not isinstance(message, dict) or "type" not in message:
        raise RemotePolicyError(
            f"{peer} sent a message without a type; check that both sides run the same "
            "awda_bench version"
        )
    return message
