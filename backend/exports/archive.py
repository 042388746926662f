"""Where an export's files go: a zip or tar archive, or a folder, written under a temporary name
and moved into place only when complete, so a failed or cancelled export leaves nothing where a
finished one is expected. Members are streamed (a zip member as it is written, a tar member
through a spool file), so no archive is ever held whole in memory.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tarfile
import tempfile
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Literal

ArchiveKind = Literal["zip", "tar", "folder"]
# Spool files larger than this go to disk (tar members must know their size up front).
_SPOOL_BYTES = 8 * 1024 * 1024


def kind_of(path: Path) -> ArchiveKind:
    """The archive kind an output path asks for: by its suffix, a folder otherwise."""
    name = path.name.lower()
    if name.endswith(".zip"):
        return "zip"
    if name.endswith(".tar"):
        return "tar"
    return "folder"


class ExportArchive:
    """Collects files under relative POSIX paths; ``commit`` moves the result to ``path``.

    Use as a context manager: leaving it with an exception (or without ``commit``) removes the
    temporary output.
    """

    def __init__(self, path: Path, kind: ArchiveKind | None = None) -> None:
        self.path = Path(path)
        self.kind: ArchiveKind = kind or kind_of(self.path)
        if self.path.exists() or self.path.is_symlink():
            raise FileExistsError(f"{self.path} exists")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = self.path.with_name(f".{self.path.name}.partial-{os.getpid()}")
        self.bytes_written = 0
        self.files = 0
        self._zip: zipfile.ZipFile | None = None
        self._tar: tarfile.TarFile | None = None
        if self.kind == "zip":
            self._zip = zipfile.ZipFile(self.tmp, "w", zipfile.ZIP_DEFLATED, allowZip64=True)
        elif self.kind == "tar":
            # Owned by the archive across calls; commit() or discard() closes it.
            self._tar = tarfile.open(self.tmp, "w", format=tarfile.PAX_FORMAT)  # noqa: SIM115
        else:
            self.tmp.mkdir()

    def __enter__(self) -> ExportArchive:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        self.discard()

    @property
    def links_allowed(self) -> bool:
        return self.kind != "zip"

    def write(self, name: str, data: bytes) -> None:
        """One file of the export (``sink(path, data)`` for the format writers)."""
        with self.open(name) as fh:
            fh.write(data)

    @contextlib.contextmanager
    def open(self, name: str) -> Iterator[IO[bytes]]:
        """A writable stream for one member, added when the block ends."""
        name = _checked(name)
        self.files += 1
        if self._zip is not None:
            info = zipfile.ZipInfo(name, date_time=time.localtime()[:6])
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            with self._zip.open(info, "w", force_zip64=True) as fh:
                yield fh
            self.bytes_written += info.compress_size
        elif self._tar is not None:
            with tempfile.SpooledTemporaryFile(_SPOOL_BYTES) as spool:
                yield spool
                size = spool.tell()
                spool.seek(0)
                member = tarfile.TarInfo(name)
                member.size, member.mode, member.mtime = size, 0o644, int(time.time())
                self._tar.addfile(member, spool)
                self.bytes_written += size
        else:
            target = self.tmp / name
            target.parent.mkdir(parents=True, exist_ok=True)
            with open(target, "wb") as fh:
                yield fh
                self.bytes_written += fh.tell()

    def link(self, name: str, target: Path) -> None:
        """A symbolic link member pointing at ``target`` (an absolute path); tar and folder."""
        name = _checked(name)
        self.files += 1
        if self._tar is not None:
            info = tarfile.TarInfo(name)
            info.type, info.linkname, info.mode = tarfile.SYMTYPE, str(target), 0o777
            self._tar.addfile(info)
        elif self.kind == "folder":
            path = self.tmp / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.symlink_to(target)
        else:
            raise ValueError("a zip archive cannot hold links")

    def commit(self) -> Path:
        """Finish the archive and move it to ``path``; returns it."""
        if self._zip is not None:
            self._zip.close()
        if self._tar is not None:
            self._tar.close()
        self._zip = self._tar = None
        if self.path.exists():
            raise FileExistsError(f"{self.path} exists")
        os.replace(self.tmp, self.path)
        return self.path

    def discard(self) -> None:
        """Remove the temporary output (no-op once committed)."""
        for archive in (self._zip, self._tar):
            if archive is not None:
                with contextlib.suppress(Exception):
                    archive.close()
        self._zip = self._tar = None
        if self.tmp.is_dir() and not self.tmp.is_symlink():
            shutil.rmtree(self.tmp, ignore_errors=True)
        else:
            self.tmp.unlink(missing_ok=True)


def _checked(name: str) -> str:
    parts = name.split("/")
    if not name or name.startswith("/") or any(p in ("", ".", "..") for p in parts):
        raise ValueError(f"invalid member name {name!r}")
    return name
