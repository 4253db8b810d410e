"""`grits-lab dataset export DIR --format lerobot|zarr --output OUT`: a demonstration dataset for other tools."""

from __future__ import annotations

import argparse
from typing import Any

from grits_lab.io import to_json

FORMATS = ("lerobot", "zarr")  # grits_lab/data/export.py EXPORT_FORMATS; kept here so --help needs no import


def register(dataset_sub: Any) -> None:
    """Add `export` to the `grits-lab dataset` actions."""
    export = dataset_sub.add_parser(
        "export",
        help="write a demonstration dataset as a LeRobotDataset or a diffusion_policy zarr ReplayBuffer",
        description="Write a demonstration dataset in a format other training code loads: `lerobot` "
                    "(LeRobotDataset; pip install \"grits-lab[lerobot]\") or `zarr` (diffusion_policy's "
                    "ReplayBuffer layout; pip install \"grits-lab[zarr]\"). See grits_lab/data/export.py.",
    )
    export.add_argument("path", help="demonstration dataset directory (kind: demos)")
    export.add_argument("--format", required=True, choices=FORMATS, help="the format to write")
    export.add_argument("--output", required=True, metavar="OUT", help="folder to create (must not exist)")
    export.add_argument("--repo-id", metavar="NAME", help="the LeRobot repo id (default grits_lab/<dataset folder name>)")
    export.set_defaults(handler=_export)


def _export(args: argparse.Namespace) -> int:
    from grits_lab.data.export import export_dataset

    print(to_json(export_dataset(args.path, args.format, args.output, repo_id=args.repo_id)))
    return 0
