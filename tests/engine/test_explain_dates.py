"""Explain judges ``date-effective``/``date-expires`` as the engine does: with the JVM's date
parser and its ``drools.dateformat`` mask, not a format of its own (a real JVM)."""

from __future__ import annotations

import os
import subprocess
import sys
from datetime import date

from gateway.engine.explain_reasons import held_back

TODAY = date(2026, 11, 28)


def test_held_back_reads_dates_as_drools_default_format_does():
    assert held_back({"enabled": "false", "date-effective": "1-Jan-2099"}, frozenset(), TODAY) == "it is disabled (enabled false)"
    assert held_back({"date-effective": "01-jan-2099"}, frozenset(), TODAY) == "it takes effect on 01-jan-2099 (date-effective)"
    assert held_back({"date-effective": "1-Jan-2020"}, frozenset(), TODAY).startswith("the fire limit")
    assert held_back({"date-expires": "28-Nov-2026"}, frozenset(), TODAY) == "it expired on 28-Nov-2026 (date-expires)"
    assert held_back({"date-expires": "29-Nov-2026"}, frozenset(), TODAY).startswith("the fire limit")
    assert held_back({"date-effective": "not a date"}, frozenset(), TODAY).startswith("the fire limit")


PROBE = """
from datetime import date
from gateway.base import jvm
from gateway.config import load_settings
from gateway.engine.explain_reasons import held_back
jvm.start(load_settings().jvm)
today = date(2026, 11, 28)
print(held_back({"date-effective": "2099-01-01"}, frozenset(), today))
print(held_back({"date-expires": "2020-01-01"}, frozenset(), today))
print(held_back({"date-effective": "1-Jan-2099"}, frozenset(), today))
"""


def test_held_back_reads_dates_with_the_engines_drools_dateformat():
    env = {**os.environ, "PRINTEPS_JVM_OPTIONS": "-Ddrools.dateformat=yyyy-MM-dd"}
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, out.stderr[-2000:]
    effective, expired, default_form = out.stdout.strip().splitlines()[-3:]
    assert effective == "it takes effect on 2099-01-01 (date-effective)"
    assert expired == "it expired on 2020-01-01 (date-expires)"
    assert default_form.startswith("the fire limit")  # not a date in this mask, as for the engine
