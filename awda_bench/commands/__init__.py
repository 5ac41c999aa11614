"""One module per CLI sub-command, named as the command; each defines ``HELP`` (its line in
``--help``), ``DESCRIPTION`` (the top of its own ``--help``), ``add_arguments(parser)`` and
``run(args) -> int`` (and ``PARSER_OPTIONS``, extra ``add_parser`` keywords, where it needs them).
:func:`awda_bench.cli.build_parser` makes the sub-parsers.

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
