"""Exports in one long-lived process keep a flat memory line (issue 31, item 6): the
resident memory of a fresh process after 10 and after 25 ``crowd export`` runs of a
small crowd (``benchmarks/export_memory.py``) differ by less than 2 MB."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_25_exports_in_one_process_keep_a_flat_memory_line():
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "export_memory.py"),
                          "--exports", "25"], cwd=ROOT, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    figures = json.loads(run.stdout.strip().splitlines()[-1])
    print(figures)
    assert set(figures) == {"rss_mb_1", "rss_mb_10", "rss_mb_25"}
    assert figures["rss_mb_25"] - figures["rss_mb_10"] < 2.0, figures
