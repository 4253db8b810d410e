"""A Ray started here for one run: what it listens on, and its token file kept private to its owner.

Measured with Ray 2.60 (`ss -ltnp` while a `grits-lab evaluate` pool ran, no cluster address):
the GCS server, the raylet, the driver and every actor listen on all interfaces (`*:port`, random
ports), the runtime-env agent on the node's address; the dashboard is not started
(`include_dashboard=False`). Ray cannot be bound to the loopback interface: `ray.init` replaces
a `_node_ip_address` of 127.0.0.1 with the node's reachable address
(`ray._private.services.resolve_ip_for_localhost`), and its gRPC servers bind every interface.

What keeps that safe is Ray's token authentication, on by default for local clusters: every
call to these ports must carry the token of `~/.ray/auth_token` (or `RAY_AUTH_TOKEN_PATH`).
Ray writes that file with mode 0644, readable by every user of the machine, so a local run makes
it 0600 (`make_token_private`); a firewall that closes the machine's ports to other hosts, or
`RAY_AUTH_MODE=disabled` never, is the rest.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path


def auth_token_path() -> Path:
    """Where Ray keeps the cluster token: RAY_AUTH_TOKEN_PATH, else ~/.ray/auth_token."""
    return Path(os.environ.get("RAY_AUTH_TOKEN_PATH") or Path.home() / ".ray" / "auth_token")


def make_token_private(path: Path | None = None) -> int | None:
    """Make the token file readable and writable by its owner only (0600) when this user owns it.

    Returns the file's mode afterwards (None: no file, or another user's, left alone).
    """
    path = auth_token_path() if path is None else Path(path)
    try:
        info = path.stat()
    except FileNotFoundError:
        return None
    if info.st_uid != os.getuid():
        return None
    if stat.S_IMODE(info.st_mode) & 0o077:
        path.chmod(0o600)
    return stat.S_IMODE(path.stat().st_mode)
