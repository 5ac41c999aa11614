"""``python -m awda_bench <command>``: the single command-line entry point.

Each sub-command lives in :mod:`awda_bench.commands.<name>`. Errors deriving from
:class:`awda_bench.errors.AwdaError` are printed as one line (``error: ...``) with the error's exit
code; so are the machine's I/O errors (:data:`STORAGE_ERRNOS`: a full disk, a read-only
directory); anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import sys
from collections.abc import Sequence

from awda_bench.commands import COMMANDS
from awda_bench.errors import AwdaError, StorageError
from awda_bench.execution.parent_death import die_with_parent_from_env


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m awda_bench",
        description="One-shot visual imitation benchmark (AWDA) on ManiSkill3 with a mink-driven Panda.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        module = importlib.import_module(f"awda_bench.commands.{name}")
        command_parser = sub.add_parser(
            name,
            help=module.HELP,
            description=module.DESCRIPTION,
            **getattr(module, "PARSER_OPTIONS", {}),
        )
        module.add_arguments(command_parser)
        command_parser.set_defaults(_run=module.run)
    return parser


STORAGE_ERRNOS = frozenset(
    {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO}
)
"""An ``OSError`` with one of these is the machine's (a full disk, a read-only or unwritable
directory, a failing device), not the program's: the CLI prints it as one line naming the file,
exit code 4 (:class:`~awda_bench.errors.StorageError`), instead of a traceback."""


def main(argv: Sequence[str] | None = None) -> int:
    die_with_parent_from_env()  # a reproduce stage stops when reproduce dies
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except AwdaError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:
        if exc.errno not in STORAGE_ERRNOS:
            raise
        where = f" {exc.filename}" if exc.filename else ""
        print(
            f"error: I/O error on{where}: {exc.strerror}; free space or fix the directory's "
            "permissions, then re-run the same command (what was written before is kept)",
            file=sys.stderr,
        )
        return StorageError.exit_code
    except KeyboardInterrupt:
        print("interrupted; results written so far are kept", file=sys.stderr)
        return 130
