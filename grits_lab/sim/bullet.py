"""PyBullet clients: every simulator in grits_lab (worlds, the IK model) connects through here."""

from __future__ import annotations

import os
import sys

import pybullet as pb
from pybullet_utils.bullet_client import BulletClient


def connect_direct() -> BulletClient:
    """A new DIRECT client. PyBullet prints "argv[0]=" on C-level stdout when connecting; keep
    stdout clean (commands print exactly one JSON object) by pointing fd 1 elsewhere meanwhile."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            return BulletClient(connection_mode=pb.DIRECT)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
