"""On-disk cache of offline data: npz files keyed by a hash of everything they depend on.

A file stores its full key and a checksum of its arrays; one whose key or
checksum does not match (another configuration, a corrupt or truncated file) is
reported and rebuilt, never used. Files are written atomically (temporary file
in the same directory, then rename) and streamed: array by array into the zip
archive, the checksum computed on the way, so that writing never holds a second
copy of the data (``pack`` may return a dict or yield (name, array) pairs in sorted
name order); a temporary left by a writer that died (kill -9 during a save) carries
its process id and host in its name and is removed by the next ``load`` or ``save``
in that directory. Subclasses set the file ``prefix`` and the ``pack`` / ``unpack``
hooks (``cem.PrimalOfflineCache``, ``mixed_cem.MixedOfflineCache``).
"""

import hashlib
import logging
import os
import re
import socket
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

from fenics_contact.errors import InputError

__all__ = ["OfflineCache", "checksum", "hash_array", "remove_stale_temporaries", "write_npz"]

log = logging.getLogger(__name__)

#: temporaries are named ``<stem>.<random>.pid<pid>@<host>.npz.tmp``
_TEMPORARY = re.compile(r"\.pid(?P<pid>\d+)@(?P<host>.+)\.npz\.tmp$")
#: age after which a temporary of another host, or without a process id (older versions), is stale
_STALE_AGE_S = 3600.0


def _host() -> str:
    return socket.gethostname() or "localhost"


def _temporary_suffix() -> str:
    return f".pid{os.getpid()}@{_host()}.npz.tmp"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def remove_stale_temporaries(directory: str | Path) -> list[Path]:
    """Remove ``*.npz.tmp`` files whose writer is gone: a dead process of this host, or older than an hour."""
    removed = []
    try:
        candidates = list(Path(directory).glob("*.npz.tmp"))
    except OSError:
        return removed
    now = time.time()
    for path in candidates:
        match = _TEMPORARY.search(path.name)
        try:
            if match is not None and match["host"] == _host():
                stale = not _alive(int(match["pid"]))
            else:
                stale = now - path.stat().st_mtime > _STALE_AGE_S
            if stale:
                path.unlink()
                removed.append(path)
        except OSError:  # gone meanwhile, or a read-only directory
            continue
    if removed:
        log.info("removed %d stale temporary file(s) in %s (writers that died during a save)", len(removed), directory)
    return removed


def hash_array(h: "hashlib._Hash", a: np.ndarray) -> None:
    a = np.ascontiguousarray(a)
    h.update(str(a.dtype).encode())
    h.update(str(a.shape).encode())
    h.update(memoryview(a).cast("B") if a.dtype.kind in "biuf" and a.ndim else a.tobytes())  # no copy


def checksum(arrays: dict) -> str:
    hasher = hashlib.sha256()
    for name in sorted(arrays):
        hasher.update(name.encode())
        hash_array(hasher, arrays[name])
    return hasher.hexdigest()


def write_npz(fh, items, key: str) -> None:
    """An npz archive of (name, array) pairs (sorted by name) followed by their ``checksum`` and ``key``.

    Each array is written straight into the zip entry ``name.npy``; the checksum is that of
    ``checksum`` (names in sorted order), computed while writing.
    """
    hasher = hashlib.sha256()
    last = None
    with zipfile.ZipFile(fh, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name, arr in items:
            if name in ("checksum", "key") or (last is not None and name <= last):
                raise ValueError(f"cache arrays must come in strictly increasing name order ({last!r}, {name!r})")
            last = name
            arr = np.asanyarray(arr)
            hasher.update(name.encode())
            hash_array(hasher, arr)
            with zf.open(f"{name}.npy", mode="w", force_zip64=True) as entry:
                np.lib.format.write_array(
                    entry, arr if arr.ndim == 0 else np.ascontiguousarray(arr), allow_pickle=False
                )
        for name, value in (("checksum", hasher.hexdigest()), ("key", key)):
            with zf.open(f"{name}.npy", mode="w", force_zip64=True) as entry:
                np.lib.format.write_array(entry, np.array(value), allow_pickle=False)


class OfflineCache:
    """npz files ``<prefix>_<key>.npz`` in a directory; each stores its full key and a checksum of its arrays.

    Subclasses set ``prefix`` and the ``pack`` / ``unpack`` hooks (``cem.PrimalOfflineCache``,
    ``mixed_cem.MixedOfflineCache``).
    """

    prefix = "offline"

    def __init__(self, directory: str | Path) -> None:
        self.directory = Path(directory)

    def path(self, key: str) -> Path:
        return self.directory / f"{self.prefix}_{key[:24]}.npz"

    @staticmethod
    def pack(obj) -> dict[str, np.ndarray]:
        """The arrays to store for ``obj`` (subclasses)."""
        raise NotImplementedError

    @staticmethod
    def unpack(arrays: dict[str, np.ndarray], *context):
        """The object rebuilt from stored arrays (subclasses)."""
        raise NotImplementedError

    def load(self, key: str, *context) -> tuple[object | None, str]:
        """(data, status): status is 'loaded', 'missing', or 'invalid: <why>' (the file is then ignored).

        ``context`` is passed to ``unpack`` (the operators and grid the data must fit).
        """
        path = self.path(key)
        remove_stale_temporaries(self.directory)
        if not path.is_file():
            return None, "missing"
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {name: data[name] for name in data.files}
            stored_key = str(arrays.pop("key"))
            stored_sum = str(arrays.pop("checksum"))
            if stored_key != key:
                return None, "invalid: stored key differs (another configuration)"
            if checksum(arrays) != stored_sum:
                return None, "invalid: checksum mismatch (corrupt file)"
            return self.unpack(arrays, *context), "loaded"
        except (OSError, EOFError, ValueError, KeyError, zipfile.BadZipFile) as err:  # unreadable/malformed: rebuild
            return None, f"invalid: {type(err).__name__}: {err}"

    def check_writable(self) -> None:
        """Raise InputError unless a file can be created in the directory (creating the directory if needed)."""
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=self.directory, prefix="write-test.", suffix=_temporary_suffix())
            os.close(fd)
            os.remove(tmp)
        except OSError as err:
            raise InputError(f"the offline cache directory {self.directory} is not writable: {err}") from err

    def save(self, key: str, obj) -> Path:
        """Write atomically (temporary file + rename), array by array (``write_npz``)."""
        self.directory.mkdir(parents=True, exist_ok=True)
        packed = self.pack(obj)
        items = ((name, packed[name]) for name in sorted(packed)) if isinstance(packed, dict) else packed
        path = self.path(key)
        remove_stale_temporaries(self.directory)
        fd, tmp = tempfile.mkstemp(dir=self.directory, prefix=f"{path.stem}.", suffix=_temporary_suffix())
        try:
            with os.fdopen(fd, "wb") as fh:
                write_npz(fh, items, key)
            os.chmod(tmp, 0o644)
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.remove(tmp)
            raise
        return path
