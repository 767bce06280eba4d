"""Frame sequences out: an mp4 video (OpenCV, mp4v) or a folder of numbered PNGs.

One writer serves ``ffls render --turntable`` and the viewer's turntable recording. An mp4 is
written to a temporary file (:func:`ffls.errors.atomic_output`) and a PNG folder to a staging
folder beside it (:func:`ffls.errors.atomic_folder`); either is renamed onto the output only when
the writer closes successfully, so an error, Ctrl-C or SIGTERM (which the CLI turns into an
exception) leaves neither a ``.tmp.mp4`` nor a folder of some frames behind, and an existing
output stays as it was.
"""
from __future__ import annotations

import contextlib
import errno
import re
from pathlib import Path

import numpy as np

from ffls.errors import (FflsError, InputError, OutputError, atomic_folder, atomic_output, disk_full,
                         os_error_message)


#: Names of the frames a PNG folder holds (an existing folder of only these may be replaced).
_FRAME = re.compile(r"frame_\d{4,}\.png")


def frame_folder_problem(out) -> str | None:
    """Why the folder ``out`` may not receive a turntable's frames (it holds other files than
    ``frame_NNNN.png``, which a new turntable would replace), or None."""
    out = Path(out)
    if not out.is_dir():
        return None
    other = [p.name for p in out.iterdir() if not _FRAME.fullmatch(p.name)]
    if other:
        return (f"the folder holds other files than frames ({other[0]!r}, ...); refusing to replace it: choose a "
                "new or empty folder")
    return None


class FrameWriter:
    """Write RGB frames to ``OUT.mp4`` or to ``DIR/frame_NNNN.png``.

    Parameters
    ----------
    out : path
        A path ending in ``.mp4``, or a folder (created when the writer closes, replacing an
        existing one; any other suffix is an error). Its parent folder must exist.
    fps : float
        Frame rate of the mp4.

    Use as a context manager: the mp4 appears at ``out`` only when the block ends without an
    exception. ``write(rgb)`` takes (H, W, 3) uint8 frames of one size.
    """

    def __init__(self, out, fps: float = 30.0):
        self.out = Path(out)
        self.fps = float(fps)
        self.frames = 0
        self.is_video = self.out.suffix.lower() == ".mp4"
        if not self.is_video and self.out.suffix:
            raise InputError("a frame sequence goes to an .mp4 file or a folder", self.out)
        if not self.fps > 0 or self.fps == float("inf"):
            raise InputError(f"frame rate must be positive, not {fps}", self.out)
        self._atomic = None
        self._tmp = None
        self._writer = None
        self._size = None
        why = None if self.is_video else frame_folder_problem(self.out)
        if why:
            raise InputError(why, self.out)
        self._atomic = atomic_output(self.out) if self.is_video else atomic_folder(self.out)
        self._tmp = self._atomic.__enter__()

    def write(self, rgb: np.ndarray) -> None:
        """Append one frame, (H, W, 3) uint8 RGB."""
        rgb = np.asarray(rgb)
        if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ValueError(f"frames must be (H, W, 3) uint8, not {rgb.dtype} {rgb.shape}")
        if self._size is None:
            self._size = rgb.shape[:2]
        elif rgb.shape[:2] != self._size:
            raise ValueError(f"frame {self.frames} is {rgb.shape[:2]}, the first was {self._size}")
        if self.is_video:
            import cv2

            if self._writer is None:
                h, w = self._size
                self._writer = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, (w, h))
                if not self._writer.isOpened():
                    if disk_full(self.out.parent if str(self.out.parent) else Path(".")):
                        raise OutputError(f"cannot write ({os_error_message(OSError(errno.ENOSPC, ''))})", self.out)
                    raise FflsError("OpenCV cannot write mp4 (mp4v) here; write PNG frames to a folder instead",
                                    self.out)
            self._writer.write(np.ascontiguousarray(rgb[..., ::-1]))
        else:
            from ffls.io.images import write_png

            write_png(self._tmp / f"frame_{self.frames:04d}.png", rgb)
        self.frames += 1

    def close(self) -> str:
        """Finish the sequence; returns a one-line description of what was written."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if self._atomic is not None:
            atomic, self._atomic = self._atomic, None
            if self.frames == 0:
                with contextlib.suppress(InputError):
                    atomic.__exit__(InputError, InputError("no frames"), None)
                raise InputError("no frames were written", self.out)
            atomic.__exit__(None, None, None)
        return self.describe()

    def describe(self) -> str:
        """One line: where the frames went."""
        if self.is_video:
            return f"{self.out} ({self.frames} frames, {self.fps:g} fps)"
        return f"{self.out}/frame_0000..{max(self.frames - 1, 0):04d}.png"

    def abort(self, exc: BaseException | None = None) -> None:
        """Stop without output: a partial mp4 or PNG folder is removed; an existing output stays.

        ``exc``, the error that stopped the writing, is passed through the output policy, which
        names the output where the error named a temporary path (:func:`ffls.errors.name_output`).
        """
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if self._atomic is not None:
            atomic, self._atomic = self._atomic, None
            exc = exc if isinstance(exc, Exception) else RuntimeError("aborted")
            with contextlib.suppress(Exception):
                atomic.__exit__(type(exc), exc, None)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort(exc)
        return False
