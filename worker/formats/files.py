"""Byte-reproducible writers for the capture files (npz, YAML, JPEG, PNG).

``np.savez`` stamps zip members with the wall-clock time, so the same data would give different
bytes on every run; here every member gets a fixed timestamp, fixed attributes and sorted names.
YAML is written with sorted keys, block mappings, flow-style lists and Python's shortest
round-trip float text, so values read back bit-exactly.
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Mapping
from pathlib import Path

import cv2
import numpy as np
import yaml

ZIP_DATE_TIME = (1980, 1, 1, 0, 0, 0)  # the earliest time a zip header can hold
JPEG_QUALITY = 95


def npz_bytes(arrays: Mapping[str, np.ndarray], compress: bool = True) -> bytes:
    """The bytes of an ``.npz`` archive (readable by ``np.load``) holding ``arrays``."""
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=method) as archive:
        for name in sorted(arrays):
            member = io.BytesIO()
            np.lib.format.write_array(member, np.ascontiguousarray(arrays[name]),
                                      allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=ZIP_DATE_TIME)
            info.compress_type = method
            info.create_system = 3  # Unix, whatever the host
            info.external_attr = 0o644 << 16
            archive.writestr(info, member.getvalue())
    return buf.getvalue()


def write_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    """Write a compressed, reproducible ``.npz`` file."""
    Path(path).write_bytes(npz_bytes(arrays))


class _CaptureDumper(yaml.SafeDumper):
    """Block-style mappings, flow-style lists of scalars."""


def _represent_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    flow = all(not isinstance(x, (list, dict)) for x in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_CaptureDumper.add_representer(list, _represent_list)


def _plain(value: object) -> object:
    """Convert numpy scalars/arrays and tuples inside ``value`` to plain Python types."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return value


def yaml_text(data: Mapping) -> str:
    """Deterministic YAML text for ``data`` (sorted keys)."""
    return yaml.dump(_plain(data), Dumper=_CaptureDumper, sort_keys=True,
                     default_flow_style=False, width=120)


def write_yaml(path: Path, data: Mapping) -> None:
    """Write ``data`` as deterministic YAML."""
    Path(path).write_text(yaml_text(data), encoding="utf-8")


def encode_image(ext: str, image: np.ndarray) -> bytes:
    """Encode with OpenCV: ``.jpg`` (quality 95, BGR uint8) or ``.png`` (uint8 / uint16)."""
    params = [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY] if ext == ".jpg" else []
    ok, data = cv2.imencode(ext, image, params)
    if not ok:
        raise ValueError(f"OpenCV could not encode a {image.dtype} {image.shape} image as {ext}")
    return data.tobytes()
