"""The map file: written once per content, safely by writers that start together."""

import multiprocessing
import tempfile
from pathlib import Path

from emml.envs.wad import build_wad, wad_path

ROUNDS = 30


def _write(directory: str, rank: int, barrier, out) -> None:
    tempfile.tempdir = directory
    got = set()
    try:
        for _ in range(ROUNDS):  # each round: the file is absent and every writer starts at once
            barrier.wait()
            if rank == 0:
                for f in Path(directory).glob("*.wad"):
                    f.unlink()
            barrier.wait()
            got.add(str(wad_path()))
        out.put(" ".join(sorted(got)))
    except Exception as e:  # reported to the parent, which fails the test with it
        barrier.abort()
        out.put(repr(e))


def test_forked_writers_starting_together_agree(tmp_path):
    ctx = multiprocessing.get_context("fork")  # forked workers share id(blob), which once named the temp file
    n = 8
    barrier, out = ctx.Barrier(n), ctx.Queue()
    procs = [ctx.Process(target=_write, args=(str(tmp_path), i, barrier, out)) for i in range(n)]
    for p in procs:
        p.start()
    got = [out.get(timeout=60) for _ in procs]
    for p in procs:
        p.join(timeout=60)
    assert len(set(got)) == 1 and got[0].endswith(".wad"), got
    assert (tmp_path / got[0].rsplit("/", 1)[1]).read_bytes() == build_wad()
    assert [p.name for p in tmp_path.iterdir()] == [got[0].rsplit("/", 1)[1]]  # no temp file left behind
