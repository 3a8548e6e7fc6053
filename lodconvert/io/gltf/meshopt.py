"""The bitstreams of ``EXT_meshopt_compression`` (meshoptimizer's codecs, as its reference
encoder writes them): vertex data (version 0, the one the extension defines), index sequences
and triangle lists. Compiled with numba; tested byte for byte against meshoptimizer's own
encoder (docs/compression.md)."""

from __future__ import annotations

import numpy as np

from ...compiled import compiled

VERTEX_HEADER = 0xA0
"""The first byte of vertex data (version 0)."""
SEQUENCE_HEADER = 0xD1
"""The first byte of an index sequence (version 1)."""
TRIANGLES_HEADER = 0xE1
"""The first byte of a triangle list (version 1)."""
BLOCK_BYTES = 8192
"""Bytes of vertex data a block holds at most (part of the format)."""
GROUP = 16
"""Bytes a group of deltas holds."""
TAIL_MIN = 32
"""Bytes the vertex data's tail (its first vertex) is padded to."""


def block_size(stride: int) -> int:
    """Vertices a block holds: at most 256, a multiple of 16 (part of the format)."""
    return min((BLOCK_BYTES // stride) & ~(GROUP - 1), 256)


@compiled
def _group_cost(deltas: np.ndarray, start: int, bits: int) -> int:
    """Bytes a group of 16 deltas takes at ``bits`` a delta (-1: cannot, for 0 bits)."""
    if bits == 0:
        for i in range(GROUP):
            if deltas[start + i] != 0:
                return -1
        return 0
    if bits == 8:
        return GROUP
    sentinel = (1 << bits) - 1
    size = GROUP * bits // 8
    for i in range(GROUP):
        if deltas[start + i] >= sentinel:
            size += 1
    return size


@compiled
def _put_group(out: np.ndarray, at: int, deltas: np.ndarray, start: int, bits: int) -> int:
    """Write a group of 16 deltas at ``bits`` each (the values at or above the sentinel
    follow in full); the offset after it."""
    if bits == 0:
        return at
    if bits == 8:
        out[at : at + GROUP] = deltas[start : start + GROUP]
        return at + GROUP
    per_byte = 8 // bits
    sentinel = (1 << bits) - 1
    for i in range(0, GROUP, per_byte):
        byte = 0
        for k in range(per_byte):
            value = deltas[start + i + k]
            byte = (byte << bits) | (sentinel if value >= sentinel else value)
        out[at] = byte
        at += 1
    for i in range(GROUP):
        value = deltas[start + i]
        if value >= sentinel:
            out[at] = value
            at += 1
    return at


@compiled
def _encode_vertices(
    data: np.ndarray, count: int, stride: int, blocks: int, out: np.ndarray
) -> int:
    """Vertex data (version 0): per block of ``blocks`` vertices, per byte of a vertex, the
    zigzag deltas of that byte from the vertex before, in groups of 16 of 0, 2, 4 or 8 bits."""
    bits = (0, 2, 4, 8)
    out[0] = VERTEX_HEADER
    at = 1
    last = np.zeros(stride, dtype=np.uint8)
    if count > 0:
        last[:] = data[:stride]
    deltas = np.zeros(256, dtype=np.uint8)
    offset = 0
    while offset < count:
        size = min(blocks, count - offset)
        aligned = (size + GROUP - 1) & ~(GROUP - 1)
        for k in range(stride):
            deltas[:] = 0
            previous = int(last[k])
            for i in range(size):
                value = int(data[(offset + i) * stride + k])
                d = (value - previous) & 0xFF
                deltas[i] = ((d << 1) ^ (0xFF if d & 0x80 else 0)) & 0xFF
                previous = value
            header = at
            header_size = (aligned // GROUP + 3) // 4
            out[header : header + header_size] = 0
            at += header_size
            last_bits = -1
            for g in range(0, aligned, GROUP):
                best = 3
                best_size = _group_cost(deltas, g, 8)
                for choice in range(3):
                    cost = _group_cost(deltas, g, bits[choice])
                    if cost < 0:
                        continue
                    if cost < best_size or (
                        cost == best_size and bits[choice] == last_bits and bits[best] != 8
                    ):
                        best, best_size = choice, cost
                n = g // GROUP
                out[header + n // 4] |= best << ((n % 4) * 2)
                at = _put_group(out, at, deltas, g, bits[best])
                last_bits = bits[best]
        last[:] = data[(offset + size - 1) * stride : (offset + size) * stride]
        offset += size
    if stride < TAIL_MIN:
        out[at : at + TAIL_MIN - stride] = 0
        at += TAIL_MIN - stride
    if count > 0:
        out[at : at + stride] = data[:stride]
    else:
        out[at : at + stride] = 0
    return at + stride


def encode_vertices(rows: np.ndarray) -> bytes:
    """``rows`` ((count, stride) bytes, the stride a multiple of 4 up to 256) as meshopt vertex
    data."""
    count, stride = rows.shape
    if stride % 4 or not 0 < stride <= 256:
        raise ValueError(f"a meshopt vertex stride must be a multiple of 4 up to 256, not {stride}")
    blocks = block_size(stride)
    groups = -(-blocks // GROUP)
    bound = 1 + -(-count // blocks) * stride * (groups * (GROUP + 1)) + TAIL_MIN + stride
    out = np.zeros(bound, dtype=np.uint8)
    data = np.ascontiguousarray(rows, dtype=np.uint8).ravel()
    return out[: _encode_vertices(data, count, stride, blocks, out)].tobytes()


@compiled
def _put_varint(out: np.ndarray, at: int, value: int) -> int:
    """``value`` in groups of 7 bits, lowest first, the high bit set on all but the last."""
    while True:
        out[at] = (value & 127) | (128 if value > 127 else 0)
        at += 1
        value >>= 7
        if value == 0:
            return at


@compiled
def _encode_sequence(indices: np.ndarray, out: np.ndarray) -> int:
    """An index sequence: each index as the zigzag delta from one of two baselines (switched
    when a delta reaches 30), with the baseline in its lowest bit, as a varint."""
    out[0] = SEQUENCE_HEADER
    at = 1
    last = np.zeros(2, dtype=np.int64)
    current = 0
    for i in range(len(indices)):
        index = np.int64(indices[i])
        if abs(index - last[current]) >= 30:
            current ^= 1
        d = (index - last[current]) & 0xFFFFFFFF
        zz = ((d << 1) ^ (0xFFFFFFFF if d & 0x80000000 else 0)) & 0xFFFFFFFF
        at = _put_varint(out, at, ((zz << 1) | current) & 0xFFFFFFFF)
        last[current] = index
    out[at : at + 4] = 0
    return at + 4


def encode_sequence(indices: np.ndarray) -> bytes:
    """``indices`` (unsigned) as a meshopt index sequence (mode ``INDICES``)."""
    out = np.zeros(1 + 5 * len(indices) + 4, dtype=np.uint8)
    return out[: _encode_sequence(np.asarray(indices, dtype=np.uint32), out)].tobytes()


CODE_AUX = np.array(
    [0x00, 0x76, 0x87, 0x56, 0x67, 0x78, 0xA9, 0x86, 0x65, 0x89, 0x68, 0x98, 0x01, 0x69, 0, 0],
    dtype=np.uint8,
)
"""The triangle codec's table of the commonest pairs of vertex-FIFO codes (it also ends the
stream)."""
_ROTATIONS = (0, 1, 2, 0, 1)


@compiled
def _zigzag32(d: int) -> int:
    """The zigzag code of a 32-bit difference."""
    d &= 0xFFFFFFFF
    return ((d << 1) ^ (0xFFFFFFFF if d & 0x80000000 else 0)) & 0xFFFFFFFF


@compiled
def _edge_in(fifo: np.ndarray, a: int, b: int, c: int, offset: int) -> int:
    """The newest of the last 16 edges that is an edge of triangle abc, as 4 × its age + the
    edge (0: ab, 1: bc, 2: ca); -1: none."""
    for i in range(16):
        k = (offset - 1 - i) & 15
        e0, e1 = fifo[k, 0], fifo[k, 1]
        if e0 == a and e1 == b:
            return i << 2
        if e0 == b and e1 == c:
            return (i << 2) | 1
        if e0 == c and e1 == a:
            return (i << 2) | 2
    return -1


@compiled
def _vertex_in(fifo: np.ndarray, v: int, offset: int) -> int:
    """The age of ``v`` among the last 16 vertices; -1: not among them."""
    for i in range(16):
        if fifo[(offset - 1 - i) & 15] == v:
            return i
    return -1


@compiled
def _push_edge(edges: np.ndarray, at: int, a: int, b: int) -> int:
    """Put edge ab at ``at`` of the 16-edge FIFO; where the next goes."""
    edges[at, 0], edges[at, 1] = a, b
    return (at + 1) & 15


@compiled
def _push_vertex(vertices: np.ndarray, at: int, v: int) -> int:
    """Put vertex ``v`` at ``at`` of the 16-vertex FIFO; where the next goes."""
    vertices[at] = v
    return (at + 1) & 15


@compiled
def _vertex_code(age: int, v: int, next_: int) -> tuple[int, int]:
    """A new triangle's vertex ``v`` as a code: 1 + its ``age`` among the last 14 vertices,
    0 for the next new vertex, 15 for a free index; and the next new vertex after it."""
    if 0 <= age < 14:
        return age + 1, next_
    if v == next_:
        return 0, next_ + 1
    return 15, next_


@compiled
def _encode_triangles(indices: np.ndarray, code: np.ndarray, data: np.ndarray) -> int:
    """A triangle list (meshoptimizer's index codec, version 1): per triangle one code byte
    (an edge of the last 16 edges and a vertex of the last 16 vertices, or a new triangle's
    vertex codes), free indices as varint deltas in ``data``; the bytes of ``data`` written."""
    edges = np.full((16, 2), -1, dtype=np.int64)
    vertices = np.full(16, -1, dtype=np.int64)
    edge_at = 0
    vertex_at = 0
    next_ = 0
    last = 0
    at = 0
    for t in range(len(indices) // 3):
        i0, i1, i2 = (
            np.int64(indices[3 * t]),
            np.int64(indices[3 * t + 1]),
            np.int64(indices[3 * t + 2]),
        )
        tri = (i0, i1, i2)
        fer = _edge_in(edges, i0, i1, i2, edge_at)
        if fer >= 0 and (fer >> 2) < 15:
            r = fer & 3
            a, b, c = tri[_ROTATIONS[r]], tri[_ROTATIONS[r + 1]], tri[_ROTATIONS[r + 2]]
            fe = fer >> 2
            fc = _vertex_in(vertices, c, vertex_at)
            if 1 <= fc < 13:
                fec = fc
            elif c == next_:
                fec = 0
                next_ += 1
            else:
                fec = 15
            if fec == 15:
                if c + 1 == last:
                    fec = 13
                    last = c
                if c == last + 1:
                    fec = 14
                    last = c
            code[t] = (fe << 4) | fec
            if fec == 15:
                at = _put_varint(data, at, _zigzag32(c - last))
                last = c
            if fec == 0 or fec >= 13:
                vertex_at = _push_vertex(vertices, vertex_at, c)
            edge_at = _push_edge(edges, edge_at, c, b)
            edge_at = _push_edge(edges, edge_at, a, c)
        else:
            r = 1 if i1 == next_ else (2 if i2 == next_ else 0)
            a, b, c = tri[_ROTATIONS[r]], tri[_ROTATIONS[r + 1]], tri[_ROTATIONS[r + 2]]
            reset = False
            if a == 0 and b == 1 and c == 2 and next_ > 0:
                reset = True
                next_ = 0
                vertices[:] = -1
            fb = _vertex_in(vertices, b, vertex_at)
            fc = _vertex_in(vertices, c, vertex_at)
            if a == next_:
                fea = 0
                next_ += 1
            else:
                fea = 15
            feb, next_ = _vertex_code(fb, b, next_)
            fec, next_ = _vertex_code(fc, c, next_)
            aux = (feb << 4) | fec
            aux_index = -1
            for k in range(16):
                if CODE_AUX[k] == aux:
                    aux_index = k
                    break
            if fea == 0 and 0 <= aux_index < 14 and not reset:
                code[t] = (15 << 4) | aux_index
            else:
                code[t] = (15 << 4) | 14 | fea
                data[at] = aux
                at += 1
            if fea == 15:
                at = _put_varint(data, at, _zigzag32(a - last))
                last = a
            if feb == 15:
                at = _put_varint(data, at, _zigzag32(b - last))
                last = b
            if fec == 15:
                at = _put_varint(data, at, _zigzag32(c - last))
                last = c
            if fea == 0 or fea == 15:
                vertex_at = _push_vertex(vertices, vertex_at, a)
            if feb == 0 or feb == 15:
                vertex_at = _push_vertex(vertices, vertex_at, b)
            if fec == 0 or fec == 15:
                vertex_at = _push_vertex(vertices, vertex_at, c)
            for e0, e1 in ((b, a), (c, b), (a, c)):
                edge_at = _push_edge(edges, edge_at, e0, e1)
    data[at : at + 16] = CODE_AUX
    return at + 16


def encode_triangles(indices: np.ndarray) -> bytes:
    """A triangle list's ``indices`` (unsigned, a multiple of 3) as meshopt triangle data
    (mode ``TRIANGLES``)."""
    flat = np.asarray(indices, dtype=np.uint32).ravel()
    if len(flat) % 3:
        raise ValueError(f"a triangle list has a multiple of 3 indices, not {len(flat)}")
    code = np.zeros(len(flat) // 3, dtype=np.uint8)
    data = np.zeros(16 * (len(flat) // 3) + 16, dtype=np.uint8)
    used = _encode_triangles(flat, code, data)
    return bytes([TRIANGLES_HEADER]) + code.tobytes() + data[:used].tobytes()


class MeshoptError(ValueError):
    """meshopt data that cannot be decoded."""


@compiled
def _get_varint(data: np.ndarray, at: int, end: int) -> tuple[int, int]:
    """A varint at ``at`` (at most 5 bytes, none past ``end``) and the offset after it;
    offset -1: it runs past ``end``."""
    value = 0
    shift = 0
    for _ in range(5):
        if at >= end:
            return 0, -1
        byte = int(data[at])
        at += 1
        value |= (byte & 127) << shift
        shift += 7
        if byte < 128:
            break
    return value & 0xFFFFFFFF, at


@compiled
def _get_group(data: np.ndarray, at: int, end: int, bits: int, out: np.ndarray) -> int:
    """Read a group of 16 deltas of ``bits`` each into ``out``; the offset after it (-1: the
    data ends first)."""
    if bits == 0:
        out[:] = 0
        return at
    if bits == 8:
        if at + GROUP > end:
            return -1
        out[:] = data[at : at + GROUP]
        return at + GROUP
    per_byte = 8 // bits
    sentinel = (1 << bits) - 1
    extra = at + GROUP * bits // 8
    if extra > end:
        return -1
    for i in range(0, GROUP, per_byte):
        byte = int(data[at + i // per_byte])
        for k in range(per_byte):
            value = (byte >> (8 - bits * (k + 1))) & sentinel
            if value == sentinel:
                if extra >= end:
                    return -1
                value = int(data[extra])
                extra += 1
            out[i + k] = value
    return extra


@compiled
def _decode_vertices(
    data: np.ndarray, count: int, stride: int, blocks: int, out: np.ndarray
) -> int:
    """Vertex data (version 0) into ``out`` (count × stride bytes); 0, or -1 where it is
    malformed or ends early."""
    bits = (0, 2, 4, 8)
    end = len(data) - max(TAIL_MIN, stride)
    if end < 1:
        return -1
    last = data[len(data) - stride :].copy()
    deltas = np.zeros(256, dtype=np.uint8)
    group = np.zeros(GROUP, dtype=np.uint8)
    at = 1
    offset = 0
    while offset < count:
        size = min(blocks, count - offset)
        aligned = (size + GROUP - 1) & ~(GROUP - 1)
        for k in range(stride):
            header_size = (aligned // GROUP + 3) // 4
            header = at
            at += header_size
            if at > end:
                return -1
            for g in range(0, aligned, GROUP):
                n = g // GROUP
                choice = (int(data[header + n // 4]) >> ((n % 4) * 2)) & 3
                at = _get_group(data, at, end, bits[choice], group)
                if at < 0:
                    return -1
                deltas[g : g + GROUP] = group
            previous = int(last[k])
            for i in range(size):
                zz = int(deltas[i])
                previous = (previous + ((zz >> 1) ^ (0xFF if zz & 1 else 0))) & 0xFF
                out[(offset + i) * stride + k] = previous
        last[:] = out[(offset + size - 1) * stride : (offset + size) * stride]
        offset += size
    return 0 if at == end else -1


def decode_vertices(data: bytes | memoryview, count: int, stride: int) -> np.ndarray:
    """meshopt vertex data as (count, stride) bytes (:class:`MeshoptError` if malformed)."""
    source = np.frombuffer(data, dtype=np.uint8)
    if stride % 4 or not 0 < stride <= 256:
        raise MeshoptError(f"a meshopt vertex stride of {stride}")
    if not len(source) or source[0] != VERTEX_HEADER:
        raise MeshoptError("not meshopt vertex data of version 0")
    out = np.zeros(count * stride, dtype=np.uint8)
    if _decode_vertices(source, count, stride, block_size(stride), out) < 0:
        raise MeshoptError(f"meshopt vertex data of {count} × {stride} bytes is malformed")
    return out.reshape(count, stride)


@compiled
def _decode_sequence(data: np.ndarray, out: np.ndarray) -> int:
    """An index sequence into ``out``; 0, or -1 where it is malformed or ends early."""
    end = len(data) - 4
    last = np.zeros(2, dtype=np.int64)
    at = 1
    for i in range(len(out)):
        value, at = _get_varint(data, at, end)
        if at < 0:
            return -1
        baseline = value & 1
        value >>= 1
        d = (value >> 1) ^ (0xFFFFFFFF if value & 1 else 0)
        index = (last[baseline] + d) & 0xFFFFFFFF
        out[i] = index
        last[baseline] = index
    return 0 if at == end else -1


@compiled
def _free_index(data: np.ndarray, at: int, end: int, last: int) -> tuple[int, int]:
    """A free index (a varint delta from ``last``) and the offset after it (-1: it runs past
    ``end``, or ``at`` was already -1)."""
    if at < 0:
        return 0, -1
    value, at = _get_varint(data, at, end)
    return (last + ((value >> 1) ^ (0xFFFFFFFF if value & 1 else 0))) & 0xFFFFFFFF, at


@compiled
def _decode_triangles(data: np.ndarray, out: np.ndarray) -> int:
    """A triangle list into ``out``; 0, or -1 where it is malformed or ends early."""
    triangles = len(out) // 3
    end = len(data) - 16
    if end < 1 + triangles:
        return -1
    edges = np.full((16, 2), 0xFFFFFFFF, dtype=np.int64)
    vertices = np.full(16, 0xFFFFFFFF, dtype=np.int64)
    edge_at = 0
    vertex_at = 0
    next_ = 0
    last = 0
    at = 1 + triangles
    for t in range(triangles):
        code = int(data[1 + t])
        if code < 0xF0:
            fe = code >> 4
            a = edges[(edge_at - 1 - fe) & 15, 0]
            b = edges[(edge_at - 1 - fe) & 15, 1]
            fec = code & 15
            if fec < 13:
                c = next_ if fec == 0 else vertices[(vertex_at - 1 - fec) & 15]
                vertices[vertex_at] = c
                if fec == 0:
                    next_ += 1
                    vertex_at = (vertex_at + 1) & 15
            else:
                if fec == 15:
                    c, at = _free_index(data, at, end, last)
                    if at < 0:
                        return -1
                else:
                    c = (last + fec * 2 - 27) & 0xFFFFFFFF
                last = c
                vertex_at = _push_vertex(vertices, vertex_at, c)
            edge_at = _push_edge(edges, edge_at, c, b)
            edge_at = _push_edge(edges, edge_at, a, c)
        else:
            if code < 0xFE:
                aux = int(data[end + (code & 15)])
                fea = 0
            else:
                if at >= end:
                    return -1
                aux = int(data[at])
                at += 1
                fea = 0 if code == 0xFE else 15
                if aux == 0:
                    next_ = 0
            feb, fec = aux >> 4, aux & 15
            a = 0
            if fea == 0:
                a = next_
                next_ += 1
            if feb == 0:
                b = next_
                next_ += 1
            else:
                b = vertices[(vertex_at - feb) & 15]
            if fec == 0:
                c = next_
                next_ += 1
            else:
                c = vertices[(vertex_at - fec) & 15]
            if fea == 15:
                a, at = _free_index(data, at, end, last)
                last = a
            if feb == 15:
                b, at = _free_index(data, at, end, last)
                last = b
            if fec == 15:
                c, at = _free_index(data, at, end, last)
                last = c
            if at < 0:
                return -1
            vertex_at = _push_vertex(vertices, vertex_at, a)
            vertices[vertex_at] = b
            if feb == 0 or feb == 15:
                vertex_at = (vertex_at + 1) & 15
            vertices[vertex_at] = c
            if fec == 0 or fec == 15:
                vertex_at = (vertex_at + 1) & 15
            for e0, e1 in ((b, a), (c, b), (a, c)):
                edge_at = _push_edge(edges, edge_at, e0, e1)
        out[3 * t], out[3 * t + 1], out[3 * t + 2] = a, b, c
    return 0 if at == end else -1


def decode_indices(data: bytes | memoryview, count: int, mode: str) -> np.ndarray:
    """meshopt index data (``mode`` ``TRIANGLES`` or ``INDICES``) as ``count`` uint32
    indices (:class:`MeshoptError` if malformed)."""
    source = np.frombuffer(data, dtype=np.uint8)
    out = np.zeros(count, dtype=np.uint32)
    if mode == "TRIANGLES":
        ok = count % 3 == 0 and len(source) and source[0] == TRIANGLES_HEADER
        ok = ok and _decode_triangles(source, out) == 0
    elif mode == "INDICES":
        ok = len(source) > 4 and source[0] == SEQUENCE_HEADER and _decode_sequence(source, out) == 0
    else:
        raise MeshoptError(f"no meshopt index mode {mode!r}")
    if not ok:
        raise MeshoptError(f"meshopt {mode.lower()} data of {count} indices is malformed")
    return out


MANTISSA_BITS = 24
"""Bits of an exponential filter's mantissa at most (float32's precision)."""


def exponential(values: np.ndarray, tolerance: float | None = None) -> np.ndarray:
    """float ``values`` (n, k) under meshopt's exponential filter with one exponent a column
    (``SharedComponent``), as uint32 words (mantissa in the low 24 bits, exponent in the top
    8): mantissas of 24 bits for the column's largest magnitude, or, with a ``tolerance``,
    of the fewest bits that keep every value within it (24 at most: float32's own step)."""
    values = np.asarray(values, dtype=np.float32)
    largest = np.full(values.shape[1], -100, dtype=np.int64)  # frexp exponents
    if len(values):
        biased = (values.view(np.uint32) >> 23) & 0xFF
        found = biased.astype(np.int64).max(axis=0) - 127 + 1
        largest = np.maximum(largest, np.where(biased.max(axis=0) > 0, found, -100))
    bits = np.full(values.shape[1], MANTISSA_BITS, dtype=np.int64)
    if tolerance is not None:  # a value moves by at most 2^(largest - bits)
        fewest = np.ceil(largest - np.log2(tolerance)).astype(np.int64)
        bits = np.clip(fewest, 1, MANTISSA_BITS)
    exponents = largest - (bits - 1)
    scaled = values.astype(np.float64) * np.exp2(-exponents.astype(np.float64))
    mantissas = np.trunc(scaled + np.where(values >= 0, 0.5, -0.5)).astype(np.int64)
    mantissas = np.minimum(mantissas, (1 << (MANTISSA_BITS - 1)) - 1)
    words = (mantissas & 0xFFFFFF) | ((exponents & 0xFF) << 24)
    return words.astype(np.uint32)


def from_exponential(words: np.ndarray) -> np.ndarray:
    """The float32 values of exponential filter ``words`` (uint32)."""
    words = np.asarray(words, dtype=np.uint32)
    mantissas = (words.astype(np.int64) << 40) >> 40
    exponents = words.view(np.int32).astype(np.int64) >> 24
    return (mantissas * np.exp2(exponents.astype(np.float64))).astype(np.float32)


def _snorm(values: np.ndarray, bits: int) -> np.ndarray:
    """float32 ``values`` clamped to [-1, 1] as signed integers of ``bits`` (rounded half
    away from zero), as meshoptimizer quantizes them."""
    scale = np.float32((1 << (bits - 1)) - 1)
    clamped = np.clip(values.astype(np.float32), np.float32(-1), np.float32(1))
    half = np.where(clamped >= 0, np.float32(0.5), np.float32(-0.5))
    return np.trunc(clamped * scale + half).astype(np.int64)


def octahedral(normals: np.ndarray) -> np.ndarray:
    """Unit ``normals`` (n, 3) under meshopt's octahedral filter with 8 bits: (n, 4) signed
    bytes (u, v, 127, 0)."""
    n = np.asarray(normals, dtype=np.float32)
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    length = np.abs(x) + np.abs(y) + np.abs(z)
    inverse = np.where(length == 0, np.float32(0), np.float32(1) / np.where(length == 0, 1, length))
    x, y = x * inverse, y * inverse
    sign_x = np.where(x >= 0, np.float32(1), np.float32(-1))
    sign_y = np.where(y >= 0, np.float32(1), np.float32(-1))
    u = np.where(z >= 0, x, (np.float32(1) - np.abs(y)) * sign_x)
    v = np.where(z >= 0, y, (np.float32(1) - np.abs(x)) * sign_y)
    out = np.zeros((len(n), 4), dtype=np.int8)
    out[:, 0], out[:, 1] = _snorm(u, 8), _snorm(v, 8)
    out[:, 2] = 127
    return out


def from_octahedral(data: np.ndarray) -> np.ndarray:
    """The (n, 4) signed bytes or shorts of octahedral filter ``data`` decoded as meshopt's
    decoder does: x, y, z normalized to the type's largest value (the fourth kept)."""
    data = np.asarray(data)
    largest = np.float32(np.iinfo(data.dtype).max)
    x, y = data[:, 0].astype(np.float32), data[:, 1].astype(np.float32)
    z = data[:, 2].astype(np.float32) - np.abs(x) - np.abs(y)
    t = np.minimum(z, np.float32(0))
    x = x + np.where(x >= 0, t, -t)
    y = y + np.where(y >= 0, t, -t)
    length = np.sqrt(x * x + y * y + z * z)
    s = largest / np.where(length == 0, np.float32(1), length)
    out = data.copy()
    for k, value in enumerate((x, y, z)):
        half = np.where(value >= 0, np.float32(0.5), np.float32(-0.5))
        out[:, k] = np.trunc(value * s + half).astype(data.dtype)
    return out
