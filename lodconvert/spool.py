"""Nodes parked on disk while a city is read through once.

A city object's switching distances depend on its neighbours (its plot radius,
:mod:`.city.plots`), so every object must have been read before the first is baked. Holding them
all would make memory grow with the city; a :class:`NodeSpool` instead keeps each node (without
its children, which are spooled in their own turn where they have geometry; its id and the
attributes of it and its parts go with it as outputs keep them, :meth:`~.model.Node.written`,
so no input nests them too deep to pickle) in memory while their geometry takes less than
:data:`SPOOL_MEMORY`, and writes the rest to an anonymous temporary file as they are read,
keeping only their position there; it gives the nodes back in the same order (or any node by its
index, for grouping them into cells: :mod:`.city.hlod`). Nodes placed by a transform stay in
memory: they share their geometry with other nodes, which a file would not. Nodes that workers
read come parked and pickled already (:class:`~.model.PackedNode`) and are kept as they came.
"""

from __future__ import annotations

import pickle
import tempfile
from collections.abc import Iterator
from typing import IO

from .model import Node, PackedNode
from .sinks import writing_temporary

SPOOL_MEMORY = 64 << 20
"""Bytes of geometry arrays a spool holds in memory before it parks nodes on disk: a district's
nodes stay (pickling and unpickling them would cost the main process a third of what reading
them took), a large city's beyond it go to disk."""


class NodeSpool:
    """Nodes written to a temporary file in the order they are added and read back in it;
    the file is gone when the spool is closed (or its ``with`` block left, or the process
    ends)."""

    def __init__(self, memory: int | None = None) -> None:
        # the spool owns the file: closed by close() or leaving its ``with`` block
        self._file: IO[bytes] = tempfile.TemporaryFile(prefix="lodconvert-spool-")  # noqa: SIM115
        self._entries: list[Node | PackedNode | int] = []
        self._room = SPOOL_MEMORY if memory is None else memory
        """Bytes of geometry it may still hold in memory (default :data:`SPOOL_MEMORY`)."""

    def add(self, node: Node | PackedNode) -> None:
        """Park ``node`` (kept in memory when it is placed by a transform, or while there is
        room; a packed node as it came); a full temporary folder is one line naming it
        (:func:`~.sinks.writing`)."""
        if node.transform is not None:
            self._entries.append(node)
            return
        parked = node.parked()
        weight = parked.geometry_bytes()
        if weight <= self._room:
            self._room -= weight
            self._entries.append(parked)
            return
        self._entries.append(self._file.tell())
        with writing_temporary():
            pickle.dump(parked, self._file, protocol=pickle.HIGHEST_PROTOCOL)

    def get(self, index: int) -> Node | PackedNode:
        """Node ``index`` (in the order added), read back from the file."""
        entry = self._entries[index]
        if not isinstance(entry, int):
            return entry
        with writing_temporary():  # the seek writes what is still buffered
            self._file.seek(entry)
        return pickle.load(self._file)

    def __len__(self) -> int:
        return len(self._entries)

    def __iter__(self) -> Iterator[Node | PackedNode]:
        """The nodes in the order they were added, each read back as it is taken."""
        for index in range(len(self._entries)):
            yield self.get(index)

    def close(self) -> None:
        """Delete the file."""
        self._file.close()

    def __enter__(self) -> NodeSpool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
