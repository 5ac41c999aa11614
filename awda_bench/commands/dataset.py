"""``python -m awda_bench dataset info DATA_DIR``: what a collection holds, and a contact sheet;
``dataset fig-s6 DATA_DIR --out PNG``: its synthesized trajectories drawn over their scenes."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "inspect a collected DATA_DIR (counts, lengths, disk size, contact sheet)"
DESCRIPTION = "Inspect training data written by `collect`."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="dataset_command", required=True, metavar="ACTION")
    info = sub.add_parser(
        "info",
        help="counts per task and embodiment, lengths, disk size, contact-sheet PNG",
        description="Print counts per (role, task), episode lengths, bytes per episode and the "
        "disk size; write a contact sheet of sample frames of each embodiment.",
    )
    info.add_argument("data_dir", type=Path, metavar="DATA_DIR")
    info.add_argument(
        "--sheet",
        type=Path,
        help="contact-sheet PNG path (default DATA_DIR/contact_sheet.png)",
    )
    info.add_argument(
        "--episodes", type=int, default=4, help="episodes per embodiment on the sheet (default 4)"
    )
    info.add_argument(
        "--verify",
        action="store_true",
        help="read every array and decode every frame (a corrupt file is named)",
    )
    info.add_argument(
        "--allow-incomplete", action="store_true", help="report an unfinished collection too"
    )
    s6 = sub.add_parser(
        "fig-s6",
        help="Fig. S6: synthesized trajectories drawn over their scenes (PNG)",
        description="Draw the recorded TCP path of synthesized episodes over each episode's first "
        "frame (projected through its own camera, coloured dark to bright in time order), several "
        "panels per image.",
    )
    s6.add_argument("data_dir", type=Path, metavar="DATA_DIR")
    s6.add_argument("--out", type=Path, required=True, help="PNG to write")
    s6.add_argument("--episodes", type=int, default=8, help="panels (default 8)")
    s6.add_argument("--columns", type=int, default=4, help="panels per row (default 4)")


def run(args: argparse.Namespace) -> int:
    from awda_bench.data.datasets import CollectedData
    from awda_bench.data.info import contact_sheet, dataset_info, verify
    from awda_bench.errors import UsageError

    if args.dataset_command == "fig-s6":
        from awda_bench.reporting.synthesis_figure import fig_s6

        data = CollectedData(args.data_dir)
        try:
            print(f"Fig. S6: {fig_s6(data, args.out, args.episodes, args.columns)}")
        finally:
            data.close()
        return 0
    if args.episodes < 1:
        raise UsageError(f"--episodes must be >= 1, got {args.episodes}")
    data = CollectedData(args.data_dir, allow_incomplete=args.allow_incomplete)
    try:
        print(dataset_info(data).format())
        if args.verify:
            print(f"verified: {verify(data)} frames decoded, every array read")
        sheet = contact_sheet(
            data, args.sheet or args.data_dir / "contact_sheet.png", args.episodes
        )
        print(f"contact sheet: {sheet}")
    finally:
        data.close()
    return 0
