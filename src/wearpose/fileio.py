"""Atomic file writes: a reader never sees a half-written file (write to a temporary file in
the same folder, then rename, which is atomic on POSIX and Windows)."""

from __future__ import annotations

import os
import tempfile
import tokenize
import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np
from numpy.lib import format as npy


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _atomic(path: str | Path, suffix: str, write: Callable[[str], None]) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        write(tmp)
        # mkstemp creates 0600 files; give the result the permissions a plain open() would.
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def atomic_savez(path: str | Path, arrays: dict[str, Any], compressed: bool = False) -> Path:
    """``np.savez`` (or ``savez_compressed``) of ``arrays`` to exactly ``path``, atomically."""
    save = np.savez_compressed if compressed else np.savez
    # The temporary name ends in .npz so numpy does not append another suffix.
    return _atomic(path, ".tmp.npz", lambda tmp: save(tmp, **arrays))


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return _atomic(path, ".tmp", lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def atomic_torch_save(path: str | Path, obj: Any) -> Path:
    """``torch.save(obj)`` to exactly ``path``, atomically, through a temporary file of its own
    (unique per call: torchrun ranks building the same cache never share one)."""
    import torch  # start-up: the recording reader imports this module and needs no torch for it

    return _atomic(path, ".tmp", lambda tmp: torch.save(obj, tmp))


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    return _atomic(path, ".tmp", lambda tmp: Path(tmp).write_bytes(data))


#: What ``np.load`` raises reading a damaged or foreign ``.npz`` (for loaders that name the
#: errors they expect rather than catch all): zip and I/O errors, numpy's ``ValueError`` for a
#: bad ``.npy`` member, and ``tokenize.TokenError``, which numpy's header filter
#: (``numpy.lib.format``, reading a damaged member header) lets through unconverted.
NPZ_READ_ERRORS: tuple[type[BaseException], ...] = (
    zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError, NotImplementedError, zipfile.LargeZipFile,
    tokenize.TokenError)


def npz_problem(path: str | Path, exc: BaseException) -> str:
    """Why ``np.load(path)`` could not read ``path`` as an ``.npz``, in a user's words: another
    kind of file, a damaged/truncated archive (e.g. an interrupted copy), or numpy's own reason.
    For error messages (:class:`wearpose.errors.InputFileError` ``problem``)."""
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError:
        head = b""
    if head[:2] != b"PK":  # every zip (hence every npz) starts with the local-file signature 'PK'
        return "not an npz (zip) archive: the file is of another type or its start is damaged"
    if isinstance(exc, (zipfile.BadZipFile, EOFError)):
        return f"a damaged or truncated npz (zip) archive, e.g. an interrupted copy ({exc})"
    if isinstance(exc, tokenize.TokenError):
        return f"a damaged array header inside the npz (numpy cannot parse it: {exc})"
    return f"not a readable npz file ({type(exc).__name__}: {exc})"


def npz_declared_size_problem(path: str | Path) -> tuple[str, str] | None:
    """``(member, problem)`` for the first ``.npy`` member of the npz at ``path`` whose header
    declares more data (shape x item size) than the member holds, else ``None``.

    Why: ``np.load`` allocates the declared array before reading it, so a forged or damaged
    header (shape ``(2**40,)`` over 64 bytes) would claim memory the file cannot fill. Checked
    from the headers and the zip directory alone, before any array is read. Members numpy cannot
    parse are left to ``np.load``, which reports them.
    """
    with zipfile.ZipFile(path) as z:
        for info in z.infolist():
            if not info.filename.endswith(".npy"):
                continue
            with z.open(info) as f:
                try:
                    version = npy.read_magic(f)
                    read = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
                    shape, _, dtype = read(f)
                    header_bytes = f.tell()
                except Exception:  # noqa: BLE001 - np.load reads the member again and names its problem
                    continue
            count = 1
            for n in shape:
                count *= n
            declared = count * dtype.itemsize
            held = info.file_size - header_bytes
            if count < 0 or declared > held:
                name = info.filename[:-4]
                return name, (f"the array header declares shape {shape} of {dtype} ({declared} bytes) but the member "
                              f"holds {max(held, 0)} bytes (truncated or damaged)")
    return None
