"""A local Ray's token file is made private to its owner; another user's file is left alone."""

from __future__ import annotations

import os
import stat

import pytest

from grits_lab.runners.local_ray import auth_token_path, make_token_private


def test_a_token_readable_by_everyone_becomes_owner_only(tmp_path, monkeypatch):
    token = tmp_path / "auth_token"
    token.write_text("secret")
    token.chmod(0o644)  # as Ray 2.60 writes it
    monkeypatch.setenv("RAY_AUTH_TOKEN_PATH", str(token))
    assert auth_token_path() == token
    assert make_token_private() == 0o600 and stat.S_IMODE(token.stat().st_mode) == 0o600
    assert token.read_text() == "secret"


def test_no_token_file_is_not_an_error(tmp_path):
    assert make_token_private(tmp_path / "absent") is None


@pytest.mark.ray
def test_a_local_ray_pool_leaves_the_token_owner_only():
    ray = pytest.importorskip("ray")
    if ray.is_initialized():
        pytest.skip("Ray already runs in this process; the executor would not start its own")
    from grits_lab.runners.ray_executor import RayExecutor

    with RayExecutor(workers=1, num_cpus=1):
        path = auth_token_path()
        if not path.exists():
            pytest.skip("this Ray wrote no token file (token authentication off)")
        assert stat.S_IMODE(path.stat().st_mode) == 0o600 and path.stat().st_uid == os.getuid()
