"""The Dask campaign example runs in CI on a LocalCluster (small grid): every task comes back, the
distributed results equal the same tasks run in one process, and the physics shows (the hot, soft
transmission lets the link lag and overshoot more than the cold one)."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples" / "python"))
import dask_campaign  # noqa: E402


def test_small_campaign_on_a_local_cluster_matches_one_process(tmp_path):
    report = dask_campaign.main(["--small", "--compare", "--workers", "2", "--out", str(tmp_path / "c.json")])
    assert report["points"] == 8 and len(report["results"]) == 8
    assert report["serial_matches"], "distributed and in-process results differ"
    by = {(r["temperature_c"], r["frequency_hz"], r["load_nm"]): r for r in report["results"]}
    for f in (0.5, 1.0):
        cold, hot = by[(22.0, f, 0.0)], by[(60.0, f, 0.0)]
        assert abs(hot["phase_deg"]) > abs(cold["phase_deg"]), (cold, hot)
        # |H| = |K + iωC| / |K − Jω² + iωC| grows as K falls: the softer link overshoots the motor more
        assert hot["amplitude_ratio"] > cold["amplitude_ratio"] > 1.0, (cold, hot)
    assert (tmp_path / "c.json").is_file()
