"""benchmarks/storage.py: each codec rewrites a file losslessly, and the page shows what was measured."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import storage  # noqa: E402
from piga.data.schema import read_sequences  # noqa: E402


def test_codecs_rewrite_losslessly_and_the_page_has_a_row_each(tiny_data: Path, tmp_path: Path) -> None:
    rows = storage.measure_codecs({"tiny": tiny_data}, tmp_path, repeats=1)
    assert [row["codec"] for row in rows] == list(storage.CODECS)
    expected = read_sequences(tiny_data, "train")[0]
    for row in rows:
        np.testing.assert_array_equal(read_sequences(tmp_path / "codecs" / f"tiny-{row['codec']}.h5", "train")[0], expected)
        assert row["write_mb_s"] > 0 and row["window_us_cold"] > 0 and row["window_us_block"] > 0
    by_codec = {row["codec"]: row for row in rows}
    assert by_codec["gzip-4"]["ratio"] > 3 * by_codec["none"]["ratio"]  # mostly background
    page = storage.markdown({"command": "c", "machine": {}, "default_codec": "gzip-4", "repeats": 1, "codecs": rows})
    assert page.count("| tiny (12 seq.) |") == len(storage.CODECS)


def test_a_repeated_file_keeps_its_split_pattern(tiny_data: Path, tmp_path: Path) -> None:
    storage.rewrite(tiny_data, tmp_path / "big.h5", "none", with_states=False, repeat=3)
    frames, _ = read_sequences(tmp_path / "big.h5", "test")
    np.testing.assert_array_equal(frames, np.concatenate([read_sequences(tiny_data, "test")[0]] * 3))
