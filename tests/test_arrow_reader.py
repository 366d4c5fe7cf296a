"""Large observation CSVs read by ``pyarrow.csv`` (issue 29): the same observations as the strict reader
for a plain file, and any file outside the plain subset handed to the strict reader, which accepts it
or names its ``FILE:LINE``. The size threshold is lowered so that small files take the Arrow path."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pyarrow.csv")

from multilat.errors import MultilatError  # noqa: E402
from multilat.network.io import fastio, files  # noqa: E402
from multilat.network.io.files import read_observations, write_observations  # noqa: E402
from multilat.network.synthetic.generator import synthetic_network  # noqa: E402


@pytest.fixture
def arrow_everywhere(monkeypatch):
    monkeypatch.setattr(fastio, "ARROW_READ_ABOVE_BYTES", 0)
    monkeypatch.setattr(files, "FAST_READ_ABOVE_BYTES", 0)
    seen = []
    orig = fastio._plain_arrow

    def spy(*a, **k):
        try:
            out = orig(*a, **k)
        except Exception:
            seen.append("refused")
            raise
        seen.append("parsed")
        return out

    monkeypatch.setattr(fastio, "_plain_arrow", spy)
    return seen


def _strict(path, monkeypatch, **kw):
    """The strict reader alone (no fast path)."""
    with monkeypatch.context() as m:
        m.setattr(files, "FAST_READ_ABOVE_BYTES", 1 << 62)
        return read_observations(path, **kw)


def _same(a, b):
    assert a.station_ids == b.station_ids and a.target_ids == b.target_ids
    for k in ("station_index", "target_index", "distance_m", "sigma_m"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k


def test_plain_file_same_observations(tmp_path, monkeypatch, arrow_everywhere):
    obs = synthetic_network(5, population="shell", n_stations=6, n_targets=40).obs
    p = tmp_path / "obs.csv"
    write_observations(p, obs)
    fast = read_observations(p)
    assert arrow_everywhere == ["parsed"]
    _same(fast, _strict(p, monkeypatch))
    p3 = tmp_path / "obs3.csv"                     # three columns and a sigma option
    p3.write_text("\n".join(ln.rsplit(",", 1)[0] for ln in p.read_text().splitlines()) + "\n")
    _same(read_observations(p3, sigma_m=5e-6), _strict(p3, monkeypatch, sigma_m=5e-6))
    assert arrow_everywhere == ["parsed", "parsed"]


@pytest.mark.parametrize("row,accepted", [
    ('"S1",T1,1.5,5e-06', True),          # quoted id (and a repeated pair): the strict reader's business
    ("S1,T1,1_5,5e-06", False),           # Python's float reads 1_5, Arrow does not: the strict reader refuses
    ("S1,T1,nan,5e-06", False),
    ("S1,,1.5,5e-06", False),             # an empty id
    ("S1,T1,-1.5,5e-06", False),
    ("S1,S2,1.5,5e-06", False),           # an id both station and target
    ("", True),                            # a blank line
])
def test_outside_the_plain_subset_the_strict_reader_decides(tmp_path, monkeypatch, arrow_everywhere, row,
                                                            accepted):
    obs = synthetic_network(2, population="shell", n_stations=8, n_targets=400).obs
    p = tmp_path / "obs.csv"
    write_observations(p, obs)
    lines = p.read_text().splitlines()
    lines.insert(len(lines) - 3, row)             # past the first fastio.PROBE_BYTES: the Arrow path parses it
    assert p.stat().st_size > 1.2 * fastio.PROBE_BYTES
    p.write_text("\n".join(lines) + "\n")
    arrow_everywhere.clear()
    try:
        want = _strict(p, monkeypatch)
    except MultilatError as exc:
        assert not accepted
        with pytest.raises(MultilatError) as got:
            read_observations(p)
        assert str(got.value) == str(exc)      # the same FILE:LINE message
    else:
        assert accepted
        _same(read_observations(p), want)
    assert arrow_everywhere == ["refused"]      # the Arrow path saw the file first and handed it on
