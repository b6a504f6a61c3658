"""A disk that fills up: what a run does when a write fails with ENOSPC."""
from __future__ import annotations

import builtins
import errno
import os


class FullDisk:
    """``os`` for a module (planecal.io.samples) whose writes fail with ENOSPC once ``left``
    bytes are written (a partial write first), the rest of ``os`` untouched. `install` puts
    it in place and also makes ``open`` of a temp file (``*.tmp``: the sidecar's) fail once
    the disk is full; ``monkeypatch.undo()`` gives the room back."""

    def __init__(self, left: int):
        self.left = left
        self._real_open = builtins.open

    def __getattr__(self, name):
        return getattr(os, name)

    def write(self, fd, data):
        if len(data) > self.left:
            n, self.left = self.left, 0
            if n:
                return os.write(fd, data[:n])
            raise OSError(errno.ENOSPC, "No space left on device")
        self.left -= len(data)
        return os.write(fd, data)

    def open_file(self, file, mode="r", *a, **k):
        """``builtins.open``, but a temp file cannot be created on the full disk."""
        if str(file).endswith(".tmp") and self.left == 0:
            raise OSError(errno.ENOSPC, "No space left on device", str(file))
        return self._real_open(file, mode, *a, **k)

    def install(self, monkeypatch, module) -> None:
        monkeypatch.setattr(module, "os", self)
        monkeypatch.setattr(builtins, "open", self.open_file)
