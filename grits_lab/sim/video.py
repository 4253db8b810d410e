"""Episode videos: a camera that frames the spoon and both bowls, captioned frames, and the writers (imageio).

Rendering costs tens of milliseconds per frame, so nothing here runs during evaluation: videos
are made while replaying an episode from its record (grits_lab/report/replay.py) or when a
rollout is asked for one (`grits-lab rollout --video`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from grits_lab.errors import InputError
from grits_lab.sim.sim_config import CameraConfig

# Above the table's far edge, looking back at the robot: the source bowl, all four corners of the
# rectangle the target bowl is drawn in (35 x 30 cm centred at (0.45, 0.28)) and the spoon's path
# between them are in view (checked by rendering the corners).
VIDEO_CAMERA = CameraConfig(name="video", eye=(1.08, 0.14, 0.6), target=(0.47, 0.12, 0.07), fov_deg=50.0, width=480, height=360)

VIDEO_SUFFIXES = (".mp4", ".gif")


def render_frame(env: Any, camera: CameraConfig = VIDEO_CAMERA) -> np.ndarray:
    """(H, W, 3) uint8 RGB image of the env's current state from `camera` (default VIDEO_CAMERA)."""
    from grits_lab.sim.cameras import render

    world = env.world
    if world is None:
        raise RuntimeError("call reset() before rendering")
    return render(world.client, camera).rgb


def caption(frame: np.ndarray, lines: Sequence[str], height: int = 18) -> np.ndarray:
    """`frame` (H, W, 3) uint8 with a dark band of `len(lines)` text lines on top: (H + band, W, 3) uint8."""
    from PIL import Image, ImageDraw

    band = height * len(lines) + 4
    image = Image.new("RGB", (frame.shape[1], frame.shape[0] + band), (24, 24, 24))
    image.paste(Image.fromarray(np.ascontiguousarray(frame)), (0, band))
    draw = ImageDraw.Draw(image)
    for i, line in enumerate(lines):
        draw.text((6, 3 + i * height), line, fill=(240, 240, 240))
    return np.asarray(image)


def check_video_path(path: str | Path, allowed: Sequence[str] = VIDEO_SUFFIXES) -> Path:
    """`path` as a Path if it ends in one of `allowed` (case-insensitive) and a file can be written
    there (grits_lab/io.py `check_writable_file`): InputError or StorageError otherwise, before any
    frame is rendered."""
    from grits_lab.io import check_writable_file

    path = Path(path)
    if path.suffix.lower() not in allowed:
        raise InputError(f"video file must end in {', '.join(allowed)}, got {path.name!r}")
    return check_writable_file(path)


def write_video(path: str | Path, frames: Sequence[np.ndarray], fps: float = 10.0) -> Path:
    """Write (H, W, 3) uint8 frames to `path` atomically: `.mp4` (H.264 via imageio-ffmpeg), `.gif`, or `.png` (a strip).

    `.png` writes one image of the frames in rows of four. Raises InputError when there are no
    frames, the suffix is unknown, or MP4 is asked for and imageio-ffmpeg is missing.
    """
    from grits_lab.io import atomic_path

    path = check_video_path(path, VIDEO_SUFFIXES + (".png",))
    if not frames:
        raise InputError("no frames were rendered")
    suffix = path.suffix.lower()
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg
        except ImportError:
            raise InputError("cannot write MP4: imageio-ffmpeg is not installed (pip install imageio-ffmpeg); or use .gif") from None
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        if suffix == ".png":
            from PIL import Image

            cols = 4
            blank = np.zeros_like(frames[0])
            padded = list(frames) + [blank] * (-len(frames) % cols)
            strip = np.concatenate([np.concatenate(padded[i:i + cols], axis=1) for i in range(0, len(padded), cols)], axis=0)
            Image.fromarray(strip).save(tmp, format="PNG")
        elif suffix == ".gif":
            import imageio.v2 as imageio

            imageio.mimsave(tmp, list(frames), format="GIF", duration=1.0 / fps, loop=0)
        else:
            height, width = frames[0].shape[:2]
            # The temporary name has no .mp4 suffix, so the container is named; H.264 in yuv420p with
            # sizes padded to a multiple of 16 plays in every browser; faststart lets it play while loading.
            writer = imageio_ffmpeg.write_frames(str(tmp), (width, height), fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                                 macro_block_size=16, output_params=["-f", "mp4", "-movflags", "+faststart"])
            writer.send(None)
            try:
                for frame in frames:
                    writer.send(np.ascontiguousarray(frame, dtype=np.uint8))
            finally:
                writer.close()
    return path
