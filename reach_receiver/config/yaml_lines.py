"""Safe YAML loading that remembers the line of every key and every list item.

Schedules and site files are checked before anything moves, and every mistake must name
its file, line and key. :class:`LineLoader` is a :class:`yaml.SafeLoader` (never the full loader:
no Python objects can be built from a schedule) whose mappings and sequences are built
as :class:`LineDict` and :class:`LineList`: ordinary ``dict``/``list`` subclasses that
carry ``line`` (where the container starts) and ``lines`` (the 1-based line of each key,
or of each item). Duplicate keys, which YAML forbids but PyYAML silently resolves to the
last, are reported naming both lines. Syntax errors become a :class:`Problem` at the
line the parser gives.

Loading is bounded, whatever the text: a document longer than
:data:`MAX_DOCUMENT_CHARS` is refused before parsing, containers nested deeper than
:data:`MAX_DEPTH` are refused at their line while composing (before any recursion gets
near Python's limit), and aliases that would expand past :data:`MAX_EXPANDED_NODES`
values ("billion laughs") or contain themselves are refused after loading (the loaded
document shares the aliased objects, so it is small in memory either way).

One extension to YAML 1.1's resolvers: a number written with an exponent but no dot
(``40e6``, YAML 1.2 style) is a float rather than a string, since sweep frequencies are
naturally written that way. YAML 1.1's ``on``/``off``/``yes``/``no`` stay booleans.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from reach_receiver.errors import ConfigError

MERGE_TAG = "tag:yaml.org,2002:merge"
#: A schedule is small; aliases must not blow it up ("billion laughs").
MAX_EXPANDED_NODES = 100_000
#: Containers inside containers: a schedule needs a handful; the composer and every
#: walk over the document recurse, and 64 levels keep them far from Python's limit.
MAX_DEPTH = 64
#: The longest document parsed (characters): the pure-Python parser takes about 8 us a
#: character, so 1 Mi characters is already seconds; callers may ask for less.
MAX_DOCUMENT_CHARS = 1024 * 1024
#: The longest integer read: Python refuses to convert more than 4300 digits anyway.
MAX_INT_DIGITS = 100


@dataclass(frozen=True)
class Problem:
    """One mistake in a document: where it is, which key, and what is wrong."""

    file: str
    line: int
    key: str
    message: str

    def __str__(self) -> str:
        text = f"{self.file}:{self.line}: {self.key}: {self.message}"
        return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class ProblemsError(ConfigError):
    """A document with mistakes; ``problems`` holds every one, in file and line order.

    ``str(error)`` gives one ``file:line: key: message`` per line.
    """

    def __init__(self, problems: Sequence[Problem]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(str(problem) for problem in self.problems))


class LineDict(dict[Any, Any]):
    """A mapping that knows its own line and the line of each of its keys."""

    line: int
    lines: dict[Any, int]

    def __init__(self, *args: Any, line: int = 1, lines: dict[Any, int] | None = None) -> None:
        super().__init__(*args)
        self.line = line
        self.lines = dict(lines or {})

    def line_of(self, key: Any) -> int:
        """The line of ``key``, or the mapping's own line when the key is absent."""
        return self.lines.get(key, self.line)


class LineList(list[Any]):
    """A sequence that knows its own line and the line of each item."""

    line: int
    lines: list[int]

    def __init__(self, *args: Any, line: int = 1, lines: list[int] | None = None) -> None:
        super().__init__(*args)
        self.line = line
        self.lines = list(lines or [])

    def line_of(self, index: int) -> int:
        """The line of item ``index``, or the sequence's own line."""
        return self.lines[index] if 0 <= index < len(self.lines) else self.line


def _line(node: Node) -> int:
    return int(node.start_mark.line) + 1


class LineLoader(yaml.SafeLoader):
    """A :class:`yaml.SafeLoader` building :class:`LineDict`/:class:`LineList` with lines.

    Duplicate keys do not stop the load: they are collected in ``duplicates`` as
    ``(key, first line, second line)`` so that every problem is reported at once.
    """

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self.duplicates: list[tuple[Any, int, int]] = []
        # (id(sequence node), index) -> line where the item is written; an alias item's
        # node is the anchored one, whose own mark points at the anchor, not the item.
        self.item_lines: dict[tuple[int, int], int] = {}
        self.depth = 0

    def compose_node(self, parent: Node | None, index: Any) -> Node | None:
        """Compose one node, first noting where a sequence item is written.

        Nesting deeper than :data:`MAX_DEPTH` stops the load at the line where it
        happens.
        """
        event = self.peek_event()
        if isinstance(parent, SequenceNode) and isinstance(index, int):
            self.item_lines[(id(parent), index)] = int(event.start_mark.line) + 1
        if self.depth >= MAX_DEPTH:
            raise yaml.composer.ComposerError(
                None, None, f"nested deeper than {MAX_DEPTH} levels", event.start_mark
            )
        self.depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1

    def construct_line_mapping(self, node: MappingNode) -> LineDict:
        """Build a mapping, recording key lines and duplicate keys (merge keys honoured)."""
        own = [(k, v) for k, v in node.value if k.tag != MERGE_TAG]
        own_keys = {id(k) for k, _ in own}
        self.flatten_mapping(node)  # resolves "<<" merges into node.value, merged pairs first
        merged = node.value[: len(node.value) - len(own)]
        result = LineDict(line=_line(node))
        seen: dict[Any, int] = {}
        for key_node, value_node in [*merged, *own]:
            key = self.construct_object(key_node, deep=True)
            try:
                hash(key)
            except TypeError as err:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping",
                    node.start_mark,
                    "found an unhashable key",
                    key_node.start_mark,
                ) from err
            line = _line(key_node)
            is_own = id(key_node) in own_keys
            if is_own and key in seen:
                self.duplicates.append((key, seen[key], line))
            if is_own:
                seen[key] = line
            result[key] = self.construct_object(value_node, deep=True)
            result.lines[key] = line
        return result

    def construct_bounded_int(self, node: ScalarNode) -> int:
        """An integer, refused at its line when longer than :data:`MAX_INT_DIGITS`."""
        text = str(node.value)
        if len(text) > MAX_INT_DIGITS:
            raise yaml.constructor.ConstructorError(
                None, None, f"an integer of {len(text)} characters (at most {MAX_INT_DIGITS})",
                node.start_mark,
            )
        return int(self.construct_yaml_int(node))

    def construct_line_sequence(self, node: SequenceNode) -> LineList:
        """Build a sequence, recording the line of each item."""
        items = [self.construct_object(child, deep=True) for child in node.value]
        lines = [
            self.item_lines.get((id(node), index), _line(child))
            for index, child in enumerate(node.value)
        ]
        return LineList(items, line=_line(node), lines=lines)


LineLoader.add_constructor("tag:yaml.org,2002:map", LineLoader.construct_line_mapping)
LineLoader.add_constructor("tag:yaml.org,2002:seq", LineLoader.construct_line_sequence)
LineLoader.add_constructor("tag:yaml.org,2002:int", LineLoader.construct_bounded_int)
LineLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def load_yaml(
    text: str, file: str, max_chars: int = MAX_DOCUMENT_CHARS
) -> tuple[Any, list[Problem]]:
    """Safe-load one YAML document with line numbers.

    Parameters
    ----------
    text
        The document.
    file
        Its name, for the problems.
    max_chars
        The longest document parsed; a longer one is a problem, not parsed.

    Returns
    -------
    tuple
        The document (``None`` when it could not be read) and the problems found:
        syntax errors, duplicate keys, recursive aliases, a document too long, too deep
        or too large once its aliases are expanded.
    """
    if len(text) > max_chars:
        message = f"the document has {len(text):,} characters; at most {max_chars:,} are read"
        return None, [Problem(file, 1, "<yaml>", message)]
    try:
        loader = LineLoader(text)
    except yaml.reader.ReaderError as err:  # a character YAML does not allow
        line = text.count("\n", 0, err.position) + 1
        return None, [
            Problem(file, line, "<yaml>", f"YAML: character {err.character:#x} is not allowed")
        ]
    try:
        document = loader.get_single_data()
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        line = int(mark.line) + 1 if mark is not None else 1
        message = " ".join(str(part) for part in (err.context, err.problem) if part)
        return None, [Problem(file, line, "<yaml>", f"YAML syntax: {message}")]
    except (yaml.YAMLError, ValueError, OverflowError, RecursionError) as err:
        # ValueError: e.g. a date 2024-13-45; RecursionError: a last guard (MAX_DEPTH)
        return None, [Problem(file, 1, "<yaml>", f"YAML: {err}")]
    finally:
        loader.dispose()
    problems = [
        Problem(file, second, str(key), f"duplicate key (first on line {first})")
        for key, first, second in loader.duplicates
    ]
    recursive = _first_recursion(document)
    if recursive is not None:
        problems.append(Problem(file, recursive, "<yaml>", "recursive alias"))
        return None, problems
    if _expanded_size(document, {}) > MAX_EXPANDED_NODES:
        message = f"more than {MAX_EXPANDED_NODES} values once aliases are expanded"
        problems.append(Problem(file, 1, "<yaml>", message))
        return None, problems
    return document, problems


def _expanded_size(value: Any, sizes: dict[int, int]) -> int:
    """How many values the document holds with every alias written out (memoised)."""
    if not isinstance(value, LineDict | LineList):
        return 1
    if id(value) not in sizes:
        children = value.values() if isinstance(value, LineDict) else value
        sizes[id(value)] = 1 + sum(_expanded_size(child, sizes) for child in children)
    return sizes[id(value)]


def _first_recursion(value: Any) -> int | None:
    """The line of a container that contains itself (``&a [*a]``), if any."""
    on_path: set[int] = set()
    done: set[int] = set()

    def visit(item: Any) -> int | None:
        if not isinstance(item, LineDict | LineList) or id(item) in done:
            return None
        if id(item) in on_path:
            return item.line
        on_path.add(id(item))
        children = item.values() if isinstance(item, LineDict) else item
        for child in children:
            found = visit(child)
            if found is not None:
                return found
        on_path.discard(id(item))
        done.add(id(item))
        return None

    try:
        return visit(value)
    except RecursionError:
        return 1


def with_lines(value: Any, line: int = 1) -> Any:
    """A plain document (dicts and lists built in code) as line-carrying containers.

    Every key and item is given ``line``, so that code-built documents go through the
    same checks as files; their problems then name line 1.
    """
    if isinstance(value, LineDict | LineList):
        return value
    if isinstance(value, dict):
        items = {k: with_lines(v, line) for k, v in value.items()}
        return LineDict(items, line=line, lines=dict.fromkeys(items, line))
    if isinstance(value, list | tuple):
        return LineList([with_lines(v, line) for v in value], line=line, lines=[line] * len(value))
    return value
