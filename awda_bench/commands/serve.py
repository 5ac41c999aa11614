"""``python -m awda_bench serve``: run a method's policy behind a websocket, for
``run --method remote --policy-url ws://HOST:PORT`` to evaluate from another process or machine.

One server serves one snapshot: the newest in ``--checkpoints`` (or ``--snapshot NAME``); to
evaluate several, serve each in turn (or on several ports) and ``run`` against each: the rows are
keyed by the served snapshot's content hash, so they land beside one another in the store as an
in-process ``run --snapshots N`` puts them. Privileged methods (which read the simulator) cannot
be served.

``--protocol openpi`` serves it over openpi's websocket policy protocol instead
(:class:`~awda_bench.serving.openpi_server.OpenpiServer`), for any openpi client
(``openpi_client.websocket_client_policy.WebsocketClientPolicy``) or
``run --method remote --protocol openpi``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.evaluation.methods import (
    MethodSpec,
    SnapshotRef,
    get_method,
    make_policy,
    method_names,
    select_snapshots,
)
from awda_bench.serving.openpi_server import OpenpiServer
from awda_bench.serving.protocol import NATIVE, OPENPI, PROTOCOLS, ServerInfo
from awda_bench.serving.server import PolicyServer

DEFAULT_PORT = 8765
"""``--port`` when none is given."""


HELP = "serve a method's policy on a websocket (evaluate it with run --method remote)"
DESCRIPTION = (
    "Build one method's policy and serve it until interrupted; each harness "
    "worker that connects plays its episodes on a policy of its own. Evaluate it with "
    "`python -m awda_bench run --suite S --method remote --policy-url ws://HOST:PORT`."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--method",
        required=True,
        help=f"method ({', '.join(method_names())}, or pkg.module:Factory); not a privileged one",
    )
    parser.add_argument("--checkpoints", type=Path, help="snapshot directory of a learned method")
    parser.add_argument(
        "--snapshot",
        metavar="NAME",
        help="learned methods: the snapshot file to serve (default: the newest)",
    )
    parser.add_argument(
        "--protocol",
        choices=PROTOCOLS,
        default=NATIVE,
        help=f"{NATIVE}: awda_bench's own (for run --method remote; default); {OPENPI}: openpi's "
        "websocket policy protocol (for any openpi client, or run --method remote --protocol "
        "openpi; docs/serving.md gives the observation keys)",
    )
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="interface to listen on (default 127.0.0.1; 0.0.0.0 for other machines)",
    )
    parser.add_argument(
        "--port",
        type=int,
        default=DEFAULT_PORT,
        help=f"port (default {DEFAULT_PORT}; 0: any free port, printed)",
    )


def served_snapshot(spec: MethodSpec, checkpoints: Path | None, name: str | None) -> SnapshotRef:
    """The one snapshot a server of ``spec`` serves: ``name``, or the newest."""
    if name is not None and not spec.learned:
        raise UsageError(f"method {spec.name!r} is not learned; drop --snapshot")
    if name is None:
        return select_snapshots(spec, checkpoints, last_n=1)[0]
    refs = select_snapshots(spec, checkpoints, last_n=1_000_000)
    for ref in refs:
        if ref.name == name:
            return ref
    listed = ", ".join(r.name for r in refs)
    raise UsageError(f"no snapshot {name!r} in {checkpoints}; choose one of: {listed}")


def build_server(
    method: str,
    checkpoints: Path | None = None,
    snapshot_name: str | None = None,
    host: str = "127.0.0.1",
    port: int = 0,
    protocol: str = NATIVE,
) -> PolicyServer:
    """A server of ``method`` (one snapshot) speaking ``protocol``, listening; one line if it
    cannot be served."""
    if protocol not in PROTOCOLS:
        raise UnknownChoiceError("--protocol", protocol, PROTOCOLS)
    spec = get_method(method)
    if spec.privileged:
        raise UsageError(
            f"method {spec.name!r} is privileged (it reads the simulator), so it cannot be "
            f"served: evaluate it in-process with `run --method {spec.name}`"
        )
    if not 0 <= port < 65536:
        raise UsageError(f"--port must be in 0..65535 (got {port})")
    snapshot = served_snapshot(spec, checkpoints, snapshot_name)
    info = ServerInfo(
        method=spec.name,
        snapshot=snapshot.sha256,
        snapshot_name=snapshot.name,
        snapshot_order=snapshot.order,
        learned=spec.learned,
    )
    server = OpenpiServer if protocol == OPENPI else PolicyServer
    try:
        return server(lambda: make_policy(spec, snapshot), info, host, port)
    except OSError as exc:
        raise UsageError(
            f"cannot listen on {host}:{port} ({exc.strerror or exc}); choose another --port or "
            "--host"
        ) from exc


def run(args: argparse.Namespace) -> int:
    server = build_server(
        args.method, args.checkpoints, args.snapshot, args.host, args.port, args.protocol
    )
    with server:
        info = server.info
        flag = "" if args.protocol == NATIVE else f" --protocol {args.protocol}"
        print(
            f"serving {info.method} (snapshot {info.snapshot_name}) on {server.url}; evaluate it "
            f"with `python -m awda_bench run --suite SUITE --method remote --policy-url "
            f"{server.url}{flag}`",
            flush=True,
        )
        try:
            server.serve_forever()
        except KeyboardInterrupt:  # Ctrl-C is how a server is stopped
            print("policy server stopped", file=sys.stderr)
    return 0
