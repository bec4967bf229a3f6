"""A schedule's files: read with bounds, included, and their definitions gathered.

Any member of the daemon's group may send a schedule, and any path may be written under
``include``: reading must not block, exhaust memory or read what is not a file. So a
file is read only when it is a regular file (:func:`read_file`): ``os.stat`` first (a
FIFO, a device such as ``/dev/zero`` or ``/dev/stdin``'s terminal, a directory are
refused by kind, a file larger than :data:`~.limits.MAX_FILE_BYTES` by size), then
opened with ``O_NONBLOCK`` (a FIFO swapped in after the check cannot block the open),
checked again on the open descriptor, and read up to one byte past the bound. A regular
file of size 0 is not opened at all: it is empty, or it is a kernel file (``/proc/kmsg``)
whose reading would block or take what is not ours. Includes nest at most
:data:`~.limits.MAX_INCLUDE_DEPTH` deep, at most :data:`~.limits.MAX_FILES` files are
read, :data:`~.limits.MAX_TOTAL_BYTES` in all, and a cycle is named.

Included paths are relative to the including file; the including file's ``vars`` and
``blocks`` override the included ones.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from reach_receiver.config.fields import closest, type_name
from reach_receiver.config.yaml_lines import LineDict, LineList, Problem, load_yaml

from .limits import MAX_FILE_BYTES, MAX_FILES, MAX_INCLUDE_DEPTH, MAX_TOTAL_BYTES, LimitExceeded
from .parsing import Block
from .variables import Defined, valid_name

TOP_KEYS = ("version", "schedule", "include", "vars", "blocks", "steps")
INCLUDED_KEYS = ("include", "vars", "blocks")

#: How included files are read: from disk, or from texts a client sent with its schedule.
Reader = Callable[[Path], str]

_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


class NotAFile(OSError):
    """A path that is not a regular file of a readable size; ``str()`` says why."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.strerror = message


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def read_file(path: Path, limit: int = MAX_FILE_BYTES) -> str:
    """A regular file's text (UTF-8), at most ``limit`` bytes, never blocking.

    Raises
    ------
    OSError
        It does not exist or cannot be read; :class:`NotAFile` when it is not a
        regular file or is larger than ``limit``.
    UnicodeDecodeError
        It is not UTF-8.
    """
    info = os.stat(path)
    if not stat.S_ISREG(info.st_mode):
        raise NotAFile(f"it is {_kind(info.st_mode)}, not a regular file")
    if info.st_size > limit:
        raise NotAFile(f"it has {info.st_size:,} bytes; at most {limit:,} are read")
    if info.st_size == 0:
        return ""
    flags = os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(path, flags)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # replaced since the stat above
            raise NotAFile("it is not a regular file")
        data = b""
        while len(data) <= limit:
            chunk = os.read(fd, limit + 1 - len(data))
            if not chunk:
                break
            data += chunk
    finally:
        os.close(fd)
    if len(data) > limit:
        raise NotAFile(f"it has more than {limit:,} bytes")
    return data.decode("utf-8")


def source_problem(text: str, file: str, total: int) -> str | None:
    """Why a file's text is not parsed (too long alone, or with the others), or ``None``."""
    size = len(text.encode("utf-8", errors="replace"))
    if size > MAX_FILE_BYTES:
        return f"{size:,} bytes; a schedule file has at most {MAX_FILE_BYTES:,}"
    if total + size > MAX_TOTAL_BYTES:
        return f"the schedule and its includes have more than {MAX_TOTAL_BYTES:,} bytes"
    return None


@dataclass
class Sources:
    """Files read so far, and the definitions they made."""

    problems: list[Problem]
    read: Reader = read_file
    texts: dict[str, str] = field(default_factory=dict)
    variables: dict[str, Defined] = field(default_factory=dict)
    blocks: dict[str, Block] = field(default_factory=dict)
    files_read: int = 0
    bytes_read: int = 0

    def add(self, file: str, text: str, stack: tuple[str, ...]) -> LineDict | None:
        """Load one file's text; read its includes, then its vars and blocks."""
        self.texts.setdefault(file, text)
        too_large = source_problem(text, file, self.bytes_read)
        if too_large is not None:
            self.problems.append(Problem(file, 1, "<file>", too_large))
            return None
        self.files_read += 1
        self.bytes_read += len(text.encode("utf-8", errors="replace"))
        document, problems = load_yaml(text, file)
        self.problems += problems
        if problems and document is None:
            return None
        if not isinstance(document, LineDict):
            what = "a schedule" if not stack else "an included file"
            message = f"{what} is a mapping of {', '.join(TOP_KEYS)}, not {type_name(document)}"
            self.problems.append(Problem(file, 1, "<document>", message))
            return None
        allowed = TOP_KEYS if not stack else INCLUDED_KEYS
        for key in document:
            if key not in allowed:
                known = ", ".join(allowed)
                message = f"unknown key '{key}'{closest(key, allowed)} (known: {known})"
                if stack and key in TOP_KEYS:
                    message = f"an included file holds only {', '.join(INCLUDED_KEYS)}"
                self.problems.append(Problem(file, document.line_of(key), str(key), message))
        self._includes(document, file, (*stack, identity(file)))
        self._definitions(document, file)
        return document

    def _includes(self, document: LineDict, file: str, stack: tuple[str, ...]) -> None:
        written = document.get("include")
        if written is None:
            return
        if isinstance(written, str):
            written = LineList([written], line=document.line_of("include"))
        if not isinstance(written, LineList):
            message = f"must be a list of file names, not {type_name(written)}"
            self.problems.append(Problem(file, document.line_of("include"), "include", message))
            return
        for index, name in enumerate(written):
            line, key = written.line_of(index), f"include[{index}]"
            if not isinstance(name, str) or not name:
                message = f"must be a file name, not {type_name(name)}"
                self.problems.append(Problem(file, line, key, message))
                continue
            path = relative(file, name)
            if identity(str(path)) in stack:
                looped = stack[stack.index(identity(str(path))) :]
                chain = " -> ".join(Path(f).name for f in (*looped, str(path)))
                self.problems.append(Problem(file, line, key, f"include cycle: {chain}"))
                continue
            self._bounded(file, line, key, len(stack))
            try:
                text = self.read(path)
            except (OSError, UnicodeDecodeError, ValueError) as err:
                message = f"cannot read {path}: {getattr(err, 'strerror', None) or err}"
                self.problems.append(Problem(file, line, key, message))
                continue
            self.add(str(path), text, stack)

    def _bounded(self, file: str, line: int, key: str, depth: int) -> None:
        """Stop at an include too deep, or one file too many."""
        if depth >= MAX_INCLUDE_DEPTH:
            message = f"includes nested more than {MAX_INCLUDE_DEPTH} deep"
            raise LimitExceeded(Problem(file, line, key, message))
        if self.files_read >= MAX_FILES:
            message = f"more than {MAX_FILES} files read (a file included many times?)"
            raise LimitExceeded(Problem(file, line, key, message))

    def _definitions(self, document: LineDict, file: str) -> None:
        for section in ("vars", "blocks"):
            written = document.get(section)
            if written is None:
                continue
            if not isinstance(written, LineDict):
                message = f"must be a mapping of names, not {type_name(written)}"
                self.problems.append(Problem(file, document.line_of(section), section, message))
                continue
            for name, value in written.items():
                line = written.line_of(name)
                if not valid_name(name):
                    message = f"{name!r} is not a valid name (letters, digits, _; not 'site')"
                    self.problems.append(Problem(file, line, f"{section}.{name}", message))
                elif section == "vars":
                    self.variables[name] = Defined(value, file, line)
                else:
                    self.blocks[name] = Block(value, file, line)


def relative(file: str, name: str) -> Path:
    """The path ``name`` written in ``file``: relative to that file's directory."""
    written = Path(name)
    if written.is_absolute() or file.startswith("<"):
        return written
    return Path(os.path.normpath(Path(file).parent / written))


def identity(file: str) -> str:
    """The same string for every spelling of one file's path."""
    if file.startswith("<"):
        return file
    try:
        return str(Path(file).resolve())
    except (OSError, ValueError, RuntimeError):
        return file
