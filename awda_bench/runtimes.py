"""Where a suite's episodes run: the project's own environment, or a virtual environment of their
own.

The ManiSkill suites run in the project's ``.venv``. Meta-World cannot: ``metaworld`` 3.1.1 pins
``mujoco==3.3.0`` and fails on mujoco 4, while the project's ``mink`` 1.3.0 needs
``mujoco>=3.10``, so no one environment holds both. Its episodes are played by workers started from
a second environment, ``.venv-metaworld`` beside ``.venv`` (made by ``bash scripts/setup.sh``):
``metaworld`` and its MuJoCo, NumPy, gymnasium and the few packages the harness's worker side
imports (``requirements-metaworld.txt``); the project's own modules come from this checkout through
``PYTHONPATH``, so both sides always run the same code. The harness, the results store, the report
and the CLI stay one program in ``.venv``.

::

    .venv (CLI, sweep, store)  --socket pair, pickled jobs/records-->  .venv-metaworld worker
                                                                       (EpisodeExecutor: env+policy)
    .venv (driver, Ray)        --Ray actor calls------------------->  .venv-metaworld actor
                                 (runtime_env py_executable)           (the same executor)

With ``--backend ray`` the actors are Ray's per-actor runtime environment: ``py_executable`` names
the second environment's interpreter and ``PYTHONPATH`` this checkout, so an actor imports
Meta-World's MuJoCo, never the driver's (:class:`~awda_bench.execution.ray_pool.RayActorPool`). That
environment holds Ray too, at the driver's version (checked at start: :func:`check_worker_ray`).
On a cluster every node needs the checkout and ``.venv-metaworld`` at the same paths.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path

from awda_bench.errors import UsageError

PROJECT_ROOT = Path(__file__).resolve().parent.parent
"""The checkout's root (holds ``awda_bench/``, ``tasks/``, ``scripts/``, the environments)."""

SECOND_VENVS = {"metaworld": ".venv-metaworld"}
"""Simulator -> the virtual environment (relative to :data:`PROJECT_ROOT`) its workers start from;
a simulator not listed runs in this interpreter's environment."""

PYTHON_OVERRIDE_VARS = {"metaworld": "AWDA_METAWORLD_PYTHON"}
"""Simulator -> environment variable naming another interpreter for its workers."""

WORKER_PACKAGES = {"metaworld": ("metaworld", "mujoco", "gymnasium", "numpy")}
"""Simulator -> the packages of its workers' environment recorded with every run."""


class MissingEnvironmentError(UsageError):
    """A suite's workers need a virtual environment of their own that is not there."""


def worker_python(simulator: str) -> str | None:
    """The interpreter ``simulator``'s workers start from, ``None`` for this one's; a one-line
    error naming ``bash scripts/setup.sh`` when the second environment is missing."""
    if simulator not in SECOND_VENVS:
        return None
    override = os.environ.get(PYTHON_OVERRIDE_VARS[simulator])
    python = (
        Path(override) if override else PROJECT_ROOT / SECOND_VENVS[simulator] / "bin" / "python"
    )
    if not os.access(python, os.X_OK):
        raise MissingEnvironmentError(
            f"{simulator} suites run in their own environment (metaworld 3.1.1 pins mujoco 3.3.0, "
            f"the project's mink needs mujoco >= 3.10) and {python} is missing; make it with "
            "`bash scripts/setup.sh`"
        )
    return str(python)


def check_local_workers(suite: str, simulator: str, workers: int, backend: str) -> None:
    """Refuse, in one line, a schedule that would play ``simulator``'s episodes where its
    environment is not: ``--workers 0`` plays in this process. Local workers and Ray actors start
    from the second environment's interpreter (:func:`worker_python`; Ray: a per-actor
    ``py_executable``), so both backends are fine with ``--workers >= 1``; nothing to refuse for a
    simulator that runs here."""
    if simulator not in SECOND_VENVS:
        return
    if workers == 0:
        raise UsageError(
            f"suite {suite!r} runs in its own environment's worker processes "
            f"({SECOND_VENVS[simulator]}), not in this one: use --workers >= 1 "
            f"(--backend {backend})"
        )


def check_worker_ray(python: str, driver_version: str) -> None:
    """Ray actors started from another interpreter (``runtime_env={"py_executable": python}``)
    need Ray installed there, at the driver's version (a worker of another version cannot join
    the driver's Ray instance): one-line error naming the fix otherwise."""
    code = "import ray, sys; sys.stdout.write(ray.__version__)"
    out = subprocess.run([python, "-c", code], capture_output=True, text=True)
    if out.returncode != 0:
        raise UsageError(
            f"--backend ray starts actors from {python}, which has no Ray; re-run "
            "`bash scripts/setup.sh` (it installs the Ray of requirements-metaworld.txt) or use "
            "--backend local"
        )
    if out.stdout.strip() != driver_version:
        raise UsageError(
            f"--backend ray: {python} has ray {out.stdout.strip()}, this environment ray "
            f"{driver_version}; install the same version in both (`pip install "
            f"ray=={driver_version}` with that interpreter) or use --backend local"
        )


def worker_versions(simulator: str) -> dict[str, str]:
    """Versions of the packages in ``simulator``'s worker environment, keyed
    ``"<environment> <package>"`` (empty for a simulator that runs in this one): a run's record
    must name the MuJoCo that played it, not this environment's."""
    python = worker_python(simulator)
    if python is None:
        return {}
    code = (
        "import json, sys; from importlib import metadata as m; "
        "print(json.dumps({p: m.version(p) for p in sys.argv[1:]}))"
    )
    names = WORKER_PACKAGES[simulator]
    out = subprocess.run([python, "-c", code, *names], capture_output=True, text=True, check=True)
    venv = SECOND_VENVS[simulator]
    return {f"{venv} {k}": str(v) for k, v in json.loads(out.stdout).items()}


VERSIONED_PACKAGES = (
    "awda_bench",
    "mani-skill",
    "sapien",
    "mink",
    "mujoco",
    "gymnasium",
    "torch",
    "numpy",
)
"""Packages whose versions are recorded with every run and printed in the report header."""


def software_versions() -> dict[str, str]:
    versions = {"python": platform.python_version()}
    for name in VERSIONED_PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions
