"""Parquet tables: the Crazyflie multisine flight (shared data, README section crazyflie_multisine;
no licence stated: read in place, never copied). Converted without a column map, every numeric
column must equal what pyarrow itself reads, NaN cells counted, the time column found by name."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from livesweep.convert import convert, sniff_format
from livesweep.telemetry.mcap_log import read_topics_fields

pytestmark = pytest.mark.slow                 # every test of this module takes over 1 s

_REL = Path("shared") / "data" / "crazyflie_multisine" / "multisine_20251017_run1.parquet"
DATA = next((p for p in (Path(__file__).resolve().parents[2] / _REL, Path("/work") / _REL) if p.is_file()), None)


def test_parquet_columns_convert_as_pyarrow_reads_them(tmp_path):
    if DATA is None:
        pytest.skip("Crazyflie parquet not found (shared/data/crazyflie_multisine)")
    pq = pytest.importorskip("pyarrow.parquet")
    ref = pq.read_table(DATA)
    assert sniff_format(DATA) == "parquet"
    res = convert(DATA, tmp_path / "cf.mcap")
    assert res.messages_written == ref.num_rows == 6000
    fields = ["t", "roll", "wx", "torque_roll", "x_r", "x_mocap"]
    got = read_topics_fields(tmp_path / "cf.mcap", {f"/table/{DATA.stem}": [*fields, "time_s"]})[f"/table/{DATA.stem}"]
    for f in fields:
        expected = ref.column(f).to_numpy(zero_copy_only=False).astype(float)
        np.testing.assert_allclose(got[f], expected, rtol=1e-6, atol=1e-9, equal_nan=True, err_msg=f)
    np.testing.assert_allclose(got["time_s"], ref.column("t").to_numpy(), atol=1e-9)
    n_nan = sum(int(np.isnan(ref.column(c).to_numpy(zero_copy_only=False).astype(float)).sum())
                for c in ref.column_names if c != "t")
    assert res.skipped.get("nonfinite_cells", 0) == n_nan
