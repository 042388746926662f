"""A capture's frames checked while it is read: each view's colour and depth image files (or
its video) found, counted against the sequence, and every one decoded in full."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from backend.captures.imagefiles import check_jpeg, check_png16
from backend.captures.plans import CameraPlan, FramePlan
from backend.captures.reader import CaptureReader
from worker.formats import dexycb
from worker.formats.dexycb import VIDEO_SUFFIXES

# Threads that decode a capture's colour and depth frames while it is checked (OpenCV decodes
# without holding the GIL).
DECODE_THREADS = min(8, os.cpu_count() or 1)


def attach_frames(
    rd: CaptureReader, seq_dir: Path, cameras: list[CameraPlan], num_frames: int | None
) -> int:
    for cam in cameras:
        folder = seq_dir / cam.serial
        if folder.is_dir():
            rd.inside(folder)
            count = (num_frames if num_frames is not None
                     else len(list(folder.glob(dexycb.COLOR_GLOB))))
            cam.frames = [_check_frame(rd, folder, cam, i) for i in range(count)]
        else:
            videos = [seq_dir / f"{cam.serial}{s}" for s in VIDEO_SUFFIXES]
            video = next((v for v in videos if v.is_file()), None)
            if video is None:
                raise rd.fail(folder, "camera folder (or <serial>.mp4 video) is missing")
            cam.video_path = rd.inside(video)
            cam.video_frames = _decode_video(rd, cam)
            rd.digest.update(f"{rd.rel(video)}:{video.stat().st_size}".encode())
    counts = {len(c.frames) if c.video_path is None else len(c.video_frames) for c in cameras}
    if len(counts) > 1 or (num_frames is not None and counts != {num_frames}):
        raise rd.fail(seq_dir / dexycb.META_FILE,
                      f"num_frames is {num_frames} but the views hold {sorted(counts)} frames")
    num_frames = counts.pop()
    if num_frames <= 0:
        raise rd.fail(seq_dir / dexycb.META_FILE, "the views hold no frames")
    _decode_frames(rd, cameras)
    return num_frames


def _decode_frames(rd: CaptureReader, cameras: list[CameraPlan]) -> None:
    """Decode every colour and depth frame in full: a header can be whole while the data after
    it is truncated or corrupt. The first bad file, in camera and frame order, is refused."""
    files: list[tuple[Path, bool]] = []
    for cam in cameras:
        for fr in cam.frames:
            files.append((fr.color_path, False))
            if fr.depth_path is not None:
                files.append((fr.depth_path, True))
    with ThreadPoolExecutor(DECODE_THREADS) as pool:
        problems = pool.map(lambda f: _decode_problem(*f), files)
        for (path, _), problem in zip(files, problems, strict=True):
            if problem:
                raise rd.fail(path, problem)


def _decode_problem(path: Path, depth: bool) -> str | None:
    """None if the image file decodes in full (depth: to 16-bit values), else what is wrong."""
    import cv2

    try:
        data = np.fromfile(path, np.uint8)
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED if depth else cv2.IMREAD_COLOR)
    except (OSError, cv2.error) as exc:
        return f"cannot be decoded: {exc}"
    if image is None:
        what = "PNG depth image" if depth else "JPEG image"
        return f"{what} does not decode (truncated or corrupt data)"
    if depth and image.dtype != np.uint16:
        return "depth must be a 16-bit single-channel PNG (millimetres)"
    return None


def _decode_video(rd: CaptureReader, cam: CameraPlan) -> list[bytes]:
    """Every frame of a camera's video, re-encoded as JPEG (the stored frame format)."""
    import cv2

    assert cam.video_path is not None
    cap = cv2.VideoCapture(str(cam.video_path))
    if not cap.isOpened():
        raise rd.fail(cam.video_path, "video cannot be opened by OpenCV")
    # The container's stated size, before a frame is decoded (each is checked again below).
    size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
    if size != (0, 0) and size != (cam.width, cam.height):
        cap.release()
        raise rd.fail(cam.video_path, f"video is {size[0]}x{size[1]}, the intrinsics say "
                                      f"{cam.width}x{cam.height}")
    frames = []
    try:
        while True:
            ok, img = cap.read()
            if not ok:
                break
            if img.shape[1] != cam.width or img.shape[0] != cam.height:
                raise rd.fail(cam.video_path, f"video is {img.shape[1]}x{img.shape[0]}, "
                                              f"the intrinsics say {cam.width}x{cam.height}")
            frames.append(cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])[1].tobytes())
    finally:
        cap.release()
    if not frames:
        raise rd.fail(cam.video_path, "video has no decodable frames")
    return frames


def _check_frame(rd: CaptureReader, folder: Path, cam: CameraPlan, index: int) -> FramePlan:
    color = folder / dexycb.color_file(index)
    depth = folder / dexycb.depth_file(index)
    for path, check, missing in ((color, check_jpeg, f"frame {index} is missing"),
                                 (depth, check_png16, f"depth of frame {index} is missing")):
        if not path.is_file():
            raise rd.fail(path, missing)
        rd.inside(path)
        problem = check(path, cam.width, cam.height)
        if problem:
            raise rd.fail(path, problem)
        rd.digest.update(f"{rd.rel(path)}:{path.stat().st_size}".encode())
    return FramePlan(index=index, color_path=color, depth_path=depth)
