"""The grammars are package data (repository folder grammars/ -> olp_compensate.grammars);
tests/test_packaging.py checks that a built wheel ships them."""

from __future__ import annotations

import pytest

from olp_compensate.data import data_folder
from olp_compensate.programs.rapid import reader as rapid
from olp_compensate.programs.vplus import reader as vplus
from olp_compensate.programs.grammar import grammar_text, parser


@pytest.mark.parametrize("name", ["rapid.lark", "vplus.lark"])
def test_grammar_text_is_the_shipped_file(name):
    text = grammar_text(name)
    assert "%ignore" in text
    assert text == (data_folder("grammars") / name).read_text("utf-8")


def test_parsers_are_built_once():
    a = parser("rapid.lark", rapid.Callbacks, ("start", "call"))
    assert parser("rapid.lark", rapid.Callbacks, ("start", "call")) is a
    assert parser("vplus.lark", vplus.Callbacks) is parser("vplus.lark", vplus.Callbacks)
