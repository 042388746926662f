"""What the streaming writers (COCO, CVAT for video) share: used as a context manager, a writer
finishes its document when the with-block ends cleanly and drops what it holds when the block
raises, so a failed export leaves no half-written spool behind."""

from __future__ import annotations

from types import TracebackType
from typing import Self


class StreamWriter:
    """Base of a writer that builds one document piece by piece and finishes it in close()."""

    def close(self) -> None:
        raise NotImplementedError

    def _discard(self) -> None:
        """Drops what the writer holds after an error; by default there is nothing to drop."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            self.close()
        else:
            self._discard()
