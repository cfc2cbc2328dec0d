"""The one way the kit writes a file: to a temporary name beside it, then moved into place.

A reader (another process, a later run reusing a cache) sees the old file or the whole
new one, never a torn one: a full disk, a kill or an exception part-way leaves the file
that was there before and no temporary behind. Text is UTF-8 whatever the locale (a
Latin-1 locale could not write the units' micro sign). The file ends with the mode a
plain open() would give it (0666 less the umask; mkstemp alone gives 0600).

Here, in fmu_src, because the FMU builds write stamps too and the data flows one way
(fmu_src -> scenarios): the scenarios import it from here.
"""
import atexit
import contextlib
import fcntl
import os
import pathlib
import tempfile
import threading


def _umask():
    """This process's umask, read without changing it (Linux /proc), else by setting it back."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def replacing(path, text=False, newline=None):
    """A file object writing ``path`` anew (text: UTF-8); the file is in place, whole,
    when the block ends, and untouched if it raises (KeyboardInterrupt and SystemExit too)."""
    path = pathlib.Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "w" if text else "wb", **({"encoding": "utf-8", "errors": "surrogateescape",
                                                      "newline": newline} if text else {})) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_bytes(path, data):
    """``path`` holds ``data``, written atomically (replacing)."""
    with replacing(path) as f:
        f.write(data)
    return pathlib.Path(path)


def write_text(path, text):
    """``path`` holds ``text`` in UTF-8, written atomically (replacing)."""
    with replacing(path, text=True) as f:
        f.write(text)
    return pathlib.Path(path)


@contextlib.contextmanager
def building(folder):
    """``folder`` held for this block against other processes building into it (fcntl.flock
    on ``folder``/.build.lock, waited for): two processes (parallel test workers, a campaign's
    workers, two shells) that find the same FMU due build it once, one after the other,
    instead of writing one file from two compilers."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fd = os.open(folder / ".build.lock", os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield folder
    finally:
        os.close(fd)                  # closing the descriptor releases the lock


_LATER: list = []   # [thread, path, error] of each write_bytes_later not yet settled


def write_bytes_later(path, data):
    """``path`` holds ``data`` (write_bytes) once settle() has returned: written on a thread,
    so that the disk's work (the write and its fsync, ~15 ms for a run's 3 MB of records)
    overlaps what the caller does next. A second write to a path waits for the first."""
    path = pathlib.Path(path)
    for pending in [p for p in _LATER if p[1] == path]:
        pending[0].join()
    pending = [None, path, None]

    def write():
        try:
            write_bytes(path, data)
        except BaseException as exc:   # kept for settle() to raise in the caller's thread
            pending[2] = exc
    pending[0] = threading.Thread(target=write, name=f"writing {path.name}")
    _LATER.append(pending)
    pending[0].start()


def settle():
    """Wait for every write_bytes_later; raise the first one's error (its file is then
    the one that was there before, as with write_bytes)."""
    while _LATER:
        thread, _, _ = _LATER[0]
        thread.join()
        _, _, error = _LATER.pop(0)
        if error is not None:
            for other in _LATER:
                other[0].join()
            _LATER.clear()
            raise error


@atexit.register
def _settle_at_exit():
    """Files written later are in place before the process ends (an error was said already)."""
    for thread, _, _ in list(_LATER):
        thread.join()
