"""`predvla push`: publish a saved checkpoint of any policy type of the plugin on the Hugging Face Hub with its card."""

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

from huggingface_hub.errors import HfHubHTTPError, OfflineModeIsEnabled

from lerobot_predvla.hub.card import HubError, report_results
from lerobot_predvla.hub.upload import push_checkpoint
from lerobot_predvla.report import SUMMARY_FILE, load_summary


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "push",
        help="publish a checkpoint (weights, config, processors, front end, model card) on the Hub",
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
    parser.add_argument("--out", type=Path, default=None,
                        help="Write the files into this new directory instead of uploading (a local copy of what the "
                        "Hub would get, loadable with --policy.path; local paths in its configs are cleared).")
    parser.add_argument("--card-out", type=Path, default=None, help="Also write the rendered card to this file.")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        files, url = push_checkpoint(
            args.checkpoint, args.repo_id, private=args.private or None, frontend=args.frontend,
            dry_run=args.dry_run or args.out is not None, **card_results(args.results, args.results_config),
        )
        if args.out is not None:
            write_snapshot(files, args.out)
    except (HubError, OfflineModeIsEnabled, HfHubHTTPError, FileExistsError) as err:
        print(f"predvla push: error: {err}", file=sys.stderr)
        return 2
    if args.card_out is not None:
        args.card_out.parent.mkdir(parents=True, exist_ok=True)
        args.card_out.write_bytes(files["README.md"])
    for name in sorted(files):
        print(f"  {name}")
    where = f"published: {url}" if url else f"written to {args.out}" if args.out else "(dry run, nothing uploaded)"
    print(f"predvla push: {len(files)} files {where}")
    return 0


def card_results(results: Path | None, config_name: str | None) -> dict:
    """`--results` as `push_checkpoint` takes it: a results folder of run records (a folder without `report.json`),
    or the table of a `predvla report` output (its directory or `report.json`)."""
    if results is None:
        return {}
    if results.is_dir() and not (results / SUMMARY_FILE).is_file():
        return {"results": results}
    return {"report": report_results(load_summary(results), results, config_name)}


def write_snapshot(files: dict[str, Path | bytes], out: Path) -> None:
    """The published files (configs without the training machine's paths) in a new directory, written beside it
    first and renamed into place."""
    if out.exists():
        raise FileExistsError(f"--out {out} exists; choose a new directory.")
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        for name, source in files.items():
            target = staging / name
            target.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(source, bytes):
                target.write_bytes(source)
            else:
                shutil.copyfile(source, target)
        staging.rename(out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
