"""Reading a file a user named, safely: nothing is opened in a way that can block (a FIFO or a device where a
file is expected is refused by its kind, not read), and nothing is read past a stated budget (a symlink to
``/dev/zero``, an 8 GB sparse picture or a model the size of a disk is refused by its size, not read whole).
Every reader of a user's file (pictures, models, keys, settings, camera files) goes through here."""

from __future__ import annotations

import os
import stat
from pathlib import Path

MB = 1 << 20
# what each kind of file may weigh: far above any real one, far below what would hurt a 2-core car computer
BUDGETS = {"picture": 256 * MB, "model": 512 * MB, "key": 64 * 1024, "settings": 4 * MB, "camera file": 4 * MB,
           "JSON": 64 * MB}


class NotAFileError(ValueError):
    """A path that names something other than a regular file within its budget (the message says what)."""


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a folder")):
        if test(mode):
            return name
    return "not a regular file"


def read_user_file(path: str | os.PathLike, what: str, budget: int | None = None, head: int | None = None) -> bytes:
    """The bytes of ``path``, a ``what`` (a key of :data:`BUDGETS`, or any name with ``budget`` given): at most
    ``head`` bytes when given (a header), else the whole file. ``FileNotFoundError`` when it is missing;
    :class:`NotAFileError` for a FIFO, a device, a socket or a folder (found without blocking), or a file over
    its budget (found from its size, before reading)."""
    p = Path(path)
    limit = budget if budget is not None else BUDGETS[what]
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK)      # a FIFO opens at once and is refused below
    except IsADirectoryError:
        raise NotAFileError(f"{what} {p} is a folder, not a file") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise NotAFileError(f"{what} {p} is {_kind(st.st_mode)}, not a file")
        want = head if head is not None else st.st_size
        if head is None and st.st_size > limit:
            raise NotAFileError(f"{what} {p} is {st.st_size / MB:.1f} MB, over the {limit / MB:.1f} MB a {what} "
                                "may be")
        chunks, got = [], 0
        while got < min(want, limit) + (0 if head is not None else 1):
            chunk = os.read(fd, min(1 << 20, min(want, limit) + 1 - got))
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
        data = b"".join(chunks)
        if head is None and len(data) > limit:       # it grew while read: not what was sized
            raise NotAFileError(f"{what} {p} is over the {limit / MB:.1f} MB a {what} may be")
        return data[:head] if head is not None else data
    finally:
        os.close(fd)
