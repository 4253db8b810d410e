"""Helpers shared by the sweep tests: repository root, free ports, the sweep command line."""

from __future__ import annotations

import socket
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def sweep_command(config: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "grits_lab.cli", "sweep", str(config), "--no-progress", "--no-plots", *extra]
