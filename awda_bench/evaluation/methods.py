"""Method registry: a name -> how to build its :class:`~awda_bench.episode.Policy`.

Targets are ``"module:attribute"`` strings, imported only when a method is used (so the harness
loads without torch models, and a spawned worker rebuilds a policy from plain strings). A
non-learned method's target is called with no argument and counts as one snapshot
(:data:`BUILTIN_SNAPSHOT`); a learned method's target is called with the snapshot file's path, and
its snapshots are listed and checked with :mod:`awda_bench.models.snapshot` (or the method's own
``list_snapshots``/``load_snapshot`` targets).

A method of your own is ``--method pkg.module:Factory`` (no registration): ``Factory()`` builds
its policy. It is learned when ``Factory`` has the two public snapshot hooks (for instance as
static methods of a policy class)::

    Factory.list_snapshots(directory) -> list of snapshot paths, oldest first
    Factory.load_snapshot(path)       -> anything; raises on a file it cannot use

and is then evaluated per snapshot with ``--checkpoints DIR``: ``Factory(path)`` builds the
policy of one snapshot, and each snapshot is keyed in the store by its content hash.

A served method (``--method remote --policy-url ws://HOST:PORT [--protocol openpi]``, see
:mod:`awda_bench.serving`) is named and keyed by what its server says it serves
(:func:`served_method`): one snapshot per server, its rows labelled with the served method's name.
"""

from __future__ import annotations

import hashlib
import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from awda_bench.episode import Policy, is_privileged
from awda_bench.errors import CorruptFileError, UnknownChoiceError, UsageError
from awda_bench.serving.openpi_policy import OpenpiPolicy, fetch_openpi_metadata
from awda_bench.serving.protocol import NATIVE, OPENPI, PROTOCOLS
from awda_bench.serving.remote_policy import (
    DEFAULT_TIMEOUT_S,
    RemotePolicy,
    ServedMethod,
    fetch_server_info,
)

BUILTIN_SNAPSHOT = "builtin"
"""Snapshot hash recorded for non-learned methods."""

SNAPSHOT_HOOKS = ("list_snapshots", "load_snapshot")
"""The attributes that make an imported ``--method pkg.module:Factory`` a learned method."""

DEFAULT_METHOD = "gt-waypoints"
"""Evaluated when ``run`` is given no ``--method``."""

REMOTE_METHOD = "remote"
"""``--method remote``: the method served at ``--policy-url`` (its rows take the served name)."""


@dataclass(frozen=True)
class MethodSpec:
    """How to build one method's policy."""

    name: str
    """Name used with ``--method`` and as the table column."""
    target: str
    """``"module:attribute"`` of the policy class or factory."""
    learned: bool = False
    """True: evaluated per snapshot file from ``--checkpoints``; False: one snapshot."""
    list_snapshots: str = "awda_bench.models.snapshot:list_snapshots"
    """``"module:attribute"`` of ``list_snapshots(directory) -> list[Path]`` (oldest first)."""
    load_snapshot: str = "awda_bench.models.snapshot:load_snapshot"
    """``"module:attribute"`` of ``load_snapshot(path)``, raising on a corrupt file."""
    description: str = ""
    """One line for ``--help``."""
    privileged: bool = False
    """The policy reads the simulator (its ``privileged`` class attribute, which
    :func:`make_policy` checks against this); its rows are marked in the tables."""
    served: ServedMethod | None = None
    """Set for a served method: its policy is a :class:`RemotePolicy` talking to this server
    (``target`` is then unused)."""
    options: tuple[tuple[str, Any], ...] = ()
    """Keyword arguments of the target's call, ``(name, value)`` pairs: a family's variant (one
    factory per family, e.g. ``tosvi-mean`` is ``TosviPolicy(path, action_select="mean")``)."""


@dataclass(frozen=True)
class SnapshotRef:
    """One snapshot to evaluate."""

    sha256: str
    """Content hash (first 16 hex digits), the snapshot's identity in the store."""
    name: str
    """File name (or ``"builtin"``)."""
    path: str | None
    """File path, ``None`` for non-learned methods."""
    order: int
    """Position in training order (0 = oldest listed)."""


_REGISTRY: dict[str, MethodSpec] = {}


def register_method(spec: MethodSpec) -> None:
    """Add (or replace) a method; tests register fakes this way."""
    _REGISTRY[spec.name] = spec


def unregister_method(name: str) -> None:
    _REGISTRY.pop(name, None)


def method_names() -> list[str]:
    return sorted(_REGISTRY)


def get_method(name: str) -> MethodSpec:
    """A registered method, or ``"module:attribute"`` naming a non-learned policy class/factory."""
    if name == REMOTE_METHOD:
        raise UsageError(
            f"--method {REMOTE_METHOD} needs --policy-url ws://HOST:PORT (a server started with "
            "`python -m awda_bench serve --method ...`, or with --protocol openpi any openpi "
            "policy server)"
        )
    if name in _REGISTRY:
        return _REGISTRY[name]
    if ":" in name:
        factory = resolve(name, what=f"method {name!r}")
        hooks = [hasattr(factory, hook) for hook in SNAPSHOT_HOOKS]
        if any(hooks) and not all(hooks):
            raise UsageError(
                f"method {name!r} has only one of {' and '.join(SNAPSHOT_HOOKS)}; a learned "
                "method needs both, a non-learned one neither"
            )
        if all(hooks):
            return MethodSpec(
                name=name,
                target=name,
                learned=True,
                privileged=is_privileged(factory),
                list_snapshots=f"{name}.{SNAPSHOT_HOOKS[0]}",
                load_snapshot=f"{name}.{SNAPSHOT_HOOKS[1]}",
                description="imported learned policy",
            )
        return MethodSpec(
            name=name,
            target=name,
            description="imported policy",
            privileged=is_privileged(factory),
        )
    raise UnknownChoiceError("method", name, [*method_names(), "module:attribute"])


def served_method(
    url: str, timeout_s: float = DEFAULT_TIMEOUT_S, protocol: str = NATIVE
) -> MethodSpec:
    """The method served at ``url`` over ``protocol`` (``awda`` or ``openpi``), named as its server
    says (one line if it cannot be reached)."""
    if protocol not in PROTOCOLS:
        raise UnknownChoiceError("protocol", protocol, list(PROTOCOLS))
    if protocol == OPENPI:
        info, _ = fetch_openpi_metadata(url, timeout_s)
        player: type = OpenpiPolicy
    else:
        info, player = fetch_server_info(url, timeout_s), RemotePolicy
    return MethodSpec(
        name=info.method,
        target=f"{player.__module__}:{player.__name__}",
        learned=info.learned,
        description=f"served at {url} ({protocol} protocol)",
        served=ServedMethod(url=url, info=info, timeout_s=timeout_s, protocol=protocol),
    )


def resolve(target: str, *, what: str) -> Any:
    """Import ``"module:attribute"`` (the attribute may be dotted: ``"module:Class.method"``); a
    missing module or attribute is a one-line usage error."""
    module_name, _, attribute = target.partition(":")
    try:
        found: Any = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        raise UsageError(f"{what} is not available: cannot import {module_name} ({exc})") from exc
    for part in attribute.split("."):
        try:
            found = getattr(found, part)
        except AttributeError as exc:
            raise UsageError(
                f"{what} is not available: {module_name} has no {attribute!r}"
            ) from exc
    return found


def make_policy(spec: MethodSpec, snapshot: SnapshotRef) -> Policy:
    """Build the policy of ``spec`` for ``snapshot`` (called inside workers)."""
    if spec.served is not None:
        if spec.served.protocol == OPENPI:
            return OpenpiPolicy(spec.served, name=spec.name)
        return RemotePolicy(spec.served, name=spec.name)
    factory = resolve(spec.target, what=f"method {spec.name!r}")
    options = dict(spec.options)
    policy = factory(snapshot.path, **options) if spec.learned else factory(**options)
    if not isinstance(policy, Policy):
        raise UsageError(f"method {spec.name!r}: {spec.target} did not return a Policy")
    if is_privileged(policy) != spec.privileged:
        raise UsageError(
            f"method {spec.name!r}: its policy declares privileged = {is_privileged(policy)} "
            f"but the method is registered with privileged = {spec.privileged}; make them agree"
        )
    return policy


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()[:16]


def select_snapshots(spec: MethodSpec, checkpoints: Path | None, last_n: int) -> list[SnapshotRef]:
    """The snapshots to evaluate: the last ``last_n`` in ``checkpoints`` for learned methods.

    Every selected file is loaded once here (and discarded) so that a corrupt snapshot is reported
    before anything is written. A served method evaluates the one snapshot its server serves.
    """
    if spec.served is not None:
        if checkpoints is not None:
            raise UsageError(
                "--method remote evaluates the snapshot its server serves; drop --checkpoints "
                "(give it to `serve`, with --snapshot NAME to choose one)"
            )
        info = spec.served.info
        return [SnapshotRef(info.snapshot, info.snapshot_name, None, info.snapshot_order)]
    if not spec.learned:
        if checkpoints is not None:
            raise UsageError(f"method {spec.name!r} is not learned; drop --checkpoints")
        return [SnapshotRef(sha256=BUILTIN_SNAPSHOT, name=BUILTIN_SNAPSHOT, path=None, order=0)]
    if checkpoints is None:
        raise UsageError(f"method {spec.name!r} is learned; pass --checkpoints DIR")
    if last_n < 1:
        raise UsageError(f"--snapshots must be at least 1 (got {last_n})")
    if not checkpoints.is_dir():
        raise UsageError(f"checkpoint directory {checkpoints} does not exist")
    lister = resolve(spec.list_snapshots, what=f"snapshot listing for {spec.name!r}")
    loader = resolve(spec.load_snapshot, what=f"snapshot loading for {spec.name!r}")
    paths = [Path(p) for p in lister(checkpoints)]
    if not paths:
        raise UsageError(f"checkpoint directory {checkpoints} holds no snapshots of {spec.name!r}")
    first = max(0, len(paths) - last_n)
    refs = []
    for order, path in enumerate(paths[first:], start=first):
        try:
            loader(path)
        except CorruptFileError:
            raise
        except Exception as exc:  # any failure to load is a corrupt snapshot, reported as such
            raise CorruptFileError(
                f"snapshot {path} cannot be loaded ({type(exc).__name__}: {exc}); "
                "remove or replace it"
            ) from exc
        refs.append(
            SnapshotRef(sha256=file_sha256(path), name=path.name, path=str(path), order=order)
        )
    hashes = [r.sha256 for r in refs]
    if len(set(hashes)) != len(hashes):
        raise UsageError(f"checkpoint directory {checkpoints} holds identical snapshot files")
    return refs


_GT_WAYPOINTS = "awda_bench.policies.gt_waypoints:gt_waypoints"
_AWDA = "awda_bench.policies.awda_policy:awda"
_TOSVI = "awda_bench.policies.tosvi_policy:TosviPolicy"
_CENTRE_RULE = (
    "grasps take the depth component nearest the image centre (the reference's rule; "
    "--grasp-select centre)"
)
_ACTION_RULES = {
    "mean": "the mixture mean as the action (--action-select mean)",
    "mode": "the heaviest component's mean (--action-select mode)",
}
_TOSVI_ARCHS = {
    "tosvi": "learned: T-OSVI closed-loop snapshots (--checkpoints DIR; also the no-waypoints "
    "ablation), actions sampled from the mixture",
    "tosvi-depth": "learned: T-OSVI +depth snapshots (wrist depth, late fusion), sampled actions",
}


def _builtin(
    name: str,
    target: str,
    description: str,
    *,
    learned: bool = False,
    privileged: bool = False,
    **options: Any,
) -> None:
    """Register a built-in method: ``options`` are its family factory's keyword arguments."""
    register_method(
        MethodSpec(
            name, target, learned=learned, privileged=privileged, description=description,
            options=tuple(options.items()),
        )
    )  # fmt: skip


_builtin(
    "gt-waypoints", _GT_WAYPOINTS,
    "privileged: ground-truth attributed waypoints executed by the primitives", privileged=True,
)  # fmt: skip
for _k in (3, 8):
    _builtin(
        f"gt-waypoints-k{_k}", _GT_WAYPOINTS,
        f"gt-waypoints with K = {_k} waypoints (--num-waypoints {_k})", privileged=True,
        num_waypoints=_k,
    )  # fmt: skip
_builtin(
    "scripted", "awda_bench.policies.scripted:ScriptedPolicy", "privileged: scripted expert",
    privileged=True,
)  # fmt: skip
_builtin(
    "awda", _AWDA,
    "learned: AWDA waypoint network snapshots (--checkpoints DIR) + motor primitives", learned=True,
)  # fmt: skip
_builtin(
    "gt-waypoints-centre", _GT_WAYPOINTS, f"gt-waypoints, {_CENTRE_RULE}", privileged=True,
    grasp_select="centre",
)  # fmt: skip
_builtin("awda-centre", _AWDA, f"awda, {_CENTRE_RULE}", learned=True, grasp_select="centre")
for _arch, _description in _TOSVI_ARCHS.items():
    _builtin(_arch, _TOSVI, _description, learned=True, action_select="sample", arch=_arch)
    for _select, _rule in _ACTION_RULES.items():
        _builtin(
            f"{_arch}-{_select}", _TOSVI, f"{_arch} with {_rule}", learned=True,
            action_select=_select, arch=_arch,
        )  # fmt: skip
_builtin(
    "random", "awda_bench.policies.random_policy:RandomPolicy",
    "uniform random actions (a floor for every table)",
)  # fmt: skip
