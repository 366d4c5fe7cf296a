"""Seeds, blocks and the work map: the unit of reproducibility of every Monte Carlo run.

Trials are cut into blocks of :data:`BLOCK` trials; block ``b`` draws from its own generator, the
``b``-th spawn child of the root seed, so the numbers depend only on the seed and the number of trials,
never on how the blocks are grouped into chunks or on which worker ran them.
"""

from __future__ import annotations

import numpy as np

from multilat.errors import MultilatError

BLOCK = 1 << 16
#: Largest number of output values (trials x outputs) kept in memory for exact quantiles.


def resolve_seed(rng) -> np.random.SeedSequence:
    """The root :class:`numpy.random.SeedSequence` for ``rng`` (int, None, SeedSequence or Generator).

    A Generator is consumed (a 128-bit root entropy is drawn from it), so successive calls with the
    same generator give independent runs, as with any other use of a generator; the drawn entropy is
    reported in ``MCResult.seed_entropy`` and reproduces the run when passed back as ``rng``.
    """
    if isinstance(rng, np.random.SeedSequence):
        return rng
    if isinstance(rng, np.random.Generator):
        return np.random.SeedSequence(int.from_bytes(rng.bytes(16), "little"))
    if rng is None:
        return np.random.SeedSequence()
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        if rng < 0:
            raise MultilatError(f"rng seed must be >= 0, got {rng!r}")
        return np.random.SeedSequence(int(rng))
    raise MultilatError(f"rng must be a numpy Generator, an int seed or None, got {type(rng).__name__}")


def block_generator(entropy, spawn_key: tuple, block: int) -> np.random.Generator:
    """Generator of block ``block``: the ``block``-th spawn child of ``SeedSequence(entropy, spawn_key)``."""
    ss = np.random.SeedSequence(entropy, spawn_key=tuple(spawn_key) + (int(block),))
    return np.random.Generator(np.random.SFC64(ss))


def block_trials(b: int, trials: int, block: int = BLOCK) -> int:
    """Number of trials in block ``b`` of a run of ``trials`` trials cut into blocks of ``block``
    (every block is full except possibly the last)."""
    return min(int(block), int(trials) - int(b) * int(block))


def chunk_ranges(trials: int, chunk_size: int, block: int = BLOCK, first_block: int = 0) -> list[tuple[int, int]]:
    """Chunks (units of work for a ``map``) as ``[block_start, block_stop)`` ranges of whole blocks.

    Trials ``first_block * block .. trials - 1`` are cut into blocks of ``block`` trials (the unit of
    seeding: block ``b`` draws from :func:`block_generator` ``(..., b)``); a chunk is
    ``ceil(chunk_size / block)`` consecutive blocks (the last chunk may have fewer). Chunking only
    distributes work: the blocks, hence the numbers, do not depend on ``chunk_size``.
    """
    n_blocks = -(-int(trials) // int(block))
    per_chunk = max(1, -(-int(chunk_size) // int(block)))
    return [(s, min(s + per_chunk, n_blocks)) for s in range(int(first_block), n_blocks, per_chunk)]


def resolve_map(map):
    """``map(func, iterable)`` for a ``map=`` argument: builtin ``map`` for None, ``obj.map`` for an
    object with a ``.map`` method (e.g. :class:`multilat.parallel.DaskMap`), else the callable itself."""
    if map is None:
        import builtins

        return builtins.map
    if hasattr(map, "map") and callable(map.map):
        return map.map
    if callable(map):
        return map
    raise MultilatError(f"map must be callable or have a .map method, got {type(map).__name__}")
