"""A glTF JSON text read window by window, for checking files of any size in bounded memory.

:class:`Source` reads bytes of the file (by ``os.pread``, so what was read is not kept mapped
in this process) or of a buffer. On it: :func:`utf8_error` finds the first byte that is not
UTF-8, :func:`too_deep` whether arrays and objects nest deeper than a limit (as a regular
expression scanning the whole text would say, strings skipped), and :func:`read_object` reads
the top-level JSON object member by member, each array member element by element
(:class:`LazyArray`: each element handed to a sink as it is read, then only its offset kept,
so that it can be read again on demand), and raises :class:`TooDeep` where it nests deeper
than a limit (as :func:`too_deep` would say of the text). Where the text is not exactly what
``json.loads`` accepts, :func:`read_object` raises :class:`NotStreamed` and the caller reads it
whole, for the message ``json.loads`` gives.
"""

from __future__ import annotations

import json
import os
import re
from array import array
from collections.abc import Callable, Iterator
from json.decoder import WHITESPACE, scanstring
from typing import Any

import numpy as np

WINDOW = 1 << 20
"""Bytes of text decoded at a time (a window grows only for a value longer than this)."""
_BATCH = 1 << 18
"""Bytes of an array's text looked at for the commas between its elements at a time."""
DEPTH_WINDOW = 1 << 18
"""Bytes counted at a time by :func:`too_deep` (its numpy arrays take some 30 times that)."""

_LOOKAHEAD = 3
"""Characters a value must leave in its window: a number cut by the window's end reads as a
shorter number followed by at most two characters that continue it (``1.5e+`` of ``1.5e+3``)."""
_QUOTE, _BACKSLASH, _NEWLINE = ord('"'), ord("\\"), ord("\n")
_COMMA, _CLOSE = ord(","), ord("]")
_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"')
_BRACKETS = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"|([\[{])|[\]}]')
"""A JSON string (skipped whole), an opening bracket (group 1) or a closing one, in bytes: as
the same expression over the decoded text (a backslash never escapes a byte of a multi-byte
character that ``.`` would not match)."""
_STEP = np.zeros(256, np.int32)
_STEP[[ord("["), ord("{")]] = 1
_STEP[[ord("]"), ord("}")]] = -1
_MARK = _STEP != 0
_MARK[_COMMA] = True
"""Brackets, braces and commas: the bytes :meth:`_Text._batch` looks at."""


class NotStreamed(Exception):
    """The text is not a JSON object that reads as ``json.loads`` reads it: read it whole."""


class TooDeep(Exception):
    """Arrays and objects nest deeper than the limit :func:`read_object` was given."""


class Source:
    """Bytes ``[0, length)`` at ``start`` of ``data`` (a file's mapped bytes), read with
    ``os.pread`` from ``fd`` when given (the pages read stay out of this process), else
    sliced from ``data``."""

    def __init__(self, data: memoryview | bytes, start: int, length: int, fd: int | None) -> None:
        self.data, self.start, self.length, self.fd = data, start, length, fd

    def __len__(self) -> int:
        return self.length

    def read(self, a: int, b: int) -> bytes | memoryview:
        """Bytes ``[a, b)`` (clipped to the source)."""
        a, b = max(0, a), min(self.length, b)
        if b <= a:
            return b""
        if self.fd is None:
            return memoryview(self.data)[self.start + a : self.start + b]
        parts = []
        while a < b:
            part = os.pread(self.fd, b - a, self.start + a)
            if not part:
                raise OSError(f"the file ended {b - a} bytes early")
            parts.append(part)
            a += len(part)
        return parts[0] if len(parts) == 1 else b"".join(parts)

    def view(self) -> memoryview:
        """The bytes as a view of ``data`` (for a regular expression that may read far)."""
        return memoryview(self.data)[self.start : self.start + self.length]


def utf8_error(source: Source, window: int = WINDOW) -> tuple[int, int] | None:
    """Offset and value of the first byte of ``source`` that is not UTF-8 (as decoding it all
    would report), or ``None``."""
    pos = 0
    while pos < len(source):
        end = min(len(source), pos + window)
        block = bytes(source.read(pos, end))
        try:
            block.decode("utf-8")
        except UnicodeDecodeError as exc:
            cut = end < len(source) and exc.end == len(block) and exc.start > 0
            if not (cut and exc.reason == "unexpected end of data"):
                return pos + exc.start, block[exc.start]
            end = pos + exc.start  # a character cut by the window: read it with the next
        pos = end
    return None


def too_deep(source: Source, limit: int, window: int = DEPTH_WINDOW) -> bool:
    """Whether arrays and objects nest deeper than ``limit`` in ``source``, counted as
    :data:`_BRACKETS` scanning the whole text counts them (strings skipped, also in text that
    is not JSON). Windows whose strings hold no backslash outside a string and no escaped line
    break are counted with numpy; others with the expression."""
    view = source.view()
    pos, depth = 0, 0
    while pos < len(source):
        end = min(len(source), pos + window)
        w = np.frombuffer(source.read(pos, end), np.uint8)
        quote = w == _QUOTE
        escaped = _escaped(w)  # after an odd run of backslashes
        quote[escaped] = False
        inside = np.cumsum(quote, dtype=np.uint8) & 1 == 1
        backslash = np.flatnonzero(w == _BACKSLASH)
        if len(backslash) and (not inside[backslash].all() or (w[escaped] == _NEWLINE).any()):
            found, pos, depth = _scan_slowly(view, pos, end, depth, limit)
            if found:
                return True
            continue
        cut, after = len(w), end
        if inside[-1]:  # a string that goes on past the window (or never ends)
            cut = int(np.flatnonzero(quote)[-1])
            string = _STRING.match(view, pos + cut)
            after = string.end() if string else pos + cut + 1
        steps = _STEP[w[:cut]]
        steps[inside[:cut]] = 0
        levels = np.cumsum(steps, dtype=np.int32)
        if len(levels) and int(levels.max()) + depth > limit:
            return True
        depth += int(levels[-1]) if len(levels) else 0
        pos = after
    return False


def _scan_slowly(
    view: memoryview, pos: int, end: int, depth: int, limit: int
) -> tuple[bool, int, int]:
    """:func:`too_deep` from ``pos`` by the expression itself, up to ``end`` or the end of the
    match that covers it: (deeper than ``limit``, where to go on, depth there)."""
    for match in _BRACKETS.finditer(view, pos):
        if match.start() >= end:
            return False, end, depth
        if match.lastindex:
            depth += 1
            if depth > limit:
                return True, match.end(), depth
        elif view[match.start()] != _QUOTE:
            depth -= 1
        if match.end() >= end:
            return False, match.end(), depth
    return False, len(view), depth


def reject_constant(name: str) -> None:
    """``json`` hook: ``NaN`` and ``Infinity`` are Python's, not JSON."""
    raise ValueError(f"{name} is not a JSON value")


class LazyArray:
    """A top-level JSON array read element by element: its length, whether every element is
    an object, what its sink made of the elements (``facts``) and each element's offset, so
    that an element can be read again (``array[i]``, iteration) without holding them all."""

    def __init__(self, text: _Text, facts: Any) -> None:
        self._source = text.source
        self._decoder = text.decoder
        self.starts = array("q")
        self.end = 0
        self.all_objects = True
        self.facts = facts
        self._cache: dict[int, Any] = {}

    def __len__(self) -> int:
        return len(self.starts)

    def __bool__(self) -> bool:
        return bool(self.starts)

    def __getitem__(self, index: int) -> Any:
        if not 0 <= index < len(self.starts):
            raise IndexError(f"list index {index} out of range")
        if index not in self._cache:
            if len(self._cache) > 4096:
                self._cache.clear()
            end = self.starts[index + 1] if index + 1 < len(self.starts) else self.end
            text = bytes(self._source.read(self.starts[index], end)).decode("utf-8")
            self._cache[index] = self._decoder.scan_once(text, WHITESPACE.match(text).end())[0]
        return self._cache[index]

    def __iter__(self) -> Iterator[Any]:
        for index in range(len(self.starts)):
            yield self[index]

    @property
    def nbytes(self) -> int:
        """Bytes of the array's text."""
        return self.end - self.starts[0] if self.starts else 0

    def whole(self) -> list[Any]:
        """The array read into memory at once."""
        if not self.starts:
            return []
        text = bytes(self._source.read(self.starts[0], self.end)).decode("utf-8")
        return self._decoder.decode(f"[{text}]")


Sink = Callable[[int, list[Any]], None]
"""Called with elements as an array is read: the index of the first, and their values."""


class _Text:
    """The JSON text of a :class:`Source`, decoded one window at a time. Positions are
    indices into the current window ``s``; a read that fails or reaches the window's end
    before the text's end loads a window starting at the value it was reading (twice as
    long when that is where the window started) and reads again."""

    def __init__(self, source: Source, window: int, limit: int) -> None:
        self.source = source
        self.window = max(window, 8)  # a window holds at least one character
        self.limit = limit
        self.decoder = json.JSONDecoder(parse_constant=reject_constant)
        self.scan = self.decoder.scan_once
        self._load(0, window)

    def _load(self, start: int, size: int) -> None:
        end = min(len(self.source), start + size)
        raw = bytes(self.source.read(start, end))
        try:
            s = raw.decode("utf-8")
        except UnicodeDecodeError as exc:  # a character cut by the window's end
            if exc.reason != "unexpected end of data" or exc.end < len(raw):
                raise NotStreamed from None  # not UTF-8
            raw = raw[: exc.start]
            s = raw.decode("utf-8")
        self.s, self.raw, self.base, self.end = s, raw, start, start + len(raw)
        self.complete = self.end == len(self.source)
        self.ascii = len(s) == len(raw)
        self.batches = self.ascii
        self._mark = (0, start)

    def byte(self, i: int) -> int:
        """Offset in the source of character ``i`` of the window."""
        if self.ascii:
            return self.base + i
        at, offset = self._mark
        if i < at:
            at, offset = 0, self.base
        offset += len(self.s[at:i].encode("utf-8"))
        self._mark = (i, offset)
        return offset

    def _reload(self, i: int) -> int:
        """Load the window from character ``i`` (or a longer one when it starts there)."""
        if self.complete:
            raise NotStreamed
        start = self.byte(i)
        size = self.window if start > self.base else max(self.window, 2 * (self.end - self.base))
        self._load(start, size)
        return 0

    def ws(self, i: int) -> int:
        """The position of the next character that is not JSON whitespace."""
        while True:
            end = WHITESPACE.match(self.s, i).end()
            if end < len(self.s) or self.complete:
                return end
            i = self._reload(i)

    def char(self, i: int) -> str:
        return self.s[i : i + 1]

    def value(self, i: int, depth: int) -> tuple[Any, int, int]:
        """The JSON value at ``i``, ``depth`` arrays and objects in: (value, its start, its
        end) in the window then loaded."""
        while True:
            try:
                value, end = self.scan(self.s, i)
            except (StopIteration, json.JSONDecodeError):
                i = self._reload(i)
                continue
            except (ValueError, RecursionError):  # NaN, Infinity; too long an integer
                raise NotStreamed from None
            if end + _LOOKAHEAD <= len(self.s) or self.complete:
                if _deeper_than(value, self.limit - depth):
                    raise TooDeep
                return value, i, end
            i = self._reload(i)

    def key(self, i: int) -> tuple[str, int]:
        """The object key (a JSON string) at ``i`` and the position after it."""
        while True:
            if self.char(i) != '"':
                raise NotStreamed
            try:
                key, end = scanstring(self.s, i + 1)
            except json.JSONDecodeError:
                i = self._reload(i)
                continue
            return key, end

    def elements(self, i: int, lazy: LazyArray, sink: Sink | None) -> int:
        """Read the array at ``i`` into ``lazy`` (each element to ``sink``); the position
        after it."""
        i = self.ws(i + 1)
        if self.char(i) == "]":
            return i + 1
        index = 0
        while True:
            batch = self._batch(i) if self.batches else None
            if batch is not None:
                values, starts, stop = batch
                lazy.starts.extend([self.base + start for start in starts])
                if lazy.all_objects and set(map(type, values)) != {dict}:
                    lazy.all_objects = False
                if sink is not None:
                    sink(index, values)
                index += len(values)
                lazy.end = self.base + stop
                if self.s[stop] == "]":
                    return stop + 1
                i = self.ws(stop + 1)
                continue
            value, i, end = self.value(i, 2)
            lazy.starts.append(self.byte(i))
            if not isinstance(value, dict):
                lazy.all_objects = False
            if sink is not None:
                sink(index, [value])
            index += 1
            i = self.ws(end)
            lazy.end = self.byte(i)
            mark = self.char(i)
            if mark == "]":
                return i + 1
            if mark != ",":
                raise NotStreamed
            i = self.ws(i + 1)

    def _batch(self, i: int) -> tuple[list[Any], list[int], int] | None:
        """The array elements from ``i`` to the window's last comma between elements (or to
        the array's end), read at once: (values, their starts, where the comma or closing
        bracket after them is); ``None`` where there is no such comma or the text between
        does not read as JSON values (then elements are read one at a time until the next
        window). Commas between elements are found with numpy, among the brackets, braces
        and commas outside strings; reading the text between decides: what reads as values
        followed by a comma is what reading one at a time would have read. Raises
        :class:`TooDeep` where the elements nest deeper than the limit (before reading them)."""
        w = np.frombuffer(self.raw, np.uint8)[i : i + _BATCH]
        marks = np.flatnonzero(_MARK[w])
        marks = marks[_outside_strings(w, marks)]
        depth = np.cumsum(_STEP[w[marks]], dtype=np.int32)
        closing = np.flatnonzero(depth < 0)
        ahead = int(closing[0]) if len(closing) else len(marks)  # marks of these elements
        if ahead and 2 + int(depth[:ahead].max()) > self.limit:
            raise TooDeep
        commas = marks[:ahead][(w[marks[:ahead]] == _COMMA) & (depth[:ahead] == 0)]
        if len(closing) and w[marks[ahead]] == _CLOSE:
            stop = int(marks[ahead])
        elif len(commas) and not len(closing):
            stop, commas = int(commas[-1]), commas[:-1]
        else:
            self.batches = False
            return None
        try:
            values = self.decoder.decode("[" + self.s[i : i + stop] + "]")
        except ValueError:
            values = None
        if not isinstance(values, list) or len(values) != len(commas) + 1:
            self.batches = False
            return None
        return values, [i, *(i + commas + 1).tolist()], i + stop


def _outside_strings(w: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Which of the positions ``at`` (sorted, none a quote) of JSON text ``w`` (starting
    outside a string) lie outside strings: after an even number of quotes (a quote after an
    odd run of backslashes does not count)."""
    quote = w == _QUOTE
    quote[_escaped(w)] = False
    return np.searchsorted(np.flatnonzero(quote), at) % 2 == 0


def _deeper_than(value: Any, levels: int) -> bool:
    """Whether arrays and objects nest more than ``levels`` deep in the decoded JSON
    ``value`` (looked into no further than that)."""
    if type(value) is list:
        children: Any = value
    elif type(value) is dict:
        children = value.values()
    else:
        return False
    return levels <= 0 or any(_deeper_than(child, levels - 1) for child in children)


def _escaped(w: np.ndarray) -> np.ndarray:
    """Positions in ``w`` that follow an odd run of backslashes."""
    at = np.flatnonzero(w == _BACKSLASH)
    if not len(at):
        return at
    first = np.ones(len(at), bool)
    first[1:] = np.diff(at) != 1
    runs = np.flatnonzero(first)
    lengths = np.diff(np.append(runs, len(at)))
    after = at[runs + lengths - 1] + 1
    after = after[lengths % 2 == 1]
    return after[after < len(w)]


def read_object(
    source: Source,
    sinks: dict[str, Callable[[], tuple[Any, Sink | None]]],
    window: int = WINDOW,
    limit: int = 1 << 30,
) -> dict[str, Any]:
    """The JSON object in ``source``, each array member a :class:`LazyArray`: for a key in
    ``sinks``, ``sinks[key]()`` gives its ``facts`` and the sink its elements go to. Raises
    :class:`NotStreamed` where the text is not one JSON object (``json.loads`` says why), and
    :class:`TooDeep` where arrays and objects nest deeper than ``limit`` in it."""
    text = _Text(source, window, limit)
    i = text.ws(0)
    if text.char(i) != "{":
        raise NotStreamed
    if limit < 1:
        raise TooDeep
    doc: dict[str, Any] = {}
    i = text.ws(i + 1)
    if text.char(i) == "}":
        i += 1
    else:
        while True:
            key, i = text.key(i)
            i = text.ws(i)
            if text.char(i) != ":":
                raise NotStreamed
            i = text.ws(i + 1)
            if text.char(i) == "[" and key not in _WHOLE:
                if limit < 2:
                    raise TooDeep
                facts, sink = sinks[key]() if key in sinks else (None, None)
                lazy = LazyArray(text, facts)
                i = text.elements(i, lazy, sink)
                doc[key] = lazy
            else:
                doc[key], _, i = text.value(i, 1)
            i = text.ws(i)
            mark = text.char(i)
            if mark == "}":
                i += 1
                break
            if mark != ",":
                raise NotStreamed
            i = text.ws(i + 1)
    if text.ws(i) != len(text.s):
        raise NotStreamed
    return doc


_WHOLE = frozenset({"asset", "buffers", "extensionsUsed", "extensionsRequired", "scene", "scenes"})
"""Members read whole even when they are arrays: small, and read as values by the checks."""
