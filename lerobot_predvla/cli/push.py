"""`predvla push`: publish a saved checkpoint of any policy type of the plugin on the Hugging Face Hub with its card."""

import argparse
import sys
from pathlib import Path

from huggingface_hub.errors import HfHubHTTPError, OfflineModeIsEnabled

from lerobot_predvla.hub.publish import HubError, push_checkpoint


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "push",
        help="Publish a checkpoint (weights, config, processors, front end, model card) on the Hub.",
        description=__doc__ + " The training posteriors and optimizer state are never published.",
    )
    parser.add_argument("checkpoint", type=Path, help="A checkpoint (e.g. outputs/RUN/checkpoints/last) or its "
                        "pretrained_model/ directory.")
    parser.add_argument("repo_id", help="Hub model repository, e.g. USER/predvla_libero_object.")
    parser.add_argument("--private", action="store_true", help="Create the repository as private.")
    parser.add_argument("--frontend", type=Path, default=None,
                        help="Front-end artefact to publish (default: the checkpoint's, else its dataset's).")
    parser.add_argument("--results", type=Path, default=None,
                        help="Output directory (or report.json) of `predvla report` for the card's results table.")
    parser.add_argument("--results-config", default=None, help="Configuration of the report to show (default predvla).")
    parser.add_argument("--dry-run", action="store_true", help="List the files; upload nothing.")
    parser.add_argument("--card-out", type=Path, default=None, help="Also write the rendered card to this file.")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        files, url = push_checkpoint(
            args.checkpoint, args.repo_id, private=args.private or None, frontend=args.frontend,
            report=args.results, report_config=args.results_config, dry_run=args.dry_run,
        )
    except (HubError, OfflineModeIsEnabled, HfHubHTTPError) as err:
        print(f"predvla push: error: {err}", file=sys.stderr)
        return 2
    if args.card_out is not None:
        args.card_out.write_bytes(files["README.md"])
    for name in sorted(files):
        print(f"  {name}")
    print(f"predvla push: {len(files)} files " + (f"published: {url}" if url else "(dry run, nothing uploaded)"))
    return 0
