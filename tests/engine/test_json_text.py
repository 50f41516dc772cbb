"""The Java helpers' JSON writer (Json.quote): a string is copied in one piece up to the first
character that needs an escape, then escaped character by character; every string must come
back as it went in, whatever it holds and wherever the escapes are."""

from __future__ import annotations

import json

import pytest

from gateway.base import jvm

TEXTS = ["", "plain", 'a "quoted" word', "back\\slash", "line\nbreak\r\n", "tab\tand \x01 control \x1f",
         '"', "\\", "\n", "üñï€ and 😀", 'end with a quote"', "x" * 500 + "\n" + "y" * 500]


@pytest.mark.parametrize("text", TEXTS)
def test_a_string_is_written_as_json_that_reads_back_the_same(text):
    jvm.start()
    written = str(jvm.helper_class("Json").toJson(text))
    assert json.loads(written) == text
    assert "\n" not in written and "\x01" not in written  # control characters are escaped
