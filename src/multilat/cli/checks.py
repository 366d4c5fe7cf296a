"""One validation layer for the CLI's options, run before any work starts.

Every command checks its numbers here, so that the same kind of option gets the same range and the
same one-line message everywhere: seeds, counts (trials, grid sizes, chunk sizes, workers),
physical values in their unit (σ in µm, offsets in µm) and the memory a request would need.
The limits are deliberate and stated in ``docs/reliability.md``.
"""

from __future__ import annotations

import math

from multilat.errors import MultilatError
from multilat.inputs import MEMORY_SHARE, physical_memory_bytes  # noqa: F401 (re-exported)

#: The largest seed accepted (numpy's SeedSequence takes any integer >= 0; 2**128 is plenty).
MAX_SEED = 2**128 - 1
#: The most Monte Carlo trials any command accepts: beyond it the run takes days.
MAX_TRIALS = 10**10
#: σ of a distance, µm: below a picometre or above a metre the weights overflow or the
#: linearisation of the model no longer holds.
SIGMA_UM_RANGE = (1e-6, 1e6)
#: A held station offset, µm (10 m: far beyond any head's additive constant).
OFFSET_UM_MAX = 1e7


def seed(value: int | None, option: str = "--seed") -> int | None:
    """A seed is an integer in [0, 2**128)."""
    if value is None:
        return None
    if not 0 <= value <= MAX_SEED:
        raise MultilatError(f"{option} must be an integer >= 0, got {value}")
    return value


def count(value: int | None, option: str, *, lo: int = 1, hi: int = MAX_TRIALS) -> int | None:
    """An integer option in ``[lo, hi]`` (None passes: the default applies)."""
    if value is None:
        return None
    if value < lo:
        raise MultilatError(f"{option} must be >= {lo}, got {value}")
    if value > hi:
        raise MultilatError(f"{option} must be at most {hi:,}, got {value:,}")
    return value


def trials(value: int | None, option: str = "--trials", *, lo: int = 1) -> int | None:
    """A number of Monte Carlo trials in ``[lo, MAX_TRIALS]``."""
    return count(value, option, lo=lo, hi=MAX_TRIALS)


def quantity(value: float | None, option: str, *, lo: float, hi: float, unit: str = "") -> float | None:
    """A finite value in ``[lo, hi]`` (None passes)."""
    if value is None:
        return None
    u = f" {unit}" if unit else ""
    if not math.isfinite(value):
        raise MultilatError(f"{option} must be finite, got {value!r}")
    if value < lo:
        low = "> 0" if lo > 0 and lo < 1e-3 else f">= {lo:g}{u}"
        raise MultilatError(f"{option} must be {low}, got {value:g}")
    if value > hi:
        raise MultilatError(f"{option} must be at most {hi:g}{u}, got {value:g}")
    return value


def table_format(fmt: str, out) -> str:
    """``--tables``: auto (the default), csv or parquet, csv and parquet only with ``--out``; parquet
    only where pyarrow is installed."""
    from multilat.io import TABLE_FORMATS

    if fmt not in ("auto", *TABLE_FORMATS):
        raise MultilatError(f"--tables must be one of auto, {', '.join(TABLE_FORMATS)}, got {fmt!r}")
    if fmt not in ("auto", "csv") and out is None:
        raise MultilatError("--tables applies to the files of --out: give --out DIR")
    if fmt == "parquet":
        from importlib.util import find_spec

        if find_spec("pyarrow") is None:           # found, not imported: ~150 MB until the tables are written
            raise MultilatError("--tables parquet needs pyarrow: pip install 'multilat[parquet]'")
    return fmt


def sigma_um(value: float | None, option: str = "--sigma-um") -> float | None:
    """A distance's standard uncertainty in µm, within :data:`SIGMA_UM_RANGE`."""
    return quantity(value, option, lo=SIGMA_UM_RANGE[0], hi=SIGMA_UM_RANGE[1], unit="µm")


def offset_um(value: float, option: str = "--fix-offsets-um") -> float:
    """A held offset in µm, ``|value| <= OFFSET_UM_MAX``."""
    return quantity(value, option, lo=-OFFSET_UM_MAX, hi=OFFSET_UM_MAX, unit="µm")


def memory(nbytes: float, what: str) -> None:
    """Refuse a request that would need more than :data:`MEMORY_SHARE` of the physical memory."""
    limit = MEMORY_SHARE * physical_memory_bytes()
    if nbytes > limit:
        raise MultilatError(f"{what} would need about {_size(nbytes)} of memory, more than this machine "
                            f"can give ({_size(limit)}); ask for less")


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} PiB"  # pragma: no cover
