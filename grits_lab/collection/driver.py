"""Collection driver: runs episode specs on an executor and writes each result as one episode file.

It knows nothing about what an episode does (the work function named by each spec does); it owns
the dataset directory: the manifest (kind, format version, config and its fingerprint), atomic
episode files, failure records, resume (finished episodes are skipped; the index is rebuilt from
the files on disk), and the progress bar. The same config always yields the same episode ids and
seeds, so an interrupted and resumed job ends with the same dataset as an uninterrupted one.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any, Callable

import yaml

from grits_lab.config import config_changes, config_fingerprint, config_to_dict, parse_yaml
from grits_lab.data.format import (
    FORMAT_VERSION,
    MANIFEST_FILE,
    RETIRED_CHUNK_KEY,
    list_episode_files,
    rebuild_index,
    refuse_retired_chunk_key,
    verify_episode,
    write_episode,
)
from grits_lab.errors import JobError, StorageError
from grits_lab.io import ensure_writable_dir, write_json_atomic, write_text_atomic
from grits_lab.versions import PROTOCOL

FAILURE_DIR = "failures"
# The code that determines episode contents: a dataset resumed after it changed mixes two versions.
_DATA_CODE = ("sim", "perception", "data")


def data_code_hash() -> str:
    """Short hash of the simulator, perception and data sources (and packaged YAML) of this install."""
    import hashlib

    import grits_lab

    root = Path(grits_lab.__file__).parent
    digest = hashlib.sha256()
    for package in _DATA_CODE:
        for path in sorted((root / package).rglob("*")):
            if path.suffix in (".py", ".yaml") and path.is_file():
                digest.update(str(path.relative_to(root)).encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def collection_identity(config: Any) -> dict[str, Any]:
    """What determines a collection's data: its config without `executor` and `output_dir`, with only
    the `sim` keys that differ from the simulator's defaults (a stored dataset keeps its
    fingerprint when the simulator gains a key with a default)."""
    identity = config_to_dict(config)
    identity.pop("executor")
    identity.pop("output_dir")
    identity["sim"] = config_changes(config.sim)
    return identity


def existing_manifest(out_dir: str | Path, kind: str, identity: Any) -> dict[str, Any] | None:
    """The manifest of the dataset at `out_dir` (None: no dataset there yet); writes nothing.

    A dataset made from another config (or of another kind, or under another task protocol) is
    refused: resuming it would mix two. One that calls the chunk length `chunk_len` (stored before
    scoop-v4) is refused naming that key.
    """
    manifest_path = Path(out_dir) / MANIFEST_FILE
    if not manifest_path.exists():
        return None
    try:
        manifest = parse_yaml(manifest_path.read_text(), manifest_path) or {}
    except yaml.YAMLError as exc:
        raise StorageError(f"unreadable manifest {manifest_path}: {exc}") from None
    stored = manifest.get("config") if isinstance(manifest.get("config"), dict) else {}
    refuse_retired_chunk_key(stored, manifest_path, RETIRED_CHUNK_KEY, "collect it again under the current protocol: choose another output or remove it")
    fingerprint = config_fingerprint(identity)
    if manifest.get("fingerprint") != fingerprint or manifest.get("kind") != kind:
        raise StorageError(
            f"{out_dir} holds a {manifest.get('kind')} dataset made with a different config "
            f"(fingerprint {manifest.get('fingerprint')} vs {fingerprint}); choose another output or remove it"
        )
    if manifest.get("protocol", PROTOCOL) != PROTOCOL:  # a manifest written before the key existed is not refused
        raise StorageError(f"{out_dir} holds a dataset of protocol {manifest['protocol']}, but this code runs {PROTOCOL} "
                           "(docs/protocol.md); choose another output or remove it")
    return manifest


class DatasetWriter:
    """Owns one dataset directory: manifest, episode files, failure records and the index.

    `identity` is the part of the config that determines the data (not where or how it runs); a
    directory made from a different identity is refused instead of being silently mixed.
    """

    def __init__(self, out_dir: str | Path, kind: str, identity: Any):
        manifest = existing_manifest(out_dir, kind, identity)
        self.out_dir = ensure_writable_dir(out_dir)
        self.kind = kind
        self.fingerprint = config_fingerprint(identity)
        if manifest is not None:
            self.manifest = manifest
            code = data_code_hash()
            if manifest.get("code_hash") not in (None, code):
                import sys

                print(
                    f"warning: the simulator/perception/data code changed since {self.out_dir} was started "
                    f"(code {manifest.get('code_hash')} -> {code}); resuming mixes episodes of both versions. "
                    "Remove the directory to regenerate it.",
                    file=sys.stderr,
                )
        else:
            self.manifest = {
                "format_version": FORMAT_VERSION,
                "kind": kind,
                "protocol": PROTOCOL,
                "fingerprint": self.fingerprint,
                "config": config_to_dict(identity),
                "code_hash": data_code_hash(),
                "status": "in_progress",
            }
            self._write_manifest()

    def _write_manifest(self) -> None:
        write_text_atomic(self.out_dir / MANIFEST_FILE, yaml.safe_dump(self.manifest, sort_keys=False))

    def finished(self) -> dict[str, dict[str, Any]]:
        """Meta of every intact episode on disk, by id; damaged files are reported and removed (they are re-run)."""
        done = {}
        for path in list_episode_files(self.out_dir):
            try:
                meta = verify_episode(path)
            except StorageError as exc:
                print(f"warning: {exc}; the episode will be regenerated", file=sys.stderr)
                path.unlink(missing_ok=True)
                continue
            done[meta["episode_id"]] = meta
        return done

    def write(self, episode_id: str, payload: dict[str, Any]) -> None:
        """Store a finished episode (payload: {"arrays": {...}, "meta": {...}}) and clear an old failure."""
        write_episode(self.out_dir, episode_id, payload["arrays"], payload["meta"])
        (self.out_dir / FAILURE_DIR / f"{episode_id}.json").unlink(missing_ok=True)

    def write_failure(self, episode_id: str, record: dict[str, Any]) -> None:
        write_json_atomic(self.out_dir / FAILURE_DIR / f"{episode_id}.json", record)

    def failures(self) -> list[dict[str, Any]]:
        out = []
        for path in sorted((self.out_dir / FAILURE_DIR).glob("*.json")):
            try:
                out.append(json.loads(path.read_text()))
            except (OSError, json.JSONDecodeError):
                continue
        return out

    def finalize(self, summary: dict[str, Any], complete: bool) -> Any:
        """Rebuild the index from disk and record the summary in the manifest."""
        frame = rebuild_index(self.out_dir)
        self.manifest["status"] = "complete" if complete else "incomplete"
        self.manifest["summary"] = summary
        self._write_manifest()
        return frame


def failure_details(result: Any) -> dict[str, Any]:
    spec = result.spec
    return {
        "episode_id": result.episode_id,
        "error": result.error,
        "traceback": result.traceback,
        "attempts": result.attempts,
        "seed": getattr(spec, "seed", None),
        "food": getattr(spec, "food", None),
        "level": getattr(spec, "level", None),
        "params": {k: v for k, v in (getattr(spec, "params", None) or {}).items() if isinstance(v, (str, int, float, bool))},
    }


class Progress:
    """tqdm bar: done / total, rate, ETA, failures and the spill ratio so far."""

    def __init__(self, total: int, initial: int, desc: str, enabled: bool = True):
        from tqdm import tqdm

        self.bar = tqdm(total=total, initial=initial, desc=desc, unit="ep", disable=not enabled, dynamic_ncols=True)
        self.spilled = 0
        self.labelled = 0
        self.failed = 0

    def update(self, n: int = 1, spilled: bool | None = None, failed: bool = False, **extra: Any) -> None:
        if spilled is not None:
            self.labelled += 1
            self.spilled += int(spilled)
        self.failed += int(failed)
        post = {"failed": self.failed}
        if self.labelled:
            post["spill"] = f"{self.spilled / self.labelled:.2f}"
        post.update(extra)
        self.bar.set_postfix(post, refresh=False)
        self.bar.update(n)

    def close(self) -> None:
        self.bar.close()


def refuse_empty(desc: str, writer: DatasetWriter, episodes: int, failed: int, first_error: str) -> None:
    """JobError when a job ends with no episode at all and this run's episodes failed: a broken
    installation or world (a missing library, a bad food file) stops the job here with its first
    error, instead of leaving an empty dataset for the next stage to trip on. A dataset with some
    episodes goes on (its failures are counted in the summary and retried by a rerun)."""
    if episodes == 0 and failed > 0:
        raise JobError(f"{desc}: every episode failed ({failed}); the first with {first_error} (tracebacks in {writer.out_dir / FAILURE_DIR})")


def run_fixed_job(
    executor: Any,
    writer: DatasetWriter,
    specs: list[Any],
    desc: str,
    spilled_of: Callable[[dict[str, Any]], bool | None] = lambda meta: None,
    progress: bool = True,
) -> dict[str, Any]:
    """Run every spec whose episode is not on disk yet; stream results into the writer."""
    done = writer.finished()
    todo = [s for s in specs if s.episode_id not in done]
    bar = Progress(total=len(specs), initial=len(specs) - len(todo), desc=desc, enabled=progress)
    for meta in done.values():
        bar.spilled += int(bool(spilled_of(meta)))
        bar.labelled += int(spilled_of(meta) is not None)
    start = time.perf_counter()
    failed, first_error = 0, ""
    try:
        for result in executor.map_unordered(todo):
            if result.ok:
                writer.write(result.episode_id, result.payload)
                bar.update(spilled=spilled_of(result.payload["meta"]))
            else:
                failed += 1
                first_error = first_error or result.error
                writer.write_failure(result.episode_id, failure_details(result))
                bar.update(failed=True)
    finally:
        bar.close()
    finished = len(writer.finished())
    summary = {
        "episodes": finished,
        "requested": len(specs),
        "failed": failed,
        "run_this_time": len(todo),
        "wall_time_s_this_time": round(time.perf_counter() - start, 2),
    }
    writer.finalize(summary, complete=finished == len(specs))
    refuse_empty(desc, writer, finished, failed, first_error)
    return summary
