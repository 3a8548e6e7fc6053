"""The manifest of a folder output: every file a run wrote there, with its size and SHA-256.

A run writes it into the folder it commits; the next run replaces that folder only when every
file in it is listed with the same size and hash (anything else is refused with its name), and
removes only what the manifest lists (docs/outputs.md).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import stat
from pathlib import Path
from typing import Any

from . import nofollow

NAME = ".lodconvert-manifest.json"
LIMIT = 1 << 28
"""Largest manifest read (bytes): about a million files."""
CHUNK = 1 << 20

Files = dict[str, dict[str, Any]]
"""Relative path → ``{"size": bytes, "sha256": hex}``."""


def _digest(fd: int) -> str:
    """SHA-256 of the file open at ``fd``, from its start."""
    digest = hashlib.sha256()
    os.lseek(fd, 0, os.SEEK_SET)
    while chunk := os.read(fd, CHUNK):
        digest.update(chunk)
    return digest.hexdigest()


def _hashed(root: int, relative: str) -> dict[str, Any] | None:
    """Size and hash of the regular file ``relative`` below ``root`` (``None``: none there)."""
    names = nofollow.parts(relative)
    try:
        with nofollow.parent(root, names) as folder:
            fd = os.open(names[-1], nofollow.READ, dir_fd=folder)
    except (OSError, nofollow.Foreign):
        return None
    try:
        found = os.fstat(fd)
        if not stat.S_ISREG(found.st_mode):
            return None
        return {"size": found.st_size, "sha256": _digest(fd)}
    finally:
        os.close(fd)


def files_of(root: int) -> Files:
    """What the manifest of the folder ``root`` lists: each file in it (but the manifest)."""
    listed: Files = {}
    for relative, found in nofollow.walk(root):
        if stat.S_ISREG(found.st_mode) and relative != NAME:
            hashed = _hashed(root, relative)
            if hashed is not None:
                listed[relative] = hashed
    return listed


def text(listed: Files, generator: str) -> bytes:
    """The manifest's bytes (the same for the same files)."""
    document = {"generator": generator, "files": dict(sorted(listed.items()))}
    return (json.dumps(document, indent=0, sort_keys=True) + "\n").encode()


def write(root: int, generator: str) -> None:
    """Write the manifest of the folder ``root`` into it."""
    data = text(files_of(root), generator)
    fd = nofollow.create(root, NAME, replace=True)
    with os.fdopen(fd, "wb") as stream:
        stream.write(data)


def read(root: int) -> Files | None:
    """The files the manifest of the folder ``root`` lists; ``None`` without a readable one."""
    data = nofollow.read(root, NAME, LIMIT + 1)
    if data is None or len(data) > LIMIT:
        return None
    try:
        listed = json.loads(data)["files"]
    except (ValueError, KeyError, TypeError):
        return None
    if not isinstance(listed, dict) or not all(isinstance(v, dict) for v in listed.values()):
        return None
    return listed


def adding(folder: Path, relative: str, data: bytes, generator: str) -> bytes | None:
    """The manifest of ``folder`` with ``relative`` (holding ``data``) added; ``None`` where
    the folder has no manifest."""
    fd = nofollow.open_folder(folder)
    try:
        listed = read(fd)
    finally:
        os.close(fd)
    if listed is None:
        return None
    listed[relative] = {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}
    return text(listed, generator)


def strays(folder: Path, listed: Files) -> list[tuple[str, str]]:
    """Entries of ``folder`` that are not as its manifest ``listed`` says: (relative path,
    what it is), e.g. ``("tiles/a.doc", "not written by lodconvert")``."""
    fd = nofollow.open_folder(folder)
    found: list[tuple[str, str]] = []
    try:
        for relative, entry in nofollow.walk(fd):
            why = nofollow.what(entry)
            if why is None and stat.S_ISREG(entry.st_mode) and relative != NAME:
                if relative not in listed:
                    why = "not written by lodconvert"
                elif _hashed(fd, relative) != listed[relative]:
                    why = "changed since lodconvert wrote it"
            if why is not None:
                found.append((relative, why))
    finally:
        os.close(fd)
    return found


def remove_listed(folder: Path) -> bool:
    """Remove from ``folder`` the files its manifest lists (and the manifest), then its
    folders left empty; anything else stays. Returns whether ``folder`` is gone."""
    try:
        fd = nofollow.open_folder(folder)
    except OSError:
        return not folder.exists()
    try:
        listed = read(fd) or {}
        entries = list(nofollow.walk(fd))
        for relative, entry in entries:
            if (relative in listed or relative == NAME) and stat.S_ISREG(entry.st_mode):
                nofollow.remove(fd, relative)
        for relative, entry in reversed(entries):
            if stat.S_ISDIR(entry.st_mode):
                names = nofollow.parts(relative)
                with contextlib.suppress(OSError), nofollow.parent(fd, names) as parent:
                    os.rmdir(names[-1], dir_fd=parent)
    finally:
        os.close(fd)
    with contextlib.suppress(OSError):
        folder.rmdir()
    return not os.path.lexists(folder)
