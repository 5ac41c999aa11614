"""One module per CLI sub-command; each defines ``add_parser(subparsers)`` and ``run(args) -> int``.

:data:`COMMANDS` is the order they are listed in ``python -m awda_bench --help``.
"""

COMMANDS: tuple[str, ...] = (
    "doctor",
    "run",
    "serve",
    "report",
    "bench",
    "demo",
    "describe",
    "collect",
    "dataset",
    "replay",
    "train",
    "reproduce",
    "study",
)
