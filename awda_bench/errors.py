"""The package's error hierarchy.

Every error a user can cause derives from :class:`AwdaError`; the CLI prints its message on one
line and exits with :attr:`AwdaError.exit_code`, never with a traceback. Messages name the
problem and the fix (or the valid choices).
"""

from __future__ import annotations

from collections.abc import Iterable


class AwdaError(Exception):
    """Base class of all errors the CLI reports as one line."""

    exit_code: int = 2


class UsageError(AwdaError):
    """Bad input from the user: unknown name, bad value, missing file."""


class UnknownChoiceError(UsageError):
    """A name that is not one of the valid choices."""

    def __init__(self, kind: str, value: object, choices: Iterable[object]) -> None:
        listed = ", ".join(str(c) for c in choices)
        super().__init__(f"unknown {kind} {value!r}; choose one of: {listed}")
        self.kind = kind
        self.value = value


class RendererUnavailableError(AwdaError):
    """SAPIEN found no usable Vulkan device (ManiSkill needs one even for state observations)."""

    exit_code = 3


class CorruptFileError(UsageError):
    """A file exists but cannot be read as what it claims to be."""


class ProtocolMismatchError(UsageError):
    """A results store was written under another evaluation protocol."""


class MissingExtraError(UsageError):
    """An option needs an optional dependency (an extra) that is not installed."""


class PrivilegedAccessError(AwdaError):
    """A method that is not privileged reached for the simulator (``ctx.env``)."""


class RemotePolicyError(AwdaError):
    """A served policy (``run --method remote``) could not be reached, timed out, dropped the
    connection, raised, or answered with something that is not an action; inside an episode it
    is recorded as that episode's error (a re-run retries it)."""


class StorageError(AwdaError):
    """Something the run must write could not be written (no space left, a read-only or
    unwritable directory, an I/O error): the message names the path and the cause; what was
    written before stays readable, and the same command resumes once the cause is fixed."""

    exit_code = 4
