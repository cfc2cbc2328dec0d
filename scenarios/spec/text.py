"""A scenario or campaign file as text: read whole, in UTF-8 (or UTF-16 with its mark),
parsed as TOML with its nesting bounded, and the error that names the file, the key and
the problem (ScenarioError)."""
import contextlib
import difflib
import os
import pathlib
import re
import tomllib

from scenarios.spec.keys import MAX_DEPTH, MAX_FILE_BYTES, MAX_INTEGER, PLAIN_NAME, TYPE_NAMES


class ScenarioError(ValueError):
    """Problems in a scenario file; the message says file, key and problem, one line each
    (every problem found in the file, not only the first)."""

    def __init__(self, source, key, problem):
        super().__init__(f"{shown(source)}: {key}: {problem}")
        self.problems = [(source, key, problem)]

    @classmethod
    def joined(cls, errors):
        """One error carrying every problem of ``errors``, in order, each told once: a
        problem told in the same words for several keys (a parameter a campaign does not
        have, once per value; a source below the horizon, once per sweep value) is told at
        the first key, the others named after it."""
        error = cls(*errors[0].problems[0])
        keys = {}
        for source, key, problem in (p for e in errors for p in e.problems):
            keys.setdefault((source, problem), []).append(key)
        error.problems = [(source, found[0], problem + (f" (the same at {', '.join(found[1:])})" if len(found) > 1
                                                         else "")) for (source, problem), found in keys.items()]
        error.args = ("\n".join(f"{shown(s)}: {k}: {p}" for s, k, p in error.problems),)
        return error


def shown(text, most=160):
    """``text`` (a path) as a message shows it: whole up to ``most`` characters, else its
    start and end around an ellipsis (a 4,000-character path was echoed whole, each line);
    the error's ``problems`` keep it whole."""
    text = str(text)
    return text if len(text) <= most else f"{text[:most // 3]}...{text[-(most - most // 3 - 3):]}"


class Problems:
    """Collects the problems of one file: each part is checked on its own, all are told."""

    def __init__(self, error=ScenarioError):
        self.errors = []
        self.error = error

    @contextlib.contextmanager
    def part(self):
        try:
            yield
        except self.error as exc:
            self.errors.append(exc)

    def raise_any(self):
        if self.errors:
            raise self.error.joined(self.errors)


def unknown_keys(keys, allowed):
    """'unknown key 'stop_tme'; did you mean 'stop_time'? allowed: ...' per key."""
    out = []
    for key in sorted(keys, key=str):
        near = difflib.get_close_matches(str(key), [str(a) for a in allowed], 1, 0.6)
        hint = f"did you mean {near[0]!r}? " if near else ""
        out.append((key, f"unknown key; {hint}allowed: {', '.join(map(str, allowed))}"))
    return out


def check_name(source, key, value, error=ScenarioError):
    """A name that becomes a file or folder name: text of letters, digits, _ . - (not
    starting with . or -), at most 100 characters; anything else is refused, naming it."""
    if not isinstance(value, str):
        raise error(source, key, f"expected text, got {TYPE_NAMES.get(type(value), type(value).__name__)}")
    if not PLAIN_NAME.fullmatch(value):
        bad = sorted({c for c in value if not re.fullmatch(r"[A-Za-z0-9_.-]", c)})
        why = (f"is {len(value)} characters long (at most 100)" if len(value) > 100 else
               f"holds {', '.join(map(repr, bad))}" if bad else "starts with . or -" if value else "is empty")
        raise error(source, key, f"{value[:60]!r}{'...' if len(value) > 60 else ''} {why}: a name is also a folder "
                    "name, so it takes letters, digits, _ . - only (not a path)")
    return value


def run_label(value):
    """The label of a run made from a value as written (a sweep value): the user's text
    ("1.8e6 N/m"), as results, tables and legends name the run."""
    return value if isinstance(value, str) else repr(value)


def file_label(value):
    """The file name of a run's label (run_label): every character but letters, digits and
    ' _.,+=-' becomes '_' ("10 N/m" -> "10 N_m"); file names only, never shown as its label."""
    return re.sub(r"[^A-Za-z0-9 _.,+=-]", "_", run_label(value))[:100] or "_"


def read_toml(text, source, error=ScenarioError):
    """TOML text to data, or ``error`` naming what is wrong: a syntax error, nesting
    deeper than MAX_DEPTH, an integer beyond MAX_INTEGER (checked before any use)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(source, "TOML", str(exc)) from None
    except RecursionError:
        raise error(source, "TOML", f"nested deeper than any scenario (at most {MAX_DEPTH} levels)") from None
    except ValueError as exc:       # an integer literal longer than Python converts
        raise error(source, "TOML", f"a value cannot be read: {exc}") from None
    stack = [(data, "", 0)]
    while stack:
        value, where, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise error(source, where, f"nested {depth} levels deep; a scenario nests at most {MAX_DEPTH}")
        if isinstance(value, dict):
            stack.extend((v, f"{where}.{k}" if where else str(k), depth + 1) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((v, f"{where}[{i}]", depth + 1) for i, v in enumerate(value))
        elif isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INTEGER:
            raise error(source, where, f"integer {str(value)[:20]}... ({len(str(abs(value)))} digits) is too "
                        f"large (at most 2^53)")
    return data


def read_text(path, error=ScenarioError, what="scenario"):
    """A TOML file's text; ``error`` for a directory, a missing file, a device or pipe,
    a file over MAX_FILE_BYTES, a binary, UTF-16 or otherwise non-UTF-8 file."""
    path = pathlib.Path(path)
    if path.is_dir():
        inside = sorted(p.name for p in path.glob("*.toml"))
        hint = f"; it holds {', '.join(inside)}" if inside else ""
        raise error(str(path), "file", f"is a directory, not a {what} file (.toml){hint}")
    if not path.exists():
        raise error(str(path), "file", "does not exist")
    if not path.is_file():
        raise error(str(path), "file", f"is not a regular file (a device or a pipe), not a {what} file")
    try:
        with open(path, "rb") as file:
            data = file.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise error(str(path), "file", f"cannot be read: {exc.strerror}") from None
    if len(data) > MAX_FILE_BYTES:
        raise error(str(path), "file", f"is larger than {MAX_FILE_BYTES >> 20} MiB: not a {what} file")
    if _utf16(data):
        raise error(str(path), "file", f"is UTF-16 text; save it as UTF-8 (a {what} is a TOML file in UTF-8)")
    if b"\0" in data:
        raise error(str(path), "file", f"is a binary file (NUL byte at offset {data.find(0)}), not a TOML {what}")
    try:
        return data.decode("utf-8-sig")   # a leading BOM (some editors write one) is not TOML
    except UnicodeDecodeError as exc:
        raise error(str(path), "file", f"is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                    f"{exc.start}); a {what} is a TOML file in UTF-8") from None


def _utf16(data):
    """Whether bytes are UTF-16 text (a BOM, or the NUL high bytes of ASCII) that decodes."""
    if not (data[:2] in (b"\xff\xfe", b"\xfe\xff") or (len(data) >= 4 and (data[1] == data[3] == 0 or
                                                                           data[0] == data[2] == 0))):
        return False
    try:
        text = data.decode("utf-16" if data[:2] in (b"\xff\xfe", b"\xfe\xff") else
                           "utf-16-le" if data[1] == 0 else "utf-16-be")
    except UnicodeDecodeError:
        return False
    return all(c.isprintable() or c in "\r\n\t" for c in text.lstrip("\ufeff"))


def merged(data, overrides):
    """data with ``overrides`` laid over it, tables merged key by key (a [ci.fmus.plant]
    table changes that instance's keys only, not the other instances)."""
    out = dict(data)
    for key, value in (overrides or {}).items():
        out[key] = merged(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def shipped_file(path, folder, error, what):
    """The file ``path``, or the name of one shipped in ``folder`` (<folder>/<name>.toml);
    ``error`` (an error class of this module's form) names the nearest shipped one if neither
    exists. ``what``: "campaign", "budget"."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"a {what} is a file path or a shipped name, got {type(path).__name__} {path!r:.60}")
    path = pathlib.Path(path).expanduser()
    if not path.exists() and path.suffix != ".toml" and (folder / f"{path}.toml").exists():
        path = folder / f"{path}.toml"
    if not path.exists():
        shipped = sorted(p.stem for p in folder.glob("*.toml"))
        near = difflib.get_close_matches(path.stem.lower(), shipped, 1, 0.6)
        raise error(str(path), "file", "does not exist; " + (f"did you mean {near[0]!r}? " if near else "")
                    + f"shipped {what}s: {', '.join(shipped)}")
    return path
