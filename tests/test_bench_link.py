"""`marionette bench link` end to end (short run): both links deliver every
tick to the simulator process, and the report holds its figures."""
import json

from conftest import run_cli


def test_bench_link_reports_every_tick_on_both_links():
    result = run_cli("bench", "link", "--seconds", "1", "--json", timeout=120)
    assert result.returncode == 0, result.stderr
    r = json.loads(result.stdout)
    assert [x["link"] for x in r["links"]] == ["pty, serial protocol", "slcan on a pty, CAN mapping"]
    for x in r["links"]:
        assert x["ticks"] == 50 and x["received"] == 50, x
        assert 0 < x["p50_us"] <= x["p99_us"] <= x["max_us"], x
    c = r["codec"]
    assert c["encode_ticks_per_s"] > 0 and c["decode_frames_per_s"] > 0
    assert 0 < c["decode_vs_crc32"] < 1
    assert r["machine"]["cores"] >= 1
