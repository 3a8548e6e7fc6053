"""Every registered reader, fuzzed: mutated small valid files must be read or refused with
lodconvert's own one-line error; never another exception, a crash, a hang or a memory blow-up
(each case runs in a child process under an address-space limit).

``LODCONVERT_FUZZ_SECONDS`` sets how long to fuzz (default: a few seconds; CI runs minutes).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from lodconvert.io import read_scene

from .harness import fuzz
from .seeds import gzipped, reader_suffixes, seeds_for
from .worker import Worker

FUZZ_SECONDS = float(os.environ.get("LODCONVERT_FUZZ_SECONDS", "3"))


@pytest.fixture(scope="module")
def worker() -> Iterator[Worker]:
    child = Worker()
    yield child
    child.close()


@pytest.mark.parametrize("suffix", reader_suffixes())
def test_seeds_are_read(tmp_path: Path, suffix: str) -> None:
    for i, seed in enumerate(seeds_for(suffix)):
        variants = [(f"s{i}{suffix}", seed)]
        if suffix != ".zip":  # a zip is compressed already: .zip.gz is refused by name
            variants.append((f"s{i}{suffix}.gz", gzipped(seed)))
        for name, data in variants:
            (tmp_path / name).write_bytes(data)
            assert list(read_scene(tmp_path / name).with_geometry()), name


def test_fuzz_every_reader(worker: Worker) -> None:
    counts = fuzz(worker, FUZZ_SECONDS)
    assert set(reader_suffixes()) <= {name.removesuffix(".gz") for name in counts}
    print(" ".join(f"{name}={n}" for name, n in sorted(counts.items())))
