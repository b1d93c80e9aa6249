"""The README's speed table is the benchmark's generated table, not typed by hand."""

import os
import re
import sys

ROOT = os.path.join(os.path.dirname(__file__), "..")
sys.path.insert(0, os.path.join(ROOT, "bench"))
import update_readme  # noqa: E402


def _readme():
    with open(os.path.join(ROOT, "README.md")) as f:
        return f.read()


def test_readme_speed_table_is_the_generated_file():
    with open(os.path.join(ROOT, "bench", "speed_table.md")) as f:
        table = f.read()
    assert update_readme.block(_readme()) == table.strip() + "\n"


def test_generated_table_has_every_case_with_median_p99_and_ratio():
    block = update_readme.block(_readme())
    lines = block.splitlines()
    assert lines[0] == ("| case | median | p99 | interleaved median | before (1f2d442) | speed-up "
                        "| target |")
    rows = [ln for ln in lines[2:] if ln.startswith("| ") and not ln.startswith("| segments")]
    cases = " ".join(rows)
    for case in (
        "forward one_segment",
        "forward two_segment",
        "inverse one_segment",
        "inverse two_segment",
    ):
        assert case in cases, case
    ms = re.compile(
        r"^\| .+ \| \d+\.\d\d ms \| \d+\.\d\d ms \| \d+\.\d\d ms \| \d+\.\d\d ms "
        r"\| \d+\.\dx \| .+ \|$"
    )
    for row in rows[:4]:
        assert ms.match(row), row
    # scaling table: n = 3, 6, 12, 24 for m = 1..4
    cells = [ln for ln in lines if re.match(r"^\| [1-4] \| (3|6|12|24) \| \d+ \|", ln)]
    assert len(cells) == 16


def test_splice_replaces_only_between_the_markers():
    text = f"head\n{update_readme.START}\nold\n{update_readme.END}\ntail\n"
    out = update_readme.splice(text, "| a |\n")
    assert out == f"head\n{update_readme.START}\n| a |\n{update_readme.END}\ntail\n"
