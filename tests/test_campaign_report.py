"""``livesweep campaign report``: one HTML page of a campaign's test points, responses and parameters."""

import math
import re

import pytest

import livesweep.campaign
from livesweep.campaign.report import write_campaign_report
from livesweep.telemetry.mcap_log import read_messages


@pytest.mark.slow
def test_campaign_report_of_two_recordings(sitl_replays, tmp_path):
    recs = [sitl_replays["roll"].recording, sitl_replays["pitch"].recording]
    records = [m.data for r in recs for m in read_messages(r, topics="/livesweep/model")]
    assert records
    with livesweep.campaign.open(tmp_path / "c.db") as c:
        c.add(recs)
        tps = c.test_points()
        page = write_campaign_report(c, tmp_path / "out")
    text = page.read_text()
    assert page.name == "campaign.html" and "<script" not in text and "http://" not in text.replace(
        'xmlns="http://www.w3.org/2000/svg"', "")
    for t in tps:                                       # every test point has its row
        assert f"<tr data-tp='flight {t.flight_id} TP{t.number}'>" in text
    assert "no response recorded" in text
    for d in records:
        for pair in d["pairs"]:
            m = re.search(f"<figure data-pair='{re.escape(pair['name'])}'>(.*?)</figure>", text, re.S)
            assert m, pair["name"]
            svg = m.group(1)
            curve = pair["curve"]
            n = sum(1 for w, v in zip(curve["omega_rad_s"], curve["magnitude_db"])
                    if w is not None and v is not None and math.isfinite(v))
            # the recorded magnitude: the first line of the magnitude panel, labelled with its test point
            g = re.search(r'data-label="flight \d+ TP\d+"><polyline points="([^"]*)"', svg)
            assert g and len(g.group(1).split()) == n
            for q in pair["parameters"] + [f for f in pair["figures"] if f["value"] is not None]:
                printed = f"{q['value']:.4g}" + (f" ± {q['cramer_rao']:.2g}" if q["cramer_rao"] is not None else "")
                assert printed in text, q
                assert f"data-quantity='{q['name']}'" in text


@pytest.mark.slow
def test_campaign_report_command(sitl_replays, tmp_path, capsys):
    from livesweep.cli import main

    db = tmp_path / "c.db"
    with livesweep.campaign.open(db) as c:
        c.add([sitl_replays["roll"].recording])
    assert main(["campaign", "report", str(db), "--out", str(tmp_path / "o"), "--input", "roll",
                 "--condition", "magnitude"]) == 0
    assert "campaign.html" in capsys.readouterr().out
    text = (tmp_path / "o" / "campaign.html").read_text()
    assert "against magnitude" in text and "data-pair='p/roll'" in text and "pitch" not in text.split("<h2>Test")[1]
